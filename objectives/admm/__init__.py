"""ADMM for compressed manifold modes (thesis Algorithm 3) and the fast approximation (Algorithms 7–8).

* ``splitting`` — ``admm`` and ``admm_sequential``: the splitting of the ℓ1 term from the orthogonality
  constraint, with ``ADMMOptions`` / ``ADMMResult``.
* ``rho`` — the rules for the penalty parameter ρ.
* ``fast`` — the fast approximation on a space of local functions.

The names of ``splitting`` are available here too (``from objectives.admm import admm``).
"""

from . import fast, rho, splitting
from .splitting import ADMMOptions, ADMMResult, admm, admm_sequential, l1_weights_np, orthonormalize, soft_threshold

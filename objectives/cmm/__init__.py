"""Compressed manifold modes: the front end and one small solver object per method.

* ``modes`` — ``compressed_modes(lap, k, mu, solver=...)``, ``select_mu``, ``CMMResult``.
* ``base`` — ``CMMSolver``, the interface every method implements; ``solvers`` — the registry.
* ``manifold_solvers`` — ``BlockCMM`` (the default) and ``SequentialCMM``, with ``newton`` (the Newton
  polish), ``saddle`` (saddle checks), ``padding`` (bucketed problem sizes) and ``active_set`` (its
  preconditioner).
* ``admm_solvers`` — ``ADMMCMM``, ``SequentialADMMCMM``, ``FastCMM`` on top of ``objectives.admm``.
* ``support_finish`` — exact zeros by a Newton finish on the identified support.
* ``batch`` — many solves under ``jax.vmap`` or as a loop; ``differentiable`` — ``cmm_solve``, a solve
  that ``jax.grad`` goes through.

The names of ``modes`` are available here too (``objectives.cmm.compressed_modes``).
"""

from .modes import (METHODS, SPARSITY_THRESHOLDS, WEIGHTINGS, CMMResult, compressed_modes, first_eigenpairs,
                    select_mu, unpack_laplacian)

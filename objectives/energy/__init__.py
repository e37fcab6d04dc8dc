"""The compressed-manifold-mode energy and its optimality (docs/maths.md §4, §9).

* ``smoothings`` — the ten ℓ1 smoothings of thesis Table 6.1 (``f0 … f9``).
* ``energies`` — Dirichlet energy, weighted ℓ1 terms, ``CMMEnergy``, compressed eigenvalues.
* ``l1_optimality`` — the exact ℓ1 stationarity residual and support statistics.
"""

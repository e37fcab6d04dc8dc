"""The solvers, first order and second order, and what drives them.

* ``linesearch`` — the strong Wolfe line search along a retraction curve.
* ``preconditioning`` — Riemannian preconditioning (``shifted_inverse``, ``PointPreconditioner``).
* ``block_steps`` — one iteration of Riemannian CG / L-BFGS / BB on the whole block ``X``;
  ``minimisers`` — the same as ``optimistix`` minimisers (``RiemannianCG``, ``RiemannianLBFGS``,
  ``RiemannianBB``); ``block_solver`` — ``minimize`` and the pure ``solve``.
* ``driver`` — compiled chunks of iterations, progress callbacks, interrupts.
* ``tcg``, ``trust_region`` — truncated CG and ``RiemannianTrustRegion``.
* ``saddle`` — the most negative curvature (a saddle test) and the step off a saddle.
* ``sequential`` — column-by-column solves (thesis Algorithm 6).
* ``penalty`` — the penalty-method baseline.
* ``sharding`` — the block solver with ``X`` split by rows over devices.
"""

"""Derivatives on the manifold and through its solves (docs/maths.md §9).

* ``hessian`` — the Riemannian Hessian as a function and as an operator.
* ``implicit`` — ``RiemannianImplicitAdjoint``: derivatives of solutions by the implicit function theorem.
* ``checks`` — Manopt-style slope tests: ``check_gradient``, ``check_hessian``, ``check_retraction``.
"""

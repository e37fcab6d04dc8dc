"""Linear algebra behind the manifolds and solvers: SPD operators and sparse factorisations.

* ``operators`` — ``LinearOperator`` and its kinds (identity, diagonal, dense, sparse), ``as_operator``.
* ``ell`` — the ELLPACK sparse product used by ``SparseOperator`` (batched under ``vmap``).
* ``sparse_factor`` — ``SymmetricFactor``: a sparse symmetric factorisation on the host (CHOLMOD or LDLᵀ).
* ``ffi_solve`` — sparse solves as CHOLMOD custom calls (through sparsax) inside compiled programs.
"""

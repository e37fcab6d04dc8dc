"""Test fixtures for the manifold layer: metric matrices of every kind and grid Laplacians."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

M_KINDS = ("diagonal", "dense", "sparse")


def metric_matrix(kind: str, n: int, seed: int = 0):
    """An SPD matrix of the given kind: a positive diagonal, a dense SPD matrix, or a sparse
    non-diagonal SPD matrix (a diagonally dominant tridiagonal "mass matrix")."""
    rng = np.random.default_rng(seed)
    if kind == "diagonal":
        return rng.uniform(0.5, 2.0, n)
    if kind == "dense":
        B = rng.standard_normal((n, n))
        return B @ B.T / n + np.eye(n)
    if kind == "sparse":
        off = rng.uniform(0.05, 0.2, n - 1)
        diag = rng.uniform(1.0, 2.0, n)
        return sp.diags([off, diag, off], [-1, 0, 1], format="csr")
    raise ValueError(kind)


def dense_of(M) -> np.ndarray:
    if sp.issparse(M):
        return M.toarray()  # tests only, small n
    M = np.asarray(M)
    return np.diag(M) if M.ndim == 1 else M


def grid_laplacian(m: int) -> sp.csr_matrix:
    """Graph Laplacian (Deg − Adj) of an m×m grid: PSD, one zero eigenvalue (constant)."""
    e = np.ones(m)
    path = sp.diags([-e[:-1], e, -e[:-1]], [-1, 0, 1]).tolil()
    path.setdiag(np.r_[1.0, 2.0 * np.ones(m - 2), 1.0])
    eye = sp.identity(m)
    return (sp.kron(path, eye) + sp.kron(eye, path)).tocsr()

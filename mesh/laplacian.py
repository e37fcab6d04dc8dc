"""Discrete Laplace–Beltrami operators ``L = A⁻¹W`` (thesis §2.5, docs/maths.md §7).

A ``Laplacian`` holds the weight matrix ``W`` (Ex. 2.5.22) and the area matrix
``A`` (Ex. 2.5.17) as ``scipy.sparse`` CSR matrices and, built on first use,
as jittable JAX operators (``stiefel.linalg.operators.SparseOperator`` for ``W`` and
a non-diagonal ``A``, ``DiagonalOperator`` for a diagonal ``A``).

Sign convention: ``W`` is the *positive* semi-definite weight matrix of
Def. 2.5.20 — positive diagonal, off-diagonal ``W_ij = 𝒲(v_i, v_j) ≤ 0`` where
the cotangent weights are positive, rows summing to zero. (libigl's
``cotmatrix`` returns ``−W``.)

Assembly is vectorised over faces (one ``coo → csr`` sum), O(m).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Literal

import numpy as np
import scipy.sparse as sp
from jaxtyping import Float

from .errors import NonManifoldError
from .io import Mesh, edges_of, face_areas

__all__ = [
    "Laplacian",
    "laplacian",
    "robust_laplacian",
    "cotangent_weights",
    "graph_weights",
    "area_matrix",
    "WEIGHTS",
    "AREAS",
]

Weights = Literal["cotangent", "graph", "uniform", "robust"]
Areas = Literal["lumped", "barycentric", "voronoi", "mixed", "fem", "uniform", "degree"]
WEIGHTS = ("cotangent", "graph", "uniform", "robust")
AREAS = ("lumped", "barycentric", "voronoi", "mixed", "fem", "uniform", "degree")


@dataclass(frozen=True, eq=False)
class Laplacian:
    """A discrete Laplacian ``L = A⁻¹W`` (Def. 2.5.23), stored as the pair ``(W, A)``.

    Attributes:
      W: ``(n, n)`` CSR weight matrix (symmetric, rows sum to 0).
      A: ``(n, n)`` CSR area matrix (diagonal unless ``area="fem"``).
      weights, area: the choices that built it.
      area_scale: the factor ``A`` was multiplied by (``1/Σ A_ij`` when
        normalised per Rem. 2.5.31, else 1). For cotangent weights this equals
        rescaling the vertices by ``sqrt(area_scale)``.
      n_negative_weights: number of edges whose weight ``𝒲(v_i, v_j) =
        −(cot α_ij + cot β_ij)/2`` is positive, i.e. ``cot α + cot β < 0``
        (``W_ij > 0``): the thesis's assumption under Ex. 2.5.22(i) fails there and
        the Geršgorin proof of Prop. 2.5.21 no longer applies. (The cotangent
        ``W`` is still PSD — it is the P1 stiffness matrix, ``fᵀWf = Σ_t area_t
        |∇f|²`` — but the sign pattern, hence the discrete maximum principle,
        is lost.) Use ``weights="robust"`` (intrinsic Delaunay) for non-negative weights.
        (Entries below ``1e-12·max|W|`` count as round-off.)
      extra: diagnostics; ``"nonpositive_areas"``: number of vertices whose area is
        ``≤ 0`` — possible only for ``area="voronoi"`` on meshes with obtuse
        triangles (Def. 2.5.14); such an ``A`` is not positive definite (use "mixed").
    """

    W: sp.csr_array
    A: sp.csr_array
    weights: str
    area: str
    area_scale: float
    n_negative_weights: int
    extra: dict = field(default_factory=dict, repr=False)

    @property
    def n(self) -> int:
        return int(self.W.shape[0])

    @property
    def is_diagonal_area(self) -> bool:
        A = self.A
        return bool(A.nnz == np.count_nonzero(A.diagonal()) and sp.triu(A, 1).nnz == 0)

    @property
    def mass_diagonal(self) -> Float[np.ndarray, " n"]:
        """Diagonal of ``A`` (for a non-diagonal ``A``: its lumped diagonal, Def. 2.5.18)."""
        return np.asarray(self.A.sum(axis=1)).reshape(-1)

    @cached_property
    def W_op(self):
        """``W`` as a jittable ``stiefel.linalg.operators.SparseOperator`` (dtype: float64 if x64 is on)."""
        return self.operators()[0]

    @cached_property
    def A_op(self):
        """``A`` as ``DiagonalOperator`` (diagonal A) or ``SparseOperator`` (FEM mass)."""
        return self.operators()[1]

    def operators(self, dtype=None, *, factor_area: bool = False):
        """Fresh JAX operators ``(W_op, A_op)`` with values of ``dtype``.

        ``factor_area=True`` factors a non-diagonal ``A`` so that ``A_op.solve`` works.
        """
        import jax.numpy as jnp

        from stiefel.linalg.operators import DiagonalOperator, SparseOperator

        W_op = SparseOperator.from_scipy(self.W, factor=False, dtype=dtype)
        if self.is_diagonal_area:
            d = self.A.diagonal()
            A_op = DiagonalOperator(jnp.asarray(d, dtype=W_op.vals.dtype))
        else:
            A_op = SparseOperator.from_scipy(self.A, factor=factor_area, dtype=dtype)
        return W_op, A_op

    def dirichlet_energy(self, f: Float[np.ndarray, "n ..."]) -> Float[np.ndarray, "..."]:
        """``E(f) = fᵀWf`` (Def. 2.5.32, eq. 2.5.10), per column."""
        f = np.asarray(f)
        return np.einsum("i...,i...->...", f, self.W @ f)


def _corner_cotangents(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """``(m, 3)`` cotangent of the angle at each corner ``c`` of each face."""
    P = V[F]  # (m, 3, 3)
    a = P[:, [1, 2, 0]] - P  # to next corner
    b = P[:, [2, 0, 1]] - P  # to previous corner
    dot = np.einsum("mcd,mcd->mc", a, b)
    cross = np.linalg.norm(np.cross(a, b), axis=2)
    return dot / cross


def _assemble(rows: np.ndarray, cols: np.ndarray, vals: np.ndarray, n: int) -> sp.csr_array:
    M = sp.csr_array(sp.coo_array((vals, (rows, cols)), shape=(n, n)))
    M.sum_duplicates()
    M.sort_indices()
    return M


def _from_offdiagonal(rows: np.ndarray, cols: np.ndarray, w: np.ndarray, n: int) -> sp.csr_array:
    """``W = Ŵ − lump(Ŵ)`` (Def. 2.5.20) from symmetric off-diagonal entries ``Ŵ_ij = w``."""
    r = np.concatenate([rows, cols])
    c = np.concatenate([cols, rows])
    v = np.concatenate([w, w])
    diag = -np.bincount(r, weights=v, minlength=n)
    idx = np.arange(n)
    return _assemble(np.concatenate([r, idx]), np.concatenate([c, idx]), np.concatenate([v, diag]), n)


def cotangent_weights(m: Mesh) -> sp.csr_array:
    """Cotangent weight matrix, Ex. 2.5.22(i): ``W_ij = −(cot α_ij + cot β_ij)/2``.

    The angles are those opposite edge ``ij`` in its (one or two) faces: one
    term on a boundary edge. ``W_ii = −Σ_{j≠i} W_ij``. Shape ``(n, n)``.
    """
    cot = _corner_cotangents(m.vertices, m.faces)
    F = m.faces
    # corner c is opposite edge (c+1, c+2)
    i = F[:, [1, 2, 0]].ravel()
    j = F[:, [2, 0, 1]].ravel()
    return _from_offdiagonal(i, j, -0.5 * cot.ravel(), m.n_vertices)


def _adjacency(m: Mesh) -> sp.csr_array:
    """``Adj(N)`` (Def. 2.5.10 with docs/maths.md note 8): 1 where vertices share an edge, else 0."""
    e = edges_of(m.faces)
    n = m.n_vertices
    return _assemble(
        np.concatenate([e[:, 0], e[:, 1]]), np.concatenate([e[:, 1], e[:, 0]]), np.ones(2 * e.shape[0]), n
    )


def graph_weights(m: Mesh) -> sp.csr_array:
    """Graph weight matrix, Ex. 2.5.22(ii): ``W = Deg(N) − Adj(N)``, shape ``(n, n)``."""
    adj = _adjacency(m)
    deg = np.asarray(adj.sum(axis=1)).reshape(-1)
    return sp.csr_array(sp.diags_array(deg) - adj)


def _voronoi_corner_areas(V: np.ndarray, F: np.ndarray, cot: np.ndarray) -> np.ndarray:
    """``(m, 3)`` circumcentric (Voronoi) area of each face assigned to each corner.

    For corner ``c`` with neighbours ``a`` (next) and ``b`` (previous):
    ``(|e_ca|² cot∠b + |e_cb|² cot∠a) / 8`` (Meyer et al.); sums to the face
    area, negative parts possible on obtuse faces (Def. 2.5.14).
    """
    P = V[F]
    nxt = [1, 2, 0]
    prv = [2, 0, 1]
    len_next = np.sum((P[:, nxt] - P) ** 2, axis=2)  # |e_{c, c+1}|²
    len_prev = np.sum((P[:, prv] - P) ** 2, axis=2)  # |e_{c, c-1}|²
    # edge (c, c+1) is opposite corner c-1 (= prv), edge (c, c-1) is opposite corner c+1
    return (len_next * cot[:, prv] + len_prev * cot[:, nxt]) / 8.0


def _mixed_corner_areas(V: np.ndarray, F: np.ndarray, cot: np.ndarray, areas: np.ndarray) -> np.ndarray:
    """``(m, 3)`` mixed Voronoi corner areas (Def. 2.5.15, Meyer et al. 2003).

    Non-obtuse face: Voronoi areas. Obtuse face: ``area/2`` at the obtuse
    corner, ``area/4`` at the other two.
    """
    vor = _voronoi_corner_areas(V, F, cot)
    obtuse_corner = cot < 0  # cot of an obtuse angle is negative
    obtuse_face = obtuse_corner.any(axis=1)
    alt = np.where(obtuse_corner, 0.5, 0.25) * areas[:, None]
    return np.where(obtuse_face[:, None], alt, vor)


def area_matrix(m: Mesh, area: Areas = "lumped") -> sp.csr_array:
    """Unnormalised area matrix, Ex. 2.5.17, shape ``(n, n)``.

    * ``"uniform"``: ``I`` (i; normalisation makes it ``I/n``).
    * ``"barycentric"``: ``⅓ Σ_{t∋i} area(t)`` (ii, Def. 2.5.13).
    * ``"voronoi"``: circumcentric cell areas (iii, Def. 2.5.14).
    * ``"mixed"``: mixed Voronoi cell areas (iii, Def. 2.5.15).
    * ``"degree"``: ``Deg(N)`` (iv).
    * ``"fem"``: FEM mass, ``⅙ Σ_{t∋i} area(t)`` on the diagonal and
      ``(area(t_ij) + area(t̄_ij))/12`` off it (v); not diagonal.
    * ``"lumped"``: the lumped FEM mass (Def. 2.5.18), equal to barycentric.
    """
    n = m.n_vertices
    V, F = m.vertices, m.faces
    idx = np.arange(n)
    if area == "uniform":
        return _assemble(idx, idx, np.ones(n), n)
    if area == "degree":
        deg = np.asarray(_adjacency(m).sum(axis=1)).reshape(-1)
        return _assemble(idx, idx, deg, n)
    areas = face_areas(V, F)
    if area == "barycentric":
        d = np.bincount(F.ravel(), weights=np.repeat(areas / 3.0, 3), minlength=n)
        return _assemble(idx, idx, d, n)
    if area in ("fem", "lumped"):
        diag_r = F.ravel()
        diag_v = np.repeat(areas / 6.0, 3)
        off_r = F[:, [0, 1, 2, 1, 2, 0]].ravel()
        off_c = F[:, [1, 2, 0, 0, 1, 2]].ravel()
        off_v = np.repeat(areas / 12.0, 6)
        M = _assemble(np.concatenate([diag_r, off_r]), np.concatenate([diag_r, off_c]), np.concatenate([diag_v, off_v]), n)
        if area == "fem":
            return M
        return _assemble(idx, idx, np.asarray(M.sum(axis=1)).reshape(-1), n)
    if area in ("voronoi", "mixed"):
        cot = _corner_cotangents(V, F)
        if area == "voronoi":
            corner = _voronoi_corner_areas(V, F, cot)
        else:
            corner = _mixed_corner_areas(V, F, cot, areas)
        d = np.bincount(F.ravel(), weights=corner.ravel(), minlength=n)
        return _assemble(idx, idx, d, n)
    raise ValueError(f"unknown area {area!r}; choose one of {AREAS}")


def laplacian(
    m: Mesh,
    *,
    weights: Weights = "cotangent",
    area: Areas = "lumped",
    normalize_area: bool = True,
    mollify_factor: float = 1e-5,
) -> Laplacian:
    """Build a discrete Laplacian ``L = A⁻¹W`` (Def. 2.5.23) for mesh ``m``.

    Args:
      m: the mesh (``n`` vertices).
      weights: ``"cotangent"`` (Ex. 2.5.22(i)), ``"graph"`` / ``"uniform"``
        (both ``Deg − Adj``, Ex. 2.5.22(ii); the graph and uniform Laplacians of
        Ex. 2.5.24(i–ii) differ in the area: use ``area="uniform"`` resp.
        ``area="degree"``), or ``"robust"`` (intrinsic-Delaunay cotangent
        weights on the tufted cover, via the ``robust_laplacian`` package;
        the area is then that package's lumped mass unless ``area`` is set to
        something other than ``"lumped"``).
      area: see ``area_matrix`` (Ex. 2.5.17). ``"fem"`` with cotangent weights is
        the FEM Laplacian (Ex. 2.5.24(iv)).
      normalize_area: scale ``A`` so its entries sum to 1 (Rem. 2.5.31).
      mollify_factor: passed to ``robust_laplacian`` (``weights="robust"`` only).

    Returns:
      a ``Laplacian``.

    Raises:
      NonManifoldError: cotangent weights on a mesh with edges shared by more
        than two faces (``load(..., allow_nonmanifold=True)``); use ``"robust"``.
    """
    if weights not in WEIGHTS:
        raise ValueError(f"unknown weights {weights!r}; choose one of {WEIGHTS}")
    if area not in AREAS:
        raise ValueError(f"unknown area {area!r}; choose one of {AREAS}")
    extra: dict = {}
    if weights == "cotangent" and not m.is_edge_manifold:
        raise NonManifoldError(
            f"the mesh has {m.n_nonmanifold_edges} non-manifold edge(s) (loaded with allow_nonmanifold=True): "
            "cotangent weights assume at most two faces per edge; use weights='robust' (mesh.robust_laplacian; "
            "--laplacian robust on the command line) or weights='graph'"
        )
    if weights == "robust":
        W, A_robust = _robust(m, mollify_factor)
        A = A_robust if area == "lumped" else area_matrix(m, area)
    else:
        W = cotangent_weights(m) if weights == "cotangent" else graph_weights(m)
        A = area_matrix(m, area)
    total = float(A.sum())
    if not total > 0:
        raise ValueError(f"area matrix {area!r} has non-positive total {total:.3e}; the mesh is degenerate")
    scale = 1.0 / total if normalize_area else 1.0
    if scale != 1.0:
        A = sp.csr_array(A * scale)
    if np.any(A.diagonal() <= 0):
        k = int(np.sum(A.diagonal() <= 0))
        extra["nonpositive_areas"] = k
    off = sp.triu(W, 1)
    tol = 1e-12 * (float(np.max(np.abs(W.data))) if W.nnz else 0.0)  # ignore round-off
    n_neg = int(np.sum(off.data > tol))
    return Laplacian(W=W, A=A, weights=weights, area=area, area_scale=scale, n_negative_weights=n_neg, extra=extra)


def _robust(m: Mesh, mollify_factor: float) -> tuple[sp.csr_array, sp.csr_array]:
    import robust_laplacian as rl

    L, M = rl.mesh_laplacian(np.asarray(m.vertices), np.asarray(m.faces), mollify_factor=mollify_factor)
    W = sp.csr_array(L, dtype=np.float64)
    W.sum_duplicates()
    W.sort_indices()
    if W.diagonal().sum() < 0:  # normalise the package's sign to our PSD convention
        W = -W
    A = sp.csr_array(M, dtype=np.float64)
    return W, A


def robust_laplacian(m: Mesh, *, normalize_area: bool = True, mollify_factor: float = 1e-5) -> Laplacian:
    """The intrinsic-Delaunay ("tufted cover") Laplacian of Sharp & Crane (2020) via ``robust_laplacian``.

    Its weights are non-negative (``n_negative_weights == 0`` up to round-off),
    so ``W ⪰ 0`` even where the plain cotangent Laplacian has obtuse pairs.
    """
    return laplacian(m, weights="robust", area="lumped", normalize_area=normalize_area, mollify_factor=mollify_factor)

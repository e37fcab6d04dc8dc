"""Differentiable JAX assembly of the cotangent Laplacian pair ``(W, A)`` (thesis §2.5, docs/maths.md §7).

``laplacian_jax(V, F, area)`` returns the matrices of ``mesh.laplacian(m, weights="cotangent",
area=area)`` as ``jax.experimental.sparse.BCOO``, with values that are a jittable, differentiable
(``jax.grad`` / ``jax.jvp``) function of the vertex positions ``V``. The faces ``F`` are host data:
they are validated with numpy and give a fixed sparsity pattern (CSR order, duplicates merged,
cached per distinct ``F``), so under ``jit`` only ``V`` is traced and the values are summed into
that pattern with one ``segment_sum``. The value computations are themselves jitted with the
pattern static, so eager calls compile once per distinct ``F`` (and area type). Nothing is densified; no Python loop runs over
vertices or faces.

Conventions are those of ``mesh.laplacian``: ``W`` is the *positive* semi-definite cotangent
stiffness (positive diagonal, rows summing to zero), ``A`` diagonal and, with ``normalize_area``,
scaled to total area 1 (Rem. 2.5.31; ``W`` is not rescaled). Values take ``V``'s dtype: float64
needs the caller's ``jax_enable_x64`` — this module never changes JAX's config.

Jit by closing over the faces: ``jax.jit(lambda V: laplacian_jax(V, F, "mixed"))``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from jax.experimental.sparse import BCOO
from jaxtyping import Array, Float, Int

from stiefel.validation import checked_finite

from .errors import (DegenerateMeshError, EmptyMeshError, IndexOutOfRangeError, MeshError, NonFiniteVerticesError,
                     NonTriangleFacesError)

__all__ = ["laplacian_jax", "mass_diagonal_jax", "weight_operator_jax", "AREAS_JAX"]

AREAS_JAX = ("lumped", "barycentric", "voronoi", "mixed")
_NEXT = np.array([1, 2, 0])
_PREV = np.array([2, 0, 1])


@dataclass(frozen=True, eq=False)
class _Pattern:
    """Host-side sparsity pattern of ``W`` for one face array (all numpy).

    ``indices (nnz, 2)``: the CSR-ordered ``(row, col)`` entries of ``W`` (every edge both ways
    and every diagonal); ``segment (12m,)``: the entry each per-corner contribution of
    ``_weight_values`` is summed into.
    """

    n: int
    faces: np.ndarray  # (m, 3) int32
    indices: np.ndarray  # (nnz, 2) int32
    segment: np.ndarray  # (12m,) int32

    @functools.cached_property
    def ell(self) -> tuple[np.ndarray, np.ndarray]:
        """``(cols (n, w), slot (nnz,))``: the ELL layout of ``stiefel.linalg.operators.SparseOperator``."""
        rows = self.indices[:, 0]
        start = np.searchsorted(rows, np.arange(self.n))
        slot = np.arange(rows.size) - start[rows]
        width = max(int(slot.max(initial=0)) + 1, 1)
        cols = np.tile(np.arange(self.n, dtype=np.int32)[:, None], (1, width))
        cols[rows, slot] = self.indices[:, 1]
        return cols, slot


@functools.lru_cache(maxsize=16)
def _pattern_cached(n: int, m: int, face_bytes: bytes) -> _Pattern:
    F = np.frombuffer(face_bytes, dtype=np.int64).reshape(m, 3)
    i, j = F[:, _NEXT].ravel(), F[:, _PREV].ravel()  # corner c is opposite edge (c+1, c+2)
    rows = np.concatenate([i, j, i, j])
    cols = np.concatenate([j, i, i, j])
    diag = np.arange(n, dtype=np.int64) * (n + 1)  # every diagonal stored, as in mesh.laplacian
    keys, inverse = np.unique(np.concatenate([rows * n + cols, diag]), return_inverse=True)
    indices = np.stack([keys // n, keys % n], axis=1).astype(np.int32)
    return _Pattern(n, F.astype(np.int32), indices, inverse[: rows.size].astype(np.int32))


def _validate(V, F, area: str) -> tuple[Array, _Pattern]:
    """Check ``V``, ``F`` and ``area`` on the host (before any tracing); return ``V`` and the pattern."""
    if area not in AREAS_JAX:
        raise MeshError(
            f"unknown area {area!r} for laplacian_jax; choose one of {AREAS_JAX} (for 'fem', which is "
            "not diagonal, and 'uniform' or 'degree', which do not depend on V, use mesh.laplacian)"
        )
    V = jnp.asarray(V)
    if V.ndim != 2 or V.shape[1] != 3:
        raise MeshError(f"V must have shape (n, 3), got {V.shape}; pass one row of xyz coordinates per vertex")
    if not jnp.issubdtype(V.dtype, jnp.floating):
        raise MeshError(f"V must be a floating array, got dtype {V.dtype}; convert it with V.astype(float)")
    if isinstance(F, jax.core.Tracer):
        raise TypeError(
            "F must be concrete (numpy), not traced: close over it, e.g. jax.jit(lambda V: laplacian_jax(V, F))"
        )
    F = np.asarray(F)
    if F.ndim != 2 or F.shape[1] != 3:
        raise NonTriangleFacesError(f"F must have shape (m, 3), got {F.shape}; triangulate the mesh (mesh.load does)")
    if not np.issubdtype(F.dtype, np.integer):
        raise MeshError(f"F must hold integer vertex indices, got dtype {F.dtype}; convert it with F.astype(int)")
    n, m = V.shape[0], F.shape[0]
    if n == 0 or m == 0:
        raise EmptyMeshError(f"the mesh has {n} vertices and {m} faces; a Laplacian needs at least one triangle")
    bad = (F < 0) | (F >= n)
    if bad.any():
        f = int(np.argmax(bad.any(axis=1)))
        raise IndexOutOfRangeError(
            f"{int(bad.sum())} face indices outside [0, {n}), e.g. face {f} = {F[f].tolist()}; "
            "check that F indexes the rows of V (0-based)"
        )
    rep = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 2] == F[:, 0])
    if rep.any():
        f = int(np.argmax(rep))
        raise DegenerateMeshError(
            f"{int(rep.sum())} faces repeat a vertex, e.g. face {f} = {F[f].tolist()}; their cotangents "
            "are undefined: clean the mesh first (mesh.load removes such faces)"
        )
    # a NaN or infinite coordinate is named here, as V (not later through W or the area it spoils); traced V: the
    # host check when its value is known (e.g. under jax.grad), else a runtime check (eqx.error_if)
    V = checked_finite("V", V, error=NonFiniteVerticesError)
    return V, _pattern_cached(n, m, np.ascontiguousarray(F, dtype=np.int64).tobytes())


def _corners(V: Float[Array, "n 3"], F: Int[np.ndarray, "m 3"]):
    """Per-corner edge vectors: ``a`` to the next corner, ``b`` to the previous, each ``(m, 3, 3)``."""
    P = V[F]
    return P[:, _NEXT] - P, P[:, _PREV] - P


def _cot_and_double_area(a: Float[Array, "m 3 3"], b: Float[Array, "m 3 3"]):
    """``cot (m, 3)`` of each corner angle, as ``⟨a, b⟩ / |a × b|`` (finite and smooth on any
    non-degenerate face), and ``|a × b| (m, 3)`` (twice the face area, per corner)."""
    cross = jnp.cross(a, b)
    double_area = jnp.sqrt(jnp.sum(cross * cross, axis=-1))
    return jnp.sum(a * b, axis=-1) / double_area, double_area


@functools.partial(jax.jit, static_argnames="pat")
def _weight_values(V: Float[Array, "n 3"], pat: _Pattern) -> Float[Array, " nnz"]:
    """Values of ``W`` on ``pat.indices``: Ex. 2.5.22(i), ``W_ij = −(cot α_ij + cot β_ij)/2``,
    ``W_ii = −Σ_{j≠i} W_ij``. Each corner adds ``∓cot/2`` at ``(i, j)``, ``(j, i)``, ``(i, i)``,
    ``(j, j)`` for its opposite edge ``(i, j)`` (one term on a boundary edge)."""
    cot, _ = _cot_and_double_area(*_corners(V, pat.faces))
    h = 0.5 * cot.ravel()
    contrib = jnp.concatenate([-h, -h, h, h])
    return jax.ops.segment_sum(contrib, pat.segment, num_segments=pat.indices.shape[0])


def _corner_areas(V: Float[Array, "n 3"], F: Int[np.ndarray, "m 3"], area: str) -> Float[Array, "m 3"]:
    """Area of each face assigned to each of its corners (Ex. 2.5.17), ``(m, 3)``.

    * ``"lumped"`` = ``"barycentric"``: ``area(t)/3`` (Def. 2.5.13, 2.5.18).
    * ``"voronoi"``: ``(|e_{c,c+1}|² cot∠(c−1) + |e_{c,c−1}|² cot∠(c+1)) / 8`` (Def. 2.5.14, Meyer et al.).
    * ``"mixed"``: Voronoi on non-obtuse faces; on obtuse ones ``area/2`` at the obtuse
      corner and ``area/4`` at the others (Def. 2.5.15).
    """
    a, b = _corners(V, F)
    cot, double_area = _cot_and_double_area(a, b)
    face = 0.5 * double_area[:, :1]  # |(v1 − v0) × (v2 − v0)| / 2, as mesh.face_areas
    if area in ("lumped", "barycentric"):
        return jnp.broadcast_to(face / 3.0, cot.shape)
    len_next = jnp.sum(a * a, axis=-1)
    len_prev = jnp.sum(b * b, axis=-1)
    vor = (len_next * cot[:, _PREV] + len_prev * cot[:, _NEXT]) / 8.0
    if area == "voronoi":
        return vor
    obtuse_corner = cot < 0
    alt = jnp.where(obtuse_corner, 0.5, 0.25) * face
    return jnp.where(jnp.any(obtuse_corner, axis=1, keepdims=True), alt, vor)


def _kind(area: str) -> str:
    return "lumped" if area == "barycentric" else area  # one compiled variant for both names


@functools.partial(jax.jit, static_argnames=("pat", "area", "normalize_area"))
def _mass_diagonal(V: Float[Array, "n 3"], pat: _Pattern, area: str, normalize_area: bool) -> Float[Array, " n"]:
    """``A_ii = Σ_{t∋i} area_i(t)`` (``(n,)``), divided by ``Σ_i A_ii`` when ``normalize_area``."""
    corner = _corner_areas(V, pat.faces, area)
    d = jax.ops.segment_sum(corner.ravel(), pat.faces.ravel(), num_segments=pat.n)
    if normalize_area:
        d = d * (1.0 / jnp.sum(d))  # Rem. 2.5.31: A only, as mesh.laplacian
    return d


def mass_diagonal_jax(
    V: Float[Array, "n 3"], F: Int[np.ndarray, "m 3"], area: str = "lumped", *, normalize_area: bool = True
) -> Float[Array, " n"]:
    """Diagonal of the area matrix ``A`` (Ex. 2.5.17) as a dense ``(n,)`` array, differentiable in ``V``.

    ``A_ii = Σ_{t∋i} area_i(t)`` with the corner areas of ``area`` (see ``laplacian_jax``);
    with ``normalize_area`` divided by ``Σ_i A_ii`` (Rem. 2.5.31), so ``Σ_i A_ii = 1``.
    """
    V, pat = _validate(V, F, area)
    return _mass_diagonal(V, pat, _kind(area), normalize_area)


def laplacian_jax(
    V: Float[Array, "n 3"], F: Int[np.ndarray, "m 3"], area: str = "lumped", *, normalize_area: bool = True
) -> tuple[BCOO, BCOO]:
    """Cotangent Laplacian ``L = A⁻¹W`` (Def. 2.5.23) as a pair of ``(n, n)`` BCOO matrices.

    Same values as ``mesh.laplacian(m, weights="cotangent", area=area, normalize_area=...)``,
    as a jittable, differentiable function of ``V``.

    Args:
      V: ``(n, 3)`` vertex positions (may be traced).
      F: ``(m, 3)`` integer faces, concrete (numpy): validated on the host, they fix the pattern.
      area: ``"lumped"`` (= ``"barycentric"``), ``"voronoi"`` or ``"mixed"`` (see ``area_matrix``).
      normalize_area: scale ``A`` to total area 1 (Rem. 2.5.31); ``W`` is unchanged.

    Returns:
      ``(W, A)``: ``W`` the cotangent stiffness, Ex. 2.5.22(i),
      ``W_ij = −(cot α_ij + cot β_ij)/2``, ``W_ii = −Σ_{j≠i} W_ij`` (positive semi-definite; CSR
      order, one stored entry per edge direction and diagonal); ``A`` diagonal (``n`` entries).

    Raises:
      MeshError (or a subclass): wrong shapes or dtypes, face indices outside ``[0, n)``, faces
      repeating a vertex, an unknown ``area``. TypeError: ``F`` is traced.
    """
    V, pat = _validate(V, F, area)
    n = pat.n
    W = BCOO((_weight_values(V, pat), jnp.asarray(pat.indices)), shape=(n, n), indices_sorted=True, unique_indices=True)
    diag = jnp.stack([jnp.arange(n, dtype=jnp.int32)] * 2, axis=1)
    d = _mass_diagonal(V, pat, _kind(area), normalize_area)
    A = BCOO((d, diag), shape=(n, n), indices_sorted=True, unique_indices=True)
    return W, A


def weight_operator_jax(V: Float[Array, "n 3"], F: Int[np.ndarray, "m 3"]):
    """``W`` of ``laplacian_jax`` as a ``stiefel.linalg.operators.SparseOperator`` (ELL layout), differentiable in ``V``.

    ``W (n, n)`` as ``cols, vals (n, w)``, ``w`` the largest row length, padded with column ``i``
    and value 0. Only ``mv`` and ``diagonal`` work: it holds no host CSR copy (``to_scipy``) and
    no factor (``solve``), since its values may be traced.
    """
    from stiefel.linalg.operators import SparseOperator

    V, pat = _validate(V, F, "lumped")
    cols, slot = pat.ell
    vals = jnp.zeros(cols.shape, V.dtype).at[pat.indices[:, 0], slot].set(_weight_values(V, pat))
    return SparseOperator(cols=jnp.asarray(cols), vals=vals)

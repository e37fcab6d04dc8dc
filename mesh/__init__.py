"""Triangle meshes and their discrete Laplacians (thesis §2.5, §4.1, §7.1; docs/maths.md §6–8).

The mesh layer knows nothing of optimisation. Public API:

* ``load(source, *, allow_nonmanifold=False, ...) -> Mesh`` — path (OBJ/OFF/PLY/STL,
  optionally ``.gz``; read strictly), ``trimesh.Trimesh`` or ``(vertices, faces)``;
  validates, cleans and reports (``Mesh.report``: ``CleaningReport`` with
  ``lines()`` and ``as_dict()``), records topology (components, boundary loops,
  Euler characteristic, non-manifold edges/vertices). Bad input raises a
  ``MeshError`` subclass (``MeshFormatError`` with ``path:line:``, ``EmptyMeshError``,
  ``NonFiniteVerticesError``, ``MeshScaleError``, ``NonTriangleFacesError``,
  ``NonManifoldError``, ``IndexOutOfRangeError``, ``DegenerateMeshError``); changes
  warn once (``MeshCleaningWarning``), several components too (``MultipleComponentsWarning``).
* ``laplacian(m, weights=, area=, normalize_area=True) -> Laplacian`` — ``W``, ``A`` as
  scipy CSR and as JAX operators (``lap.W_op``, ``lap.A_op``); ``robust_laplacian(m)``.
* ``laplacian_jax(V, F, area=, normalize_area=True) -> (W, A)`` — the cotangent pair as BCOO,
  differentiable in ``V`` and jittable; ``mass_diagonal_jax``, ``weight_operator_jax``.
* ``example(name)`` — generated example surfaces (``bumpy``, ``starfish``, ``torus``, ``patch``;
  ``mesh.examples``), so examples run without any mesh file; ``example_arrays(name)`` gives ``(V, F)``.
* ``eigenbasis(lap, k) -> Eigenbasis(evals (k,), evecs (n, k))`` — ``Wφ = λAφ``, A-orthonormal.
* Descriptors (§4.1): ``geodesic_distance``, ``geodists``, ``deltas``, ``normdist``,
  ``hks``, ``wks``, ``constant``, ``vertex_positions``, ``extremal_points``,
  ``central_points``, ``landmarks``, ``scaled_to_unit_area``.
* Sampling (§7.1): ``poisson_disk_sample``, ``local_functions -> LocalFunctions(U, radii, …)``,
  ``local_distance`` (the Euclidean-corrected Dijkstra distance), ``SamplingError``.
* Permutations and isometry (Def. 3.4.8): ``permute``, ``reorder`` (reverse
  Cuthill–McKee, opt-in), ``inverse_permutation``, ``permutation_matrix``,
  ``is_isometric``, ``isometry_defect``.

Conventions: ``W`` is positive semi-definite (Def. 2.5.20; libigl's cotmatrix is
``−W``); areas sum to 1 when ``normalize_area``; float64 numpy/scipy on the host,
JAX operators use float64 only if the caller enabled ``jax_enable_x64``.
"""

from .descriptors import (central_points, constant, deltas, edge_graph, extremal_points, geodesic_distance, geodists, hks, hks_times, landmarks, normdist, scaled_to_unit_area, vertex_positions, wks, wks_energies)
from .eigen import Eigenbasis, eigenbasis
from .examples import EXAMPLES, ExampleError, example, example_arrays
from .errors import (DegenerateMeshError, EmptyMeshError, IndexOutOfRangeError, MeshCleaningWarning, MeshError, MeshFormatError, MeshScaleError, MultipleComponentsWarning, NonFiniteVerticesError, NonManifoldError, NonTriangleFacesError)
from .io import CleaningReport, Mesh, face_areas, load
from .isometry import is_isometric, isometry_defect
from .laplacian import AREAS, WEIGHTS, Laplacian, area_matrix, laplacian, robust_laplacian
from .laplacian_jax import laplacian_jax, mass_diagonal_jax, weight_operator_jax
from .ordering import inverse_permutation, permutation_matrix, permute, reorder
from .sampling import LocalFunctions, SamplingError, local_distance, local_functions, poisson_disk_sample
from .segmentation import (SegmentMatch, SegmentMatchError, Segmentation, SegmentationError, match_segments, persistence_segmentation, segment_indicators)

__all__ = [
    "AREAS",
    "WEIGHTS",
    "CleaningReport",
    "DegenerateMeshError",
    "Eigenbasis",
    "EmptyMeshError",
    "IndexOutOfRangeError",
    "Laplacian",
    "LocalFunctions",
    "SamplingError",
    "Mesh",
    "MeshCleaningWarning",
    "MeshError",
    "MeshFormatError",
    "MeshScaleError",
    "MultipleComponentsWarning",
    "NonFiniteVerticesError",
    "NonManifoldError",
    "NonTriangleFacesError",
    "area_matrix",
    "central_points",
    "constant",
    "deltas",
    "edge_graph",
    "eigenbasis",
    "EXAMPLES",
    "ExampleError",
    "example",
    "example_arrays",
    "extremal_points",
    "face_areas",
    "geodesic_distance",
    "geodists",
    "hks",
    "hks_times",
    "inverse_permutation",
    "is_isometric",
    "isometry_defect",
    "landmarks",
    "laplacian",
    "laplacian_jax",
    "load",
    "local_distance",
    "local_functions",
    "mass_diagonal_jax",
    "normdist",
    "permutation_matrix",
    "permute",
    "poisson_disk_sample",
    "reorder",
    "robust_laplacian",
    "scaled_to_unit_area",
    "SegmentMatch",
    "SegmentMatchError",
    "Segmentation",
    "SegmentationError",
    "match_segments",
    "persistence_segmentation",
    "segment_indicators",
    "vertex_positions",
    "wks",
    "weight_operator_jax",
    "wks_energies",
]

"""SEG descriptors: persistence-based segmentation and segment indicators (thesis §4.1, §5.3.1)."""

from __future__ import annotations

import functools
import time

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
import trimesh

import mesh
from mesh.segmentation import SegmentationError, SegmentMatchError
from mesh_fixtures import surface, two_spheres
from objectives.evaluation import reconstruct
from objectives.fmaps import functional_map


def _arm_directions(arms):
    return np.array([[np.cos(np.deg2rad(el)) * np.cos(np.deg2rad(az)),
                      np.cos(np.deg2rad(el)) * np.sin(np.deg2rad(az)), np.sin(np.deg2rad(el))] for az, el, _ in arms])


@functools.lru_cache(maxsize=None)
def armed_sphere(arms: tuple, subdivisions: int = 3) -> mesh.Mesh:
    """A sphere of radius 0.5 with smooth arms ``(azimuth°, elevation°, length)`` (as ``mesh.example('starfish')``)."""
    s = trimesh.creation.icosphere(subdivisions=subdivisions)
    u = np.asarray(s.vertices, dtype=np.float64)
    r = 0.5 + sum(length * np.exp(-(1.0 - u @ d) / 0.06) for d, (_, _, length) in zip(_arm_directions(arms), arms))
    return mesh.load((u * r[:, None], np.asarray(s.faces)), warn=False)


THREE = ((0.0, 0.0, 1.0), (120.0, 20.0, 0.8), (240.0, -20.0, 0.6))
TWO = ((0.0, 0.0, 1.0), (180.0, 0.0, 0.6))
SYMMETRIC = ((0.0, 0.0, 0.8), (180.0, 0.0, 0.8))


def _tips(m: mesh.Mesh, arms) -> np.ndarray:
    """The vertex furthest along each arm."""
    return np.argmax(m.vertices @ _arm_directions(arms).T, axis=0)


def _smooth_random(m: mesh.Mesh, seed: int, k: int = 20) -> np.ndarray:
    """A generic smooth function without ties: a random mix of low eigenfunctions."""
    B = _basis(m, k)
    return B.evecs @ np.random.default_rng(seed).standard_normal(k)


_BASES: dict = {}


def _basis(m: mesh.Mesh, k: int):
    key = (id(m), k)
    if key not in _BASES:
        _BASES[key] = (m, mesh.eigenbasis(mesh.laplacian(m), k))
    return _BASES[key][1]


def _assert_partition(m: mesh.Mesh, seg: mesh.Segmentation) -> None:
    """Labels cover ``0 … s−1``, each segment is edge-connected and holds its peak as the maximum of f."""
    lab, s = seg.labels, seg.n_segments
    assert lab.shape == (m.n_vertices,) and lab.dtype == np.int64
    assert np.array_equal(np.unique(lab), np.arange(s))
    e = m.edges
    same = lab[e[:, 0]] == lab[e[:, 1]]
    G = sp.coo_array((np.ones(same.sum()), (e[same, 0], e[same, 1])), shape=(m.n_vertices,) * 2)
    n_comp, comp = csgraph.connected_components(G, directed=False)
    assert n_comp == s  # one graph component per segment: connected, and no two segments share one
    assert np.array_equal(lab[seg.peaks], np.arange(s))
    for j in range(s):
        assert seg.f[seg.peaks[j]] == seg.f[lab == j].max()
    np.testing.assert_allclose(seg.areas.sum(), 1.0, rtol=1e-12)
    assert np.all(np.diff(seg.areas) <= 0)


def _naive_tomato(m: mesh.Mesh, f: np.ndarray, thr: float) -> np.ndarray:
    """Reference: ToMATo vertex by vertex (Chazal et al. 2013, Alg. 1) on the edge graph, as written."""
    n = m.n_vertices
    order = np.lexsort((np.arange(n), -f))
    rank = np.empty(n, dtype=np.int64)
    rank[order] = np.arange(n)
    e = m.edges
    nbrs = [[] for _ in range(n)]
    for a, b in e:
        nbrs[a].append(b)
        nbrs[b].append(a)
    parent = -np.ones(n, dtype=np.int64)

    def find(x):
        while parent[x] != x:
            x = parent[x]
        return x

    for i in order:
        up = sorted((j for j in nbrs[i] if rank[j] < rank[i]), key=lambda j: rank[j])
        if not up:
            parent[i] = i
            continue
        parent[i] = find(up[0])
        for j in up:
            ri, rj = find(i), find(j)
            if ri != rj and min(f[ri], f[rj]) < f[i] + thr:
                low, high = (ri, rj) if rank[ri] > rank[rj] else (rj, ri)
                parent[low] = high
    return np.array([find(v) for v in range(n)])


def _same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    pairs = np.unique(np.stack([a, b], axis=1), axis=0)
    return len(pairs) == len(np.unique(a)) == len(np.unique(b))


# --- segmentation ------------------------------------------------------------------------------


@pytest.mark.parametrize("arms", [TWO, THREE])
def test_protrusions_become_segments_with_peaks_at_the_tips(arms):
    m = armed_sphere(arms)
    seg = mesh.persistence_segmentation(m)  # default: HKS at 2 ln10 / λ_10, tau = 0.1
    assert seg.n_segments == len(arms)
    _assert_partition(m, seg)
    tips = _tips(m, arms)
    assert len(set(seg.labels[tips])) == len(arms)  # each tip in its own segment
    for t in tips:  # the segment's peak is the tip, or next to it
        p = seg.peaks[seg.labels[t]]
        assert np.linalg.norm(m.vertices[p] - m.vertices[t]) < 0.1
    # one global maximum (infinite persistence); the other peaks clear the threshold
    finite = np.isfinite(seg.persistence)
    assert finite.sum() == len(arms) - 1 and seg.f[seg.peaks[~finite]] == seg.f.max()
    assert np.all(seg.persistence[finite] >= 0.1 * np.ptp(seg.f))


def test_starfish_example_has_five_arms():
    m = mesh.example("starfish", size=0)
    seg = mesh.persistence_segmentation(m)
    assert seg.n_segments == 5
    _assert_partition(m, seg)


@pytest.mark.parametrize("seed, noise", [(0, 1e-3), (1, 1e-3), (2, 0.05), (3, np.inf)])
def test_matches_naive_tomato_and_partitions(seed, noise):
    """Same clusters as ToMATo run vertex by vertex, for smooth, rough and pure-noise functions."""
    m = armed_sphere(THREE, 2)
    rough = np.random.default_rng(seed).standard_normal(m.n_vertices)
    f = rough if noise == np.inf else _smooth_random(m, seed) + noise * rough
    for tau in (0.0, 0.02, 0.1, 0.3):
        seg = mesh.persistence_segmentation(m, f, tau=tau)
        _assert_partition(m, seg)
        ref = _naive_tomato(m, f, tau * np.ptp(f))
        assert _same_partition(seg.labels, ref)
        assert set(seg.peaks) == set(np.unique(ref))


def test_tau_is_monotone_and_n_segments_exact():
    m = armed_sphere(THREE)
    f = _smooth_random(m, 7)
    full = mesh.persistence_segmentation(m, f, tau=0.0)
    p = full.all_peaks.size
    assert p == full.n_segments > 3  # tau = 0 keeps every local maximum
    assert np.all(np.diff(full.all_persistence[1:]) <= 0) and full.all_persistence[0] == np.inf
    counts = [mesh.persistence_segmentation(m, f, tau=t).n_segments for t in np.linspace(0, 1.2, 25)]
    assert all(a >= b for a, b in zip(counts, counts[1:])) and counts[-1] == 1
    rel = full.all_persistence / np.ptp(f)
    for k in range(1, p + 1):
        seg = mesh.persistence_segmentation(m, f, n_segments=k)
        assert seg.n_segments == k
        assert set(seg.peaks) == set(full.all_peaks[:k])  # the k most persistent peaks
        _assert_partition(m, seg)
        if k < p and rel[k] < rel[k - 1]:  # a tau between the k-th and (k+1)-th persistence: same segments
            by_tau = mesh.persistence_segmentation(m, f, tau=0.5 * (rel[k] + min(rel[k - 1], 2.0)))
            np.testing.assert_array_equal(by_tau.labels, seg.labels)


def test_permuted_mesh_gives_permuted_labels():
    m = armed_sphere(THREE)
    perm = np.random.default_rng(3).permutation(m.n_vertices)
    mp = mesh.permute(m, perm)
    f = _smooth_random(m, 4)
    a, b = mesh.persistence_segmentation(m, f, tau=0.05), mesh.persistence_segmentation(mp, f[perm], tau=0.05)
    assert a.n_segments > 3
    np.testing.assert_array_equal(b.labels, a.labels[perm])
    np.testing.assert_array_equal(perm[b.peaks], a.peaks)
    a, b = mesh.persistence_segmentation(m), mesh.persistence_segmentation(mp)  # HKS recomputed on each
    np.testing.assert_array_equal(b.labels, a.labels[perm])


def test_components_are_never_merged():
    m = mesh.load(two_spheres(2), warn=False)
    f = np.random.default_rng(0).standard_normal(m.n_vertices)
    seg = mesh.persistence_segmentation(m, f, tau=1.5)
    assert seg.n_segments == 2 and np.all(np.isinf(seg.persistence))
    assert _same_partition(seg.labels, m.component)
    with pytest.raises(SegmentationError, match="2 connected components"):
        mesh.persistence_segmentation(m, f, n_segments=1)


# --- indicators and matching ---------------------------------------------------------------------


def test_indicators_sum_to_one_and_reconstruct():
    m = armed_sphere(THREE)
    seg = mesh.persistence_segmentation(m)
    F = mesh.segment_indicators(seg.labels)
    assert F.shape == (m.n_vertices, 3) and F.dtype == np.float64
    np.testing.assert_array_equal(F.sum(axis=1), np.ones(m.n_vertices))
    np.testing.assert_array_equal(F, (seg.labels[:, None] == np.arange(3)).astype(float))
    # reconstruct (§4.2): the basis holds the constant, so the reconstructions sum to 1
    R, C = reconstruct(F, _basis(m, 20).evecs)
    assert R.shape == F.shape and C.shape == (20, 3)
    np.testing.assert_allclose(R.sum(axis=1), 1.0, atol=1e-8)
    # areas= orders the columns by decreasing area; the segmentation's labels are already in that order
    va = mesh.area_matrix(m, "barycentric").diagonal()
    np.testing.assert_array_equal(mesh.segment_indicators(seg.labels, areas=va), F)
    relabel = np.array([2, 0, 1])
    np.testing.assert_array_equal(mesh.segment_indicators(relabel[seg.labels], areas=va), F)
    np.testing.assert_array_equal(mesh.segment_indicators(relabel[seg.labels]), F[:, np.argsort(relabel)])


def test_match_across_resolutions_and_functional_map():
    coarse, fine = mesh.example("starfish", size=0), mesh.example("starfish", size=1)  # 642 and 2562 vertices
    a, b = mesh.persistence_segmentation(coarse), mesh.persistence_segmentation(fine)
    match = mesh.match_segments(a, b)
    np.testing.assert_array_equal(match.src, np.arange(5))
    # matched segments are the same arm: each fine peak is the one nearest in space to its coarse peak
    D = np.linalg.norm(coarse.vertices[a.peaks][:, None] - fine.vertices[b.peaks][None], axis=2)
    np.testing.assert_array_equal(match.tgt, np.argmin(D, axis=1))
    assert D[match.src, match.tgt].max() < 0.2 < np.sort(D, axis=1)[:, 1].min()
    # permuted copy: identity match, and SEG + HKS constraints give a signed-identity functional map
    perm = np.random.default_rng(1).permutation(coarse.n_vertices)
    p = mesh.permute(coarse, perm)
    c = mesh.persistence_segmentation(p)
    match = mesh.match_segments(a, c)
    np.testing.assert_array_equal(match.tgt, np.arange(5))
    np.testing.assert_allclose(match.distance, 0.0, atol=1e-8)
    Ba, Bc = _basis(coarse, 12), _basis(p, 12)
    k = 6
    lap_a, lap_c = mesh.laplacian(coarse), mesh.laplacian(p)
    Fa = np.hstack([mesh.segment_indicators(a.labels)[:, match.src], mesh.hks(*Ba, 8)])
    Fc = np.hstack([mesh.segment_indicators(c.labels)[:, match.tgt], mesh.hks(*Bc, 8)])
    C = functional_map(Ba.evecs[:, :k], Bc.evecs[:, :k], Fa, Fc, lap_a.A, lap_c.A)
    np.testing.assert_allclose(np.abs(C), np.eye(k), atol=1e-6)


def test_match_rejects_unclear_correspondences():
    sym = mesh.persistence_segmentation(armed_sphere(SYMMETRIC))
    assert sym.n_segments == 3 and abs(sym.areas[1] - sym.areas[2]) < 1e-9  # body and two equal arms
    with pytest.raises(SegmentMatchError, match="no clear partner"):
        mesh.match_segments(sym, sym)  # two equal arms: left and right cannot be told apart
    three = mesh.persistence_segmentation(armed_sphere(THREE))
    two = mesh.persistence_segmentation(armed_sphere(TWO))
    with pytest.raises(SegmentMatchError, match="3 segments but target has 2"):
        mesh.match_segments(three, two)
    one = mesh.persistence_segmentation(armed_sphere(THREE), n_segments=1)
    with pytest.raises(SegmentMatchError, match="single segment"):
        mesh.match_segments(one, one)
    with pytest.raises(SegmentationError, match="ratio"):
        mesh.match_segments(three, three, ratio=1.5)
    assert issubclass(SegmentMatchError, SegmentationError) and issubclass(SegmentationError, ValueError)


# --- validation --------------------------------------------------------------------------------


@pytest.mark.parametrize("kwargs, match", [
    (dict(tau=-0.1), "tau"),
    (dict(tau=float("nan")), "tau"),
    (dict(tau=float("inf")), "tau"),
    (dict(tau="0.1"), "tau"),
    (dict(tau=0.1, n_segments=3), "not both"),
    (dict(n_segments=0), "n_segments"),
    (dict(n_segments=2.0), "n_segments"),
    (dict(n_segments=True), "n_segments"),
    (dict(n_segments=10**6), r"n = \d+ vertices"),
    (dict(n_segments=500), "local maxima"),
])
def test_bad_options_raise_named_errors(kwargs, match):
    m = armed_sphere(THREE)
    f = _smooth_random(m, 0)
    with pytest.raises(SegmentationError, match=match):
        mesh.persistence_segmentation(m, f, **kwargs)


def test_bad_functions_and_labels_raise_named_errors():
    m = armed_sphere(THREE)
    n = m.n_vertices
    for bad in (np.ones(n + 1), np.ones((n, 2)), np.array(["a"] * n), 1.0):
        with pytest.raises(SegmentationError, match=r"shape \(\d+,\)"):
            mesh.persistence_segmentation(m, bad)
    f = np.ones(n)
    f[5] = np.nan
    with pytest.raises(SegmentationError, match="NaN/inf values, e.g. at vertex 5"):
        mesh.persistence_segmentation(m, f)
    with pytest.raises(SegmentationError, match="basis has"):
        mesh.persistence_segmentation(m, basis=_basis(armed_sphere(THREE, 2), 20))
    with pytest.raises(SegmentationError, match="k"):
        mesh.persistence_segmentation(m, k=5)
    with pytest.raises(SegmentationError, match="time"):
        mesh.persistence_segmentation(m, basis=_basis(m, 20), time=-1.0)
    for bad, match in [(np.zeros((n, 1), dtype=int), "1-D integer"), (np.zeros(n), "1-D integer"),
                       (np.array([], dtype=int), "non-empty"), (np.array([0, -1, 1]), "≥ 0"),
                       (np.array([0, 2, 2]), "label 1 of 0 … 2 is never used")]:
        with pytest.raises(SegmentationError, match=match):
            mesh.segment_indicators(bad)
    with pytest.raises(SegmentationError, match="areas"):
        mesh.segment_indicators(np.array([0, 1, 1]), areas=np.ones(4))
    f = np.arange(n, dtype=float)  # integer-valued f is fine (a column too)
    assert mesh.persistence_segmentation(m, f[:, None]).n_segments >= 1


# --- irregular meshes with limbs ----------------------------------------------------------------


@pytest.mark.parametrize("name, low", [("quadruped", 4), ("hand", 5)])
def test_irregular_meshes_have_their_limbs(name, low):
    """A quadruped gets legs and head, a hand its fingers: at least ``low`` segments, each connected
    (jittered vertices, flattened and stretched bodies: not the clean arms of ``armed_sphere``)."""
    m = surface(name)
    seg = mesh.persistence_segmentation(m)
    assert low <= seg.n_segments <= 10
    _assert_partition(m, seg)
    assert seg.areas.min() > 0.01


@pytest.mark.slow
def test_large_quadruped_segments_fast():
    """40 962 vertices: ≥ 5 segments (legs, head, tail); the union–find itself well under a second."""
    m = surface("quadruped_large")
    seg = mesh.persistence_segmentation(m)
    assert 5 <= seg.n_segments <= 10
    _assert_partition(m, seg)
    noisy = seg.f + 1e-3 * np.ptp(seg.f) * np.random.default_rng(0).standard_normal(m.n_vertices)
    start = time.perf_counter()
    out = mesh.persistence_segmentation(m, noisy, tau=0.1)
    assert time.perf_counter() - start < 2.0
    assert out.all_peaks.size > 100 and 5 <= out.n_segments <= 10

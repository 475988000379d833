"""Visibility: Embree robustness, exact classification, adaptive rays, exact shadows."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import corner_point_factor

pytest.importorskip("embreex")

from radiosity import _tol  # noqa: E402
from radiosity.formfactors import polygon_normals  # noqa: E402
from radiosity.visibility import FREE, FULL, MAYBE, Visibility  # noqa: E402
from radiosity.visibility._embree import EmbreeOccluder  # noqa: E402
from radiosity.visibility._occluders import build_occluders, classify_rows, classify_rows_numpy  # noqa: E402


def rect(x0, x1, y0, y1, z, *, down=False):
    q = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], float)
    return q[::-1].copy() if down else q


def make_vis(quads, groups=None, **kw):
    quads = np.asarray(quads, float)
    groups = np.arange(len(quads)) if groups is None else np.asarray(groups)
    scale = float(np.linalg.norm(np.ptp(quads.reshape(-1, 3), axis=0)))
    return Visibility(quads, polygon_normals(quads), groups, scale, **kw)


# ---------------------------------------------------------------- Embree: shared edges and vertices
@pytest.mark.parametrize("shift", [0.0, 1e4])
def test_rays_through_shared_edges_and_vertices_are_blocked(shift):
    """A quad cut in a fan of 8 triangles around its centre: aim at every shared edge and vertex."""
    c = np.array([0.5, 0.5, 0.0])
    ring = np.array([[0, 0, 0], [0.5, 0, 0], [1, 0, 0], [1, 0.5, 0], [1, 1, 0], [0.5, 1, 0], [0, 1, 0], [0, 0.5, 0]])
    tris = np.stack([np.stack([c, ring[k], ring[(k + 1) % 8]]) for k in range(8)]) + shift
    occ = EmbreeOccluder(tris)
    t = np.linspace(0, 1, 41)[1:-1, None]
    targets = np.concatenate([c + t * (ring[k] - c) for k in range(8)] + [c[None], ring[1::2]]) + shift
    origins = targets + np.array([0.3, -0.2, 1.0])
    ends = targets - np.array([0.3, -0.2, 1.0])
    assert occ.occluded(origins, ends).all()


def test_rays_leaving_a_surface_near_shared_edges_do_not_self_shadow():
    """Two coplanar triangles and a perpendicular wall: rays from near the shared edges escape."""
    floor = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0]], [[0, 0, 0], [1, 1, 0], [0, 1, 0]]], float)
    wall = np.array([[[0, 0, 0], [0, 1, 0], [0, 1, 1]], [[0, 0, 0], [0, 1, 1], [0, 0, 1]]], float)
    occ = EmbreeOccluder(np.concatenate([floor, wall]))
    off = _tol.RAY_OFFSET_REL * np.sqrt(3)
    rng = np.random.default_rng(1)
    s = rng.uniform(1e-3, 1, 2000)
    near_diag = np.column_stack([s, s + rng.uniform(-1e-3, 1e-3, 2000), np.zeros(2000)])
    origins = near_diag + [0, 0, off]
    ends = np.column_stack([np.full(2000, off), rng.uniform(0, 1, 2000), rng.uniform(1e-3, 1, 2000)])
    assert not occ.occluded(origins, ends).any()


# ---------------------------------------------------------------- classification
def test_classification_kernel_matches_numpy_reference():
    rng = np.random.default_rng(7)
    blockers = [rect(-0.3, 0.3, -0.3, 0.3, 0.0) + rng.normal(0, 0.05, 3) for _ in range(5)]
    occ = build_occluders(np.array(blockers), np.tile([0, 0, 1.0], (5, 1)), np.arange(5), np.ones(5, bool), 2.0)
    t = 4000
    base_i = rect(-0.1, 0.1, -0.1, 0.1, 0)
    vi = base_i + rng.normal(0, 0.5, (t, 1, 3)) * [1, 1, 0] + rng.uniform(-1.5, 1.5, (t, 1, 1)) * [0, 0, 1]
    vj = base_i + rng.normal(0, 0.5, (t, 1, 3)) * [1, 1, 0] + rng.uniform(-1.5, 1.5, (t, 1, 1)) * [0, 0, 1]
    k = rng.integers(0, occ.n_occluders, t)
    a = classify_rows(occ, vi, vj, k, 2.0)
    b = classify_rows_numpy(occ, vi, vj, k, 2.0)
    np.testing.assert_array_equal(a, b)
    assert {FREE, FULL, MAYBE} <= set(np.unique(a).tolist())


def test_classification_of_plates_and_blocker():
    low = [rect(0, 0.3, 0, 0.3, 0), rect(0.5, 1, 0.5, 1, 0), rect(0.4, 0.6, 0.4, 0.6, 0)]
    up = [rect(0.4, 0.6, 0.4, 0.6, 1, down=True), rect(0, 0.1, 0, 0.1, 1, down=True)]
    blocker = rect(0.25, 0.75, 0.25, 0.75, 0.5)
    vis = make_vis(low + up + [blocker])
    status, _, _ = vis.classify(np.array([2, 0, 0, 1]), np.array([3, 3, 4, 4]))
    # centre-centre: full; corner-centre: partial; corner-corner: free (misses the blocker)
    np.testing.assert_array_equal(status, [FULL, MAYBE, FREE, MAYBE])


# ---------------------------------------------------------------- exact shadows at a point
SOURCE = rect(-1, 1, -1, 1, 2, down=True)
FLOOR = rect(-1, 1, -1, 1, 0)  # keeps the receiver point inside the scene's hull
ORIGIN = np.zeros((1, 3))
UP = np.array([[0, 0, 1.0]])


def test_point_fraction_exact_quarter_shadow():
    """A blocker at mid-height hiding exactly one quadrant of the source from the origin."""
    vis = make_vis([SOURCE, FLOOR, rect(0, 0.5, 0, 0.5, 1)])
    exact = vis.point_fraction(ORIGIN, UP, np.array([0]), exact=True)
    assert exact[0] == pytest.approx(0.75, abs=1e-12)
    rays = make_vis([SOURCE, FLOOR, rect(0, 0.5, 0, 0.5, 1)], samples=16).point_fraction(ORIGIN, UP, np.array([0]))
    assert rays[0] == pytest.approx(0.75, abs=0.03)


def test_point_fraction_exact_union_of_overlapping_occluders_with_a_hole():
    """Four overlapping bars (two heights) whose shadows form a square ring on the source."""
    bars = [rect(-0.4, 0.4, -0.4, -0.25, 1), rect(-0.4, 0.4, 0.25, 0.4, 1),
            rect(-0.6, -0.375, -0.6, 0.6, 1.5), rect(0.375, 0.6, -0.6, 0.6, 1.5)]
    vis = make_vis([SOURCE, FLOOR] + bars)
    full = 4 * corner_point_factor(1, 1, 2)
    ring = 4 * corner_point_factor(0.8, 0.8, 2) - 4 * corner_point_factor(0.5, 0.5, 2)
    exact = vis.point_fraction(ORIGIN, UP, np.array([0]), exact=True)
    assert exact[0] == pytest.approx(1 - ring / full, abs=1e-12)


def test_horizon_straddling_source_rays_aim_only_at_the_visible_part():
    """The source reaches below the receiver's plane; an occluder hides only that part."""
    receiver = rect(0, 1, 0, 1, 0)
    source = np.array([[2, 0, -1], [2, 1, -1], [2, 1, 1], [2, 0, 1]], float)[::-1].copy()  # faces -x
    below = np.array([[1.5, -1, -1], [1.5, 2, -1], [1.5, 2, -0.01], [1.5, -1, -0.01]], float)
    quads = [receiver, source, below]
    for exact in (False, True):
        vis = make_vis(quads, samples=3, max_samples=6)
        assert vis.fraction(np.array([0]), np.array([1]), exact=exact)[0] == pytest.approx(1.0, abs=1e-12)
    points = np.array([[0.5, 0.5, 0.0], [0.1, 0.9, 0.0]])
    normals = np.tile([0, 0, 1.0], (2, 1))
    for exact in (False, True):
        f = make_vis(quads).point_fraction(points, normals, np.array([1, 1]), exact=exact)
        np.testing.assert_allclose(f, 1.0, atol=1e-12)


def test_adaptive_rays_refine_only_partial_pairs():
    low = [rect(0.45, 0.55, 0.45, 0.55, 0), rect(0.2, 0.3, 0.45, 0.55, 0)]
    up = [rect(0.45, 0.55, 0.45, 0.55, 1, down=True)]
    blocker = rect(0.5, 0.75, 0.25, 0.75, 0.5)  # its edge x = 0.5 halves the centre pair
    vis = make_vis(low + up + [blocker], samples=2, max_samples=8)
    f = vis.fraction(np.array([0]), np.array([2]))
    assert vis.n_rays == 2**4 + 8**4
    assert f[0] == pytest.approx(0.5, abs=0.05)
    exact = vis.fraction(np.array([0]), np.array([2]), exact=True, order=6)
    assert exact[0] == pytest.approx(0.5, abs=1e-9)  # symmetric about the edge

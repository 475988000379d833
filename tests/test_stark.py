"""Stark's vertex-based formulations (radiosity.alternatives._stark) against the Lambert kernel.

Agreement is asserted as |F - F_lambert| <= RTOL * F_lambert + ATOL: the formulations add
O(1) terms whose sum is F, so tiny form factors (a sliver above the plane) carry an absolute
rounding floor. The conditions under which each formula holds to that level are the ones stated
in docs/stark.md: not far (distance/size <= ~10), vertices either exactly on the receiver plane
or clearly off it (no grazing vertices); the image-plane formula only for sources strictly above.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from radiosity.alternatives import _stark
from radiosity.formfactors import lambert_pairs, point_to_polygon

RTOL = 1e-12
ATOL = 1e-14  # k * eps * pi: the vertex terms are angles of O(1) that cancel to F


def _star(rng, k, convex):
    """Simple polygon, star-shaped about 0 (angular gaps < pi, else the closing edge may cross)."""
    while True:
        ang = np.sort(rng.uniform(0, 2 * np.pi, k))
        if np.diff(np.r_[ang, ang[0] + 2 * np.pi]).max() < 0.9 * np.pi:
            break
    if convex:
        r = np.ones(k)
    else:
        r = rng.uniform(0.3, 1.0, k)
    return np.stack([r * np.cos(ang), r * np.sin(ang)], 1)


def _rotation(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q


def _polys(seed, n, k, convex, kind):
    """n polygons relative to a receiver at 0 facing +z, of one kind (see docstring above)."""
    rng = np.random.default_rng(seed)
    out = np.empty((n, k, 3))
    for i in range(n):
        while True:
            s = _star(rng, k, convex) * rng.uniform(0.2, 2.0)
            q = _rotation(rng)
            p = s[:, :1] * q[0] + s[:, 1:] * q[1] + rng.uniform(-1.5, 1.5, 3)
            if kind == "above":
                p[:, 2] += rng.uniform(0.05, 2.0) * np.ptp(p[:, :2]) - p[:, 2].min()
            elif kind == "touching":
                p[:, 2] -= p[:, 2].min()  # one vertex exactly on the plane
            elif kind == "crossing":
                p[:, 2] -= p[:, 2].mean()
            # No grazing vertices: each is on the plane or clearly off it (docs/stark.md).
            z = np.abs(p[:, 2])
            if not ((z > 0) & (z < 0.02 * np.ptp(p, axis=0).max())).any():
                break
        out[i] = p
    return out


def _frame_rows(polys, seed):
    """Put each row in a random rigid frame (receiver moved off the origin, normal tilted)."""
    rng = np.random.default_rng(seed + 1)
    n = len(polys)
    pts = rng.uniform(-3, 3, (n, 3))
    nrm = np.empty((n, 3))
    moved = np.empty_like(polys)
    for i in range(n):
        q = _rotation(rng)
        moved[i] = polys[i] @ q.T + pts[i]
        nrm[i] = q[:, 2]
    return pts, nrm, moved


def _origin_rows(polys):
    n = len(polys)
    return np.zeros((n, 3)), np.tile([0, 0, 1.0], (n, 1)), polys


def _assert_close(f, ref):
    err = np.abs(f - ref)
    tol = RTOL * ref + ATOL
    worst = int(np.argmax(err - tol))
    assert (err <= tol).all(), f"row {worst}: {f[worst]!r} vs {ref[worst]!r}"


shapes = st.tuples(st.integers(0, 2**32 - 1), st.integers(3, 9), st.booleans())


@given(shapes)
def test_image_plane_matches_lambert_above(args):
    seed, k, convex = args
    pts, nrm, polys = _frame_rows(_polys(seed, 20, k, convex, "above"), seed)
    ref = lambert_pairs(pts, nrm, polys)
    for form in ("slope", "projective"):
        f, valid = _stark.image_plane(pts, nrm, polys, form=form)
        assert valid.all()
        _assert_close(f, ref)


@given(shapes, st.sampled_from(["above", "touching", "crossing"]))
def test_vertex_lambert_matches_lambert(args, kind):
    seed, k, convex = args
    pts, nrm, polys = _frame_rows(_polys(seed, 20, k, convex, kind), seed)
    ref = lambert_pairs(pts, nrm, polys)
    _assert_close(_stark.vertex_lambert(pts, nrm, polys), ref)
    _assert_close(_stark.vertex_lambert(pts, nrm, polys, angle="arccos"), ref)


@given(shapes, st.sampled_from(["above", "touching", "crossing"]))
def test_homogeneous_matches_lambert(args, kind):
    # Receiver frame kept exact (origin, +z) so that vertices on the plane stay exactly on it.
    seed, k, convex = args
    pts, nrm, polys = _origin_rows(_polys(seed, 20, k, convex, kind))
    ref = lambert_pairs(pts, nrm, polys)
    _assert_close(_stark.homogeneous(pts, nrm, polys), ref)


def test_homogeneous_edge_on_plane():
    """Vertical rectangles standing on the receiver plane (an edge at infinity), any winding."""
    rng = np.random.default_rng(5)
    rows = []
    for _ in range(50):
        a = np.array([*rng.uniform(-2, 2, 2), 0.0])
        d = np.array([*rng.normal(size=2), 0.0])
        b = a + d
        h = rng.uniform(0.1, 2.0)
        lean = np.array([*rng.normal(scale=0.3, size=2), 0.0])
        rect = np.array([a, b, b + lean + [0, 0, h], a + lean + [0, 0, h]])
        rows.append(rect if rng.random() < 0.5 else rect[::-1])
    pts, nrm, polys = _origin_rows(np.array(rows))
    ref = lambert_pairs(pts, nrm, polys)
    assert (ref > 0).all()
    _assert_close(_stark.homogeneous(pts, nrm, polys), ref)
    _assert_close(_stark.vertex_lambert(pts, nrm, polys), ref)


def test_slope_form_with_vertical_edges():
    """Axis-aligned squares: edges exactly vertical on the image plane (slopes undefined)."""
    sq = np.array([[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1.0]])
    shifts = np.array([[0, 0, 0], [-0.3, 0.2, 0.5], [-2, -2, 3], [0.4, -0.5, 0.1]])
    polys = sq[None] + shifts[:, None]
    pts, nrm, _ = _origin_rows(polys)
    ref = lambert_pairs(pts, nrm, polys)
    f, valid = _stark.image_plane(pts, nrm, polys)
    assert valid.all()
    _assert_close(f, ref)
    assert f[0] == pytest.approx(0.1385316060, rel=1e-9)  # Howell, point under the corner


def test_image_plane_invalid_rows_give_zero():
    polys = _polys(3, 10, 5, False, "crossing")
    pts, nrm, _ = _origin_rows(polys)
    for form in ("slope", "projective"):
        f, valid = _stark.image_plane(pts, nrm, polys, form=form)
        assert not valid.any()
        assert (f == 0).all()


@pytest.mark.parametrize("radius", [3.0, 30.0, 1e3, 1e4])
def test_clipped_image_plane_within_lemma1(radius):
    polys = _polys(11, 200, 6, False, "crossing")
    pts, nrm, polys = _frame_rows(polys, 11)
    ref = lambert_pairs(pts, nrm, polys)
    f, bound = _stark.image_plane_clipped(pts, nrm, polys, radius)
    deficit = ref - f
    assert (deficit >= -1e-9).all()  # rounding grows like eps R^2 (docs/stark.md)
    assert (deficit <= bound + 1e-9).all()
    assert bound.max() == pytest.approx(1.0 / (1.0 + radius**2))


def test_clipped_image_plane_exact_when_inside():
    polys = _polys(12, 30, 6, True, "above")
    pts, nrm, polys = _frame_rows(polys, 12)
    f, bound = _stark.image_plane_clipped(pts, nrm, polys, 1e6)
    assert (bound == 0).all()
    _assert_close(f, lambert_pairs(pts, nrm, polys))


def test_lemma1_bound_and_radius():
    assert _stark.clip_error_bound(0.0) == 1.0
    assert _stark.clip_error_bound(3.0) == pytest.approx(0.1)
    r = _stark.radius_for_error(1e-8)
    assert _stark.clip_error_bound(r) == pytest.approx(1e-8)
    # The bound is the form factor of the outside of the disc: a huge square ring at height 1.
    big = 1e3
    ring_outer = point_to_polygon([[0, 0, 0]], [[0, 0, 1]], [[-big, -big, 1], [big, -big, 1],
                                                              [big, big, 1], [-big, big, 1]])[0]
    assert 1.0 - ring_outer <= _stark.clip_error_bound(big)


@pytest.mark.parametrize("fn", [
    lambda p, n, q: _stark.image_plane(p, n, q)[0],
    lambda p, n, q: _stark.image_plane(p, n, q, form="projective")[0],
    lambda p, n, q: _stark.image_plane_clipped(p, n, q, 100.0)[0],
    _stark.vertex_lambert,
    _stark.homogeneous,
])
def test_degenerate_rows_are_zero_not_nan(fn):
    pts = np.zeros((5, 3))
    nrm = np.tile([0, 0, 1.0], (5, 1))
    polys = np.array([
        [[0, 0, 1], [1, 0, 1], [2, 0, 1], [3, 0, 1]],       # collinear
        [[1, 1, 1], [1, 1, 1], [1, 1, 1], [1, 1, 1]],       # one point
        [[0, 0, 0], [1, 0, 1], [0, 1, 1], [0, 0, 0]],       # receiver at a vertex (in the plane)
        [[-1, 0, 0], [1, 0, 0], [1, 0, 1], [-1, 0, 1]],     # receiver on an edge
        [[0, 0, -1], [1, 0, -1], [1, 1, -1], [0, 1, -1]],   # below
    ], float)
    f = fn(pts, nrm, polys)
    assert np.isfinite(f).all()
    assert (f == 0).all()


def test_winding_ignored_and_padding_allowed():
    polys = _polys(21, 30, 5, False, "crossing")
    pts, nrm, _ = _origin_rows(polys)
    padded = np.concatenate([polys, polys[:, -1:]], axis=1)
    for fn in (_stark.vertex_lambert, _stark.homogeneous):
        f = fn(pts, nrm, polys)
        np.testing.assert_allclose(fn(pts, nrm, polys[:, ::-1]), f, rtol=1e-13, atol=ATOL)
        np.testing.assert_allclose(fn(pts, nrm, padded), f, rtol=1e-13, atol=ATOL)


def test_bad_options_raise():
    pts, nrm, polys = _origin_rows(_polys(1, 2, 4, True, "above"))
    with pytest.raises(ValueError, match="form must be"):
        _stark.image_plane(pts, nrm, polys, form="polar")
    with pytest.raises(ValueError, match="angle must be"):
        _stark.vertex_lambert(pts, nrm, polys, angle="asin")

"""Adaptive refinement of near pairs (radiosity.formfactors._quadrature.pair_factors) against closed forms.

References are exact: Howell's aligned parallel rectangles (C-11), parallel rectangles in general
position (the four-fold sum of C-12), perpendicular rectangles with a common edge (C-14), and,
for T-junctions, C-14 combined by view-factor algebra along the common line (for collinear
edge intervals [a, b] and [c, d], A F = (K(|b - c|) + K(|a - d|) - K(|a - c|) - K(|b - d|)) / 2
with K(L) = A F of the common-edge pair of length L). Everything is evaluated with mpmath.
"""

from __future__ import annotations

import mpmath as mp
import numpy as np
import pytest

from radiosity import polygon_to_polygon
from helpers import parallel_rectangles_mp as parallel, perpendicular_rectangles_mp as perpendicular
from radiosity.formfactors._quadrature import gauss_legendre_01, pair_factors, rect_points
from radiosity.formfactors._reference import _rect_points_numpy
from radiosity.geometry import centroids_and_areas

mp.mp.dps = 30


def parallel_offset(x, y, xi, eta, z):
    """[x0, x1] x [y0, y1] at height 0 to [xi0, xi1] x [eta0, eta1] at height z, facing it."""
    z = mp.mpf(z)

    def g(x, y, e, s):
        a, b = mp.mpf(x) - s, mp.mpf(y) - e
        ra, rb = mp.sqrt(a * a + z * z), mp.sqrt(b * b + z * z)
        out = (b * ra * mp.atan(b / ra) if b else 0) + (a * rb * mp.atan(a / rb) if a else 0)
        return (out - z * z / 2 * mp.log(a * a + b * b + z * z)) / (2 * mp.pi)

    total = sum((-1) ** (p + q + r + s) * g(x[p], y[q], eta[r], xi[s])
                for p in range(2) for q in range(2) for r in range(2) for s in range(2))
    return float(total / ((mp.mpf(x[1]) - x[0]) * (mp.mpf(y[1]) - y[0])))


def t_junction(a, b, c, d, w, h):
    """Receiver [0, w] x [a, b] on z = 0 to the wall x = 0, y in [c, d], z in [0, h]."""
    a, b, c, d = (mp.mpf(x) for x in (a, b, c, d))

    def k(length):
        return length * w * perpendicular(length, w, h) if length else 0

    return float((k(abs(b - c)) + k(abs(a - d)) - k(abs(a - c)) - k(abs(b - d))) / (2 * (b - a) * w))


def floor(a, b, w=1.0):
    return np.array([[0, a, 0], [w, a, 0], [w, b, 0], [0, b, 0]], float)  # normal +z


def wall(c, d, h):
    return np.array([[0, c, 0], [0, d, 0], [0, d, h], [0, c, h]], float)  # x = 0, normal +x


def ceiling(x, y, z):
    return np.array([[x[0], y[0], z], [x[0], y[1], z], [x[1], y[1], z], [x[1], y[0], z]], float)  # normal -z


UNIT = floor(0, 1)
CASES = {
    "parallel gap 1": (UNIT, ceiling((0, 1), (0, 1), 1), lambda: parallel(1, 1, 1)),
    "parallel gap 0.01": (UNIT, ceiling((0, 1), (0, 1), 0.01), lambda: parallel(1, 1, mp.mpf("0.01"))),
    "parallel gap 0.001": (UNIT, ceiling((0, 1), (0, 1), 0.001), lambda: parallel(1, 1, mp.mpf("0.001"))),
    "offset parallel gap 0.001": (UNIT, ceiling((0.3, 1.3), (0.2, 1.2), 0.001), lambda: parallel_offset(
        (0, 1), (0, 1), (mp.mpf("0.3"), mp.mpf("1.3")), (mp.mpf("0.2"), mp.mpf("1.2")), mp.mpf("0.001"))),
    "perpendicular shared edge": (UNIT, wall(0, 1, 1), lambda: float(perpendicular(1, 1, 1))),
    "2x1 floor, 1x0.5 wall, common edge": (floor(0, 1, 2), wall(0, 1, 0.5), lambda: float(perpendicular(1, 2, 0.5))),
    "T: wall corner at 1/3": (UNIT, wall(1 / 3, 4 / 3, 1), lambda: t_junction(0, 1, mp.mpf(1) / 3, mp.mpf(4) / 3, 1, 1)),
    "T: small wall inside the edge": (UNIT, wall(0.3, 0.65, 0.4), lambda: t_junction(
        0, 1, mp.mpf("0.3"), mp.mpf("0.65"), 1, mp.mpf("0.4"))),
    "T: receiver inside the wall's edge": (floor(0.3, 0.8), wall(0, 1, 1), lambda: t_junction(
        mp.mpf("0.3"), mp.mpf("0.8"), 0, 1, 1, 1)),
    # a corner 1e-3 from the receiver's (mesh round-off on the Cornell box): no needle triangles
    "T: wall corner 1e-3 before the receiver's corner": (UNIT, wall(0.999, 1.999, 1), lambda: t_junction(
        0, 1, mp.mpf("0.999"), mp.mpf("1.999"), 1, 1)),
    "T: wall corner 1e-3 past the receiver's corner": (UNIT, wall(1.001, 2, 1), lambda: t_junction(
        0, 1, mp.mpf("1.001"), 2, 1, 1)),
}


@pytest.fixture(scope="module")
def exact():
    return {name: ref() for name, (_, _, ref) in CASES.items()}


def receiver_pair(receiver, source):
    """The arguments of pair_factors for one receiver quad and one source polygon."""
    quads = receiver[None].astype(float)
    normal = np.cross(receiver[1] - receiver[0], receiver[2] - receiver[0])
    c, a = centroids_and_areas(quads)
    zero = np.zeros(1, dtype=np.int64)
    return (quads, (normal / np.linalg.norm(normal))[None], c, a, zero, zero), {"sources": source[None]}


def test_references_match_the_aligned_formulas():
    assert parallel_offset((0, 1), (0, 1), (0, 1), (0, 1), 1) == pytest.approx(parallel(1, 1, 1), rel=1e-14)
    assert t_junction(0, 1, 0, 1, 1, 1) == pytest.approx(float(perpendicular(1, 1, 1)), rel=1e-14)
    assert parallel(1, 1, 1) == pytest.approx(0.19982489569838738304, rel=1e-15)


@pytest.mark.parametrize("rtol", [1e-4, 1e-7, 1e-10])
@pytest.mark.parametrize("name", list(CASES))
def test_polygon_to_polygon_meets_rtol(name, rtol, exact):
    receiver, source, _ = CASES[name]
    f = polygon_to_polygon(receiver, source, rtol=rtol)
    assert abs(f / exact[name] - 1) <= rtol


@pytest.mark.parametrize("name", ["parallel gap 0.01", "T: wall corner at 1/3", "2x1 floor, 1x0.5 wall, common edge"])
def test_error_shrinks_with_rtol_and_flags_convergence(name, exact):
    args, kwargs = receiver_pair(*CASES[name][:2])
    errors = []
    for rtol in (1e-3, 1e-5, 1e-7, 1e-9):
        f, info = pair_factors(*args, rtol=rtol, return_info=True, **kwargs)
        assert info["converged"].all()
        errors.append(abs(f[0] / exact[name] - 1))
        assert errors[-1] <= rtol
    assert errors[-1] < 1e-3 * errors[0]


def test_budget_stops_refinement_unconverged():
    args, kwargs = receiver_pair(*CASES["parallel gap 0.001"][:2])
    f, info = pair_factors(*args, rtol=1e-8, return_info=True, max_points=500, **kwargs)
    assert not info["converged"][0] and info["points"][0] <= 500
    assert f[0] == pytest.approx(parallel(1, 1, mp.mpf("0.001")), rel=1e-2)


@pytest.mark.parametrize("max_points", [5, 40, 300, 4096])
def test_max_points_is_respected(max_points):
    quads = np.array([CASES[name][0] for name in CASES] + [CASES[name][1] for name in CASES])
    normals = np.array([np.cross(q[1] - q[0], q[2] - q[0]) for q in quads])
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    n = len(CASES)
    i = np.r_[np.arange(n), np.arange(n, 2 * n)]
    j = np.r_[np.arange(n, 2 * n), np.arange(n)]  # both ways, so touching pairs meet as receivers too
    c, a = centroids_and_areas(quads)
    f, info = pair_factors(quads, normals, c, a, i, j, rtol=1e-10, return_info=True, max_points=max_points)
    assert (info["points"] <= max_points).all() and np.isfinite(f).all() and (f >= 0).all()
    if max_points == 4096:
        np.testing.assert_allclose(a[i] * f, a[j] * f[np.r_[np.arange(n, 2 * n), np.arange(n)]], rtol=1e-4)


def test_max_points_below_five_is_rejected():
    args, kwargs = receiver_pair(*CASES["parallel gap 1"][:2])
    with pytest.raises(ValueError, match="max_points"):
        pair_factors(*args, rtol=1e-6, max_points=4, **kwargs)


def test_reciprocity_of_a_slowly_rising_touching_edge():
    """A thin triangle in x = 0 with a corner on the floor's edge, rising 1 in 40 over the floor:
    a layer that widens from the T-junction (the case that fooled the estimates on the Cornell box)."""
    sliver = np.array([[0, 0.4, 0], [0, 1.6, 0], [0, 1.6, 0.03]])
    quads = np.array([UNIT, np.vstack([sliver, sliver[2:]])])
    normals = np.array([[0, 0, 1.0], [1.0, 0, 0]])
    c, a = centroids_and_areas(quads)
    f, info = pair_factors(quads, normals, c, a, np.array([0, 1]), np.array([1, 0]), rtol=1e-8, return_info=True)
    assert info["converged"].all()
    assert a[0] * f[0] == pytest.approx(a[1] * f[1], rel=1e-7)


@pytest.mark.parametrize("framed", [False, True])
def test_rect_points_loop_matches_numpy_and_areas(framed):
    rng = np.random.default_rng(1)
    quads = rng.random((50, 4, 3))
    rects = rng.random((50, 4)) * 0.5
    frames = rng.random((50, 4, 2)) if framed else None
    if framed:
        frames[:, 3] = frames[:, 2]  # Duffy triangles
    nodes, w = gauss_legendre_01(5)
    p1, w1 = rect_points(quads, rects, 5, frames)
    p2, w2 = _rect_points_numpy(quads, rects, nodes, w, frames)
    np.testing.assert_allclose(p1, p2, rtol=0, atol=1e-15)
    np.testing.assert_allclose(w1, w2, rtol=1e-13)
    # a square's whole parameter square, as two Duffy triangles, has the square's area
    tri = np.array([[[1, 0], [1, 1], [0, 0], [0, 0]], [[1, 1], [0, 1], [0, 0], [0, 0]]], float)
    _, wt = rect_points(np.repeat(UNIT[None] * 2, 2, axis=0), np.tile([0, 0, 1, 1.0], (2, 1)), 3, tri)
    assert wt.sum() == pytest.approx(4.0, rel=1e-14)

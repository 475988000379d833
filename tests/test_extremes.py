"""Form factors at the extremes: near and far, grazing, coplanar, touching, shared edges and
vertices, degenerate faces, tiny and huge coordinates (docs/extremes.md).

Thresholds are about ten times the worst error that ``bench/bench_extremes.py`` measured on the
same family (bench/results/extremes.json). Where an error is set by the problem's conditioning
rather than by the kernel, the bound is written in units of ``u·(1 + kappa)``, the error a
backward-stable kernel may make (``kappa`` from :func:`condition_mp`, central differences in
mpmath). Cases that fail today because of a bug are ``xfail(strict=True)`` with the measured
error in the reason: when a fix lands they XPASS and fail, so the marker must be removed.
"""

from __future__ import annotations

import warnings

import mpmath as mp
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import radiosity
from radiosity import point_to_polygon, polygon_to_polygon
from helpers import lambert_mp, parallel_rectangles_mp, perpendicular_rectangles_mp, polygon_area
from helpers import mp_vector as _mp3

U = 2.0**-53
Z = np.array([0.0, 0.0, 1.0])
SQUARE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)  # normal +z
TRIANGLE = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
PENTAGON = np.array([[0, 0, 0], [1.1, -0.2, 0], [1.4, 0.7, 0], [0.6, 1.3, 0], [-0.3, 0.8, 0]], float)
WALL_X0 = np.array([[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]], float)  # x = 0, facing +x


# ----------------------------------------------------------------------------------- references
def condition_mp(x, n, poly):
    """kappa = (L·Σ_points |∇F| + |∇_n F|) / F, L the largest coordinate (see the bench); forward
    differences of 1e-12 L at 30 digits, enough for the one digit a bound needs."""
    with mp.workdps(30):
        pts = [_mp3(x)] + [_mp3(v) for v in poly]
        nrm = _mp3(n)
        L = max(abs(c) for p in pts for c in p)
        f0 = lambert_mp(pts[0], nrm, pts[1:], dps=30)
        total = mp.mpf(0)
        for which in range(len(pts) + 1):
            step = mp.mpf(10) ** -12 * (L if which < len(pts) else 1)
            g2 = mp.mpf(0)
            for c in range(3):
                P = [list(p) for p in pts]
                N = list(nrm)
                (P[which] if which < len(pts) else N)[c] += step
                g2 += ((lambert_mp(P[0], N, P[1:], dps=30) - f0) / step) ** 2
            total += mp.sqrt(g2) * (L if which < len(pts) else 1)
        return float(total / f0)


def assert_backward_stable(x, n, poly, times, floor=1e-14):
    """|F - exact| / exact <= max(floor, times·u·(1 + kappa)); kappa (slow) only when needed."""
    err = rel_err(F(x, n, poly), lambert_mp(x, n, poly))
    if err > floor:
        kappa = condition_mp(x, n, poly)
        assert err <= times * U * (1 + kappa), f"error {err:.2e} is {err / (U * (1 + kappa)):.0f} u(1 + kappa)"


def howell_b3(a, b, c):
    """Element under the corner of a parallel a x b rectangle at distance c (Howell B-3)."""
    X, Y = mp.mpf(a) / c, mp.mpf(b) / c
    return float((X / mp.sqrt(1 + X**2) * mp.atan(Y / mp.sqrt(1 + X**2))
                  + Y / mp.sqrt(1 + Y**2) * mp.atan(X / mp.sqrt(1 + Y**2))) / (2 * mp.pi))


def howell_b2(a, b, c):
    """Element at the origin facing +z; rectangle in y = c, x in [0, b], z in [0, a] (Howell B-2)."""
    with mp.workdps(50):  # the two terms cancel for thin strips: 15 digits are not enough
        X, Y = mp.mpf(a) / b, mp.mpf(c) / b
        R = mp.sqrt(X**2 + Y**2)
        return float((mp.atan(1 / Y) - Y / R * mp.atan(1 / R)) / (2 * mp.pi))


def howell_c11(a, b, c):
    return float(parallel_rectangles_mp(a, b, c))


def howell_c14(l, w, h):
    return float(perpendicular_rectangles_mp(l, w, h))


def ngon_axis(sides, h):
    """Point on the axis of a regular N-gon (circumradius 1) at height h, in closed form."""
    with mp.workdps(40):
        ra = mp.cos(mp.pi / sides)
        d = mp.sqrt(mp.mpf(h) ** 2 + ra**2)
        return float(sides / mp.pi * mp.atan(mp.sin(mp.pi / sides) / d) * ra / d)


# Reference values of pairs without a closed form: bench_extremes.contour_mp, the double contour
# integral (1/2π)∮∮ ln r ds·ds at 30 digits (it reproduces C-11 and C-14 to 30 digits).
CONTOUR = {"squares at a corner": 0.040592230101558539, "triangles at a vertex 60": 0.088706469966006771,
           "squares hinged 45": 0.48334769547887779, "floor moved 0.01": 0.1957990371213256,
           "floor moved 0.001": 0.19961080893591968, "wall lifted 0.001": 0.19961080893591965,
           "wall lifted 0.0001": 0.2000003614816441}


def F(x, n, poly):
    return float(point_to_polygon(np.asarray(x, float)[None], np.asarray(n, float)[None], poly)[0])


def rel_err(ours, ref):
    """Relative error; against a zero reference only an exact 0 counts as right."""
    ref = float(ref)
    if ref == 0.0:
        return 0.0 if ours == 0.0 else float("inf")
    return abs(ours - ref) / abs(ref)


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def hinge(alpha, a2d, b2d):
    """Receiver a2d in z = 0 (facing +z), b2d rotated by alpha about the x axis (facing a)."""
    a = np.array([[x, y, 0] for x, y in a2d], float)
    b = np.array([[x, y * np.cos(alpha), y * np.sin(alpha)] for x, y in b2d], float)[::-1]
    return a, b


def square_top(gap):
    return np.array([[0, 0, gap], [0, 1, gap], [1, 1, gap], [1, 0, gap]], float)


def outward(poly, i):
    return unit(np.cross(poly[(i + 1) % len(poly)] - poly[i], Z))


# ----------------------------------------------------------------------------------- near
@pytest.mark.parametrize("h", [1e-6, 1e-4, 1e-2, 1.0])
@pytest.mark.parametrize("poly", [SQUARE, TRIANGLE], ids=["square", "triangle"])
def test_near_exact_geometry(poly, h):
    """Dyadic polygons: the relative coordinates are exact, so near receivers keep all digits
    (measured 8.6e-16 at h = 1e-6 .. 1 of the size; 2.2e-16 against Howell B-3)."""
    k = len(poly)
    spots = [poly.mean(0)] + [poly[i] for i in range(k)]
    spots += [(poly[i] + poly[(i + 1) % k]) / 2 for i in range(k)]
    spots += [(poly[i] + poly[(i + 1) % k]) / 2 + h * outward(poly, i) for i in range(k)]
    for xy in spots:
        x = [xy[0], xy[1], -h]
        assert rel_err(F(x, Z, poly), lambert_mp(x, Z, poly)) < 1e-14
    if len(poly) == 4:  # Howell B-3 under each corner, an independent closed form
        for v in poly:
            assert rel_err(F([v[0], v[1], -h], Z, poly), howell_b3(1, 1, h)) < 2e-15


@pytest.mark.parametrize("h", [1e-6, 1e-3])
def test_near_general_polygon_is_backward_stable(h):
    """A non-dyadic pentagon: beside an edge at height h the problem's condition number is about
    size/h, and the kernel stays within it (measured 2 u·(1 + kappa) at most, 3.1e-11 at 1e-6)."""
    for i in range(len(PENTAGON)):
        mid = (PENTAGON[i] + PENTAGON[(i + 1) % 5]) / 2
        for xy in (mid, mid + h * outward(PENTAGON, i)):
            x = np.array([xy[0], xy[1], -h])
            assert rel_err(F(x, Z, PENTAGON), lambert_mp(x, Z, PENTAGON)) < 3e-10
            assert_backward_stable(x, Z, PENTAGON, 20)


@pytest.mark.parametrize("d", [1e-8, 1e-5, 1e-2])
def test_near_vertex_is_backward_stable(d):
    """Beside a vertex, outside the polygon: errors up to 3.9e-8 at d = 1e-8 of the size, all
    within 2 u·(1 + kappa) (moving the receiver by one ulp changes F that much)."""
    for poly in (SQUARE, TRIANGLE, PENTAGON):
        k = len(poly)
        for i in range(k):
            x = poly[i] + d * unit(unit(poly[i] - poly[i - 1]) - unit(poly[(i + 1) % k] - poly[i]))
            x[2] = -d
            assert_backward_stable(x, Z, poly, 20)


# ----------------------------------------------------------------------------------- far
@pytest.mark.parametrize("dist", [1.0, 10.0, 1e2, 1e4, 1e6])
def test_far(dist):
    """Distance/size 1 .. 1e6, three directions, straight and tilted receivers (measured 4.4e-14
    over 234 cases, 1.9e-14 on this subset)."""
    for poly in (SQUARE, TRIANGLE, PENTAGON):
        c = poly.mean(0)
        for ang in (0, 60, 85):
            a = np.radians(ang)
            u = unit([np.sin(a), 0.3 * np.sin(a), np.cos(a)])
            for tilt in (0, 30):
                t = np.radians(tilt)
                n = unit(u * np.cos(t) + np.cross(u, [0, 1, 0]) * np.sin(t))
                x = c - dist * u
                assert rel_err(F(x, n, poly), lambert_mp(x, n, poly)) < 1e-13


@pytest.mark.parametrize("a", [1e-4, 1e-2, 1.0, 1e2, 1e4])
@pytest.mark.parametrize("b", [1e-4, 1e-2, 1.0, 1e2, 1e4])
def test_howell_b3_aspect_ratios(a, b):
    """Howell B-3 with side ratios 1e-4 .. 1e4: measured 3.1e-13 (1e4 x 1e-4), at most
    0.3 u·(1 + kappa)."""
    rect = np.array([[0, 0, 1], [a, 0, 1], [a, b, 1], [0, b, 1]], float)
    err = rel_err(F([0, 0, 0], Z, rect), howell_b3(a, b, 1))
    assert err < 3e-12 and (err < 1e-14 or err <= 3 * U * (1 + condition_mp([0, 0, 0], Z, rect)))


@pytest.mark.parametrize("a", [1e-2, 1.0, 1e2, 1e4])
@pytest.mark.parametrize("b", [1e-4, 1e-2, 1.0, 1e2, 1e4])
def test_howell_b2_aspect_ratios(a, b):
    """Howell B-2 (perpendicular rectangle rising from the receiver's plane): measured 2.2e-9,
    within 50 u·(1 + kappa), for heights a >= 1e-2 (a = 1e-4: the thin strip below)."""
    wall = np.array([[0, 1, 0], [b, 1, 0], [b, 1, a], [0, 1, a]], float)
    err = rel_err(F([0, 0, 0], Z, wall), howell_b2(a, b, 1))
    assert err < 1e-14 or err <= 500 * U * (1 + condition_mp([0, 0, 0], Z, wall))


def test_howell_b2_thin_strip_at_the_horizon():
    """A strip 1e-4 high, 1e4 wide, rising from the receiver's horizon: Lambert's raw sum cancels
    (top and bottom edge planes both ~ the tangent plane; it erred by 6.2e-5), the horizon form
    does not: measured 6.2e-13 (kappa u = 4.4e-8)."""
    wall = np.array([[0, 1, 0], [1e4, 1, 0], [1e4, 1, 1e-4], [0, 1, 1e-4]], float)
    err = rel_err(F([0, 0, 0], Z, wall), howell_b2(1e-4, 1e4, 1))
    assert err < 1e-11 and err <= 100 * U * (1 + condition_mp([0, 0, 0], Z, wall))


@pytest.mark.parametrize("sides", [3, 8, 64, 1024])
def test_regular_ngon_on_axis(sides):
    """Closed form of the regular N-gon (measured 6.1e-14 on this subset; 1.6e-13 for the
    4096-gon at h = 1000 R)."""
    t = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    poly = np.column_stack([np.cos(t), np.sin(t), np.zeros(sides)])
    for h in (1e-6, 1e-3, 1.0, 1e3, 1e6):
        assert rel_err(F([0, 0, -h], Z, poly), ngon_axis(sides, h)) < 6e-13


def test_ngon_tends_to_the_disk():
    """The 4096-gon is the disk R²/(R²+h²) up to its O(1/N²) geometry (2.0e-7 at h = R)."""
    t = np.linspace(0, 2 * np.pi, 4096, endpoint=False)
    poly = np.column_stack([np.cos(t), np.sin(t), np.zeros(4096)])
    assert F([0, 0, -1], Z, poly) == pytest.approx(0.5, rel=2.1e-7)
    assert F([0, 0, -1], Z, poly) < 0.5


# ----------------------------------------------------------------------------------- grazing
@pytest.mark.parametrize("eps", [1e-8, 1e-6, 1e-4, 1e-2])
def test_grazing_source_at_the_horizon(eps):
    """A vertical square whose bottom edge is eps rad above (or below: clipped) the receiver's
    horizon, at distance 2 and 1000 (measured 7.9e-16)."""
    for dist in (2.0, 1e3):
        for sign in (1, -1):
            z0 = sign * dist * np.tan(eps)
            wall = np.array([[dist, -0.5, z0], [dist, 0.5, z0], [dist, 0.5, z0 + 1], [dist, -0.5, z0 + 1]])
            assert rel_err(F([0, 0, 0], Z, wall), lambert_mp([0, 0, 0], Z, wall)) < 8e-15


@pytest.mark.parametrize("eps", [1e-8, 1e-6, 1e-4, 1e-2])
def test_grazing_source_edge_on(eps):
    """Receiver eps rad above the square's plane, facing it sideways (measured 4.0e-16)."""
    for dist in (0.5, 2.0):
        x = [1 + dist, 0.5, dist * np.tan(eps)]
        for n in ([-1, 0, 0], [-1, 0.3, 0]):
            assert rel_err(F(x, n, SQUARE), lambert_mp(x, unit(n), SQUARE)) < 4e-15


@pytest.mark.parametrize("eps", [1e-8, 1e-6, 1e-4, 1e-2])
def test_grazing_nearly_coplanar_absolute_error(eps):
    """Nearly coplanar receiver, normal parallel to the source's: F ~ eps², absolute error
    below 4e-16 (and relative, below)."""
    for dist in (0.5, 2.0):
        x = [1 + dist, 0.5, -dist * np.tan(eps)]
        for n in (Z, unit([-np.sin(eps), 0, np.cos(eps)])):
            value = F(x, n, SQUARE)
            assert 0.0 <= value and abs(value - float(lambert_mp(x, n, SQUARE))) < 4e-16


@pytest.mark.parametrize("eps", [1e-8, 1e-6, 1e-4, 1e-2])
def test_grazing_nearly_coplanar_relative_error(eps):
    """Receiver eps rad below the source's plane, normal parallel to the source's (or tilted by
    eps): Lambert's raw terms are O(1) and F ~ eps², so the raw sum erred by u/eps² (0.5 at
    1e-8); the horizon form keeps the relative accuracy: measured 2.2e-16 (parallel normal) and
    within 9 u·(1 + kappa) (tilted, 1e-12 at eps = 1e-2, where the raw sum erred by 6e-13)."""
    for dist in (0.5, 2.0):
        x = [1 + dist, 0.5, -dist * np.tan(eps)]
        for n in (Z, unit([-np.sin(eps), 0, np.cos(eps)])):
            err = rel_err(F(x, n, SQUARE), lambert_mp(x, n, SQUARE))
            assert err < 2e-15 or err <= 20 * U * (1 + condition_mp(x, n, SQUARE))


def test_horizon_form_keeps_the_winding_number():
    """Sources whose every vertex is near the horizon but which surround the zenith (a huge
    ceiling) or pass over it (a long strip): the horizon form's 2 pi w term (measured 1.1e-16)."""
    ceiling = np.array([[-1e3, -1e3, 1.0], [2e3, -1e3, 1.0], [-1e3, 2e3, 1.0]])
    strip = np.array([[-1e3, -0.1, 1.0], [1e3, -0.1, 1.0], [1e3, 0.1, 1.0], [-1e3, 0.1, 1.0]])
    for poly in (ceiling, strip, ceiling[::-1]):
        assert rel_err(F([0, 0, 0], Z, poly), lambert_mp([0, 0, 0], Z, poly)) < 1e-15


@settings(max_examples=60, deadline=None)
@given(st.integers(3, 6), st.floats(-8, -1.7), st.floats(0, 2 * np.pi), st.floats(1.5, 5), st.integers(0, 2**31))
def test_low_sources_are_backward_stable(k, log_elev, azimuth, dist, seed):
    """Random convex sources parallel to the receiver's plane, seen at elevation 1e-8 .. 0.04 (the
    horizon form): within 10 u·(1 + kappa) of mpmath (the raw sum erred by u / elevation²; just
    above GRAZING_SINE, where it still serves, it errs by up to ~2^8 u: 3e-13 at 0.065)."""
    rng = np.random.default_rng(seed)
    poly = _random_convex(rng, k) + [dist * np.cos(azimuth), dist * np.sin(azimuth), 0]
    poly[:, 2] = 10.0**log_elev * dist
    err = rel_err(F([0, 0, 0], Z, poly), lambert_mp([0, 0, 0], Z, poly))
    assert err < 1e-14 or err <= 10 * U * (1 + condition_mp([0, 0, 0], Z, poly))


@pytest.mark.parametrize("d", [1e-2, 1e-4, 1e-6, 1e-8])
def test_tilted_receiver_near_the_source_plane(d):
    """Receiver d above the square's plane, beside it, its normal tilted towards the plane: with
    n = nu N + n_perp Lambert's terms are O(nu) and cancel to O(d) (the raw sum erred by 1.2e-7 at
    d = 1e-8, 2 u(1+kappa)); the near-plane form sums nu S_N (horizon form for the normal N) and
    O(d) terms: measured 4.6e-16 at every d."""
    for n in (unit([-1, 0, 1]), unit([-1, 0, -1]), unit([-1, 0.5, 0.2]), unit([-0.1, 0, 1])):
        x = [1.5, 0.5, d]
        assert rel_err(F(x, n, SQUARE), lambert_mp(x, n, SQUARE)) < 2e-15


@settings(max_examples=40, deadline=None)
@given(st.integers(3, 6), st.floats(-9, -1.3), st.floats(0.1, 1.0), st.integers(0, 2**31))
def test_near_plane_receivers_are_backward_stable(k, log_height, tilt, seed):
    """Random convex sources, receivers 1e-9 .. 0.05 (times the distance) off the source's plane
    and outside it, normals tilted towards it by any angle: within 30 u·(1 + kappa) (measured up to
    10 at 1e-9, where the height over the plane itself carries a few roundings of |c|)."""
    rng = np.random.default_rng(seed)
    poly = _random_convex(rng, k)
    azimuth = rng.uniform(0, 2 * np.pi)
    dist = rng.uniform(1.5, 3)
    x = np.array([dist * np.cos(azimuth), dist * np.sin(azimuth), 10.0**log_height * dist])
    n = unit([-np.cos(azimuth) * np.cos(tilt * np.pi / 2), -np.sin(azimuth) * np.cos(tilt * np.pi / 2),
              rng.choice([-1, 1]) * np.sin(tilt * np.pi / 2)])
    rot = _rotation(rng)
    poly, x, n = poly @ rot.T, x @ rot.T, n @ rot.T
    ref = lambert_mp(x, n, poly)
    assume(ref > 0)
    err = rel_err(F(x, n, poly), ref)
    assert err < 1e-14 or err <= 30 * U * (1 + condition_mp(x, n, poly))


def test_fill_mode_leaves_out_only_sub_1e16_grazing_error():
    """pair_factors(mode="fill") (the matrix fill) skips the grazing forms: on nearly coplanar
    plates and a thin strip its factors differ from mode "auto" by less than 1e-16 absolute."""
    from radiosity.formfactors._quadrature import pair_factors
    from radiosity.geometry import centroids_and_areas

    for eps in (1e-8, 1e-6, 1e-4):
        lower = SQUARE.copy()
        upper = SQUARE[::-1] + [1.5, 0, eps]
        strip = np.array([[1, 0, 0], [1, 1, 0], [1, 1, eps], [1, 0, eps]], float)[::-1] + [0.5, 0, 0]
        quads = np.array([lower, upper, strip])
        normals = np.array([Z, -Z, [-1, 0, 0]])
        c, a = centroids_and_areas(quads)
        i, j = np.array([0, 0, 1]), np.array([1, 2, 0])
        auto = pair_factors(quads, normals, c, a, i, j, rtol=1e-8)
        fill = pair_factors(quads, normals, c, a, i, j, rtol=1e-8, mode="fill")
        assert np.all(np.abs(auto - fill) < 1e-16)


# ----------------------------------------------------------------------------------- straddling
def _random_convex(rng, k):
    while True:
        ang = np.sort(rng.uniform(0, 2 * np.pi, k))
        r = rng.uniform(0.3, 1.0, k)
        poly = np.column_stack([r * np.cos(ang), r * np.sin(ang), np.zeros(k)])
        e = np.roll(poly, -1, 0) - poly
        if (np.cross(e, np.roll(e, -1, 0))[:, 2] > 1e-3).all():
            return poly


def _rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.diag(r))


def test_straddling_random_is_backward_stable():
    """Random convex polygons crossing the receiver's plane (clipped): measured up to
    45 u·(1 + kappa) (the bench's 98 cases; 12 on these), 9.2e-12 relative where F is 2e-8."""
    rng = np.random.default_rng(11)
    done = 0
    while done < 15:
        poly = _random_convex(rng, int(rng.integers(3, 7))) @ _rotation(rng).T + 0.5 * rng.normal(size=3)
        x, n = 0.3 * rng.normal(size=3), unit(rng.normal(size=3))
        h = (poly - x) @ n
        if not h.max() > 0 > h.min():
            continue
        assert_backward_stable(x, n, poly, 500)
        done += 1


@pytest.mark.parametrize("height", [0.0, 1e-300, 1e-15, 1e-12, -1e-15, -1e-12])
def test_vertex_or_edge_on_the_receiver_plane(height):
    """A vertex or an edge on (or 1e-15 .. 1e-12 off) the receiver's tangent plane (measured 1.8e-15)."""
    x = [0.2, 0.2, 0.0]
    tri = np.array([[0, 0, height], [1, 0, 1], [0, 1, 1]], float)
    edge = np.array([[0, 0, height], [1, 0, height], [0, 1, 1]], float)
    for n in (Z, unit([0.3, -0.2, 1])):
        assert rel_err(F(x, n, tri), lambert_mp(x, n, tri)) < 2e-14
    assert rel_err(F(x, Z, edge), lambert_mp(x, Z, edge)) < 2e-14


# ----------------------------------------------------------------------------------- zero by definition
@pytest.mark.parametrize("x", [[0.5, 0.5, 0], [0.5, 0, 0], [0, 0, 0], [1, 1, 0], [2, 0.5, 0], [1e6, -3e5, 0],
                               [-0.0, 0.5, -0.0]],
                         ids=["inside", "on edge", "vertex 0", "vertex 2", "outside", "far outside", "minus zero"])
def test_receiver_in_the_source_plane_is_exactly_zero(x):
    for n in (Z, -Z, [1, 0, 0], [0.6, 0, 0.8]):
        assert F(x, n, SQUARE) == 0.0
    assert F(x, [0.6, 0, 0.8], PENTAGON) == 0.0


def test_degenerate_faces_give_zero_not_nan():
    """Below DEGENERATE_REL (area < 1e-14 r²) a triangle counts as degenerate: 0 instead of its
    true F (4.4e-15 at apex height 1e-15), never NaN; collinear and repeated vertices too."""
    for eta in (1e-15, 1e-16, 0.0):
        assert F([0.5, 0, -0.1], Z, np.array([[0, 0, 0], [1, 0, 0], [0.5, eta, 0]])) == 0.0
    assert F([0.5, 0, -0.1], Z, np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2], [1, 1, 1]], float)) == 0.0
    assert F([0.5, 0, -0.1], Z, np.zeros((4, 3))) == 0.0


@pytest.mark.parametrize("eta", [1e-3, 1e-6, 1e-9, 1e-12, 1e-13])
def test_near_degenerate_triangles(eta):
    """Triangles of apex height down to 1e-13 (area/r² = 5e-14): measured 4.7e-14 (0.16 u·(1 + kappa))."""
    tri = np.array([[0, 0, 0], [1, 0, 0], [0.5, eta, 0]])
    for x in ([0.5, 0, -0.1], [0.3, 0, -1e-9], [0.5, eta / 2, -1e-3]):
        assert rel_err(F(x, Z, tri), lambert_mp(x, Z, tri)) < 5e-13


# ----------------------------------------------------------------------------------- approaching the plane
@pytest.mark.parametrize("eps", [1e-3, 1e-6, 1e-9, 1e-11])
def test_approaching_the_source_plane(eps):
    """Receiver eps off the source's plane: F tends to 1/2 (floor under a wall's edge; above an
    edge of the square), 1 (above its centre), 1/4 (above a vertex). Measured 2.2e-16."""
    assert rel_err(F([eps, 0.5, 0], Z, WALL_X0), lambert_mp([eps, 0.5, 0], Z, WALL_X0)) < 3e-15
    for xy in ((0.5, 0.5), (0.5, 0.0), (1.0, 1.0)):
        x = [xy[0], xy[1], eps]
        assert rel_err(F(x, -Z, SQUARE), lambert_mp(x, -Z, SQUARE)) < 3e-15


def test_receiver_1e_13_above_the_square_sees_it():
    assert F([0.5, 0.5, 1e-13], -Z, SQUARE) == pytest.approx(1.0, rel=1e-12)


def test_receiver_1e_12_from_the_wall_sees_it():
    assert F([1e-12, 0.5, 0], Z, WALL_X0) == pytest.approx(float(lambert_mp([1e-12, 0.5, 0], Z, WALL_X0)), rel=1e-3)


# ----------------------------------------------------------------------------------- scale and offsets
SAMPLES = [([0.3, 0.4, -0.01], Z, SQUARE), ([0.5, 0, -1e-4], Z, SQUARE), ([0.2, 0.7, -1e-6], unit([0.1, 0, 1]), SQUARE),
           ([3, 2, -5], unit([-0.3, -0.2, 0.5]), SQUARE), ([5, 5, -100], Z, SQUARE),
           ([1e3, -2e3, -1e4], unit([-0.1, 0.2, 1]), PENTAGON), ([0.5, -0.5, -0.3], unit([0, 1, 0.2]), SQUARE),
           ([0.2, 0.2, -1e-3], Z, TRIANGLE)]


@pytest.mark.parametrize("scale", [1e-45, 1e-20, 1e-6, 1e-3, 1e3, 1e20, 1e40])
def test_scaled_scene(scale):
    """Scaling the scene changes nothing between 1e-50 and 1e50 (measured 3.3e-16)."""
    for x, n, poly in SAMPLES:
        xs, ps = np.asarray(x) * scale, poly * scale
        assert rel_err(F(xs, n, ps), lambert_mp(xs, n, ps)) < 4e-15


def test_scene_scaled_by_1e_minus_60():
    x, n, poly = SAMPLES[0]
    xs, ps = np.asarray(x) * 1e-60, poly * 1e-60
    assert rel_err(F(xs, n, ps), lambert_mp(xs, n, ps)) < 1e-13


def test_scene_scaled_by_1e55():
    x, n, poly = SAMPLES[4]
    xs, ps = np.asarray(x) * 1e55, poly * 1e55
    assert rel_err(F(xs, n, ps), lambert_mp(xs, n, ps)) < 1e-13


@pytest.mark.parametrize("offset", [1e6, 1e9])
def test_huge_offsets_lose_nothing_beyond_the_inputs(offset):
    """Translated by 1e6 or 1e9: exact for the translated (rounded) inputs to 3.3e-16. Against the
    untranslated scene only the rounding of the inputs counts (8.7e-8 at 1e9, see the docs)."""
    shift = np.array([offset, -0.37 * offset, 0.71 * offset])
    for x, n, poly in SAMPLES:
        xs, ps = np.asarray(x) + shift, poly + shift
        assert rel_err(F(xs, n, ps), lambert_mp(xs, n, ps)) < 4e-15


# ----------------------------------------------------------------------------------- slivers
SLIVER_RECT = np.array([[0, 0, 0], [1, 0, 0], [1, 1e-6, 0], [0, 1e-6, 0]], float)
SLIVER_TRI = np.array([[0, 0, 0], [1, 0, 0], [0.3, 1e-6, 0]], float)
SLIVER_SPOTS = [[0.5, 5e-7, -1e-7], [0.5, 5e-7, -1e-6], [0.5, 0, -1e-3], [0.5, 2e-6, -1e-9], [1 + 1e-7, 0, -1e-7],
                [0.5, 0.5, -0.5], [3, 2, -10], [0.5, 0, -1e3]]


@pytest.mark.parametrize("poly", [SLIVER_RECT, SLIVER_TRI], ids=["rectangle", "triangle"])
def test_slivers_are_backward_stable(poly):
    """Aspect ratio 1e6: measured within 0.23 u·(1 + kappa) except the case below (xfail)."""
    for x in SLIVER_SPOTS:
        for n in (Z, unit([0.2, -0.3, 1])):
            if poly is SLIVER_RECT and x[0] > 1 and n is Z:
                continue  # the quad-path bug, test below
            assert_backward_stable(x, n, poly, 3)


def test_sliver_quad_beyond_its_short_end():
    x = [1 + 1e-7, 0, -1e-7]
    err = rel_err(F(x, Z, SLIVER_RECT), lambert_mp(x, Z, SLIVER_RECT))
    assert err <= 100 * U * (1 + condition_mp(x, Z, SLIVER_RECT))


# ----------------------------------------------------------------------------------- non-convex
L_SHAPE = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]], float)
_t = np.linspace(0, 2 * np.pi, 10, endpoint=False)
STAR = np.column_stack([np.where(np.arange(10) % 2, 0.35, 1.0) * np.cos(_t),
                        np.where(np.arange(10) % 2, 0.35, 1.0) * np.sin(_t), np.zeros(10)])


@pytest.mark.parametrize("poly,reflex,notch", [(L_SHAPE, [1, 1], [1.5, 1.5]), (STAR, STAR[1, :2], [0.485, 0.353])],
                         ids=["L", "star"])
def test_non_convex(poly, reflex, notch):
    """Near a reflex vertex, above and beside; above the notch (h >= 1e-3); far; tilted normals
    (clipped): measured within 70 u·(1 + kappa)."""
    cases = []
    for d in (1e-6, 1e-3, 1e-1):
        cases += [([reflex[0], reflex[1], -d], Z), ([reflex[0] + d, reflex[1] + d, -d], Z),
                  ([notch[0], notch[1], -d], unit([0.3, 0.4, 1]))]
    cases += [([notch[0], notch[1], -1e-3], Z), ([notch[0], notch[1], -0.1], Z), ([0.3, 0.2, -1e3], unit([0.1, 0, 1]))]
    for x, n in cases:
        assert_backward_stable(x, n, poly, 700)


def test_non_convex_equals_its_pieces():
    """The L equals the sum of its two rectangles, near the reflex vertex too (measured 2.3e-13)."""
    a = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], float)
    b = np.array([[0, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]], float)
    for x in ([1.0, 1.0, -1e-3], [1.2, 1.3, -1e-2], [0.5, 0.5, -5.0]):
        assert rel_err(F(x, Z, L_SHAPE), F(x, Z, a) + F(x, Z, b)) < 2e-12


# ----------------------------------------------------------------------------------- enclosures
def _cube_faces():
    t = np.linspace(0, 1, 3)
    out = []
    for axis in range(3):
        other = [k for k in range(3) if k != axis]
        for side in (0, 1):
            for a in range(2):
                for b in range(2):
                    q = np.array([[t[a], t[b]], [t[a + 1], t[b]], [t[a + 1], t[b + 1]], [t[a], t[b + 1]]])
                    P = np.zeros((4, 3))
                    P[:, other[0]], P[:, other[1]], P[:, axis] = q[:, 0], q[:, 1], side
                    out.append(P)
    return out


@pytest.mark.parametrize("d", [1e-3, 1e-6])
def test_closed_cube_sums_to_one(d):
    """From inside a closed box every upper hemisphere is covered once: Σ_faces F = 1. Random
    points: measured 2.2e-16; 1e-3 and 1e-6 from a face, an edge or a corner: 2.2e-16 and 1.8e-14
    (each term is ill-conditioned there; the identity is not)."""
    rng = np.random.default_rng(5)
    faces = _cube_faces()
    pts = np.vstack([rng.uniform(0.05, 0.95, (8, 3)), [[0.37, 0.61, d], [d, 0.44, d], [d, d, d]]])
    nrm = np.array([unit(v) for v in rng.normal(size=(len(pts), 3))])
    total = sum(point_to_polygon(pts, nrm, face) for face in faces)
    assert np.abs(total[:8] - 1).max() < 3e-15
    assert np.abs(total[8:] - 1).max() < {1e-3: 3e-15, 1e-6: 2e-13}[d]


# ----------------------------------------------------------------------------------- hypothesis: invariances
@st.composite
def scenes(draw):
    """A convex polygon 0.3 .. 3 above the receiver, clear of its horizon, then rotated."""
    k = draw(st.integers(3, 6))
    angles = sorted(draw(st.lists(st.floats(0, 2 * np.pi), min_size=k, max_size=k, unique=True)))
    assume(min(np.diff(angles + [angles[0] + 2 * np.pi])) > 0.2)
    radius = draw(st.floats(0.2, 1.0))
    cx, cy = draw(st.floats(-1.5, 1.5)), draw(st.floats(-1.5, 1.5))
    height = draw(st.floats(0.3, 3.0))
    tilt = np.array([draw(st.floats(-0.3, 0.3)), draw(st.floats(-0.3, 0.3)), 1.0])
    poly = np.column_stack([cx + radius * np.cos(angles), cy + radius * np.sin(angles), np.full(k, height)])
    n = unit(tilt)
    assume((poly @ n).min() > 0.2 * np.linalg.norm(poly, axis=1).max())  # well above the horizon
    a, b, c = draw(st.floats(0, 2 * np.pi)), draw(st.floats(0, np.pi)), draw(st.floats(0, 2 * np.pi))
    R = (np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
         @ np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
         @ np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]]))
    x = np.array([draw(st.floats(-2, 2)) for _ in range(3)])
    return poly @ R.T + x, x, n @ R.T


POINT_PROPERTY = settings(max_examples=15)


def _close(a, b, rtol):
    return abs(a - b) <= rtol * max(abs(a), abs(b))


@POINT_PROPERTY
@given(scenes(), st.integers(-2**20, 2**20), st.integers(-2**20, 2**20), st.integers(-2**20, 2**20))
def test_translation_on_a_dyadic_grid_is_exact(scene, i, j, k):
    """With coordinates on a 2^-30 grid, translating by up to 2^20 is exact, and so are the
    kernel's relative coordinates: the result does not change."""
    poly, x, n = scene
    poly, x = np.round(poly * 2**30) / 2**30, np.round(x * 2**30) / 2**30
    shift = np.array([i, j, k], float)
    f0, f1 = F(x, n, poly), F(x + shift, n, poly + shift)
    assert 0.0 < f0 <= 1.0 and _close(f0, f1, 1e-15)


@POINT_PROPERTY
@given(scenes(), st.floats(-1e6, 1e6), st.floats(-1e6, 1e6), st.floats(-1e6, 1e6))
def test_translation(scene, tx, ty, tz):
    """Any translation up to 1e6: the inputs round (to 1.2e-10 absolute); F moves by no more
    than that makes it (well-conditioned scenes: 1e-8 relative)."""
    poly, x, n = scene
    shift = np.array([tx, ty, tz])
    assert _close(F(x, n, poly), F(x + shift, n, poly + shift), 1e-8)


@POINT_PROPERTY
@given(scenes(), st.floats(0, 2 * np.pi), st.floats(0, np.pi), st.floats(0, 2 * np.pi))
def test_rotation(scene, a, b, c):
    poly, x, n = scene
    R = (np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
         @ np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
         @ np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]]))
    assert _close(F(x, n, poly), F(x @ R.T, n @ R.T, poly @ R.T), 1e-13)


@POINT_PROPERTY
@given(scenes(), st.permutations([0, 1, 2]), st.lists(st.sampled_from([-1.0, 1.0]), min_size=3, max_size=3))
def test_axis_permutations_and_mirrors(scene, perm, signs):
    """The 48 symmetries of the cube move no digit of the inputs (mirrors reverse the winding);
    the kernel's fused multiply-adds round a x b - c x d asymmetrically, a few ulp."""
    poly, x, n = scene
    s = np.array(signs)
    assert _close(F(x, n, poly), F(x[perm] * s, n[perm] * s, poly[:, perm] * s), 5e-14)


@POINT_PROPERTY
@given(scenes(), st.integers(-60, 60), st.floats(1e-3, 1e3))
def test_uniform_scaling(scene, k, s):
    """Scaling by 2^k is exact and changes nothing; by any s in [1e-3, 1e3] the rounding of the
    scaled inputs moves F by at most 1e-13 (well-conditioned scenes)."""
    poly, x, n = scene
    f0 = F(x, n, poly)
    assert _close(f0, F(x * 2.0**k, n, poly * 2.0**k), 1e-15)
    assert _close(f0, F(x * s, n, poly * s), 1e-13)


@POINT_PROPERTY
@given(scenes(), st.integers(0, 5))
def test_vertex_order(scene, roll):
    """Any first vertex and either winding (point_to_polygon ignores the winding)."""
    poly, x, n = scene
    f0 = F(x, n, poly)
    rolled = np.roll(poly, roll % len(poly), axis=0)
    assert _close(f0, F(x, n, rolled), 1e-13) and _close(f0, F(x, n, rolled[::-1]), 1e-13)


@POINT_PROPERTY
@given(scenes(), st.integers(0, 5), st.floats(0.1, 0.9))
def test_splitting_is_additive(scene, start, t):
    """Cut the polygon by a chord from a vertex to a point on an opposite edge: F adds up."""
    poly, x, n = scene
    k = len(poly)
    i = start % k
    j = (i + k // 2) % k
    cut = poly[j] + t * (poly[(j + 1) % k] - poly[j])
    idx = [(i + m) % k for m in range(k)]
    split = idx.index(j)
    first = np.vstack([poly[idx[:split + 1]], cut])
    second = np.vstack([cut, poly[idx[split + 1:]], poly[i]])
    whole, parts = F(x, n, poly), F(x, n, first) + F(x, n, second)
    assert _close(whole, parts, 1e-12)


# ----------------------------------------------------------------------------------- polygon to polygon
@pytest.mark.parametrize("gap,rtol,bound", [(1.0, 1e-10, 3e-14), (0.1, 1e-10, 3e-12), (0.01, 1e-6, 2e-7)])
def test_parallel_plates(gap, rtol, bound):
    """Howell C-11: measured 2.8e-15, 2.4e-13 at rtol 1e-10, 2.0e-8 at rtol 1e-6."""
    assert rel_err(polygon_to_polygon(SQUARE, square_top(gap), rtol=rtol), howell_c11(1, 1, gap)) < bound


def test_parallel_plates_gap_0_01_tight():
    assert rel_err(polygon_to_polygon(SQUARE, square_top(0.01), rtol=1e-10), howell_c11(1, 1, 0.01)) <= 1e-10


def test_parallel_plates_gap_1e_3():
    assert rel_err(polygon_to_polygon(SQUARE, square_top(1e-3), rtol=1e-6), howell_c11(1, 1, 1e-3)) <= 1e-6


def test_parallel_plates_1e_12_apart():
    assert polygon_to_polygon(SQUARE, square_top(1e-12), rtol=1e-6) == pytest.approx(1.0, rel=1e-6)


def test_shared_edge_at_right_angles():
    """Howell C-14 for unit squares (measured 2.4e-15 at rtol 1e-10) and for a 2x1 floor with a
    1x0.5 wall, whose corners sit on the shared edge (4.8e-7 at rtol 1e-6)."""
    assert rel_err(polygon_to_polygon(SQUARE, WALL_X0, rtol=1e-10), howell_c14(1, 1, 1)) < 3e-14
    floor = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], float)
    wall = np.array([[0, 0, 0], [0, 1, 0], [0, 1, 0.5], [0, 0, 0.5]], float)
    assert rel_err(polygon_to_polygon(floor, wall, rtol=1e-6), howell_c14(1, 2, 0.5)) <= 1e-6


@pytest.mark.parametrize("deg", [5, 45, 135, 179])
def test_shared_edge_hinged_meets_rtol_1e_6(deg):
    """Squares hinged at 5 .. 179 degrees at rtol 1e-6: measured 5.9e-7 at worst (5 degrees)."""
    a, b = hinge(np.radians(deg), [(0, 0), (1, 0), (1, 1), (0, 1)], [(0, 0), (1, 0), (1, 1), (0, 1)])
    ref = polygon_to_polygon(a, b, rtol=1e-6)
    if deg == 45:
        assert rel_err(ref, CONTOUR["squares hinged 45"]) <= 1e-6
    assert 0 < ref < 1 and polygon_to_polygon(b, a, rtol=1e-6) == pytest.approx(ref, rel=1e-12)


def test_shared_edge_hinged_45_tight():
    a, b = hinge(np.radians(45), [(0, 0), (1, 0), (1, 1), (0, 1)], [(0, 0), (1, 0), (1, 1), (0, 1)])
    assert rel_err(polygon_to_polygon(a, b, rtol=1e-10), CONTOUR["squares hinged 45"]) <= 1e-10


def test_shared_edge_unequal_tight():
    floor = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], float)
    wall = np.array([[0, 0, 0], [0, 1, 0], [0, 1, 0.5], [0, 0, 0.5]], float)
    assert rel_err(polygon_to_polygon(floor, wall, rtol=1e-10), howell_c14(1, 2, 0.5)) <= 1e-10


def test_shared_vertex_only():
    """Squares meeting at a corner and triangles meeting at a vertex (60 degrees), rtol 1e-10:
    measured 1.2e-15 and 1.7e-15 against the contour integral."""
    wall = np.array([[0, 1, 0], [0, 2, 0], [0, 2, 1], [0, 1, 1]], float)
    assert rel_err(polygon_to_polygon(SQUARE, wall, rtol=1e-10), CONTOUR["squares at a corner"]) < 2e-14
    a, b = hinge(np.radians(60), [(0, 0), (1, 0), (0.4, 0.9)], [(0, 0), (0.5, 0.8), (-0.7, 0.6)][::-1])
    assert rel_err(polygon_to_polygon(a, b, rtol=1e-10), CONTOUR["triangles at a vertex 60"]) < 2e-14


def test_near_touching_floor_moved_off_the_wall():
    """Floor 0.01 away from the wall's plane, rtol 1e-10: measured 1.2e-13."""
    got = polygon_to_polygon(SQUARE + [0.01, 0, 0], WALL_X0, rtol=1e-10)
    assert rel_err(got, CONTOUR["floor moved 0.01"]) < 1.2e-12


def test_near_touching_floor_moved_1e_3_tight():
    got = polygon_to_polygon(SQUARE + [1e-3, 0, 0], WALL_X0, rtol=1e-10)
    assert rel_err(got, CONTOUR["floor moved 0.001"]) <= 1e-10


def test_near_touching_wall_lifted_1e_3():
    assert rel_err(polygon_to_polygon(SQUARE, WALL_X0 + [0, 0, 1e-3], rtol=1e-6), CONTOUR["wall lifted 0.001"]) <= 1e-6


def test_near_touching_wall_lifted_1e_4():
    got = polygon_to_polygon(SQUARE, WALL_X0 + [0, 0, 1e-4], rtol=1e-6)
    assert rel_err(got, CONTOUR["wall lifted 0.0001"]) <= 1e-6


@pytest.mark.parametrize("shift", [[1, 0, 0], [0.5, 0.5, 0], [5, 0, 0], [1, 1, 0]],
                         ids=["adjacent", "overlapping", "distant", "at a corner"])
def test_coplanar_pairs_are_exactly_zero(shift):
    other = SQUARE + shift
    assert polygon_to_polygon(SQUARE, other, rtol=1e-10) == 0.0
    assert polygon_to_polygon(SQUARE, other[::-1], rtol=1e-10) == 0.0


@pytest.mark.parametrize("scale", [1e-6, 1e6])
def test_pair_scaled(scale):
    """Measured 3.2e-15 (parallel, shared edge) scaled by 1e-6 and 1e6."""
    assert rel_err(polygon_to_polygon(SQUARE * scale, square_top(1.0) * scale, rtol=1e-10), howell_c11(1, 1, 1)) < 3e-14
    assert rel_err(polygon_to_polygon(SQUARE * scale, WALL_X0 * scale, rtol=1e-10), howell_c14(1, 1, 1)) < 3e-14


def test_pair_translated_by_1e6():
    """Translated by 1e6 (coordinates exact): 8e-12 and 1.1e-11, inside rtol 1e-10 (the point
    kernel keeps 3e-16 there; the quadrature nodes are absolute)."""
    shift = np.array([1e6, 2e6, -1e6])
    got = polygon_to_polygon(SQUARE + shift, square_top(1.0) + shift, rtol=1e-10)
    assert rel_err(got, howell_c11(1, 1, 1)) <= 1e-10
    assert rel_err(polygon_to_polygon(SQUARE + shift, WALL_X0 + shift, rtol=1e-10), howell_c14(1, 1, 1)) <= 1e-10


def test_pair_translated_by_1e9():
    shift = np.array([1e9, 2e9, -1e9])
    assert rel_err(polygon_to_polygon(SQUARE + shift, WALL_X0 + shift, rtol=1e-10), howell_c14(1, 1, 1)) <= 1e-10


def test_receiver_across_the_source_plane_is_additive():
    def floor(x0, x1):
        return np.array([[x0, 0, 0], [x1, 0, 0], [x1, 1, 0], [x0, 1, 0]], float)

    halves = polygon_to_polygon(floor(-1, 0), WALL_X0) + polygon_to_polygon(floor(0, 1), WALL_X0)
    assert polygon_to_polygon(floor(-1, 1), WALL_X0) == pytest.approx(halves / 2, rel=1e-6)


def _facing_pair(seed):
    """Random convex polygons, each entirely in front of the other, windings facing."""
    rng = np.random.default_rng(seed)

    def newell(p):
        c = p - p.mean(0)
        return unit(np.cross(c, np.roll(c, -1, 0)).sum(0))

    while True:
        a = _random_convex(rng, int(rng.integers(3, 6))) @ _rotation(rng).T
        b = _random_convex(rng, int(rng.integers(3, 6))) @ _rotation(rng).T
        b = b + unit(rng.normal(size=3)) * rng.uniform(0.8, 3)
        if newell(a) @ (b.mean(0) - a.mean(0)) < 0:
            a = a[::-1].copy()
        if newell(b) @ (a.mean(0) - b.mean(0)) < 0:
            b = b[::-1].copy()
        if ((b - a[0]) @ newell(a)).min() > 0 and ((a - b[0]) @ newell(b)).min() > 0:
            return a, b


@settings(max_examples=8)
@given(st.integers(0, 2**32 - 1))
def test_pair_reciprocity(seed):
    """Facing pairs at rtol 1e-10: A_a F_ab = A_b F_ba (measured 7.8e-14 over 15 pairs, whose
    values also match the contour integral to 7.7e-14)."""
    a, b = _facing_pair(seed)
    fab, fba = polygon_to_polygon(a, b, rtol=1e-10), polygon_to_polygon(b, a, rtol=1e-10)
    assert fab > 0 and _close(polygon_area(a) * fab, polygon_area(b) * fba, 1e-11)


@settings(max_examples=6)
@given(st.integers(0, 2**32 - 1), st.floats(-1e3, 1e3), st.floats(0, 2 * np.pi), st.floats(1e-3, 1e3),
       st.integers(0, 4))
def test_pair_rigid_motion_scaling_and_vertex_order(seed, shift, angle, scale, roll):
    """Translation (up to 1e3), rotation, uniform scaling (1e-3 .. 1e3) and the receiver's first
    vertex change F by no more than the tolerance (rtol 1e-10)."""
    a, b = _facing_pair(seed)
    f0 = polygon_to_polygon(a, b, rtol=1e-10)
    c, s = np.cos(angle), np.sin(angle)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    assert _close(f0, polygon_to_polygon(a + shift, b + shift, rtol=1e-10), 1e-9)
    assert _close(f0, polygon_to_polygon(a @ R.T, b @ R.T, rtol=1e-10), 1e-9)
    assert _close(f0, polygon_to_polygon(a * scale, b * scale, rtol=1e-10), 1e-9)
    assert _close(f0, polygon_to_polygon(np.roll(a, roll % len(a), axis=0), b, rtol=1e-10), 1e-9)
    assert _close(f0, polygon_to_polygon(a, b[::-1], rtol=1e-10), 1e-12)


def _small_lit_box(tmp_path, offset: float) -> str:
    """A closed 1 mm box (normals in) with a lamp 0.1 mm under its ceiling, moved by ``offset``
    metres along every axis, as an OBJ (coordinates to 17 digits)."""
    from helpers import axis_box, write_obj

    shift = np.full(3, offset)
    room = [q + shift for q in axis_box((0, 0, 0), (1e-3, 1e-3, 1e-3), inward=True)]
    lamp = np.array([[3e-4, 9e-4, 3e-4], [7e-4, 9e-4, 3e-4], [7e-4, 9e-4, 7e-4], [3e-4, 9e-4, 7e-4]]) + shift
    materials = {"grey": ((0.5, 0.5, 0.5), (0.0, 0.0, 0.0)), "light": ((0.0, 0.0, 0.0), (10.0, 10.0, 10.0))}
    return write_obj(tmp_path / f"box_{offset:g}.obj", {"room": room, "lamp": [lamp]}, materials,
                     {"room": "grey", "lamp": "light"})


def test_a_small_box_far_from_the_origin_solves_as_at_the_origin(tmp_path):
    """A 1 mm box 1e6 m from the origin: float64 resolves its coordinates to 1.2e-10 m, 1e-7 of its
    size and coarser than the visibility's plane tolerance, so the lamp's back no longer hid the
    ceiling above it and 13% of the light left the closed box. Solved moved to the origin
    (``Scene.centred``), it keeps its light and its object means to the inputs' rounding; the
    solution's scene is back where the input was."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", radiosity.RadiosityWarning)
        near, far = (radiosity.solve(radiosity.load_scene(_small_lit_box(tmp_path, d)), preset="draft", cache=False)
                     for d in (0.0, 1e6))
    for name, value in near.object_radiosity().items():
        np.testing.assert_allclose(far.object_radiosity()[name], value, rtol=1e-4)
    escaped, emitted = np.asarray(far.energy["escaped"]), np.asarray(far.energy["emitted"])
    assert np.abs(escaped).max() <= 1e-2 * emitted.max()
    assert far.scene.patch_quads.min() > 1e6 - 1e-9


def test_view_factors_of_a_small_box_far_from_the_origin_in_and_out_of_core(tmp_path):
    """The same 1 mm box 1e6 m away: its view factors, in memory and written out of core, are
    those of the box at the origin (both fill it moved there); the shards keep the patches
    where the input put them."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", radiosity.RadiosityWarning)
        near, far = (radiosity.load_scene(_small_lit_box(tmp_path, d)) for d in (0.0, 1e6))
    reference = radiosity.view_factors(near, preset="draft", cache=False).toarray()
    np.testing.assert_allclose(radiosity.view_factors(far, preset="draft", cache=False).toarray(), reference,
                               atol=1e-6)
    shards = radiosity.write_view_factors(far, tmp_path / "F.shards", preset="draft")
    np.testing.assert_allclose(shards @ np.eye(far.n_patches), reference, atol=1e-6)
    stored = np.load(tmp_path / "F.shards" / "patches.npz")
    assert stored["patch_quads"].min() > 1e6 - 1e-9

"""Form factors at the extremes: worst relative error per family of hard cases, against exact
references (Howell's closed forms, a regular N-gon's closed form, mpmath at 40 digits).

    python bench/bench_extremes.py [--quick]

Writes bench/results/extremes.json and prints one table (family, cases, worst relative error,
reference, seconds) plus the per-case detail of the families that miss their target.
``docs/extremes.md`` is generated from the JSON: ``python bench/bench_extremes.py --markdown``
prints its table from the last results without recomputing.

References
----------
- ``lambert_mp``: Lambert's formula in mpmath (40 digits) on the exact binary values of the
  inputs, after clipping the polygon to the receiver's upper half-space in mpmath. It shares
  only the formula with the kernel, none of its numerics (far branch, series, relative
  coordinates, Chebyshev arctangent, float clipping).
- Howell's catalogue in mpmath: B-3 (element under the corner of a parallel rectangle),
  B-2 (element on the normal through a corner of a perpendicular rectangle), C-11 (parallel
  opposed rectangles), C-14 (perpendicular rectangles sharing an edge).
- ``ngon_axis``: point on the axis of a regular N-gon, summed in closed form per edge; and the
  disk R²/(R²+h²), whose difference is the polygon-vs-disk geometry error, not a kernel error.
- ``contour_mp``: A_1 F_12 = (1/2π) ∮∮ ln r ds_1·ds_2 (Stokes, valid when each polygon lies in
  front of the other's plane), inner integral in closed form, outer by mpmath tanh-sinh at 30
  digits split where the integrand is nearly singular. It is checked against C-11 and C-14.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import mpmath as mp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.append(str(Path(__file__).resolve().parents[1]))  # after PYTHONPATH: lets a checkout be measured
from _common import RESULTS, parse_args, print_table, write_json  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from helpers import lambert_mp  # noqa: E402  (the tests' reference too)
from helpers import mp_vector as _mpv, vec_cross as _cross, vec_dot as _dot, vec_sub as _sub  # noqa: E402

# ------------------------------------------------------------------------------------ references
DPS = 40


def howell_b3(a, b, c):
    """Element under the corner of an a x b rectangle, parallel, at distance c (Howell B-3)."""
    with mp.workdps(DPS):
        X, Y = mp.mpf(a) / c, mp.mpf(b) / c
        return (X / mp.sqrt(1 + X**2) * mp.atan(Y / mp.sqrt(1 + X**2))
                + Y / mp.sqrt(1 + Y**2) * mp.atan(X / mp.sqrt(1 + Y**2))) / (2 * mp.pi)


def howell_b2(a, b, c):
    """Element on the normal through a corner of a perpendicular a x b rectangle (Howell B-2).

    The element is at the origin facing +z; the rectangle lies in the plane y = c with
    x in [0, b] (along the planes' intersection) and z in [0, a].
    """
    with mp.workdps(DPS):
        X, Y = mp.mpf(a) / b, mp.mpf(c) / b
        R = mp.sqrt(X**2 + Y**2)
        return (mp.atan(1 / Y) - Y / R * mp.atan(1 / R)) / (2 * mp.pi)


def howell_c11(a, b, c):
    """Directly opposed parallel a x b rectangles a distance c apart (Howell C-11)."""
    with mp.workdps(DPS):
        X, Y = mp.mpf(a) / c, mp.mpf(b) / c
        t = (mp.log(mp.sqrt((1 + X**2) * (1 + Y**2) / (1 + X**2 + Y**2)))
             + X * mp.sqrt(1 + Y**2) * mp.atan(X / mp.sqrt(1 + Y**2))
             + Y * mp.sqrt(1 + X**2) * mp.atan(Y / mp.sqrt(1 + X**2)) - X * mp.atan(X) - Y * mp.atan(Y))
        return 2 * t / (mp.pi * X * Y)


def howell_c14(l, w, h):
    """Rectangle w x l to a perpendicular h x l rectangle sharing the edge l (Howell C-14)."""
    with mp.workdps(DPS):
        H, W = mp.mpf(h) / l, mp.mpf(w) / l
        s = H**2 + W**2
        t = (W * mp.atan(1 / W) + H * mp.atan(1 / H) - mp.sqrt(s) * mp.atan(1 / mp.sqrt(s))
             + mp.log((1 + W**2) * (1 + H**2) / (1 + s)
                      * (W**2 * (1 + s) / ((1 + W**2) * s)) ** (W**2)
                      * (H**2 * (1 + s) / ((1 + H**2) * s)) ** (H**2)) / 4)
        return t / (mp.pi * W)


def ngon_axis(radius, sides, height):
    """Point on the axis of a regular N-gon (circumradius ``radius``) at ``height``, facing it:
    N edges, each subtending 2·atan(half-edge / d) at apothem r_a, d = sqrt(h² + r_a²)."""
    with mp.workdps(DPS):
        R, h = mp.mpf(radius), mp.mpf(height)
        ra = R * mp.cos(mp.pi / sides)
        d = mp.sqrt(h**2 + ra**2)
        return sides / mp.pi * mp.atan(R * mp.sin(mp.pi / sides) / d) * ra / d


def disk_axis(radius, height):
    """Point on the axis of a disk, facing it: R²/(R²+h²)."""
    with mp.workdps(DPS):
        R, h = mp.mpf(radius), mp.mpf(height)
        return R**2 / (R**2 + h**2)


def _segment_log_integral(p, q0, d):
    """∫_0^1 ln|p - (q0 + t d)| dt in closed form (mpf vectors)."""
    L2 = _dot(d, d)
    L = mp.sqrt(L2)
    w = _sub(p, q0)
    a = _dot(w, d) / L
    h2 = _dot(w, w) - a * a
    if h2 < 0:
        h2 = mp.mpf(0)
    h = mp.sqrt(h2)

    def G(u):  # antiderivative of ln sqrt(u^2 + h^2)
        if h == 0:
            return u * mp.log(abs(u)) - u if u != 0 else mp.mpf(0)
        return (u * mp.log(u * u + h2) - 2 * u + 2 * h * mp.atan(u / h)) / 2

    return (G(L - a) - G(-a)) / L


def contour_mp(receiver, source, dps=30):
    """A_r F(receiver -> source) / A_r by the double contour integral (1/2π)∮∮ ln r ds·ds.

    Valid when each polygon lies entirely in front of the other's plane (touching allowed).
    Returns the area-averaged form factor (mpf).
    """
    with mp.workdps(dps):
        P = [_mpv(v) for v in receiver]
        Q = [_mpv(v) for v in source]
        total = mp.mpf(0)
        for i in range(len(P)):
            p0, e = P[i], _sub(P[(i + 1) % len(P)], P[i])
            for j in range(len(Q)):
                q0, d = Q[j], _sub(Q[(j + 1) % len(Q)], Q[j])
                ed = _dot(e, d)
                if ed == 0:
                    continue
                # split points: projections of the other segment's ends and its closest approach
                ee = _dot(e, e)
                cuts = set()
                for q in (q0, [q0[c] + d[c] for c in range(3)]):
                    s = _dot(_sub(q, p0), e) / ee
                    if 0 < s < 1:
                        cuts.add(s)
                pts = [mp.mpf(0)] + sorted(cuts) + [mp.mpf(1)]

                def f(s, p0=p0, e=e, q0=q0, d=d):
                    return _segment_log_integral([p0[c] + s * e[c] for c in range(3)], q0, d)

                total += ed * mp.quad(f, pts)
        area = mp.mpf(0)
        N = [mp.mpf(0)] * 3
        for i in range(len(P)):
            c = _cross(P[i], P[(i + 1) % len(P)])
            N = [N[0] + c[0], N[1] + c[1], N[2] + c[2]]
        area = mp.sqrt(_dot(N, N)) / 2
        return abs(total) / (2 * mp.pi) / area


U = 2.0**-53  # unit roundoff of float64


def condition_mp(x, n, poly, dps=DPS):
    """Relative condition number of point_to_polygon at this input (mpmath, central differences).

    kappa = (L · Σ_p |∇_p F| + |∇_n F|) / F, the points p being the receiver and the vertices and
    L the largest coordinate magnitude: moving every point by at most u·L (and the normal by u)
    changes F by at most u·kappa·F to first order. A kernel that is backward stable (exact for
    inputs perturbed by a few ulps) errs by O(u·kappa); an error far above that is lost by the
    algorithm, not by the problem.
    """
    with mp.workdps(dps):
        pts = [list(map(mp.mpf, map(float, x)))] + [list(map(mp.mpf, map(float, v))) for v in poly]
        nrm = list(map(mp.mpf, map(float, n)))
        L = max(abs(c) for p in pts for c in p)
        if L == 0:
            return float("nan")
        f0 = lambert_mp(pts[0], nrm, pts[1:], dps)
        if f0 == 0:
            return float("nan")
        h = L * mp.mpf(10) ** (-15)
        total = mp.mpf(0)
        for which in range(len(pts) + 1):
            g2 = mp.mpf(0)
            for c in range(3):
                vals = []
                for sgn in (1, -1):
                    P = [list(p) for p in pts]
                    N = list(nrm)
                    if which < len(pts):
                        P[which][c] += sgn * h
                    else:
                        N[c] += sgn * mp.mpf(10) ** (-15)
                    vals.append(lambert_mp(P[0], N, P[1:], dps))
                step = h if which < len(pts) else mp.mpf(10) ** (-15)
                g2 += ((vals[0] - vals[1]) / (2 * step)) ** 2
            total += mp.sqrt(g2) * (L if which < len(pts) else 1)
        return float(total / f0)


# ------------------------------------------------------------------------------------ geometry
UNIT_SQUARE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)  # normal +z
RIGHT_TRIANGLE = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
PENTAGON = np.array([[0, 0, 0], [1.1, -0.2, 0], [1.4, 0.7, 0], [0.6, 1.3, 0], [-0.3, 0.8, 0]], float)
CONVEX = {"square": UNIT_SQUARE, "triangle": RIGHT_TRIANGLE, "pentagon": PENTAGON}
L_SHAPE = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]], float)
COMB = np.array([[0, 0, 0], [3, 0, 0], [3, 2, 0], [2.6, 2, 0], [2.6, 0.4, 0], [1.7, 0.4, 0], [1.7, 2, 0],
                 [1.3, 2, 0], [1.3, 0.4, 0], [0.4, 0.4, 0], [0.4, 2, 0], [0, 2, 0]], float)
_t = np.linspace(0, 2 * np.pi, 10, endpoint=False)
STAR = np.column_stack([np.where(np.arange(10) % 2, 0.35, 1.0) * np.cos(_t),
                        np.where(np.arange(10) % 2, 0.35, 1.0) * np.sin(_t), np.zeros(10)])
NON_CONVEX = {"L": L_SHAPE, "comb": COMB, "star": STAR}
Z = np.array([0.0, 0.0, 1.0])


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.diag(r))


def random_convex(rng, k=None, radius=1.0):
    """Random convex-ish star polygon (sorted angles, radii 0.3..1) in the plane z = 0."""
    k = int(k or rng.integers(3, 7))
    while True:
        ang = np.sort(rng.uniform(0, 2 * np.pi, k))
        r = radius * rng.uniform(0.3, 1.0, k)
        poly = np.column_stack([r * np.cos(ang), r * np.sin(ang), np.zeros(k)])
        e = np.roll(poly, -1, 0) - poly
        turns = np.cross(e, np.roll(e, -1, 0))[:, 2]
        if (turns > 1e-3 * radius**2).all():
            return poly


def polygon_area(poly):
    c = poly - poly.mean(0)
    return 0.5 * float(np.linalg.norm(np.cross(c, np.roll(c, -1, 0)).sum(0)))


def newell(poly):
    c = poly - poly.mean(0)
    return unit(np.cross(c, np.roll(c, -1, 0)).sum(0))


# ------------------------------------------------------------------------------------ cases
def _err(ours, ref):
    """(relative, absolute) error; a zero reference wants exactly 0 (relative inf otherwise)."""
    ours, ref = float(ours), float(ref)
    if not np.isfinite(ours):
        return float("inf"), float("inf")
    if ref == 0.0:
        return (0.0 if ours == 0.0 else float("inf")), abs(ours)
    return abs(ours - ref) / abs(ref), abs(ours - ref)


def verdict(summary):
    """One phrase for the docs: the target met, or why not (conditioning or the kernel)."""
    if summary["meets"]:
        return "meets the target"
    if summary.get("rtol_misses"):
        return f"misses rtol in {summary['rtol_misses']} cases"
    ratio = summary.get("worst_ratio")
    if ratio is None or not np.isfinite(ratio):
        return "misses the target"
    if ratio <= 10:
        return "conditioning-limited: within 10 u(1+κ)"
    if ratio <= 100:
        return "within 100 u(1+κ)"
    return "the kernel loses digits"


class Family:
    """A list of cases: each holds our value, the reference, the errors and our time."""

    def __init__(self, name, kernel, reference, target, note=""):
        self.name, self.kernel, self.reference, self.target, self.note = name, kernel, reference, target, note
        self.cases, self.seconds, self.ref_seconds = [], 0.0, 0.0

    def point(self, label, x, n, poly, ref=None, cond=True):
        """Add a point_to_polygon case; ``ref`` defaults to lambert_mp on the same floats.

        With ``cond`` (and at most 12 vertices) the case also records the condition number
        ``kappa`` and ``ratio`` = relative error / (u·(1 + kappa)), the error in units of what a
        backward-stable kernel may commit (the 1 is the rounding of the result itself).
        """
        from radiosity import point_to_polygon

        t0 = time.perf_counter()
        try:
            ours = float(point_to_polygon(np.asarray(x, float)[None], np.asarray(n, float)[None], poly)[0])
        except Exception as exc:  # noqa: BLE001 - a crash is a finding, recorded as such
            ours = float("nan")
            label = f"{label} [raised {type(exc).__name__}]"
        self.seconds += time.perf_counter() - t0
        t0 = time.perf_counter()
        if ref is None:
            ref = lambert_mp(x, unit(n), poly)
        elif callable(ref):
            ref = ref()
        case = self.add(label, ours, ref)
        if cond and len(poly) <= 12 and case["ref"] != 0.0:
            kappa = condition_mp(x, unit(n), poly)
            case["kappa"] = kappa
            case["ratio"] = case["rel"] / (U * (1.0 + kappa))
        self.ref_seconds += time.perf_counter() - t0
        return case

    def pair(self, label, receiver, source, ref, rtol=1e-10):
        from radiosity import polygon_to_polygon

        t0 = time.perf_counter()
        ours = float(polygon_to_polygon(receiver, source, rtol=rtol))
        dt = time.perf_counter() - t0
        self.seconds += dt
        t0 = time.perf_counter()
        ref = ref() if callable(ref) else ref
        self.ref_seconds += time.perf_counter() - t0
        case = self.add(label, ours, ref)
        case.update(rtol=rtol, seconds=dt, meets_rtol=bool(case["rel"] <= rtol))
        return case

    def add(self, label, ours, ref, **extra):
        rel, ab = _err(ours, ref)
        case = {"case": label, "ours": float(ours), "ref": float(ref), "rel": rel, "abs": ab, **extra}
        self.cases.append(case)
        return case

    def summary(self):
        worst = max(self.cases, key=lambda c: (c["rel"], c["abs"]))
        out = {"family": self.name, "kernel": self.kernel, "cases": len(self.cases),
               "worst_rel": worst["rel"], "worst_abs": max(c["abs"] for c in self.cases),
               "worst_case": worst["case"], "target": self.target,
               "meets": bool(worst["rel"] <= self.target), "seconds": self.seconds,
               "ref_seconds": self.ref_seconds, "reference": self.reference, "note": self.note}
        ratios = [c["ratio"] for c in self.cases if np.isfinite(c.get("ratio", np.nan))]
        if ratios:
            out["worst_ratio"] = max(ratios)
            out["worst_ratio_case"] = max((c for c in self.cases if np.isfinite(c.get("ratio", np.nan))),
                                          key=lambda c: c["ratio"])["case"]
        rtol_cases = [c for c in self.cases if "meets_rtol" in c]
        if rtol_cases:
            out["rtol_misses"] = sum(not c["meets_rtol"] for c in rtol_cases)
        out["verdict"] = verdict(out)
        return out


# ------------------------------------------------------------------------------------ point families
def fam_near(quick):
    f = Family("near: under the polygon or beside an edge", "point_to_polygon",
               "Howell B-3 (square corners), mpmath Lambert", 1e-13,
               "height/size 1e-6..1; receivers under the interior, edge midpoints and vertices, and "
               "beside edge midpoints; normal facing the polygon")
    for d in np.logspace(-6, 0, 4 if quick else 13):
        for pname, poly in CONVEX.items():
            k = len(poly)
            spots = [("interior", poly.mean(0))]
            for i in range(k):
                mid = (poly[i] + poly[(i + 1) % k]) / 2
                out = unit(np.cross(poly[(i + 1) % k] - poly[i], Z))  # outward for ccw polygons
                spots += [(f"under edge {i}", mid), (f"beside edge {i}", mid + d * out), (f"under vertex {i}", poly[i])]
            for sname, xy in spots:
                x = np.array([xy[0], xy[1], -d])
                ref = None
                if pname == "square" and sname.startswith("under vertex"):
                    ref = lambda d=d: howell_b3(1, 1, d)  # noqa: E731
                f.point(f"{pname} {sname}, h={d:.0e}", x, Z, poly, ref)
    return f


def fam_near_vertex(quick):
    f = Family("near: beside a vertex, outside the polygon", "point_to_polygon", "mpmath Lambert", 1e-13,
               "receiver at distance d (1e-8..1e-2 of the size) diagonally outside each vertex, height d")
    for d in np.logspace(-8, -2, 4 if quick else 7):
        for pname, poly in CONVEX.items():
            k = len(poly)
            for i in range(k):
                out = unit(unit(poly[i] - poly[i - 1]) - unit(poly[(i + 1) % k] - poly[i]))
                x = poly[i] + d * out
                x[2] = -d
                f.point(f"{pname} vertex {i}, d={d:.0e}", x, Z, poly)
    return f


def fam_far(quick):
    f = Family("far: distance/size 1..1e6", "point_to_polygon", "mpmath Lambert", 1e-13,
               "from the centroid along the normal and at 60 and 85 degrees; receiver normal towards "
               "the polygon, straight or tilted 30 degrees")
    for dist in np.logspace(0, 6, 4 if quick else 13):
        for pname, poly in CONVEX.items():
            c = poly.mean(0)
            for ang in (0, 60, 85):
                a = np.radians(ang)
                u = np.array([np.sin(a), 0.3 * np.sin(a), np.cos(a)])
                u /= np.linalg.norm(u)
                x = c - dist * u
                for tilt in (0, 30):
                    t = np.radians(tilt)
                    n = unit(u * np.cos(t) + np.cross(u, [0, 1, 0]) * np.sin(t))
                    f.point(f"{pname} at {dist:.0e}, {ang} deg, tilt {tilt}", x, n, poly)
    return f


def fam_howell(quick):
    f = Family("Howell B-2/B-3 aspect sweep", "point_to_polygon", "Howell B-2, B-3 (mpmath)", 1e-13,
               "element under a corner of a parallel rectangle (B-3) or on the normal through a corner "
               "of a perpendicular one (B-2), side ratios 1e-4..1e4")
    ratios = [1e-4, 1e-2, 1, 1e2, 1e4] if not quick else [1e-3, 1, 1e3]
    for a in ratios:
        for b in ratios:
            rect = np.array([[0, 0, 1], [a, 0, 1], [a, b, 1], [0, b, 1]], float)
            f.point(f"B-3 a={a:g} b={b:g} c=1", [0, 0, 0], Z, rect, lambda a=a, b=b: howell_b3(a, b, 1))
            # B-2: element at the origin facing +z; rectangle in y = c, x in [0, b], z in [0, a]
            c = 1.0
            wall = np.array([[0, c, 0], [b, c, 0], [b, c, a], [0, c, a]], float)
            f.point(f"B-2 a={a:g} b={b:g} c=1", [0, 0, 0], Z, wall, lambda a=a, b=b, c=c: howell_b2(a, b, c))
    return f


def fam_ngon(quick):
    f = Family("regular N-gon on its axis (disk limit)", "point_to_polygon", "N-gon closed form (mpmath)",
               1e-13, "")
    sides = [3, 4, 6, 16, 64, 256, 1024] + ([] if quick else [4096])
    for n_sides in sides:
        t = np.linspace(0, 2 * np.pi, n_sides, endpoint=False)
        poly = np.column_stack([np.cos(t), np.sin(t), np.zeros(n_sides)])
        for h in (1e-6, 1e-3, 1.0, 1e3, 1e6):
            f.point(f"N={n_sides}, h/R={h:g}", [0, 0, -h], Z, poly,
                    lambda n_sides=n_sides, h=h: ngon_axis(1, n_sides, h))
    big = sides[-1]
    gap = float(abs(ngon_axis(1, big, 1) / disk_axis(1, 1) - 1))
    f.note = (f"N = 3..{big}, height/radius 1e-6..1e6. The {big}-gon differs from the disk R²/(R²+h²) "
              f"by {gap:.1e} at h = R (geometry, O(1/N²); not a kernel error)")
    return f


def fam_grazing_horizon(quick):
    f = Family("grazing: source at the receiver's horizon", "point_to_polygon", "mpmath Lambert", 1e-13,
               "vertical square whose bottom edge is eps above (or below: clipped) the receiver's "
               "tangent plane, eps 1e-8..1e-2 rad, at distance 2 and 1000")
    for eps in np.logspace(-8, -2, 4 if quick else 7):
        for dist in (2.0, 1e3):
            for sign, word in ((1, "above"), (-1, "below")):
                z0 = sign * dist * np.tan(eps)
                wall = np.array([[dist, -0.5, z0], [dist, 0.5, z0], [dist, 0.5, z0 + 1], [dist, -0.5, z0 + 1]])
                f.point(f"edge {word} horizon by {eps:.0e} rad, distance {dist:g}", [0, 0, 0], Z, wall)
    return f


def fam_grazing_edge_on(quick):
    f = Family("grazing: source seen edge-on, receiver facing it", "point_to_polygon", "mpmath Lambert",
               1e-13, "receiver beside the unit square at elevation eps (1e-8..1e-2 rad) above its plane, "
               "normal horizontal towards it")
    for eps in np.logspace(-8, -2, 4 if quick else 7):
        for dist in (0.5, 2.0):
            x = np.array([1 + dist, 0.5, dist * np.tan(eps)])
            for n in ([-1, 0, 0], [-1, 0.3, 0]):
                f.point(f"elevation {eps:.0e}, distance {dist:g}, n={n}", x, n, UNIT_SQUARE)
    return f


def fam_grazing_coplanar(quick):
    f = Family("grazing: nearly coplanar, normals nearly parallel", "point_to_polygon", "mpmath Lambert",
               1e-13, "receiver beside the unit square, eps (1e-8..1e-2 rad) below its plane, normal "
               "parallel to the square's (or tilted by eps towards it): F ~ eps²")
    for eps in np.logspace(-8, -2, 4 if quick else 7):
        for dist in (0.5, 2.0):
            x = np.array([1 + dist, 0.5, -dist * np.tan(eps)])
            for n, word in ((Z, "parallel"), (unit([-np.sin(eps), 0, np.cos(eps)]), "tilted eps")):
                f.point(f"eps {eps:.0e}, distance {dist:g}, {word}", x, n, UNIT_SQUARE)
    return f


def fam_grazing_low(quick):
    f = Family("grazing: low sources parallel to the receiver's plane", "point_to_polygon", "mpmath Lambert",
               1e-13, "random convex polygons (3..6 vertices) in a plane parallel to the tangent plane, "
               "seen at elevation 1e-8..0.05 from distance 1.5..5 (the horizon form); a strip 1e-4 x 1e4 "
               "rising from the horizon; sources near the horizon that surround or cross the zenith")
    rng = np.random.default_rng(5)
    for count in range(30 if quick else 120):
        dist, azimuth = rng.uniform(1.5, 5), rng.uniform(0, 2 * np.pi)
        poly = random_convex(rng) + [dist * np.cos(azimuth), dist * np.sin(azimuth), 0]
        poly[:, 2] = 10.0 ** rng.uniform(-8, -1.3) * dist
        f.point(f"random #{count}, elevation {poly[0, 2] / dist:.0e}", [0, 0, 0], Z, poly)
    strip = np.array([[0, 1, 0], [1e4, 1, 0], [1e4, 1, 1e-4], [0, 1, 1e-4]], float)
    f.point("strip 1e-4 high, 1e4 wide, at distance 1 (Howell B-2)", [0, 0, 0], Z, strip,
            lambda: howell_b2(1e-4, 1e4, 1))
    ceiling = np.array([[-1e3, -1e3, 1.0], [2e3, -1e3, 1.0], [-1e3, 2e3, 1.0]])
    zenith_strip = np.array([[-1e3, -0.1, 1.0], [1e3, -0.1, 1.0], [1e3, 0.1, 1.0], [-1e3, 0.1, 1.0]])
    f.point("ceiling triangle 3e3 wide at height 1 (winding number 1)", [0, 0, 0], Z, ceiling)
    f.point("strip 2e3 long at height 1, crossing the zenith", [0, 0, 0], Z, zenith_strip)
    return f


def fam_straddling(quick):
    f = Family("straddling the receiver's plane", "point_to_polygon", "mpmath clip + Lambert", 1e-13,
               "random convex polygons crossing the tangent plane (clipped); vertices and edges on or "
               "1e-15..1e-12 from the plane")
    rng = np.random.default_rng(1)
    n_random = 20 if quick else 80
    while sum(c["case"].startswith("random") for c in f.cases) < n_random:
        poly = random_convex(rng) @ rotation(rng).T + 0.5 * rng.normal(size=3)
        x = 0.3 * rng.normal(size=3)
        n = unit(rng.normal(size=3))
        h = (poly - x) @ n
        if h.max() > 0 > h.min():
            f.point(f"random #{len(f.cases)}", x, n, poly)
    x = np.array([0.2, 0.2, 0.0])
    for hv in (0.0, 1e-300, 1e-15, 1e-12, -1e-15, -1e-12):
        tri = np.array([[0, 0, hv], [1, 0, 1], [0, 1, 1]], float)
        edge = np.array([[0, 0, hv], [1, 0, hv], [0, 1, 1]], float)
        for n in (Z, unit([0.3, -0.2, 1])):
            f.point(f"vertex at height {hv:g}, n={np.round(n, 2).tolist()}", x, n, tri)
        f.point(f"edge at height {hv:g}", x, Z, edge)
    return f


def fam_zero(quick):
    f = Family("in the source's plane / sub-tolerance triangles: exact 0", "point_to_polygon",
               "0 by definition (edge-on) or by design (area < DEGENERATE_REL·r²)", 0.0,
               "receivers inside, on an edge, at a vertex, outside and far outside, in the plane of "
               "the square, 4 normals; triangles of apex height 1e-15, 1e-16 (true F recorded as 'true')")
    spots = {"inside": [0.5, 0.5, 0], "on edge": [0.5, 0, 0], "at vertex 0": [0, 0, 0], "at vertex 2": [1, 1, 0],
             "outside": [2, 0.5, 0], "far outside": [1e6, -3e5, 0], "at -0.0": [-0.0, 0.5, -0.0]}
    for sname, x in spots.items():
        for n in (Z, -Z, [1, 0, 0], [0.6, 0, 0.8]):
            f.point(f"{sname}, n={np.round(n, 2).tolist()}", x, n, UNIT_SQUARE, 0.0)
        f.point(f"{sname}, pentagon", x, [0.6, 0, 0.8], PENTAGON, 0.0)
    for eta in (1e-15, 1e-16):
        tri = np.array([[0, 0, 0], [1, 0, 0], [0.5, eta, 0]])
        x = np.array([0.5, 0, -0.1])
        case = f.point(f"triangle apex height {eta:g}", x, Z, tri, 0.0)
        case["true"] = float(lambert_mp(x, Z, tri))
    return f


def fam_edge_limit(quick):
    f = Family("approaching the source's plane (limit)", "point_to_polygon", "mpmath Lambert", 1e-13,
               "receiver eps (1e-3..1e-15) off the source's plane: on the floor under a wall's bottom "
               "edge (limit 1/2), facing the square above its centre (1), an edge (1/2), a vertex (1/4)")
    wall = np.array([[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]], float)
    epss = [1e-3, 1e-6, 1e-9, 1e-11, 1e-12, 1e-13, 1e-15] if not quick else [1e-6, 1e-11, 1e-13]
    for eps in epss:
        f.point(f"floor under wall edge, eps={eps:g}", [eps, 0.5, 0], Z, wall)
        for sname, xy in (("centre", (0.5, 0.5)), ("edge", (0.5, 0.0)), ("vertex", (1.0, 1.0))):
            f.point(f"facing square, above {sname}, eps={eps:g}", [xy[0], xy[1], eps], -Z, UNIT_SQUARE)
    return f


def _sample_cases():
    """A handful of near, far, straddling and grazing receivers for the scale/offset families."""
    return [("near interior h=1e-2", [0.3, 0.4, -0.01], Z, UNIT_SQUARE),
            ("near edge h=1e-4", [0.5, 0, -1e-4], Z, UNIT_SQUARE),
            ("near tilted h=1e-6", [0.2, 0.7, -1e-6], unit([0.1, 0, 1]), UNIT_SQUARE),
            ("oblique", [3, 2, -5], unit([-0.3, -0.2, 0.5]), UNIT_SQUARE),
            ("far 100", [5, 5, -100], Z, UNIT_SQUARE),
            ("far 1e4 pentagon", [1e3, -2e3, -1e4], unit([-0.1, 0.2, 1]), PENTAGON),
            ("straddling", [0.5, -0.5, -0.3], unit([0, 1, 0.2]), UNIT_SQUARE),
            ("triangle near", [0.2, 0.2, -1e-3], Z, RIGHT_TRIANGLE)]


def fam_tiny(quick):
    f = Family("tiny: scene scaled by 1e-6", "point_to_polygon", "mpmath Lambert on the scaled floats", 1e-13,
               "near, far, oblique, straddling receivers with the scene multiplied by 1e-6 (and 1e-3)")
    for s in (1e-6, 1e-3):
        for label, x, n, poly in _sample_cases():
            f.point(f"{label}, scale {s:g}", np.asarray(x) * s, n, poly * s)
    return f


def fam_offsets(quick):
    f = Family("huge offsets: translated by 1e6 and 1e9", "point_to_polygon",
               "mpmath Lambert on the translated floats", 1e-13,
               "")
    worst_untranslated = {}
    for T in (1e6, 1e9):
        shift = np.array([T, -0.37 * T, 0.71 * T])
        for label, x, n, poly in _sample_cases():
            xs, ps = np.asarray(x) + shift, poly + shift
            case = f.point(f"{label}, +{T:g}", xs, n, ps)
            r0 = lambert_mp(x, n, poly)
            case["rel_vs_untranslated"] = _err(case["ours"], r0)[0]
            case["input_rounding"] = _err(case["ref"], r0)[0]
            worst_untranslated[T] = max(worst_untranslated.get(T, 0.0), case["rel_vs_untranslated"])
    f.note = ("error against the exact value for the rounded (translated) inputs; against the untranslated "
              "scene the rounding of the inputs themselves dominates: worst "
              + ", ".join(f"{v:.1e} at +{T:g} ({-np.log10(max(v, 1e-17)):.1f} digits kept)"
                          for T, v in worst_untranslated.items()))
    f.extra = {"worst_rel_vs_untranslated": {f"{T:g}": v for T, v in worst_untranslated.items()}}
    return f


def fam_scale_sweep(quick):
    f = Family("scale sweep 1e-100..1e100", "point_to_polygon", "mpmath Lambert on the scaled floats", 1e-13, "")
    ks = range(-100, 101, 20 if quick else 5)
    ok = {}
    for k in ks:
        s = 10.0**k
        worst = 0.0
        for label, x, n, poly in _sample_cases()[:5]:
            case = f.point(f"{label}, scale 1e{k}", np.asarray(x) * s, n, poly * s)
            worst = max(worst, case["rel"])
        ok[k] = worst <= 1e-13
    good = [k for k in ks if ok[k]]
    lo = hi = 0
    while lo - (5 if not quick else 20) in ok and ok[lo - (5 if not quick else 20)]:
        lo -= 5 if not quick else 20
    while hi + (5 if not quick else 20) in ok and ok[hi + (5 if not quick else 20)]:
        hi += 5 if not quick else 20
    bad = [c["case"] for c in f.cases if c["rel"] > 1e-13]
    raised = sum("raised" in c for c in bad)
    f.note = (f"5 receivers per scale, scale 10^k for k = {ks.start}..{ks.stop - 1} step {ks.step}: "
              f"error <= 1e-13 for 1e{lo}..1e{hi}; {len(bad)} bad cases ({raised} raised)")
    f.extra = {"ok_scales": [f"1e{k}" for k in good], "ok_range": [lo, hi]}
    return f


def fam_slivers(quick):
    f = Family("slivers (aspect 1e6) and near-degenerate triangles", "point_to_polygon", "mpmath Lambert",
               1e-13, "1 x 1e-6 rectangle (quad path) and triangle; triangles of apex height 1e-3..1e-13")
    rect = np.array([[0, 0, 0], [1, 0, 0], [1, 1e-6, 0], [0, 1e-6, 0]], float)
    tri = np.array([[0, 0, 0], [1, 0, 0], [0.3, 1e-6, 0]], float)
    spots = [("above middle h=1e-7", [0.5, 5e-7, -1e-7]), ("above middle h=1e-6", [0.5, 5e-7, -1e-6]),
             ("above long edge h=1e-3", [0.5, 0, -1e-3]), ("beside long edge", [0.5, 2e-6, -1e-9]),
             ("beyond the short end", [1 + 1e-7, 0, -1e-7]), ("half a length away", [0.5, 0.5, -0.5]),
             ("at 10", [3, 2, -10]), ("at 1e3", [0.5, 0, -1e3])]
    for pname, poly in (("rectangle", rect), ("triangle", tri)):
        for sname, x in spots:
            for n in (Z, unit([0.2, -0.3, 1])):
                f.point(f"{pname} {sname}, n={np.round(n, 2).tolist()}", x, n, poly)
    for eta in (1e-3, 1e-6, 1e-9, 1e-12, 1e-13):
        t = np.array([[0, 0, 0], [1, 0, 0], [0.5, eta, 0]])
        for x in ([0.5, 0, -0.1], [0.3, 0, -1e-9], [0.5, eta / 2, -1e-3]):
            f.point(f"apex height {eta:g}, x={x}", x, Z, t)
    return f


def fam_nonconvex(quick):
    f = Family("non-convex polygons", "point_to_polygon", "mpmath clip + Lambert", 1e-13,
               "L, comb (12 vertices), 10-point star: receivers near reflex vertices, above the notches, "
               "beside, far, and with tilted normals (clipped)")
    reflex = {"L": [[1, 1]], "comb": [[2.6, 0.4], [1.7, 0.4], [1.3, 0.4], [0.4, 0.4]],
              "star": [STAR[1, :2].tolist(), STAR[5, :2].tolist()]}
    notch = {"L": [1.5, 1.5], "comb": [2.15, 1.2], "star": [0.6 * np.cos(np.pi / 5), 0.6 * np.sin(np.pi / 5)]}
    for pname, poly in NON_CONVEX.items():
        for d in (1e-6, 1e-3, 1e-1):
            for r in reflex[pname]:
                f.point(f"{pname} above reflex vertex {r}, h={d:g}", [r[0], r[1], -d], Z, poly)
                f.point(f"{pname} beside reflex vertex {r}, d={d:g}", [r[0] + d, r[1] + d, -d], Z, poly)
            f.point(f"{pname} above the notch, h={d:g}", [notch[pname][0], notch[pname][1], -d], Z, poly)
            f.point(f"{pname} notch, tilted", [notch[pname][0], notch[pname][1], -d], unit([0.3, 0.4, 1]), poly)
        for dist in (10.0, 1e3, 1e5):
            f.point(f"{pname} far {dist:g}", [0.3, 0.2, -dist], unit([0.1, 0, 1]), poly)
    return f


def _closed_cube(nd):
    t = np.linspace(0, 1, nd + 1)
    out = []
    for axis in range(3):
        other = [k for k in range(3) if k != axis]
        for side in (0, 1):
            for a in range(nd):
                for b in range(nd):
                    q = np.array([[t[a], t[b]], [t[a + 1], t[b]], [t[a + 1], t[b + 1]], [t[a], t[b + 1]]])
                    P = np.zeros((4, 3))
                    P[:, other[0]], P[:, other[1]], P[:, axis] = q[:, 0], q[:, 1], side
                    out.append(P)
    return out


def _icosphere(level):
    p = (1 + 5 ** 0.5) / 2
    v = [unit(x) for x in [[-1, p, 0], [1, p, 0], [-1, -p, 0], [1, -p, 0], [0, -1, p], [0, 1, p], [0, -1, -p],
                           [0, 1, -p], [p, 0, -1], [p, 0, 1], [-p, 0, -1], [-p, 0, 1]]]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
             (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
             (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    tris = [np.array([v[a], v[b], v[c]]) for a, b, c in faces]
    for _ in range(level):
        new = []
        for t in tris:
            a, b, c = t
            ab, bc, ca = unit(a + b), unit(b + c), unit(c + a)
            new += [np.array(x) for x in ([a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca])]
        tris = new
    return tris


def fam_enclosure(quick):
    f = Family("closed enclosures: sum over faces = 1", "point_to_polygon", "identity (sum = 1)", 1e-13,
               "unit cube (6 faces as 2x2 quads) and icosphere (80 triangles); random interior points, "
               "points 1e-3..1e-10 from a face, an edge, a corner; random normals")
    from radiosity import point_to_polygon

    rng = np.random.default_rng(5)
    for ename, faces in (("cube", _closed_cube(2)), ("icosphere", _icosphere(1))):
        pts = [("random", p) for p in (rng.uniform(0.05, 0.95, (4 if quick else 12, 3)) if ename == "cube"
                                        else 0.5 * rng.uniform(-1, 1, (4 if quick else 12, 3)))]
        for d in (1e-3, 1e-6, 1e-10):
            if ename == "cube":
                pts += [(f"{d:g} from a face", np.array([0.37, 0.61, d])),
                        (f"{d:g} from an edge", np.array([d, 0.44, d])),
                        (f"{d:g} from a corner", np.array([d, d, d]))]
            else:
                tri = faces[7]
                c = tri.mean(0)
                pts += [(f"{d:g} inside a face centre", c - d * newell(tri) * np.sign(newell(tri) @ c)),
                        (f"{d:g} inside a vertex", tri[0] * (1 - d))]
        labels, xs, ns = [], [], []
        for pname, x in pts:
            for n in (unit(rng.normal(size=3)), unit(rng.normal(size=3))):
                labels.append(f"{ename} {pname}, n={np.round(n, 2).tolist()}")
                xs.append(x)
                ns.append(n)
        t0 = time.perf_counter()
        total = sum(point_to_polygon(np.array(xs), np.array(ns), face) for face in faces)
        f.seconds += time.perf_counter() - t0
        for label, value in zip(labels, total):
            f.add(label, value, 1.0)
    return f


# ------------------------------------------------------------------------------------ pair families
def square_top(gap):
    """Unit square at height ``gap`` facing down."""
    return np.array([[0, 0, gap], [0, 1, gap], [1, 1, gap], [1, 0, gap]], float)


WALL_X0 = np.array([[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]], float)  # x = 0, facing +x


def hinge(alpha, a2d, b2d):
    """Receiver a2d in z = 0 (facing +z) and b2d rotated by ``alpha`` about the x axis (facing a)."""
    a = np.array([[x, y, 0] for x, y in a2d], float)
    b = np.array([[x, y * np.cos(alpha), y * np.sin(alpha)] for x, y in b2d], float)[::-1]
    return a, b


SQ2 = [(0, 0), (1, 0), (1, 1), (0, 1)]
TRI2 = [(0, 0), (1, 0), (0.3, 0.8)]


def fam_parallel(quick):
    f = Family("pair: parallel plates", "polygon_to_polygon", "Howell C-11", 1e-10,
               "directly opposed unit squares, gap 1, 0.1, 0.01, 1e-3, at rtol 1e-10 and 1e-6")
    for gap in (1.0, 0.1, 0.01, 1e-3):
        for rtol in (1e-10, 1e-6):
            f.pair(f"gap {gap:g}, rtol {rtol:g}", UNIT_SQUARE, square_top(gap), lambda g=gap: howell_c11(1, 1, g), rtol)
    return f


def fam_shared_edge(quick):
    f = Family("pair: sharing an edge", "polygon_to_polygon", "Howell C-14, contour integral (mpmath)", 1e-10,
               "perpendicular unit squares; 2x1 floor and 1x0.5 wall (source corners on the edge); "
               "squares and triangles hinged at 5..179 degrees; rtol 1e-10 and 1e-6")
    for rtol in (1e-10, 1e-6):
        f.pair(f"perpendicular unit squares, rtol {rtol:g}", UNIT_SQUARE, WALL_X0, lambda: howell_c14(1, 1, 1), rtol)
        floor = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], float)
        wall = np.array([[0, 0, 0], [0, 1, 0], [0, 1, 0.5], [0, 0, 0.5]], float)
        f.pair(f"2x1 floor to 1x0.5 wall, rtol {rtol:g}", floor, wall, lambda: howell_c14(1, 2, 0.5), rtol)
    angles = (5, 45, 135, 179) if quick else (5, 10, 30, 45, 60, 120, 135, 170, 179)
    for deg in angles:
        for name, a2, b2 in (("squares", SQ2, SQ2), ("triangles", TRI2, [(1, 0), (0, 0), (0.6, 0.7)][::-1])):
            a, b = hinge(np.radians(deg), a2, b2)
            ref = contour_mp(a, b)
            for rtol in (1e-10, 1e-6):
                f.pair(f"{name} hinged at {deg} deg, rtol {rtol:g}", a, b, ref, rtol)
    return f


def fam_shared_vertex(quick):
    f = Family("pair: sharing a vertex only", "polygon_to_polygon", "contour integral (mpmath)", 1e-10,
               "perpendicular unit squares meeting at a corner; triangles meeting at a vertex at 30..150 deg")
    wall = np.array([[0, 1, 0], [0, 2, 0], [0, 2, 1], [0, 1, 1]], float)
    ref = contour_mp(UNIT_SQUARE, wall)
    for rtol in (1e-10, 1e-6):
        f.pair(f"perpendicular squares at a corner, rtol {rtol:g}", UNIT_SQUARE, wall, ref, rtol)
    for deg in ((60, 150) if quick else (30, 60, 90, 120, 150)):
        a, b = hinge(np.radians(deg), [(0, 0), (1, 0), (0.4, 0.9)], [(0, 0), (0.5, 0.8), (-0.7, 0.6)][::-1])
        ref = contour_mp(a, b)
        for rtol in (1e-10, 1e-6):
            f.pair(f"triangles at a vertex, {deg} deg, rtol {rtol:g}", a, b, ref, rtol)
    return f


def fam_near_touching(quick):
    f = Family("pair: near-touching perpendicular", "polygon_to_polygon", "contour integral (mpmath)", 1e-10,
               "unit floor and wall with a gap g between their edges (floor moved off, or wall lifted)")
    for g in ((1e-3,) if quick else (1e-2, 1e-3, 1e-4)):
        for how, a, b in (("floor moved by g", UNIT_SQUARE + [g, 0, 0], WALL_X0),
                          ("wall lifted by g", UNIT_SQUARE, WALL_X0 + [0, 0, g])):
            ref = contour_mp(a, b)
            for rtol in (1e-10, 1e-6):
                f.pair(f"{how}, g={g:g}, rtol {rtol:g}", a, b, ref, rtol)
    return f


def fam_coplanar(quick):
    f = Family("pair: coplanar", "polygon_to_polygon", "0 (each lies in the other's plane)", 0.0,
               "adjacent, overlapping and distant coplanar squares, both windings")
    for label, b in (("adjacent", UNIT_SQUARE + [1, 0, 0]), ("overlapping", UNIT_SQUARE + [0.5, 0.5, 0]),
                     ("distant", UNIT_SQUARE + [5, 0, 0]), ("at a corner", UNIT_SQUARE + [1, 1, 0])):
        for wind, bb in (("same", b), ("reversed", b[::-1])):
            f.pair(f"{label}, {wind} winding", UNIT_SQUARE, bb, 0.0, 1e-10)
    return f


def fam_pair_scale(quick):
    f = Family("pair: tiny/huge scale and offsets", "polygon_to_polygon", "Howell C-11, C-14", 1e-10,
               "parallel squares (gap 1) and perpendicular shared-edge squares, scaled by 1e-6, 1e6 or "
               "translated by 1e6, 1e9 (all coordinates stay exact)")
    for what, a, b, ref in (("parallel", UNIT_SQUARE, square_top(1.0), howell_c11(1, 1, 1)),
                            ("shared edge", UNIT_SQUARE, WALL_X0, howell_c14(1, 1, 1))):
        for s in (1e-6, 1e6):
            f.pair(f"{what} x {s:g}", a * s, b * s, ref, 1e-10)
        for T in (1e6, 1e9):
            shift = np.array([T, 2 * T, -T])
            f.pair(f"{what} + {T:g}", a + shift, b + shift, ref, 1e-10)
    return f


def _facing_pair(rng):
    """Random convex polygons, each entirely in front of the other, windings facing each other."""
    while True:
        a = random_convex(rng) @ rotation(rng).T
        b = random_convex(rng) @ rotation(rng).T + unit(rng.normal(size=3)) * rng.uniform(0.8, 3)
        if newell(a) @ (b.mean(0) - a.mean(0)) < 0:
            a = a[::-1].copy()
        if newell(b) @ (a.mean(0) - b.mean(0)) < 0:
            b = b[::-1].copy()
        if ((b - a[0]) @ newell(a)).min() > 0 and ((a - b[0]) @ newell(b)).min() > 0:
            return a, b


def fam_reciprocity(quick):
    f = Family("pair: random facing pairs, both directions", "polygon_to_polygon",
               "contour integral (mpmath); reciprocity", 1e-10,
               "")
    from radiosity import polygon_to_polygon

    rng = np.random.default_rng(7)
    worst_recip = 0.0
    for t in range(5 if quick else 15):
        a, b = _facing_pair(rng)
        Aa, Ab = polygon_area(a), polygon_area(b)
        ref = contour_mp(a, b)
        fa = f.pair(f"#{t} a->b", a, b, ref, 1e-10)
        fb = f.pair(f"#{t} b->a", b, a, ref * mp.mpf(Aa) / mp.mpf(Ab), 1e-10)
        worst_recip = max(worst_recip, abs(Aa * fa["ours"] - Ab * fb["ours"]) / (Aa * fa["ours"]))
    t0 = time.perf_counter()
    straddle, worst_recip_straddle = 0, 0.0
    while straddle < (5 if quick else 15):  # pairs crossing each other's planes: reciprocity only
        a = random_convex(rng) @ rotation(rng).T
        b = random_convex(rng) @ rotation(rng).T + 0.6 * rng.normal(size=3)
        ha, hb = (b - a.mean(0)) @ newell(a), (a - b.mean(0)) @ newell(b)
        if not (ha.max() > 0 > ha.min() and hb.max() > 0 > hb.min()):
            continue
        if newell(b) @ (a.mean(0) - b.mean(0)) < 0:
            b = b[::-1].copy()
        fab, fba = polygon_to_polygon(a, b, rtol=1e-10), polygon_to_polygon(b, a, rtol=1e-10)
        if fab > 0 or fba > 0:
            r = abs(polygon_area(a) * fab - polygon_area(b) * fba) / max(polygon_area(a) * fab, polygon_area(b) * fba)
            worst_recip_straddle = max(worst_recip_straddle, r)
            straddle += 1
    f.seconds += time.perf_counter() - t0
    f.note = (f"{len(f.cases) // 2} random convex pairs, each in front of the other; worst reciprocity "
              f"|A_a F_ab - A_b F_ba| / A_a F_ab = {worst_recip:.1e}. Pairs crossing each other's planes "
              f"(clipped, no exact reference): worst reciprocity {worst_recip_straddle:.1e}")
    f.extra = {"worst_reciprocity": worst_recip, "worst_reciprocity_straddling": worst_recip_straddle}
    return f


def fam_behind(quick):
    f = Family("pair: receiver across the source's plane (additivity)", "polygon_to_polygon",
               "area-weighted sum of the receiver's parts on either side", 1e-10,
               "2x1 floor centred under a wall (x = 0) vs its halves x < 0 and x > 0, both wall windings; "
               "a hexagon floor across the wall (earcut pieces) vs its two parts")
    from radiosity import polygon_to_polygon

    def floor(x0, x1):
        return np.array([[x0, 0, 0], [x1, 0, 0], [x1, 1, 0], [x0, 1, 0]], float)

    for wind, wall in (("wall facing +x", WALL_X0), ("wall facing -x", WALL_X0[::-1].copy())):
        halves = [polygon_to_polygon(floor(-1, 0), wall, rtol=1e-10), polygon_to_polygon(floor(0, 1), wall, rtol=1e-10)]
        f.pair(f"2x1 floor vs its halves, {wind}", floor(-1, 1), wall, 0.5 * sum(halves), 1e-10)
        f.cases[-1]["halves"] = halves
    t = np.linspace(0, 2 * np.pi, 6, endpoint=False) + 0.3
    hexagon = np.column_stack([0.3 + 0.6 * np.cos(t), 0.5 + 0.6 * np.sin(t), np.zeros(6)])
    cuts = []  # where the hexagon's edges cross the wall's plane x = 0
    for i in range(6):
        p, q = hexagon[i], hexagon[(i + 1) % 6]
        if (p[0] < 0) != (q[0] < 0):
            cuts.append(p + (0 - p[0]) / (q[0] - p[0]) * (q - p))

    def piece(sign):
        pts = [v for v in hexagon if sign * v[0] >= 0] + cuts
        c = np.mean(pts, axis=0)
        pts = sorted(pts, key=lambda v: np.arctan2(v[1] - c[1], v[0] - c[0]))
        return np.array(pts)
    parts = [piece(1), piece(-1)]
    vals = [polygon_to_polygon(p, WALL_X0, rtol=1e-10) * polygon_area(p) for p in parts]
    f.pair("hexagon floor vs its two parts, wall facing +x", hexagon, WALL_X0, sum(vals) / polygon_area(hexagon), 1e-10)
    f.cases[-1]["front_part_only"] = vals[0] / polygon_area(hexagon)
    return f


POINT_FAMILIES = [fam_near, fam_near_vertex, fam_far, fam_howell, fam_ngon, fam_grazing_horizon,
                  fam_grazing_edge_on, fam_grazing_coplanar, fam_grazing_low, fam_straddling, fam_zero, fam_edge_limit,
                  fam_tiny, fam_offsets, fam_scale_sweep, fam_slivers, fam_nonconvex, fam_enclosure]
PAIR_FAMILIES = [fam_parallel, fam_shared_edge, fam_shared_vertex, fam_near_touching, fam_coplanar,
                 fam_pair_scale, fam_reciprocity, fam_behind]


# ------------------------------------------------------------------------------------ report
COLUMNS = ["family", "cases", "worst_rel", "worst_abs", "worst_ratio", "target", "meets", "seconds"]


def markdown_table(summaries):
    """The docs table: family, cases, worst relative and absolute error, the worst error in units
    of u·(1 + kappa) (what a backward-stable kernel may make), target, reference, our time."""
    def fmt(v):
        if v == float("inf"):
            return "inf (NaN, raised or non-zero)"
        return "0" if v == 0 else f"{v:.1e}"

    lines = ["| family | kernel | cases | worst relative error | worst absolute error | worst error / "
             "u(1+κ) | target | reference | our time (s) |", "|---|---|---|---|---|---|---|---|---|"]
    for s in summaries:
        miss = f" ({s['verdict']})" if "verdict" in s else ""
        extra = f", {s['rtol_misses']} miss rtol" if s.get("rtol_misses") else ""
        ratio = fmt(s["worst_ratio"]) if "worst_ratio" in s else "–"
        lines.append(f"| {s['family']} | `{s['kernel']}` | {s['cases']}{extra} | {fmt(s['worst_rel'])}{miss} | "
                     f"{fmt(s['worst_abs'])} | {ratio} | {fmt(s['target'])} | {s['reference']} | "
                     f"{s['seconds']:.2f} |")
    return "\n".join(lines)


def source_info():
    """Which radiosity was measured: its path, and the commit (and whether radiosity/ differs from it)
    when it is imported from a git checkout; an archive may carry a COMMIT file instead."""
    import subprocess

    import radiosity

    root = Path(radiosity.__file__).resolve().parents[1]
    info = {"radiosity": str(root)}
    try:
        info["commit"] = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True,
                                        text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--", "radiosity"],
                               capture_output=True, text=True, check=True).stdout.strip()
        info["radiosity_modified"] = bool(dirty)
    except (subprocess.CalledProcessError, FileNotFoundError):
        if (root / "COMMIT").exists():
            info["commit"] = (root / "COMMIT").read_text().strip()
            info["radiosity_modified"] = False
    return info


def main(argv=None):
    def extra(p):
        p.add_argument("--markdown", action="store_true",
                       help="print the docs table from the saved JSON and exit (no computation)")
        p.add_argument("--families", default=None, help="comma-separated substrings of family functions to run")

    args = parse_args(__doc__.splitlines()[0], argv, extra)
    if args.markdown:
        data = json.loads(Path(args.out or RESULTS / "extremes.json").read_text())
        print(markdown_table(data["summary"]))
        return
    import radiosity

    radiosity.point_to_polygon([[0, 0, 0]], [[0, 0, 1]], UNIT_SQUARE + [0, 0, 1])  # compile / load caches
    radiosity.polygon_to_polygon(UNIT_SQUARE, square_top(1.0))
    funcs = POINT_FAMILIES + PAIR_FAMILIES
    if args.families:
        keys = args.families.split(",")
        funcs = [fn for fn in funcs if any(k in fn.__name__ for k in keys)]
    summaries, details = [], {}
    t_all = time.perf_counter()
    for fn in funcs:
        t0 = time.perf_counter()
        fam = fn(args.quick)
        s = fam.summary()
        s.update(getattr(fam, "extra", {}))
        s["wall_seconds"] = time.perf_counter() - t0
        summaries.append(s)
        details[fam.name] = fam.cases
        print(f"{fam.name}: {s['cases']} cases, worst rel {s['worst_rel']:.2e} ({s['worst_case']}), "
              f"{s['wall_seconds']:.1f} s", flush=True)
    print_table(summaries, COLUMNS, title="worst relative error per family")
    bad = [(name, c) for name, cases in details.items() for c in cases
           if c["rel"] > next(s["target"] for s in summaries if s["family"] == name)]
    if bad:
        print(f"\n{len(bad)} cases above their family's target (first 40):")
        for name, c in bad[:40]:
            print(f"  [{name}] {c['case']}: ours {c['ours']:.17g} ref {c['ref']:.17g} rel {c['rel']:.2e}")
    path = write_json("extremes", {"quick": args.quick, "source": source_info(),
                                   "total_seconds": time.perf_counter() - t_all,
                                   "summary": summaries, "cases": details}, args.out)
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()

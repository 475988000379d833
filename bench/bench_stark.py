"""Stark's vertex-based formulations and the hemicube / Nusselt-disk estimators vs Lambert.

    python bench/bench_stark.py [--quick]

Section "stark": per kind of case (far, near, grazing, vertex on the receiver plane, edge on it,
clipped by it) the worst and median relative error of each formulation against mpmath (40
digits, Lambert's formula with exact clipping), and the time per pair of each on the same rows.
Section "hemicube": error of ``hemicube_factors`` against resolution on Howell cases, and its
time against ``point_to_polygon``. Writes bench/results/stark.json and prints tables.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import best_time, parse_args, print_table, write_json  # noqa: E402

import mpmath  # noqa: E402

from radiosity.alternatives import _stark, hemicube  # noqa: E402
from radiosity.formfactors import lambert_pairs, point_to_polygon  # noqa: E402

CLIP_RADIUS = 1e4  # image-plane clip radius used in the table (Lemma 1 bound 1e-8)


# ---------------------------------------------------------------------------------------------
# Cases: receiver at the origin with normal +z (so z in the receiver frame is exact)
# ---------------------------------------------------------------------------------------------

def _star(rng, k):
    """Star-shaped (often non-convex) polygon in the plane, radius ~1, centred at 0."""
    while True:  # angular gaps < pi, else the closing edge may cross another: not simple
        ang = np.sort(rng.uniform(0, 2 * np.pi, k))
        if np.diff(np.r_[ang, ang[0] + 2 * np.pi]).max() < 0.9 * np.pi:
            break
    r = rng.uniform(0.3, 1.0, k)
    return np.stack([r * np.cos(ang), r * np.sin(ang)], 1)


def _frame(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q[:, 0], q[:, 1]


def make_case(kind, n, rng, k=6):
    """``n`` polygons (n, k, 3) of size ~1 of one kind, relative to a receiver at 0 facing +z."""
    polys = np.empty((n, k, 3))
    for i in range(n):
        s = _star(rng, k)
        if kind == "edge on plane":
            # Two consecutive vertices on the line t = 0, the others above it.
            s[:, 1] -= s[:, 1].min()
            j = int(np.argmin(s[:, 1]))
            s = np.roll(s, -j, axis=0)
            s[1, 1] = 0.0
            s[1, 0] = s[0, 0] + rng.uniform(0.3, 1.0)
            e1 = np.array([*rng.normal(size=2), 0.0])
            e1 /= np.linalg.norm(e1)
            tilt = rng.uniform(0.2, 1.4)
            perp = np.cross([0, 0, 1.0], e1)
            e2 = np.cos(tilt) * perp + np.sin(tilt) * np.array([0, 0, 1.0])
            o = np.array([*rng.uniform(-1, 1, 2), 0.0])
            p = o + s[:, :1] * e1 + s[:, 1:] * e2
            p[:2, 2] = 0.0
            polys[i] = p
            continue
        e1, e2 = _frame(rng)
        p = s[:, :1] * e1 + s[:, 1:] * e2
        if kind == "far":
            d = 10.0 ** rng.uniform(0.5, 6)
            el = rng.uniform(0.3, 1.3)
            az = rng.uniform(0, 2 * np.pi)
            p = p + d * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        elif kind == "near":
            c = rng.uniform(-1, 1, 3)
            c[2] = 0
            p = p + c
            p[:, 2] += 0.1 - p[:, 2].min() + rng.uniform(0, 1.5)
        elif kind == "grazing":
            c = rng.uniform(-1.5, 1.5, 3)
            p = p + c
            p[:, 2] = p[:, 2] - p[:, 2].min() + 10.0 ** rng.uniform(-9, -3)
        elif kind == "vertex on plane":
            c = rng.uniform(-1.5, 1.5, 3)
            p = p + c
            p[:, 2] = p[:, 2] - p[:, 2].min()
        elif kind == "clipped":
            c = rng.uniform(-1, 1, 3)
            c[2] = rng.uniform(-0.5, 0.5)
            p = p + c
            if p[:, 2].max() <= 0 or p[:, 2].min() >= 0:
                p[:, 2] -= p[:, 2].mean()
        polys[i] = p
    return polys


KINDS = ["far", "near", "grazing", "vertex on plane", "edge on plane", "clipped"]


def mp_lambert(poly, dps=40):
    """Lambert's sum in mpmath for a receiver at 0 facing +z, clipping to z >= 0 exactly."""
    with mpmath.workdps(dps):
        V = [[mpmath.mpf(float(c)) for c in v] for v in poly]
        out = []
        n = len(V)
        for i in range(n):
            a, b = V[i], V[(i + 1) % n]
            if a[2] >= 0:
                out.append(a)
            if (a[2] > 0 > b[2]) or (a[2] < 0 < b[2]):
                t = a[2] / (a[2] - b[2])
                out.append([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), mpmath.mpf(0)])
        s = mpmath.mpf(0)
        for i in range(len(out)):
            a, b = out[i], out[(i + 1) % len(out)]
            c = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
            cn = mpmath.sqrt(sum(x * x for x in c))
            if cn == 0:
                continue
            th = mpmath.atan2(cn, sum(a[j] * b[j] for j in range(3)))
            s += th * c[2] / cn
        return float(abs(s) / (2 * mpmath.pi))


def formulations():
    """name -> (function(points, normals, polys) -> F, applies(kind) -> bool)."""
    strictly_above = {"far", "near", "grazing"}

    def img(form):
        return lambda p, n, q: _stark.image_plane(p, n, q, form=form)[0]

    return {
        "lambert (numba)": (lambda p, n, q: lambert_pairs(p, n, q), lambda kind: True),
        "lambert (numpy raw)": (lambda p, n, q: lambert_pairs(p, n, q, backend="numpy"), lambda kind: True),
        "image plane, slopes (eq. 8)": (img("slope"), lambda kind: kind in strictly_above),
        "image plane, projective (eq. 44)": (img("projective"), lambda kind: kind in strictly_above),
        f"image plane clipped R={CLIP_RADIUS:g}": (
            lambda p, n, q: _stark.image_plane_clipped(p, n, q, CLIP_RADIUS)[0], lambda kind: True),
        "vertex Lambert atan2 (eq. 12)": (lambda p, n, q: _stark.vertex_lambert(p, n, q), lambda kind: True),
        "vertex Lambert arccos (eq. 13)": (
            lambda p, n, q: _stark.vertex_lambert(p, n, q, angle="arccos"), lambda kind: True),
        "homogeneous (Fig. 11)": (_stark.homogeneous, lambda kind: True),
    }


def stark_accuracy(n, rng):
    rows = []
    forms = formulations()
    for kind in KINDS:
        polys = make_case(kind, n, rng)
        pts = np.zeros((n, 3))
        nrm = np.tile([0, 0, 1.0], (n, 1))
        truth = np.array([mp_lambert(p) for p in polys])
        for name, (fn, applies) in forms.items():
            if not applies(kind):
                continue
            f = fn(pts, nrm, polys)
            err = np.abs(f - truth) / np.maximum(truth, np.finfo(float).tiny)
            err[(truth == 0) & (f == 0)] = 0.0
            rows.append({"case": kind, "formulation": name, "n": n, "max rel err": float(err.max()),
                         "median rel err": float(np.median(err)),
                         "max abs err": float(np.abs(f - truth).max()),
                         "min F": float(truth.min())})
    return rows


def stark_timing(m, rng, repeat):
    rows = []
    for kind in ("near", "clipped"):
        polys = make_case(kind, 2000, rng)
        polys = np.ascontiguousarray(np.tile(polys, (m // 2000, 1, 1)))
        mm = len(polys)
        pts = np.zeros((mm, 3))
        nrm = np.tile([0, 0, 1.0], (mm, 1))
        for name, (fn, applies) in formulations().items():
            if not applies(kind):
                continue
            t = best_time(lambda: fn(pts, nrm, polys), repeat=repeat)
            cpu0 = time.process_time()
            fn(pts, nrm, polys)
            cpu = time.process_time() - cpu0
            rows.append({"case": kind, "formulation": name, "pairs": mm, "ns/pair wall": 1e9 * t / mm,
                         "ns/pair cpu": 1e9 * cpu / mm})
    return rows


def clip_radius_sweep(n, rng):
    """Clipped image-plane formula: error vs R against Lemma 1's bound, on crossing sources."""
    polys = make_case("clipped", n, rng)
    pts = np.zeros((n, 3))
    nrm = np.tile([0, 0, 1.0], (n, 1))
    truth = np.array([mp_lambert(p) for p in polys])
    rows = []
    for R in (1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e8):
        f, bound = _stark.image_plane_clipped(pts, nrm, polys, R)
        deficit = truth - f
        rows.append({"R": R, "bound 1/(1+R^2)": float(_stark.clip_error_bound(R)),
                     "max (truth - F)": float(deficit.max()), "min (truth - F)": float(deficit.min()),
                     "within bound": bool((deficit <= bound + 1e-12).all())})
    return rows


# ---------------------------------------------------------------------------------------------
# Hemicube / Nusselt disk
# ---------------------------------------------------------------------------------------------

def howell_cases():
    """(name, polygon, exact F) for a receiver at 0 facing +z: Howell's corner formula."""
    def corner(a, b, c):
        X, Y = a / c, b / c
        return (X / np.sqrt(1 + X * X) * np.arctan(Y / np.sqrt(1 + X * X))
                + Y / np.sqrt(1 + Y * Y) * np.arctan(X / np.sqrt(1 + Y * Y))) / (2 * np.pi)

    rot = 0.37  # rotate about z so no edge lines up with texel boundaries
    R = np.array([[np.cos(rot), -np.sin(rot), 0], [np.sin(rot), np.cos(rot), 0], [0, 0, 1.0]])
    cases = []
    for a, b, c in ((1, 1, 1), (2, 1, 0.5), (0.3, 0.2, 1.0), (5, 5, 1)):
        poly = np.array([[0, 0, c], [a, 0, c], [a, b, c], [0, b, c]], float) @ R.T
        cases.append((f"corner {a}x{b} at {c}", poly, float(corner(a, b, c))))
    return cases


def hemicube_sweep(resolutions, repeat):
    point_to_polygon([[0, 0, 0]], [[0, 0, 1]], howell_cases()[0][1])  # load the compiled kernel
    rows = []
    for name, poly, exact in howell_cases():
        for method in ("hemicube", "nusselt"):
            for res in resolutions:
                t = best_time(lambda: hemicube.hemicube_factors([0, 0, 0], [0, 0, 1], [poly], res,
                                                                method=method), repeat=repeat)
                f = float(hemicube.hemicube_factors([0, 0, 0], [0, 0, 1], [poly], res, method=method)[0])
                rows.append({"case": name, "method": method, "resolution": res,
                             "rel err": abs(f - exact) / exact, "time s": t})
        t = best_time(lambda: point_to_polygon([[0, 0, 0]], [[0, 0, 1]], poly), repeat=repeat, number=20)
        f = float(point_to_polygon([[0, 0, 0]], [[0, 0, 1]], poly)[0])
        rows.append({"case": name, "method": "point_to_polygon", "resolution": 0,
                     "rel err": abs(f - exact) / exact, "time s": t})
    return rows


def main(argv=None):
    args = parse_args(__doc__.splitlines()[0], argv)
    rng = np.random.default_rng(2000)
    n = 40 if args.quick else 300
    repeat = 2 if args.quick else 5
    acc = stark_accuracy(n, rng)
    print_table(acc, ["case", "formulation", "max rel err", "median rel err", "max abs err", "min F"],
                title="Accuracy against mpmath (40 digits)")
    timing = stark_timing(20_000 if args.quick else 200_000, rng, repeat)
    print_table(timing, title="Time per pair (numpy formulations vs the numba Lambert kernel)")
    sweep = clip_radius_sweep(n, rng)
    print_table(sweep, title="Clipped image plane: error vs R (Lemma 1)")
    resolutions = [16, 32, 64, 128] if args.quick else [16, 32, 64, 128, 256, 512]
    hc = hemicube_sweep(resolutions, repeat)
    print_table(hc, title="Hemicube / Nusselt disk vs resolution (Howell corner cases)")
    path = write_json("stark", {"quick": args.quick, "accuracy": acc, "timing": timing,
                                "clip_radius": sweep, "hemicube": hc}, args.out)
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()

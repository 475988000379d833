"""Form-factor kernels: Lambert pairs/s (numba on 1 and 2 threads vs plain numpy, same run;
independent pairs and the receivers x triangles pattern of a matrix fill),
far-field accuracy, polygon_to_polygon time vs rtol, closed-cube row sums with pair_factors.

    python bench/bench_formfactors.py [--quick]

Writes bench/results/formfactors.json and prints tables. Pairs/s are reported as wall rate and
as pairs per CPU-second (process time), because the 2-core machine is often shared.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parse_args, print_table, write_json  # noqa: E402


def pairs_case(m, rng):
    """Receivers on the floor of a unit box, random triangles above (sizes 0.02..2): near and far."""
    pts = rng.uniform(0, 1, (m, 3))
    pts[:, 2] = 0
    nrm = np.tile([0, 0, 1.0], (m, 1))
    tri = rng.uniform(0, 1, (m, 3, 3))
    tri[:, :, 2] = rng.uniform(0.05, 1, (m, 1))
    c = tri.mean(1, keepdims=True)
    tri = c + (tri - c) * rng.choice([0.02, 0.1, 0.5, 1, 2], size=(m, 1, 1))
    return pts, nrm, np.ascontiguousarray(np.concatenate([tri, tri[:, 2:3]], 1))


def closed_cube(nd):
    """Unit cube, each face cut into nd x nd patches, normals pointing inwards."""
    t = np.linspace(0, 1, nd + 1)
    quads, normals = [], []
    for axis in range(3):
        other = [k for k in range(3) if k != axis]
        for side in (0, 1):
            nrm = np.zeros(3)
            nrm[axis] = 1 if side == 0 else -1
            for a in range(nd):
                for b in range(nd):
                    q = np.array([[t[a], t[b]], [t[a + 1], t[b]], [t[a + 1], t[b + 1]], [t[a], t[b + 1]]])
                    P = np.zeros((4, 3))
                    P[:, other[0]], P[:, other[1]], P[:, axis] = q[:, 0], q[:, 1], side
                    if np.cross(P[1] - P[0], P[2] - P[0]) @ nrm < 0:
                        P = P[::-1]
                    quads.append(P)
                    normals.append(nrm)
    return np.array(quads), np.array(normals)


def minimal_matrix_kernel():
    """The float64 limit of the receivers x triangles pattern on this machine: Lambert's raw sum
    and nothing else (no clipping, far-field series, degenerate or in-plane checks), one SIMD
    loop per edge over (3, m) receiver rows, in parallel over triangles. Not a usable kernel
    (it errs where the product's does not); a ceiling to read the product's figure against."""
    import numba

    from radiosity.formfactors._lambert import _atan2p

    @numba.njit(parallel=True, fastmath={"contract"}, error_model="numpy", cache=False)
    def kernel(P, N, tris, out):
        m = P.shape[1]
        for q in numba.prange(tris.shape[0]):
            row = out[q]
            row[:] = 0.0
            for i in range(3):
                j = (i + 1) % 3
                w0, w1, w2 = tris[q, i, 0], tris[q, i, 1], tris[q, i, 2]
                e0, e1, e2 = tris[q, j, 0] - w0, tris[q, j, 1] - w1, tris[q, j, 2] - w2
                for u in range(m):
                    a0, a1, a2 = w0 - P[0, u], w1 - P[1, u], w2 - P[2, u]
                    x0, x1, x2 = a1 * e2 - a2 * e1, a2 * e0 - a0 * e2, a0 * e1 - a1 * e0
                    s = np.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
                    dot = a0 * a0 + a1 * a1 + a2 * a2 + a0 * e0 + a1 * e1 + a2 * e2
                    row[u] += _atan2p(s, dot) / s * (x0 * N[0, u] + x1 * N[1, u] + x2 * N[2, u])
            for u in range(m):
                row[u] = abs(row[u]) / (2 * np.pi)

    def run(points, normals, tris, out=None):
        out = np.empty((len(tris), len(points))) if out is None else out
        kernel(np.ascontiguousarray(points.T), np.ascontiguousarray(normals.T), tris, out)
        return out

    return run


def rate(fn, m, repeat):
    best_wall, best_cpu = np.inf, np.inf
    for _ in range(repeat):
        c0, w0 = time.process_time(), time.perf_counter()
        fn()
        best_cpu = min(best_cpu, time.process_time() - c0)
        best_wall = min(best_wall, time.perf_counter() - w0)
    return m / best_wall / 1e6, m / best_cpu / 1e6


def main(argv=None):
    args = parse_args(__doc__.splitlines()[0], argv)
    import numba

    from radiosity import point_to_polygons, polygon_to_polygon
    from radiosity.formfactors import lambert_pairs
    from radiosity.formfactors._closed_form import _lambert_numpy
    from radiosity.formfactors._quadrature import pair_factors
    from radiosity.geometry import centroids_and_areas

    rng = np.random.default_rng(0)
    m = 200_000 if args.quick else 2_000_000
    repeat = 2 if args.quick else 7  # best of 7: the VM's timings vary by ~30% run to run
    pts, nrm, polys = pairs_case(m, rng)
    # the fill's pattern: many receivers against each triangle (point_to_polygons)
    mr, nt = (512, 400) if args.quick else (2048, 1000)
    rpts, rnrm, _ = pairs_case(mr, rng)
    tris = pairs_case(nt, rng)[2][:, :3].copy()
    lambert_pairs(pts[:10], nrm[:10], polys[:10])  # compile / load cache
    point_to_polygons(rpts[:3], rnrm[:3], tris[:2])
    minimal = minimal_matrix_kernel()
    minimal(rpts[:3], rnrm[:3], tris[:2])
    rows = []
    mn = min(m, 200_000)
    base_wall, base_cpu = rate(lambda: _lambert_numpy(pts[:mn], nrm[:mn], polys[:mn]), mn, repeat)
    rows.append({"kernel": "numpy (raw sum), independent pairs", "threads": 1, "Mpairs/s wall": base_wall,
                 "Mpairs/cpu-s": base_cpu, "x numpy (cpu)": 1.0})
    for threads in (1, 2):
        numba.set_num_threads(threads)
        cases = {"numba, independent pairs": (lambda: lambert_pairs(pts, nrm, polys), m),
                 "numba, receivers x triangles": (lambda: point_to_polygons(rpts, rnrm, tris), mr * nt),
                 "ceiling: bare raw sum, receivers x triangles": (lambda: minimal(rpts, rnrm, tris), mr * nt)}
        for name, (fn, count) in cases.items():
            wall, cpu = rate(fn, count, repeat)
            rows.append({"kernel": name, "threads": threads, "Mpairs/s wall": wall, "Mpairs/cpu-s": cpu,
                         "x numpy (cpu)": cpu / base_cpu})
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    print_table(rows, title=f"Lambert receiver-triangle pairs ({m:,} independent pairs; {mr:,} x {nt:,} matrix)")

    # polygon_to_polygon time and error vs rtol
    lower = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    cases = {"parallel gap 1": (lower, lower[::-1] + [0, 0, 1], 0.19982489569838737),
             "perpendicular shared edge": (lower, np.array([[0, 0, 0], [0, 0, 1], [0, 1, 1], [0, 1, 0]], float),
                                           0.20004377607540363),
             "parallel gap 0.01": (lower, lower[::-1] + [0, 0, 0.01], 0.9804166029259733)}
    p2p = []
    for name, (a, b, ref) in cases.items():
        for rtol in (1e-4, 1e-6, 1e-8):
            t0 = time.perf_counter()
            v = polygon_to_polygon(a, b, rtol=rtol)
            p2p.append({"case": name, "rtol": rtol, "seconds": time.perf_counter() - t0,
                        "rel error": abs(v / ref - 1)})
    print_table(p2p, title="polygon_to_polygon")

    # closed cube with pair_factors
    cube = []
    for nd in ((4,) if args.quick else (4, 8)):
        quads, normals = closed_cube(nd)
        c, a = centroids_and_areas(quads)
        n = len(quads)
        I, J = (x.ravel() for x in np.meshgrid(np.arange(n), np.arange(n), indexing="ij"))
        keep = np.einsum("nc,nc->n", normals[I], normals[J]) < 0.5
        I, J = I[keep], J[keep]
        for rtol in (1e-4, 1e-6, 1e-8):
            t0 = time.perf_counter()
            f, info = pair_factors(quads, normals, c, a, I, J, rtol=rtol, return_info=True)
            dt = time.perf_counter() - t0
            rowsum = np.bincount(I, f, minlength=n)
            cube.append({"patches": n, "rtol": rtol, "pairs": len(I), "seconds": dt,
                         "max |row sum - 1|": float(np.abs(rowsum - 1).max()),
                         "mean points/pair": float(info["points"].mean())})
    print_table(cube, title="closed unit cube, pair_factors")
    path = write_json("formfactors", {"quick": args.quick, "lambert": rows, "polygon_to_polygon": p2p,
                                      "cube": cube}, args.out)
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()

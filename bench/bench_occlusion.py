"""Occluded view factors: two parallel unit squares 1 apart, a centred 0.5 x 0.5 blocker midway.

Times are wall and CPU (``time.process_time``, all threads) seconds of the whole fill.

Each plate is cut into n x n patches (n = 8, 16, 32; n = 32 is 1,048,576 plate-to-plate pairs);
the blocker is one patch. The measured quantity is the plate-to-plate total
``sum_ij A_i F_ij / A_plate`` against the reference 0.0995062946 (FIELD_NOTES.md), for our
"rays" and "exact" visibility modes, and for pyviewfactor (bench-only dependency) in the same
run. pyviewfactor returns F[i, j] = F(j -> i); we transpose it before summing.

Run: ``python bench/bench_occlusion.py [--quick] [--no-pyviewfactor]``. Writes
``bench/results/occlusion.json``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _common import parse_args, plate_quads, print_table, write_json  # noqa: E402

from radiosity.methods.uniform.assembly import FillSettings, assemble  # noqa: E402
from radiosity.geometry import polygon_normals  # noqa: E402
from radiosity.geometry import centroids_and_areas  # noqa: E402
from radiosity.visibility import Visibility  # noqa: E402

REFERENCE = 0.0995062946

# The settings each mode is measured with. Receiver quadrature: 2 x 2 Gauss points for every pair
# (far_separation = inf): the plate-to-plate total is then a Gauss rule of a function that is
# smooth on every patch (its kinks sit at x = 0.5, y = 0.5, on patch edges for even n).
MODES = {
    "exact": FillSettings(formfactor_rtol=1e-6, near_order=2, far_separation=float("inf"), visibility="exact"),
    "rays": FillSettings(formfactor_rtol=1e-6, near_order=2, far_separation=float("inf"), visibility="rays", visibility_samples=2,
                         visibility_max_samples=4),
}


def plates(n: int) -> tuple[np.ndarray, np.ndarray]:
    quads = plate_quads(n, blocked=True)
    groups = np.r_[np.zeros(n * n, int), np.ones(n * n, int), 2]
    return quads, groups


def time_ours(n: int, mode: str) -> dict:
    quads, groups = plates(n)
    settings = MODES[mode]
    t0, c0 = time.perf_counter(), time.process_time()
    normals = polygon_normals(quads)
    centroid, area = centroids_and_areas(quads)
    vis = Visibility(quads, normals, groups, float(np.sqrt(3)), samples=settings.visibility_samples,
                     max_samples=settings.visibility_max_samples)
    F, stats = assemble(quads, normals, centroid, area, vis, settings)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    m = n * n
    total = float(F[:m, m:2 * m].multiply(area[:m, None]).sum())
    back = float(F[m:2 * m, :m].multiply(area[m:2 * m, None]).sum())
    return {"n": n, "method": f"radiosity {mode}", "seconds": seconds, "cpu_seconds": cpu, "total": total,
            "error": total - REFERENCE, "reciprocity": back - total, "pairs": stats.n_pairs,
            "blocked_pairs": stats.n_blocked_pairs, "partial_pairs": stats.n_traced_pairs, "rays": stats.n_rays,
            "seconds_formfactors": stats.seconds_formfactors, "seconds_visibility": stats.seconds_visibility}


def time_pyviewfactor(n: int) -> dict:
    import pyvista as pv
    import pyviewfactor as pvf

    quads, _ = plates(n)
    m = n * n

    def polydata(q):
        pts = q.reshape(-1, 3)
        faces = np.column_stack([np.full(len(q), 4), np.arange(4 * len(q)).reshape(-1, 4)]).ravel()
        return pv.PolyData(pts, faces)

    mesh = polydata(quads[:2 * m])
    blocker = polydata(quads[2 * m:]).triangulate()
    t0, c0 = time.perf_counter(), time.process_time()
    F = np.asarray(pvf.compute_viewfactor_matrix(mesh, obstacles=[blocker]))
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    F = F.T  # pyviewfactor's F[i, j] is F(j -> i)
    area = centroids_and_areas(quads[:2 * m])[1]
    total = float((area[:m, None] * F[:m, m:2 * m]).sum())
    return {"n": n, "method": "pyviewfactor 1.1.0", "seconds": seconds, "cpu_seconds": cpu, "total": total,
            "error": total - REFERENCE}


def main(argv=None) -> None:
    def extra(parser):
        parser.add_argument("--no-pyviewfactor", action="store_true", help="skip the peer")

    args = parse_args(__doc__.splitlines()[0], argv, extra)
    sizes = [8, 16] if args.quick else [8, 16, 32]
    rows = []
    # warm up the compiled kernels (numba caches them on disk; the first call in a fresh
    # install compiles) so the table shows steady-state times
    for mode in MODES:
        time_ours(4, mode)
    for n in sizes:
        for mode in MODES:
            rows.append(time_ours(n, mode))
            print_table([rows[-1]], ["n", "method", "seconds", "cpu_seconds", "total", "error"])
    peer_note = None
    if not args.no_pyviewfactor:
        try:
            t0 = time.perf_counter()
            time_pyviewfactor(4)
            peer_note = f"first call (numba compile) took {time.perf_counter() - t0:.1f} s, excluded"
            for n in sizes:
                rows.append(time_pyviewfactor(n))
                print_table([rows[-1]], ["n", "method", "seconds", "cpu_seconds", "total", "error"])
        except Exception as exc:  # noqa: BLE001 - the peer is optional; say why it is missing
            peer_note = f"pyviewfactor unavailable: {type(exc).__name__}: {exc}"
    for row in rows:
        peer = [r for r in rows if r["n"] == row["n"] and r["method"].startswith("pyviewfactor")]
        if peer and not row["method"].startswith("pyviewfactor"):
            row["speedup_vs_pyviewfactor"] = peer[0]["seconds"] / row["seconds"]
    print_table(rows, ["n", "method", "seconds", "cpu_seconds", "total", "error", "speedup_vs_pyviewfactor"],
                title="Occluded parallel plates (reference 0.0995062946)")
    settings = {k: vars(v) if hasattr(v, "__dict__") else str(v) for k, v in MODES.items()}
    path = write_json("occlusion", {"reference": REFERENCE, "settings": settings, "pyviewfactor": peer_note,
                                    "rows": rows}, args.out)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

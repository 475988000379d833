"""Fill speed on the plates of issue 15, against View3D or against the bare Lambert kernel.

Two parallel unit squares 1 apart, each cut n x n (n = 8, 16, 32; n = 32 is 1,048,576
plate-to-plate pairs), open and with a centred 0.5 x 0.5 blocker midway (a View3D ``O`` surface).
Both programs read the same ``.vs3`` file; ours is timed as ``radiosity.view_factors(scene,
cache=False, ...)`` on the loaded scene (warm: numba compiled, one untimed run first), View3D as
the wall time of its process (reading the model, computing, writing the binary ``out=1`` matrix).
The runs are interleaved (ours, View3D, ours, ...); the best and the median of each are reported
and the ratio is of the bests: this machine is shared, so only ratios measured in one run mean
anything, and the best run is the one least disturbed by the other processes.

The measured quantity is the plate-to-plate total ``sum_ij A_i F_ij / A_plate`` against the
exact values (FIELD_NOTES.md): 0.1998248957 open (Howell C-11), 0.0995062946 blocked.

    python bench/bench_fill.py [--view3d PATH] [--quick] [--repeats R] [--sizes 8,16,32]

Without ``--view3d`` the baseline is the kernel's own ceiling: the bare raw-sum Lambert kernel of
bench_formfactors (no clipping, no far form, no checks) evaluating one point per pair, i.e. what
the fill would cost if each pair were a single kernel evaluation and nothing else.
``--threads`` also times our open and blocked n = 32 cases on 1 and 2 threads (``numba.set_num_threads``).
``--omp-wait-policy`` (default ``PASSIVE``, what the ``radiosity`` command sets for itself, see
``radiosity._startup``) sets ``OMP_WAIT_POLICY`` before numba starts its threads; ``unset``
leaves the environment's (a Python program importing radiosity: libgomp's spin-then-sleep).
Writes ``bench/results/fill.json``.

Building View3D 4.0 from its public source (https://github.com/jasondegraw/View3D), outside this
repository::

    git clone https://github.com/jasondegraw/View3D && cd View3D/src
    gcc -O2 -w -o view3d v3main.c view3d.c viewunob.c viewobs.c viewpp.c polygn.c ctrans.c getdat.c \\
        heap.c misc.c readvf.c savevf.c tmpstore.c test3d.c -lm
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parse_args, plate_quads, print_table, write_json  # noqa: E402

EXACT = {"open": 0.19982489569838738, "blocked": 0.0995062946}
# What each case is filled with: the accuracy we claim for it. Open: formfactor_rtol 1e-5, the
# loosest that keeps the total error below 1e-8 at n = 8, 16, 32 (2e-10, 4e-12, 2e-9; at 1e-4
# n = 16 errs by 3e-8); blocked: the view_factors defaults (each factor to 1e-6, partly occluded
# pairs by exact shadow clipping).
OURS = {"open": {"formfactor_rtol": 1e-5}, "blocked": {"formfactor_rtol": 1e-6, "visibility_atol": 1e-6}}
VIEW3D_EPS = 1e-6


def plates(n: int, blocked: bool) -> np.ndarray:
    """(2 n^2 [+ 1], 4, 3) quads: the lower plate facing up, the upper facing down, the blocker."""
    return plate_quads(n, blocked)

def write_model(quads: np.ndarray, n_obstructions: int, path: Path, eps: float) -> None:
    """A View3D model: one ``S`` surface per plate patch, ``O`` for the blocker, binary output."""
    lines = ["T plates", f"C eps={eps:g} col=0 list=0 out=1", "F 3"]
    surfaces = []
    for k, quad in enumerate(quads, start=1):
        refs = []
        for v in quad:
            lines.append(f"V {len(lines) - 2} {v[0]:.17g} {v[1]:.17g} {v[2]:.17g}")
            refs.append(len(lines) - 3)
        kind = "O" if k > len(quads) - n_obstructions else "S"
        surfaces.append(f"{kind} {k} {' '.join(map(str, refs))}" + ("" if kind == "O" else f" 0 0 0.9 p{k}"))
    path.write_text("\n".join(lines + surfaces + ["E"]) + "\n")


def read_view3d_binary(path: Path, n_surfaces: int) -> tuple[np.ndarray, np.ndarray]:
    """View3D's ``out=1`` file: a 32-byte header, float32 areas, the float32 matrix row by row."""
    raw = path.read_bytes()
    area = np.frombuffer(raw, np.float32, n_surfaces, 32).astype(float)
    F = np.frombuffer(raw, np.float32, n_surfaces * n_surfaces, 32 + 4 * n_surfaces).astype(float)
    return area, F.reshape(n_surfaces, n_surfaces)


def plate_total(F, area: np.ndarray, m: int) -> float:
    """sum_{i lower, j upper} A_i F_ij / A_lower."""
    block = F[:m, m:2 * m]
    block = block.toarray() if hasattr(block, "toarray") else block
    return float((block * area[:m, None]).sum() / area[:m].sum())


def run_ours(scene, case: str) -> tuple[float, float]:
    import radiosity

    t0 = time.perf_counter()
    F = radiosity.view_factors(scene, cache=False, **OURS[case])
    seconds = time.perf_counter() - t0
    m = (scene.n_patches - (case == "blocked")) // 2
    return seconds, plate_total(F, scene.patch_area, m)


def run_view3d(binary: str, model: Path, n_surfaces: int, m: int) -> tuple[float, float]:
    out = model.with_suffix(".bin")
    t0 = time.perf_counter()
    subprocess.run([binary, str(model), str(out)], check=True, capture_output=True, cwd=model.parent)
    seconds = time.perf_counter() - t0
    area, F = read_view3d_binary(out, n_surfaces)
    return seconds, plate_total(F, area, m)


def ceiling_seconds(n: int) -> float:
    """The bare raw-sum kernel, one evaluation per plate pair (n^4): lower centroids against the
    first triangle of each upper patch; best of 3."""
    from bench_formfactors import minimal_matrix_kernel

    quads = plates(n, False)
    m = n * n
    points = quads[:m].mean(axis=1)
    normals = np.tile([0.0, 0.0, 1.0], (m, 1))
    tris = np.ascontiguousarray(quads[m:, :3])
    kernel = minimal_matrix_kernel()
    kernel(points, normals, tris)
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        kernel(points, normals, tris)
        best = min(best, time.perf_counter() - t0)
    return best


def measure(case: str, n: int, repeats: int, view3d: str | None, folder: Path) -> list[dict]:
    import radiosity

    blocked = case == "blocked"
    quads = plates(n, blocked)
    model = folder / f"plates_{case}_{n}.vs3"
    write_model(quads, int(blocked), model, VIEW3D_EPS)
    scene = radiosity.load_scene(model)
    m = n * n
    run_ours(scene, case)  # warm
    if view3d:
        run_view3d(view3d, model, 2 * m, m)
    ours, theirs = [], []
    for _ in range(repeats):
        ours.append(run_ours(scene, case))
        if view3d:
            theirs.append(run_view3d(view3d, model, 2 * m, m))
    rows = [_row(case, n, "radiosity " + " ".join(f"{k}={v:g}" for k, v in OURS[case].items()), ours)]
    if view3d:
        rows.append(_row(case, n, f"View3D eps={VIEW3D_EPS:g}", theirs))
        rows[0]["ratio"] = rows[1]["best"] / rows[0]["best"]
        rows[0]["median_ratio"] = rows[1]["seconds"] / rows[0]["seconds"]
    elif not blocked:
        rows.append({"case": case, "n": n, "method": "bare Lambert kernel, 1 point/pair", "seconds": ceiling_seconds(n),
                     "pairs": m * m})
        rows[0]["ratio"] = rows[1]["seconds"] / rows[0]["seconds"]
    return rows


def _row(case, n, method, runs):
    seconds = [s for s, _ in runs]
    total = runs[-1][1]
    return {"case": case, "n": n, "method": method, "seconds": statistics.median(seconds), "best": min(seconds),
            "runs": seconds, "total": total, "error": total - EXACT[case], "pairs": n ** 4}


def thread_scaling(repeats: int, folder: Path) -> list[dict]:
    """Our open and blocked n = 32 fills on 1 and 2 threads, interleaved."""
    import numba

    import radiosity

    counts = [c for c in (1, 2) if c <= numba.config.NUMBA_NUM_THREADS]
    rows = []
    for case in ("open", "blocked"):
        blocked = case == "blocked"
        model = folder / f"plates_{case}_32.vs3"
        write_model(plates(32, blocked), int(blocked), model, VIEW3D_EPS)
        scene = radiosity.load_scene(model)
        times = {c: [] for c in counts}
        run_ours(scene, case)
        for _ in range(repeats):
            for c in counts:
                numba.set_num_threads(c)
                times[c].append(run_ours(scene, case)[0])
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        one = min(times[1])
        rows += [{"case": case, "threads": c, "seconds": statistics.median(times[c]), "best": min(times[c]),
                  "runs": times[c], "speedup": one / min(times[c])} for c in counts]
    return rows


def main(argv=None):
    def extra(parser):
        parser.add_argument("--view3d", default=None, help="path of a View3D 4.0 binary")
        parser.add_argument("--repeats", type=int, default=5)
        parser.add_argument("--sizes", default="8,16,32")
        parser.add_argument("--threads", action="store_true", help="also time 1 vs 2 threads")
        parser.add_argument("--omp-wait-policy", default="PASSIVE", choices=["PASSIVE", "ACTIVE", "unset"],
                            help="OMP_WAIT_POLICY for our runs (default: PASSIVE, as the radiosity command)")

    args = parse_args(__doc__.splitlines()[0], argv, extra)
    import os

    if args.omp_wait_policy != "unset":  # before numba's OpenMP pool starts (radiosity is imported below)
        os.environ["OMP_WAIT_POLICY"] = args.omp_wait_policy
    sizes = [8, 16] if args.quick else [int(s) for s in args.sizes.split(",")]
    repeats = 2 if args.quick else args.repeats
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for case in ("open", "blocked"):
            for n in sizes:
                rows += measure(case, n, repeats, args.view3d, Path(tmp))
        scaling = thread_scaling(repeats, Path(tmp)) if args.threads else []
    print_table(rows, ["case", "n", "method", "best", "seconds", "error", "ratio", "median_ratio"],
                title="Plates 1 apart, n x n each (best and median wall seconds; ratio = baseline / ours, of the bests)")
    if scaling:
        print_table(scaling, ["case", "threads", "best", "seconds", "speedup"],
                    title="n = 32, ours on 1 and 2 threads")
    path = write_json("fill", {"exact": EXACT, "ours": OURS, "view3d_eps": VIEW3D_EPS,
                               "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY", "unset"),
                               "view3d": args.view3d, "rows": rows, "threads": scaling}, args.out)
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()

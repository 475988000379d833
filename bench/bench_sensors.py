"""Sensor grids: time of ``Solution.irradiance`` per number of points, against the old ray gather.

The scene is the bundled Cornell box solved at one preset (default: ``default``, 1,7xx patches).
The sensors form a square grid on the floor (normal +y), 1 mm above it, so most of them see
the blocks' penumbrae. The baseline, measured in the same run, is the gather this replaced
(``old_irradiance`` below: rays through ``Visibility.point_fraction``, all pairs of a block of
points at once); it runs on the smallest grid only, because it is slow.

Printed per grid: points, wall seconds, microseconds per point, time per point relative to
the smallest grid (1.0 for a cost linear in the number of points), and the speed-up over the
baseline per point (CPU time: wall time on a shared machine measures the neighbours). Run: ``python bench/bench_sensors.py [--quick] [--full] [--preset P]``
(``--full`` adds the 200k and 1M grids). Writes ``bench/results/sensors.json``.

``--order SIZE`` times, on one grid of SIZE points and in the same run (alternating, twice each),
the kernel as it was before issue 19 item 6 (blocks of clusters in order, the BVH walked again
for each exact shadow) against the kernel now (blocks in a fixed shuffle, ``_points.block_order``;
each partly occluded source's occluders kept from its classification, ``REUSE_WALKS``), and
checks the two give the same irradiance, bit for bit.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _common import parse_args, print_table, write_json  # noqa: E402

import radiosity  # noqa: E402
from radiosity.formfactors import lambert_pairs  # noqa: E402
from radiosity.scene import bundled_scene  # noqa: E402
from radiosity.visibility import Visibility  # noqa: E402

FLOOR = (0.0, 0.5496, 0.0, 0.5592)  # x and z extent of the Cornell box floor, metres


def floor_grid(n: int) -> tuple[np.ndarray, np.ndarray]:
    """About n points (a square grid) 1 mm above the Cornell floor, facing up."""
    side = max(1, int(round(np.sqrt(n))))
    x = np.linspace(FLOOR[0] + 0.005, FLOOR[1] - 0.005, side)
    z = np.linspace(FLOOR[2] + 0.005, FLOOR[3] - 0.005, side)
    xx, zz = np.meshgrid(x, z, indexing="ij")
    points = np.column_stack([xx.ravel(), np.full(xx.size, 1e-3), zz.ravel()])
    return points, np.tile([0.0, 1.0, 0.0], (len(points), 1))


def old_irradiance(solution, points: np.ndarray, normals: np.ndarray, samples: int = 2) -> np.ndarray:
    """The gather before exact sensor shadows (rays; kept here as the baseline only)."""
    scene = solution.scene
    vis = Visibility(scene.patch_quads, scene.patch_normal, scene.patch_object, scene.scale, samples=samples)
    out = np.zeros((len(points), 3))
    block = max(1, 1_000_000 // max(scene.n_patches, 1))
    lit = np.flatnonzero(solution.radiosity.any(axis=1))
    for start in range(0, len(points), block):
        x, nx = points[start:start + block], normals[start:start + block]
        r = np.repeat(np.arange(len(x)), len(lit))
        j = np.tile(lit, len(x))
        front = np.einsum("mc,mc->m", x[r] - scene.patch_centroid[j], scene.patch_normal[j]) > 0
        r, j = r[front], j[front]
        f = lambert_pairs(x[r], nx[r], scene.patch_quads[j])
        nz = f > 0
        r, j, f = r[nz], j[nz], f[nz]
        f *= vis.point_fraction(x[r], nx[r], j)
        np.add.at(out[start:start + block], r, f[:, None] * solution.radiosity[j])
    return out


def timed(fn) -> tuple[float, object]:
    t0 = time.perf_counter()
    value = fn()
    return time.perf_counter() - t0, value


def order_ratio(solution, n: int) -> dict:
    """Wall and CPU time of the gather before ("in_order") and now ("shuffled"), alternating."""
    import radiosity.visibility._points as points_module

    shuffled = points_module.block_order
    in_order = lambda n_clusters: np.arange(len(shuffled(n_clusters)), dtype=np.int64)  # noqa: E731
    p, nrm = floor_grid(n)
    times = {"in_order": [], "shuffled": []}
    values = {}
    for name in ["in_order", "shuffled", "in_order", "shuffled"]:
        points_module.block_order = in_order if name == "in_order" else shuffled
        points_module.REUSE_WALKS = name == "shuffled"
        solution._sensors = None  # a fresh gather each time: nothing cached between the runs
        cpu = time.process_time()
        seconds, values[name] = timed(lambda: solution.irradiance(p, nrm))
        times[name].append((seconds, time.process_time() - cpu))
        print(f"  {name}: {seconds:.1f} s wall, {times[name][-1][1]:.1f} s CPU", flush=True)
    points_module.block_order = shuffled
    points_module.REUSE_WALKS = True
    best = {k: min(v) for k, v in times.items()}
    return {"points": len(p), "in_order_s": best["in_order"][0], "shuffled_s": best["shuffled"][0],
            "in_order_cpu_s": best["in_order"][1], "shuffled_cpu_s": best["shuffled"][1],
            "wall_speedup": best["in_order"][0] / best["shuffled"][0],
            "identical": bool(np.array_equal(values["in_order"], values["shuffled"]))}


def main(argv=None) -> None:
    def extra(parser):
        parser.add_argument("--full", action="store_true", help="add the 200k and 1M grids")
        parser.add_argument("--sizes", type=int, nargs="+", default=None, help="grid sizes (points) to time")
        parser.add_argument("--preset", default="default", choices=("draft", "default", "fine"))
        parser.add_argument("--order", type=int, default=None, metavar="SIZE",
                            help="only compare blocks in order against shuffled on SIZE points")

    args = parse_args(__doc__.splitlines()[0], argv, extra)
    solution = radiosity.solve(radiosity.load_scene(bundled_scene("cornell_box")), preset=args.preset)
    if args.order:
        solution.irradiance(*floor_grid(16))  # compile (or load) the kernel outside the timings
        row = order_ratio(solution, args.order)
        print_table([row], title="sensor gather: before (in order, walks repeated) vs now (this run)")
        write_json("sensors_order", {"preset": args.preset, "patches": int(solution.scene.n_patches),
                                     "rows": [row]}, args.out)
        return
    sizes = [1_000, 4_000] if args.quick else [1_000, 10_000, 50_000]
    if args.full:
        sizes += [200_000, 1_000_000]
    if args.sizes:
        sizes = sorted(args.sizes)
    warm_p, warm_n = floor_grid(16)
    solution.irradiance(warm_p, warm_n)  # compile (or load) the kernels outside the timings
    old_irradiance(solution, warm_p, warm_n)

    base_p, base_n = floor_grid(sizes[0])
    old_cpu = time.process_time()
    old_s, old_h = timed(lambda: old_irradiance(solution, base_p, base_n))
    old_cpu = time.process_time() - old_cpu
    rows = []
    for n in sizes:
        p, nrm = floor_grid(n)
        cpu = time.process_time()
        seconds, h = timed(lambda: solution.irradiance(p, nrm))
        cpu = time.process_time() - cpu
        rows.append({"points": len(p), "seconds": seconds, "cpu_seconds": cpu,
                     "us_per_point": 1e6 * seconds / len(p)})
        print(f"  {len(p)} points: {seconds:.1f} s wall, {cpu:.1f} s CPU", flush=True)
        if n == sizes[0]:
            new_h = h
    first = rows[0]["us_per_point"]
    old_per_point = 1e6 * old_s / len(base_p)
    for row in rows:
        row["per_point_vs_smallest"] = row["us_per_point"] / first
        row["cpu_speedup_vs_old"] = (old_cpu / len(base_p)) / (row["cpu_seconds"] / row["points"])
    lit = new_h[:, 1] > 0
    diff = np.abs(old_h[lit, 1] - new_h[lit, 1]) / new_h[lit, 1]
    leaked = int(((old_h[:, 1] > 0) & ~lit).sum())  # points inside a block: the old gather lit them
    print(f"scene: Cornell box, preset {args.preset}, {solution.scene.n_patches} patches")
    print(f"baseline (old ray gather): {len(base_p)} points in {old_s:.2f} s ({old_cpu:.1f} s CPU) = "
          f"{old_per_point:.0f} us/point; "
          f"it differs from the exact gather by {np.median(diff):.2%} median, {diff.max():.2%} max where lit, "
          f"and lit {leaked} points inside the blocks that read 0 now")
    print_table(rows, ["points", "seconds", "cpu_seconds", "us_per_point", "per_point_vs_smallest",
                      "cpu_speedup_vs_old"],
                title="exact sensor gather (rtol 1e-3)")
    write_json("sensors", {"preset": args.preset, "patches": int(solution.scene.n_patches),
                           "baseline": {"points": len(base_p), "seconds": old_s, "cpu_seconds": old_cpu,
                                        "us_per_point": old_per_point},
                           "rows": rows}, args.out)


if __name__ == "__main__":
    main()

"""Clustering (issue 14 item 2): furnace scenes of many input faces, solved hierarchically.

    python bench/bench_clusters.py [--quick] [--sizes 5,10,20,40,71] [--tolerance 1e-2] [--room 100,1000]

Two closed furnaces where every face emits E = 1 and reflects rho = 0.5, so B = E / (1 - rho)
= 2 on every leaf exactly: a geodesic sphere shell of 20 m^2 triangles (``--sizes`` lists m;
m = 71 is 100,820 triangles) and a unit room holding k small floating cubes (``--room`` lists
k; 6 + 6k faces, heavy occlusion). Each case runs in its own process (``ru_maxrss`` is its
peak), one after the other, so times compare within the run. Reports links (element +
cluster), links per input face, time, peak RSS, the hierarchy's own memory figure, and the
worst and mean leaf error against B = 2. The scenes come from ``tests/helpers.py``.
Writes ``bench/results/clusters.json``.
"""

from __future__ import annotations

import json
import resource
import sys
import time
from pathlib import Path

from _common import parse_args, print_table, run_cases, write_json

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))


def run_case(spec: dict) -> dict:
    import numpy as np

    import radiosity
    from helpers import cube_room_scene, sphere_scene

    scene = sphere_scene(spec["m"]) if spec["kind"] == "sphere" else cube_room_scene(spec["k"])
    t0 = time.perf_counter()
    solution = radiosity.solve(scene, method="hierarchical", preset="draft", cache=False,
                               link_tolerance=spec["tolerance"])
    seconds = time.perf_counter() - t0
    error = solution.radiosity / 2.0 - 1.0
    h = solution.summary()["hierarchy"]
    return {**spec, "faces": int(scene.n_patches), "seconds": seconds, "leaves": int(solution.scene.n_patches),
            "links": h["links"], "cluster_links": h["cluster_links"], "links_per_face": h["links"] / scene.n_patches,
            "max_error": float(np.abs(error).max()), "mean_error": float(error.mean()),
            "hierarchy_MB": h["memory_bytes"] / 2 ** 20,
            "peak_rss_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "rounds": h["rounds"]}


def main() -> None:
    if len(sys.argv) > 2 and sys.argv[1] == "--case":
        print(json.dumps(run_case(json.loads(sys.argv[2]))))
        return

    def extra(p):
        p.add_argument("--sizes", default="5,10,20,40")
        p.add_argument("--room", default="100,400")
        p.add_argument("--tolerance", type=float, default=1e-2)

    args = parse_args(__doc__.splitlines()[0], extra=extra)
    sizes = [int(x) for x in args.sizes.split(",") if x]
    rooms = [int(x) for x in args.room.split(",") if x]
    if args.quick:
        sizes, rooms = sizes[:2], rooms[:1]
    specs = ([{"kind": "sphere", "m": m, "tolerance": args.tolerance} for m in sizes]
             + [{"kind": "room", "k": k, "tolerance": args.tolerance} for k in rooms])
    rows = run_cases(Path(__file__), specs, cwd=HERE, tail=800)
    print_table(rows, ["kind", "faces", "tolerance", "seconds", "leaves", "links", "cluster_links", "links_per_face",
                       "max_error", "mean_error", "hierarchy_MB", "peak_rss_MB"], title="furnaces, B = 2")
    path = write_json("clusters", {"cases": rows})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

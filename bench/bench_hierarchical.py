"""Hierarchical vs uniform radiosity on the bundled Cornell box: error against time and memory.

    python bench/bench_hierarchical.py [--quick] [--scale]

Each case runs in its own process (so ``ru_maxrss`` is that case's peak memory), one after the
other in this run, so the times compare (the machine is shared: read ratios, not seconds). The
error is the largest relative difference of an object's mean radiosity (any channel, the light
left out) from ``bench/results/cornell_reference.json`` (uniform ``fine`` at 2 cm, 6,494
patches); the per-patch error is each lit patch's mean irradiance against the uniform ``fine``
solution's at its centroid (``Solution.irradiance``, after the timed solve and its peak memory),
as its median and 95th percentile: what object means average away (a leaf that gets its
ancestors' mean is off where light varies across them). ``--scale`` adds a hierarchical case with 3.5 mm minimum elements (the issue's
100k-leaf target); ``--matched`` runs only the uniform fill at 12.5 mm (14,564 patches, 7.6 GB peak:
not for a loaded machine) and hierarchical ``draft`` (``hierarchical_matched.json``). Writes
``bench/results/hierarchical.json``.
"""

from __future__ import annotations

import json
import resource
import sys
import time
from pathlib import Path

from _common import RESULTS, parse_args, print_table, run_cases, write_json

HERE = Path(__file__).resolve().parent


def run_case(spec: dict) -> dict:
    """Solve one case in this process; the numbers the table shows."""
    import numpy as np

    import radiosity

    reference = json.loads((RESULTS / "cornell_reference.json").read_text())["objects"]
    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    t0 = time.perf_counter()
    solution = radiosity.solve(scene, cache=False, **spec)
    seconds = time.perf_counter() - t0
    means = solution.object_radiosity()
    error = max(float(np.abs(means[k] / np.asarray(v) - 1).max()) for k, v in reference.items() if k != "light")
    hierarchy = solution.summary()["hierarchy"] or {}
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    p50, p95 = patch_errors(scene, solution)
    return {**{k: v for k, v in spec.items()}, "seconds": seconds, "patches": int(solution.scene.n_patches),
            "links_or_nonzeros": int(solution.F.nnz), "max_object_error": error,
            "patch_error_p50": p50, "patch_error_p95": p95, "peak_rss_MB": peak,
            "rounds": hierarchy.get("rounds"), "partly_visible_links": hierarchy.get("partly_visible_links"),
            "timings": solution.timings}


def patch_errors(scene, solution) -> tuple[float, float]:
    """Median and 95th percentile over lit patches of |H / H_ref - 1| (worst channel), H_ref the
    uniform ``fine`` solution's irradiance at the patch's centroid."""
    import numpy as np

    import radiosity

    reference = radiosity.solve(scene, method="uniform", preset="fine", cache=True)
    solved = solution.scene
    normal = solved.patch_normal
    expected = reference.irradiance(solved.patch_centroid + 1e-6 * normal, normal)
    lit = solved.emission.max(axis=1) == 0
    error = np.abs(solution.patch_irradiance[lit] / np.maximum(expected[lit], 1e-12) - 1).max(axis=1)
    return float(np.percentile(error, 50)), float(np.percentile(error, 95))


def cases(quick: bool, scale: bool, matched: bool = False) -> list[dict]:
    if matched:  # meant as the leaf count of hierarchical draft (5,256); 12.5 mm cuts 14,564 patches, 7.6 GB
        return [{"method": "uniform", "preset": "draft", "max_patch_size": 0.0125},
                {"method": "hierarchical", "preset": "draft"}]
    out = [{"method": "uniform", "preset": "draft"},
           {"method": "hierarchical", "preset": "draft", "link_tolerance": 3e-2, "min_element_rel": 1 / 25},
           {"method": "hierarchical", "preset": "draft", "link_tolerance": 1e-2, "min_element_rel": 1 / 25},
           {"method": "hierarchical", "preset": "draft", "leaf_tolerance": 0.0},
           {"method": "hierarchical", "preset": "draft"}]
    if not quick:
        out += [{"method": "uniform", "preset": "default"},
                {"method": "hierarchical", "preset": "default", "leaf_tolerance": 0.0},
                {"method": "hierarchical", "preset": "default"}]
    if scale:
        out.append({"method": "hierarchical", "preset": "draft", "min_element_size": 0.0035})
    return out


def main() -> None:
    if len(sys.argv) > 2 and sys.argv[1] == "--case":
        print(json.dumps(run_case(json.loads(sys.argv[2]))))
        return
    def extra(p):
        p.add_argument("--scale", action="store_true")
        p.add_argument("--matched", action="store_true", help="only uniform at 12.5 mm vs hierarchical draft")

    args = parse_args(__doc__.splitlines()[0], extra=extra)
    rows = run_cases(Path(__file__), cases(args.quick, args.scale, args.matched), cwd=HERE, tail=500)
    print_table(rows, ["method", "preset", "link_tolerance", "leaf_tolerance", "min_element_rel", "max_patch_size",
                       "seconds", "patches", "links_or_nonzeros", "max_object_error", "patch_error_p50",
                       "patch_error_p95", "peak_rss_MB"], title="Cornell box")
    name = "hierarchical_matched" if args.matched else "hierarchical"
    path = write_json(name, {"reference": "bench/results/cornell_reference.json (uniform fine, 2 cm)", "cases": rows})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

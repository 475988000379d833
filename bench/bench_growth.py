"""Growth (issue 14): time and peak memory against N, for input faces and for leaves.

    python bench/bench_growth.py [--quick] [--timeout 15] [--budget 75] [--plot docs/growth.png]
    python bench/bench_growth.py --plot-only            # redraw the plot and the table from the JSON
    python bench/bench_growth.py --moonshot             # issue 14's 1M input faces (about 25 min)

Three series, each case in its own process (``ru_maxrss`` is that case's peak; times compare
within one run only, the machine is shared):

- **faces**: the closed furnace sphere ``tests/helpers.py::sphere_scene(m)`` (20 m^2 triangles,
  every face emits 1 and reflects 0.5, so B = 2 on every leaf exactly), solved hierarchically
  (``preset="draft"``, ``link_tolerance=1e-2``, clustering from 400 faces on). N = input faces,
  about 1k, 3k, 10k, 30k, 100k. Error: worst and mean |B/2 - 1| over the leaves.
- **leaves**: the bundled Cornell box, hierarchical ``draft`` with ``min_element_size`` chosen
  for about 1k, 3k, 10k, 30k and 100k leaves (3.5 mm is the issue's 100k-leaf point). N = leaves.
- **uniform**: the same box, ``method="uniform"``, ``draft``, ``max_patch_size`` for about 1k,
  2k, 5k and 9.5k patches (18k patches need 13 GB: not run). N = patches.

For the box the error is the largest relative difference of an object's mean radiosity (any
channel, the light left out) from ``bench/results/cornell_reference.json`` (uniform ``fine``,
2 cm). Links: the hierarchy's links (element + cluster), the uniform matrix's non-zeros.

The cases run smallest first (all series interleaved by size). A case still running after
``--timeout`` minutes is killed and recorded as not finished; a case whose time, projected from
its series' growth so far (the larger of the fitted and the last two cases' exponent), is over
the timeout or would take the run past ``--budget`` minutes, or whose projected peak memory is
over 85% of the memory available, is skipped and recorded so. A warm-up (tiny cases, not
recorded) first compiles any numba kernel missing from the cache. The growth exponents are the
least-squares slopes of log time and log peak RSS against log N over each series' finished
cases. Writes ``bench/results/growth.json`` and the plot ``docs/growth.png``.

``--moonshot`` (issue 14: 1M input faces in 30 minutes) runs two cases instead, each in its own
process with a 30-minute timeout, hierarchical ``draft`` (``method="auto"`` picks it): the
furnace sphere at m = 224 (1,003,520 faces; error as the faces series) and the height-field
terrain of ``bench_load.generate_terrain`` at side 709 (1,002,529 triangles under a small lamp,
written as an OBJ and read by ``load_scene``, whose time is counted; no closed form: the ground's
mean radiosity and the energy balance are recorded). Writes ``bench/results/moonshot.json``.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

from _common import RESULTS, parse_args, print_table, run_cases, write_json

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT / "tests"))

SERIES = {  # name: (label, the knob, [(value, target N)], preset); fitted and drawn as lines
    "faces": ("hierarchical, input faces (furnace sphere)", "m",
              [(7, 980), (12, 2_880), (22, 9_680), (39, 30_420), (71, 100_820)], "draft"),
    # draft stops refining at its tolerance long before the minimum size: 3.5 mm gives about 23k
    # leaves (measured 2026-12-04), so the series goes below it to reach 100k
    "leaves": ("hierarchical, leaves (Cornell box)", "min_element_size",
               [(0.045, 1_000), (0.024, 3_600), (0.009, 11_000), (0.0035, 23_000), (0.0023, 35_000),
                (0.0006, 115_000)], "draft"),
    "uniform": ("uniform, patches (Cornell box)", "max_patch_size",
                [(0.052, 1_050), (0.035, 2_000), (0.0215, 5_100), (0.0155, 9_500)], "draft"),
}
# The issue's 100k-leaf point (3.5 mm) at the tighter presets' tolerances: single cases, not fitted
EXTRA = {"leaves_default": ("hierarchical, 3.5 mm, default (3e-3)", "min_element_size", [(0.0035, 38_000)], "default"),
         "leaves_fine": ("hierarchical, 3.5 mm, fine (1e-3)", "min_element_size", [(0.0035, 56_000)], "fine")}
QUICK = {"faces": 2, "leaves": 2, "uniform": 2, "leaves_default": 0, "leaves_fine": 0}  # --quick: the first cases
WARM = [{"series": "faces", "m": 7}, {"series": "leaves", "min_element_size": 0.045},
        {"series": "uniform", "max_patch_size": 0.052},
        {"series": "leaves_default", "min_element_size": 0.045, "preset": "default"},
        {"series": "leaves_fine", "min_element_size": 0.045, "preset": "fine"}]
TIME_TARGET_S, MEMORY_TARGET_MB, EXPONENT_TARGET = 600.0, 8 * 1024.0, 1.3  # issue 14


def run_case(spec: dict) -> dict:
    """Solve one case in this process; the row the table shows."""
    import numpy as np

    import radiosity

    load_before = os.getloadavg()[0]
    load_seconds = 0.0
    if spec["series"] in ("faces", "moonshot_sphere"):
        from helpers import sphere_scene

        scene = sphere_scene(spec["m"])
        options = {"method": "hierarchical", "link_tolerance": 1e-2}
    elif spec["series"] == "moonshot_terrain":
        import tempfile

        from bench_load import generate_terrain

        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "terrain.obj"
            generate_terrain(path, spec["side"])
            t0 = time.perf_counter()
            scene = radiosity.load_scene(path)
            load_seconds = time.perf_counter() - t0
        options = {}  # method auto
    else:
        scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
        options = ({"method": "uniform", "max_patch_size": spec["max_patch_size"]} if spec["series"] == "uniform"
                   else {"method": "hierarchical", "min_element_size": spec["min_element_size"]})
        options.update({k: spec[k] for k in ("link_tolerance",) if k in spec})  # a single case's own
    baseline = _rss_MB()  # interpreter, libraries, the scene
    t0 = time.perf_counter()
    solution = radiosity.solve(scene, preset=spec.get("preset", "draft"), cache=False, **options)
    seconds = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    summary = solution.summary()
    h = summary["hierarchy"] or {}
    row = {**spec, "seconds": seconds + load_seconds, "load_seconds": load_seconds, "peak_rss_MB": peak,
           "rss_before_solve_MB": baseline, "faces": int(scene.n_patches),
           "patches": int(solution.scene.n_patches), "nonzeros": int(solution.F.nnz),
           "links": int(h["links"]) if h else int(solution.F.nnz)}
    if spec["series"] == "moonshot_terrain":
        # no closed form here: the ground's mean, and the energy balance (a check of the solve)
        row.update(N=int(scene.n_patches), method=summary["method"], energy_W=summary["energy_W"],
                   ground_mean=float(np.asarray(solution.object_radiosity()["ground"]).mean()))
    elif spec["series"] in ("faces", "moonshot_sphere"):
        error = np.abs(solution.radiosity / 2.0 - 1.0)
        row.update(N=int(scene.n_patches), max_error=float(error.max()), mean_error=float(error.mean()),
                   mean_signed_error=float((solution.radiosity / 2.0 - 1.0).mean()))
    else:
        reference = json.loads((RESULTS / "cornell_reference.json").read_text())["objects"]
        means = solution.object_radiosity()
        objects = {k: float(np.abs(means[k] / np.asarray(v) - 1).max()) for k, v in reference.items() if k != "light"}
        row.update(N=int(solution.scene.n_patches), max_error=max(objects.values()), object_errors=objects)
    if h:
        row.update(cluster_links=h.get("cluster_links"), partly_visible_links=h.get("partly_visible_links"),
                   rounds=h.get("rounds"), converged=h.get("converged"), hierarchy_MB=h["memory_bytes"] / 2 ** 20,
                   elements=h.get("elements"), clusters=h.get("clusters"), split_per_round=h.get("split_per_round"))
    row.update(solver=summary["solver"], view_factors=summary["view_factors"], timings={k: round(v, 2) for k, v in solution.timings.items()},
               load_before=load_before, load_after=os.getloadavg()[0],
               radiosity_from=str(Path(radiosity.__file__).resolve().parent))
    return row


# --- the run -------------------------------------------------------------------------------------

def _rss_MB() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _available_MB() -> float:
    for line in Path("/proc/meminfo").read_text().splitlines():
        if line.startswith("MemAvailable:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _shell(*command: str) -> str:
    try:
        return subprocess.run(command, capture_output=True, text=True, cwd=ROOT, check=False).stdout.strip()
    except OSError:
        return ""


def fit(rows: list[dict], key: str) -> float | None:
    """Least-squares slope of log ``key`` against log N over ``rows`` (None under two)."""
    import numpy as np

    points = [(r["N"], r[key]) for r in rows if "failed" not in r and "skipped" not in r]
    if len(points) < 2:
        return None
    n, y = np.log(np.array(points, dtype=float)).T
    return float(np.polyfit(n, y, 1)[0])


def _project(done: list[dict], n_next: float, key: str) -> float | None:
    """``key`` at N = ``n_next`` from the growth so far: the larger of the fitted exponent and
    the last two cases' (None while fewer than two cases finished)."""
    if len(done) < 2:
        return None
    slopes = [fit(done, key), fit(done[-2:], key)]
    last = done[-1]
    return float(last[key] * (n_next / last["N"]) ** max(s for s in slopes if s is not None))


def measure(plan: list[dict], *, timeout: float, budget: float) -> list[dict]:
    """Run ``plan`` (specs with ``target``, smallest first), skipping what would not finish."""
    rows, started = [], time.perf_counter()
    for spec in plan:
        done = [r for r in rows if r["series"] == spec["series"] and "failed" not in r and "skipped" not in r]
        n_next = spec["target"]
        if done:  # the last case's N against its target corrects this one's (the leaves are not known in advance)
            n_next = spec["target"] * done[-1]["N"] / done[-1]["target"]
        t_next, m_next = _project(done, n_next, "seconds"), _project(done, n_next, "peak_rss_MB")
        available = _available_MB()
        elapsed = time.perf_counter() - started
        print(f"\n--- {spec}: projected N {n_next:,.0f}, time {t_next or float('nan'):.0f} s, "
              f"peak {m_next or float('nan'):.0f} MB; available {available:,.0f} MB; run so far {elapsed:.0f} s; "
              f"load {os.getloadavg()[0]:.1f}", flush=True)
        if n_next >= 20_000:
            print(_shell("free", "-g"), flush=True)
        reason = None
        if t_next is not None and t_next > timeout:
            reason = f"skipped: projected {t_next:.0f} s over the {timeout / 60:g} min timeout"
        elif t_next is not None and elapsed + t_next > budget:
            reason = f"skipped: projected {t_next:.0f} s would take the run past its {budget / 60:g} min budget"
        elif m_next is not None and m_next > 0.85 * available:
            reason = f"skipped: projected peak {m_next:,.0f} MB over 85% of the {available:,.0f} MB available"
        if reason:
            print(reason, flush=True)
            rows.append({**spec, "skipped": reason, "projected_seconds": t_next, "projected_peak_rss_MB": m_next})
            continue
        (row,) = run_cases(Path(__file__), [spec], cwd=HERE, tail=800, timeout=timeout)
        row["available_MB_before"] = available
        rows.append(row)
    return rows


def plan_cases(quick: bool) -> list[dict]:
    specs = []
    for name, (_, knob, points, preset) in {**SERIES, **EXTRA}.items():
        for value, target in points[:QUICK[name]] if quick else points:
            specs.append({"series": name, knob: value, "preset": preset, "target": target})
    return sorted(specs, key=lambda s: s["target"])  # smallest first, the series interleaved


# --- report -------------------------------------------------------------------------------------

def _note(r: dict) -> str:
    return r.get("skipped") or (r["failed"] if isinstance(r.get("failed"), str) else "; ".join(r.get("failed", [])))


def _finished(rows: list[dict], name: str | None = None) -> list[dict]:
    return [r for r in rows if "failed" not in r and "skipped" not in r and (name is None or r["series"] == name)]


def report(rows: list[dict]) -> dict:
    """Print the table and the exponents; return the exponents per series."""
    table = []
    for r in rows:
        ok = "failed" not in r and "skipped" not in r
        table.append({"series": r["series"], "preset": r.get("preset", "draft"),
                      "knob": r.get("m", r.get("min_element_size", r.get("max_patch_size"))),
                      "N": r.get("N", f"~{r['target']:,}"), "links": r.get("links", ""),
                      "seconds": r.get("seconds", ""), "peak_rss_MB": r.get("peak_rss_MB", ""),
                      "max_error": r.get("max_error", ""), "mean_error": r.get("mean_error", ""),
                      "note": "" if ok else _note(r)})
    print_table(table, title="growth (error: faces |B/2 - 1| per leaf, box: worst object mean vs uniform fine)")
    exponents = {}
    fmt = lambda v: "n/a" if v is None else f"{v:.2f}"
    for name, (label, *_) in SERIES.items():
        mine = _finished(rows, name)
        above = [{**r, "above": r["peak_rss_MB"] - r["rss_before_solve_MB"]} for r in mine if "rss_before_solve_MB" in r]
        exponents[name] = {"label": label, "cases": len(mine), "N": [r["N"] for r in mine],
                           "time": fit(mine, "seconds"), "memory": fit(mine, "peak_rss_MB"),
                           "time_last_two": fit(mine[-2:], "seconds"), "memory_last_two": fit(mine[-2:], "peak_rss_MB"),
                           "memory_above_baseline": fit(above, "above")}
        e = exponents[name]
        print(f"{label}: time ~ N^{fmt(e['time'])}, peak RSS ~ N^{fmt(e['memory'])} over {e['cases']} cases "
              f"(last two: N^{fmt(e['time_last_two'])}, N^{fmt(e['memory_last_two'])}; "
              f"peak RSS less the RSS before the solve: N^{fmt(e['memory_above_baseline'])})")
    return exponents


def plot(rows: list[dict], exponents: dict, path: Path, *, timeout: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    styles = {"faces": ("tab:blue", "o"), "leaves": ("tab:orange", "s"), "uniform": ("tab:green", "^"),
              "leaves_default": ("tab:red", "D"), "leaves_fine": ("tab:purple", "P")}
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.6))
    for ax, key, unit, target, what in ((axes[0], "seconds", "solve time (s)", TIME_TARGET_S, "time"),
                                        (axes[1], "peak_rss_MB", "peak RSS (MB)", MEMORY_TARGET_MB, "memory")):
        for name, (label, *_) in {**SERIES, **EXTRA}.items():
            colour, marker = styles[name]
            mine = _finished(rows, name)
            if mine and name in SERIES:
                slope = exponents[name][what]
                tag = f"N^{slope:.2f}" if slope is not None else "one case"
                ax.plot([r["N"] for r in mine], [r[key] for r in mine], marker=marker, color=colour,
                        label=f"{label}: {tag}")
            elif mine:
                ax.plot([r["N"] for r in mine], [r[key] for r in mine], marker=marker, ls="", ms=8, color=colour,
                        label=label)
            lost = [r for r in rows if r["series"] == name and ("failed" in r or "skipped" in r)]
            if lost and key == "seconds":
                n = [r.get("N") or r["target"] for r in lost]
                ax.scatter(n, [timeout] * len(n), marker="x", s=70, color=colour, zorder=5,
                           label=f"{label}: not finished or skipped (drawn at the timeout)")
        finished = _finished(rows)
        if finished:  # the exponent bound, from the smallest case over the range measured
            n0 = min(r["N"] for r in finished)
            y0 = min(r[key] for r in finished if r["N"] == n0)
            n = np.array([n0, max(r["N"] for r in finished)])
            ax.plot(n, y0 * (n / n0) ** EXPONENT_TARGET, ls=":", color="grey", label="slope 1.3 (issue 14's bound)")
        ax.axhline(target, ls="--", color="grey", lw=1,
                   label="issue 14: 100k in 10 min" if what == "time" else "issue 14: 100k in 8 GB")
        if what == "time":
            ax.axhline(timeout, ls="-", color="lightgrey", lw=1, label=f"timeout per case ({timeout / 60:g} min)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        if finished:  # the guide may leave the data's range: keep the data and the targets in view
            ax.set_ylim(top=3 * max(target, timeout if what == "time" else 0, *(r[key] for r in finished)))
        ax.set_xlabel("N: input faces (sphere), leaves or patches (Cornell box)")
        ax.set_ylabel(unit)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="upper left", framealpha=0.9)
    axes[0].set_title("time of radiosity.solve against N (draft unless marked)")
    axes[1].set_title("peak RSS of each case's process against N")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


MOONSHOT = [{"series": "moonshot_sphere", "m": 224}, {"series": "moonshot_terrain", "side": 709}]
MOONSHOT_TIMEOUT_S = 30 * 60.0


def moonshot(out: str | None) -> None:
    """Issue 14's moonshot: about a million input faces each, one process a case."""
    uptime_before = _shell("uptime")
    print(uptime_before)
    run_cases(Path(__file__), [{"series": "faces", "m": 7}], cwd=HERE)  # compile what the cache lacks
    rows = run_cases(Path(__file__), MOONSHOT, cwd=HERE, timeout=MOONSHOT_TIMEOUT_S)
    print_table([{"case": r["series"], "faces": r.get("faces", ""), "links": r.get("links", ""),
                  "seconds": r.get("seconds", ""), "load_seconds": r.get("load_seconds", ""),
                  "peak_rss_MB": r.get("peak_rss_MB", ""), "max_error": r.get("max_error", ""),
                  "ground_mean": r.get("ground_mean", ""), "note": _note(r) if "failed" in r else ""} for r in rows],
                title="moonshot (error: the sphere's worst |B/2 - 1| per leaf)")
    path = write_json("moonshot", {"uptime_before": uptime_before, "uptime_after": _shell("uptime"),
                                   "timeout_s": MOONSHOT_TIMEOUT_S, "cases": rows}, out)
    print(f"wrote {path}")


def main() -> None:
    if len(sys.argv) > 2 and sys.argv[1] == "--case":
        print(json.dumps(run_case(json.loads(sys.argv[2]))))
        return

    def extra(p):
        p.add_argument("--timeout", type=float, default=15.0, help="minutes per case (default 15)")
        p.add_argument("--budget", type=float, default=75.0, help="minutes for the whole run (default 75)")
        p.add_argument("--plot", default=None, help="PNG path (default docs/growth.png; none with --quick)")
        p.add_argument("--plot-only", action="store_true", help="redraw from the JSON (--out or growth.json)")
        p.add_argument("--moonshot", action="store_true", help="issue 14's 1M input faces: sphere and terrain")
        p.add_argument("--code", default=None,
                       help="where the imported radiosity came from when not this checkout (e.g. a git archive "
                            "of a commit on PYTHONPATH, while someone edits the checkout): recorded in the JSON")

    args = parse_args(__doc__.splitlines()[0], extra=extra)
    timeout, budget = args.timeout * 60, args.budget * 60
    name = "growth_quick" if args.quick else "growth"
    plot_path = Path(args.plot) if args.plot else (None if args.quick else ROOT / "docs" / "growth.png")
    if args.plot_only:
        data = json.loads(Path(args.out or RESULTS / f"{name}.json").read_text())
        exponents = report(data["cases"])
        if plot_path:
            plot(data["cases"], exponents, plot_path, timeout=data.get("timeout_s", timeout))
        return
    if args.moonshot:
        return moonshot(args.out)
    uptime_before = _shell("uptime")
    print(uptime_before)
    print(_shell("free", "-g"))
    warm = run_cases(Path(__file__), WARM, cwd=HERE, timeout=timeout)  # compile what the cache lacks; not recorded
    print("warm-up:", [(w["series"], round(w.get("seconds", float("nan")), 1)) for w in warm])
    started = time.perf_counter()
    rows = measure(plan_cases(args.quick), timeout=timeout, budget=budget)
    total = time.perf_counter() - started
    uptime_after = _shell("uptime")
    exponents = report(rows)
    print(f"run: {total / 60:.1f} min; before: {uptime_before}; after: {uptime_after}")
    payload = {"settings": {"preset": "draft", "faces": "sphere_scene(m), hierarchical, link_tolerance=1e-2",
                            "leaves": "cornell_box, hierarchical, min_element_size",
                            "uniform": "cornell_box, uniform, max_patch_size",
                            "reference": "bench/results/cornell_reference.json (uniform fine, 2 cm)"},
               "timeout_s": timeout, "budget_s": budget, "run_seconds": total,
               "uptime_before": uptime_before, "uptime_after": uptime_after,
               "code": {"note": args.code, "head": _shell("git", "rev-parse", "HEAD"),
                        "checkout_radiosity_changes": _shell("git", "status", "--porcelain", "radiosity"),
                        "radiosity_from": sorted({r["radiosity_from"] for r in rows if "radiosity_from" in r})},
               "exponents": exponents, "warm_up": warm, "cases": rows}
    path = write_json(name, payload, args.out)
    print(f"wrote {path}")
    if plot_path:
        plot(rows, exponents, plot_path, timeout=timeout)


if __name__ == "__main__":
    main()

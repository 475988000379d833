"""Convergence of per-object radiosity on the Cornell box, with and without imprinting.

For each preset (draft, default, fine) and each meshing (imprinted contacts, the default; and
plain uniform subdivision, ``imprint=False``) this solves the bundled Cornell box and compares
``Solution.object_radiosity()`` with a much finer reference solution (imprinted,
``max_patch_size`` = 0.02 m, the fine preset). The error of a
run is the worst relative change over the non-emitting objects and the three channels:
``max |B - B_ref| / B_ref``.

The reference takes several minutes on two cores; it is cached in
``bench/results/cornell_reference.json`` and recomputed only when its settings change (or with
``--new-reference``). Results go to ``bench/results/convergence.json``; docs/meshing.md quotes
them.

Usage: ``python bench/bench_convergence.py [--quick] [--new-reference]``. ``--quick`` runs the
draft preset against a coarse reference (0.03 m), not cached, to check the script.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import _common  # noqa: E402

import radiosity  # noqa: E402

REFERENCE_SIZE = 0.02  # metres; the same reference as bench/accuracy_vs_time.py (6,494 patches)
REFERENCE_PRESET = "fine"
QUICK_REFERENCE_SIZE = 0.03
PRESETS = ("draft", "default", "fine")


def _commit() -> str:
    try:
        root = Path(radiosity.__file__).resolve().parents[1]
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True)
        return out.stdout.strip()
    except OSError:
        return ""


def _load(imprint: bool):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", radiosity.RadiosityWarning)
        return radiosity.load_scene(radiosity.bundled_scene("cornell_box"), imprint=imprint)


def _emitters(scene) -> set[str]:
    emits = np.zeros(len(scene.objects), bool)
    np.logical_or.at(emits, scene.patch_object, scene.emission.max(axis=1) > 0)
    return {name for name, e in zip(scene.objects, emits) if e}


def reference(size: float, *, cache_path: Path | None, fresh: bool) -> dict:
    """Object radiosity of the fine reference solution (cached in ``cache_path``)."""
    settings = {"max_patch_size": size, "preset": REFERENCE_PRESET, "imprint": True}
    if cache_path is not None and cache_path.exists() and not fresh:
        data = json.loads(cache_path.read_text())
        if data.get("settings") == settings:
            return data
    scene = _load(True)
    t0 = time.perf_counter()
    solution = radiosity.solve(scene, preset=REFERENCE_PRESET, max_patch_size=size, cache=False)
    seconds = time.perf_counter() - t0
    data = {"settings": settings, "patches": int(solution.scene.n_patches),
            "hidden_patches": int(solution.scene.patch_hidden.sum()), "seconds": seconds,
            "timings": solution.timings, "commit": _commit(),
            "objects": {k: [float(x) for x in v] for k, v in solution.object_radiosity().items()},
            "emitters": sorted(_emitters(scene))}
    if cache_path is not None:
        _common.write_json(cache_path.stem, data, str(cache_path))
    return data


def solve_case(preset: str, imprint: bool) -> dict:
    """Solve one case; the raw result (object radiosity, patches, time)."""
    scene = _load(imprint)
    t0 = time.perf_counter()
    solution = radiosity.solve(scene, preset=preset, cache=False)
    seconds = time.perf_counter() - t0
    return {"preset": preset, "imprint": imprint, "patches": int(solution.scene.n_patches),
            "hidden_patches": int(solution.scene.patch_hidden.sum()), "seconds": seconds,
            "timings": solution.timings, "commit": _commit(),
            "objects": {k: [float(x) for x in v] for k, v in solution.object_radiosity().items()}}


def compare(case: dict, ref: dict) -> dict:
    """The case with its relative change per object and channel against the reference."""
    errors = {}
    for name, value in case["objects"].items():
        if name in ref["emitters"]:
            continue
        target = np.asarray(ref["objects"][name])
        errors[name] = [float(x) for x in (np.asarray(value) - target) / target]
    worst = max(errors, key=lambda n: max(abs(e) for e in errors[n]))
    return {**case, "worst_object": worst, "worst_relative_change": max(abs(e) for e in errors[worst]),
            "relative_change": errors}


def main(argv=None) -> int:
    def extra(parser):
        parser.add_argument("--new-reference", action="store_true", help="recompute the cached reference")
        parser.add_argument("--cases", default=None,
                            help="JSON list of raw cases (from --save-cases) to compare instead of solving")
        parser.add_argument("--save-cases", default=None, help="also write the raw cases to this JSON file")
        parser.add_argument("--no-reference", action="store_true",
                            help="only solve the cases (use with --save-cases, compare later with --cases)")

    args = _common.parse_args(__doc__.splitlines()[0], argv, extra=extra)
    if args.no_reference:
        raw = [solve_case(p, i) for i in (True, False) for p in (("draft",) if args.quick else PRESETS)]
        Path(args.save_cases).write_text(json.dumps(raw, indent=1))
        return 0
    if args.quick:
        ref = reference(QUICK_REFERENCE_SIZE, cache_path=None, fresh=True)
        presets = ("draft",)
    else:
        ref = reference(REFERENCE_SIZE, cache_path=_common.RESULTS / "cornell_reference.json",
                        fresh=args.new_reference)
        presets = PRESETS
    print(f"reference: {ref['patches']} patches, {ref['seconds']:.0f} s ({ref['settings']})")
    rows = []
    raw = json.loads(Path(args.cases).read_text()) if args.cases else None
    for imprint in (True, False):
        for preset in presets:
            if raw is not None:
                case = next((c for c in raw if c["preset"] == preset and c["imprint"] == imprint), None)
                if case is None:
                    print(f"{preset:8s} imprint={str(imprint):5s} not in {args.cases}: skipped")
                    continue
            else:
                case = solve_case(preset, imprint)
            case = compare(case, ref)
            rows.append(case)
            print(f"{preset:8s} imprint={str(imprint):5s} {case['patches']:6d} patches {case['seconds']:7.1f} s  "
                  f"worst {case['worst_object']:12s} {100 * case['worst_relative_change']:.2f} %", flush=True)
    if args.save_cases:
        Path(args.save_cases).write_text(json.dumps([{k: v for k, v in r.items() if k in (
            "preset", "imprint", "patches", "hidden_patches", "seconds", "timings", "commit", "objects")}
            for r in rows], indent=1))
    payload = {"scene": "cornell_box", "reference": {k: ref[k] for k in ("settings", "patches", "seconds", "commit")},
               "commit": _commit(), "quick": bool(args.quick), "cases": rows}
    if args.quick and args.out is None:
        print(json.dumps(payload["cases"], indent=1)[:2000])
        return 0
    path = _common.write_json("convergence", payload, args.out)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Accuracy against time, per preset: the speed/accuracy trade users make with one knob.

For each preset (draft, default, fine) this measures, in one run on this machine:

* view factors of canonical geometry with exact answers (Howell's catalogue; field notes):
  parallel unit squares 1 apart and perpendicular squares sharing an edge, each cut n x n,
  error of the total F; the same parallel squares with a centred 0.5 x 0.5 blocker midway;
  the closed unit cube cut 4 x 4 per face (worst row-sum error);
* the bundled Cornell box: patches, time, and worst per-object, per-channel relative
  deviation of ``object_radiosity()`` from a reference solved much finer
  (bench/results/accuracy_reference.json if present, else computed here and saved).

Run ``python bench/accuracy_vs_time.py [--quick]``; it writes
bench/results/accuracy_vs_time.json and regenerates the table in docs/accuracy.md.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, Timer, parse_args, write_json  # noqa: E402

os.environ.setdefault("RADIOSITY_CACHE", tempfile.mkdtemp(prefix="radiosity-bench-"))

import radiosity  # noqa: E402

DOCS = Path(__file__).resolve().parents[1] / "docs" / "accuracy.md"
PRESETS = ("draft", "default", "fine")
REFERENCE_PATCH_SIZE = 0.02


def square(z: float, down: bool) -> np.ndarray:
    sq = np.array([[0, 0, z], [1, 0, z], [1, 1, z], [0, 1, z]], float)
    return sq[::-1].copy() if down else sq


def write_obj(path: Path, objects: dict) -> Path:
    lines = []
    vid = 1
    for name, polys in objects.items():
        lines.append(f"o {name}")
        for poly in polys:
            lines += ["v %.17g %.17g %.17g" % tuple(v) for v in poly]
            lines.append("f " + " ".join(str(vid + k) for k in range(len(poly))))
            vid += len(poly)
    path.write_text("\n".join(lines) + "\n")
    return path


def total_factor(scene, F, a: str, b: str) -> float:
    ia = scene.patch_object == scene.objects.index(a)
    ib = scene.patch_object == scene.objects.index(b)
    area = scene.patch_area
    return float((area[ia, None] * F[ia][:, ib].toarray()).sum() / area[ia].sum())


def canonical_cases(folder: Path, n: int) -> dict:
    blocker = np.array([[0.25, 0.25, 0.5], [0.75, 0.25, 0.5], [0.75, 0.75, 0.5], [0.25, 0.75, 0.5]])
    wall = np.array([[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]], float)  # x = 0, facing +x
    return {
        "parallel squares 1 apart": (write_obj(folder / "par.obj", {"a": [square(0, False)], "b": [square(1, True)]}),
                                     0.1998248957),
        "perpendicular squares": (write_obj(folder / "perp.obj", {"a": [square(0, False)], "b": [wall]}), 0.2000437761),
        "parallel squares + blocker": (write_obj(folder / "blk.obj", {"a": [square(0, False)], "b": [square(1, True)],
                                                                      "blocker": [blocker]}), 0.0995062946),
    }


def measure_view_factors(preset: str, n: int, folder: Path) -> list[dict]:
    rows = []
    for name, (path, exact) in canonical_cases(folder, n).items():
        scene = radiosity.load_scene(path, max_patch_size=1.0 / n * 1.0000001)
        with Timer() as t:
            F = radiosity.view_factors(scene, preset=preset, cache=False)
        value = total_factor(scene, F, "a", "b")
        rows.append({"case": f"{name} ({n}x{n})", "preset": preset, "seconds": t.seconds,
                     "pairs": int(scene.n_patches) ** 2, "error": abs(value - exact) / exact})
    cube = radiosity.load_scene(radiosity.bundled_scene("unit_cube"), max_patch_size=0.25)
    with Timer() as t:
        F = radiosity.view_factors(cube, preset=preset, cache=False)
    rows.append({"case": "closed cube 4x4/face: max |row sum - 1|", "preset": preset, "seconds": t.seconds,
                 "pairs": int(cube.n_patches) ** 2, "error": float(np.abs(F.sum(axis=1).A1 - 1).max())})
    return rows


def cornell_reference(quick: bool) -> dict:
    path = RESULTS / "accuracy_reference.json"
    if path.exists():
        data = json.loads(path.read_text())
        return {k: np.array(v) for k, v in data["objects"].items()}
    size = 0.03 if quick else REFERENCE_PATCH_SIZE
    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    sol = radiosity.solve(scene, preset="fine", max_patch_size=size, cache=False, progress=True)
    objects = {k: v.tolist() for k, v in sol.object_radiosity().items()}
    if not quick:
        path.write_text(json.dumps({"max_patch_size": size, "patches": sol.scene.n_patches,
                                    "objects": objects}, indent=2) + "\n")
    return {k: np.array(v) for k, v in objects.items()}


def measure_cornell(preset: str, reference: dict) -> dict:
    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    with Timer() as t:
        sol = radiosity.solve(scene, preset=preset, cache=False)
    worst, where = 0.0, ""
    for name, value in sol.object_radiosity().items():
        if name == "light":
            continue
        dev = np.abs(value - reference[name]) / reference[name]
        if dev.max() > worst:
            worst, where = float(dev.max()), name
    return {"preset": preset, "patches": sol.scene.n_patches, "seconds": t.seconds, "worst_object_error": worst,
            "worst_object": where}


def markdown(vf_rows: list[dict], cornell_rows: list[dict], reference_note: str) -> str:
    out = ["# Accuracy against time", "",
           "Generated by `python bench/accuracy_vs_time.py` (tables: do not edit by hand). Times are wall",
           "seconds on the machine in `bench/results/accuracy_vs_time.json`; compare ratios, not",
           "absolute values.", "", "## View factors with exact answers", "",
           "| case | preset | seconds | relative error |", "|---|---|---:|---:|"]
    for r in vf_rows:
        out.append(f"| {r['case']} | {r['preset']} | {r['seconds']:.3f} | {r['error']:.2e} |")
    out += ["", "## Cornell box", "", reference_note, "",
            "| preset | patches | seconds | worst object error | object |", "|---|---:|---:|---:|---|"]
    for r in cornell_rows:
        out.append(f"| {r['preset']} | {r['patches']} | {r['seconds']:.2f} | {100 * r['worst_object_error']:.2f}% "
                   f"| {r['worst_object']} |")
    return "\n".join(out) + "\n"


# Below this line docs/accuracy.md holds hand-written sections (other knobs' trades measured by
# their own benches); a rerun regenerates the tables above it and keeps what follows.
KEEP_MARKER = "<!-- generated above; written by hand below -->"


def with_kept_sections(generated: str, old: str) -> str:
    kept = old.split(KEEP_MARKER, 1)[1] if KEEP_MARKER in old else "\n"
    return generated + "\n" + KEEP_MARKER + kept


def main(argv=None) -> int:
    args = parse_args(__doc__.splitlines()[0], argv)
    n = 8 if args.quick else 16
    folder = Path(tempfile.mkdtemp())
    vf_rows = [row for preset in PRESETS for row in measure_view_factors(preset, n, folder)]
    for r in vf_rows:
        print(f"{r['case']:<45} {r['preset']:<8} {r['seconds']:8.3f} s  error {r['error']:.2e}")
    reference = cornell_reference(args.quick)
    cornell_rows = [measure_cornell(p, reference) for p in PRESETS]
    for r in cornell_rows:
        print(f"cornell {r['preset']:<8} {r['patches']:6d} patches {r['seconds']:7.2f} s  "
              f"worst object {100 * r['worst_object_error']:.2f}% ({r['worst_object']})")
    note = ("Reference: the same scene solved with the `fine` preset at max_patch_size "
            f"{REFERENCE_PATCH_SIZE} m (bench/results/accuracy_reference.json); error = worst per-object, "
            "per-channel relative deviation of the area-weighted mean radiosity (light excluded).")
    path = write_json("accuracy_vs_time", {"view_factors": vf_rows, "cornell": cornell_rows, "n": n}, args.out)
    if not args.quick:
        DOCS.write_text(with_kept_sections(markdown(vf_rows, cornell_rows, note),
                                           DOCS.read_text() if DOCS.exists() else ""))
    print(f"wrote {path}" + ("" if args.quick else f" and {DOCS}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())

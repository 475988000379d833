"""A furnace: a closed room full of floating, rotated boxes, every surface emitting and reflecting.

Every surface has E = 1 and rho = 0.5, so the exact answer is B = E / (1 - rho) = 2 on every
patch, and every row of F sums to 1 (nothing escapes). Prints the row sums of F, the error of
B, the energy balance and the stage timings of ``radiosity.solve`` at the presets asked for.

    python bench/closed_boxes.py --boxes 50 --presets draft default
    python bench/closed_boxes.py --write /tmp/furnace.obj      # just the OBJ

``--baseline DIR`` also runs the same scene with the ``radiosity`` package found in DIR (an
older checkout: ``git archive <commit> radiosity | tar -x -C DIR``), alternating with this one
in separate processes, so the timings of both come from the same period of load: compare
their ratio, not the seconds.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOM = (3.0, 2.5, 3.0)  # x, y (up), z, metres


def box_faces(center, size, rotation) -> list[np.ndarray]:
    """Six outward quads of a box (size (3,)) rotated by the 3x3 matrix about its center."""
    h = np.asarray(size) / 2
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
    corners = corners @ np.asarray(rotation).T + center
    # corner index = 4 sx + 2 sy + sz with s in {0, 1}; each face counter-clockwise seen from outside
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return [corners[list(q)] for q in quads]


def room_faces() -> list[np.ndarray]:
    """The six walls facing into the room."""
    return [q[::-1].copy() for q in box_faces(np.array(ROOM) / 2, ROOM, np.eye(3))]


def random_rotation(rng) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def floating_boxes(n: int, seed: int = 0, gap: float = 0.02) -> list[list[np.ndarray]]:
    """n rotated boxes inside the room, none touching another or a wall (bounding spheres apart by gap)."""
    rng = np.random.default_rng(seed)
    placed: list[tuple[np.ndarray, float]] = []
    boxes = []
    lo, hi = np.zeros(3), np.array(ROOM)
    while len(boxes) < n:
        size = rng.uniform(0.1, 0.45, 3)
        radius = float(np.linalg.norm(size) / 2)
        center = rng.uniform(lo + radius + gap, hi - radius - gap)
        if any(np.linalg.norm(center - c) < radius + r + gap for c, r in placed):
            continue
        placed.append((center, radius))
        boxes.append(box_faces(center, size, random_rotation(rng)))
    return boxes


def write_scene(path: Path, n_boxes: int, seed: int = 0) -> Path:
    lines = [f"mtllib {path.with_suffix('.mtl').name}", "o room", "usemtl furnace"]
    nv = 0

    def add(quads):
        nonlocal nv
        for q in quads:
            lines.extend("v %.9f %.9f %.9f" % tuple(v) for v in q)
            lines.append("f " + " ".join(str(nv + k + 1) for k in range(len(q))))
            nv += len(q)

    add(room_faces())
    for k, quads in enumerate(floating_boxes(n_boxes, seed)):
        lines += [f"o box{k:02d}", "usemtl furnace"]
        add(quads)
    path.with_suffix(".mtl").write_text("newmtl furnace\nKd 0.5 0.5 0.5\nKe 1 1 1\n")
    path.write_text("\n".join(lines) + "\n")
    return path


def measure(path: str, preset: str, method: str = "auto") -> dict:
    """Solve once (no cache) and report rows, B error, energy and timings."""
    import time
    import warnings

    import radiosity

    scene = radiosity.load_scene(path)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        solution = radiosity.solve(scene, preset=preset, cache=False, method=method)
    wall = time.perf_counter() - t0
    cut = solution.scene
    active = ~cut.patch_inactive
    # F @ 1, not F.sum: a hierarchical solution's F is a LinearOperator over its leaves
    rows = np.asarray(solution.F @ np.ones(cut.n_patches)).ravel()[active]
    e = solution.energy
    expected = cut.emission[active, 0] / (1 - cut.reflectance[active, 0])
    b = solution.radiosity[active, 0] / expected - 1
    return {"preset": preset, "patches": int(active.sum()), "row_min": float(rows.min()), "row_max": float(rows.max()),
            "rows_off_1e-3": int((abs(rows - 1) > 1e-3).sum()), "B_err_max": float(abs(b).max()),
            "B_err_area_mean": float(np.average(abs(b), weights=cut.patch_area[active])),
            "escaped_share": float(e["escaped"][0] / e["emitted"][0]), "seconds": wall,
            "timings": {k: round(v, 2) for k, v in solution.timings.items()},
            "method": solution.summary().get("method"),
            **{name: int(getattr(solution.fill, f"n_{name}", 0) or 0)
               for name in ("exact_pairs", "traced_pairs", "rays")}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--boxes", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--presets", nargs="+", default=["draft", "default"])
    ap.add_argument("--write", type=Path, help="write the OBJ there and stop")
    ap.add_argument("--baseline", type=Path, help="folder holding an older radiosity package to compare with")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--method", choices=("auto", "uniform", "hierarchical"), default="auto")
    ap.add_argument("--measure", nargs=3, metavar=("OBJ", "PRESET", "METHOD"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.measure:
        print(json.dumps(measure(*args.measure)))
        return
    path = args.write or Path("/tmp") / f"closed_boxes_{args.boxes}_{args.seed}.obj"
    write_scene(path, args.boxes, args.seed)
    if args.write:
        return
    here = Path(__file__).resolve().parents[1]
    trees = {"this": here} | ({"baseline": args.baseline.resolve()} if args.baseline else {})
    results = []
    for preset in args.presets:
        for _ in range(args.repeat):
            for label, tree in trees.items():  # alternate, so both see the same load
                env = dict(os.environ, PYTHONPATH=str(tree))
                out = subprocess.run([sys.executable, __file__, "--measure", str(path), preset, args.method], env=env,
                                     capture_output=True, text=True, check=True, cwd=tree)
                r = json.loads(out.stdout.strip().splitlines()[-1]) | {"code": label}
                results.append(r)
                print(json.dumps(r))
    if args.baseline:
        for preset in args.presets:
            t = [r["seconds"] for r in results if r["preset"] == preset and r["code"] == "this"]
            b = [r["seconds"] for r in results if r["preset"] == preset and r["code"] == "baseline"]
            print(f"{preset}: solve time this / baseline = {np.median(t) / np.median(b):.2f}")


if __name__ == "__main__":
    main()

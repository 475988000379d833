"""Load times of large scenes, with and without imprinting, against the all-pairs imprint.

A generated scene: a floor of square tiles (one object) and boxes standing on it, some stacked,
some without a bottom face, some touching a neighbour sideways (every kind of contact, one box
per object). For each size the script times ``load_scene`` with ``imprint=False``, with the
indexed imprint (the default), and, at the small sizes, with the old all-pairs search
(``imprint_faces(..., _all_pairs=True)``), in the same run; the patch arrays of the two
imprints are compared for equality.

    python bench/bench_load.py                 # 1k, 8k, 50k, 300k faces; all pairs at 1k
    python bench/bench_load.py --quick         # 1k and 8k
    python bench/bench_load.py --all-pairs 1000 8000
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine_info, parse_args, print_table, write_json  # noqa: E402

BOX = [f[::-1] for f in ([0, 1, 2, 3], [4, 7, 6, 5], [0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3], [3, 7, 4, 0])]


def generate(path: Path, faces: int, seed: int = 0) -> int:
    """Write the floor-and-boxes scene of about ``faces`` faces; returns the face count."""
    rng = np.random.default_rng(seed)
    n_boxes = max(1, int(0.8 * faces) // 6)
    tiles = max(1, int(np.sqrt(max(faces - 6 * n_boxes, 1))))
    side = float(np.ceil(np.sqrt(n_boxes)))  # boxes on a unit grid, 1 m apart
    lines = ["mtllib bench_load.mtl", "o floor", "usemtl grey"]
    g = np.linspace(0.0, side, tiles + 1)
    x, z = np.meshgrid(g, g)
    lines += [f"v {a:.6f} 0 {b:.6f}" for a, b in zip(x.ravel(), z.ravel())]
    k = np.arange(tiles * (tiles + 1)).reshape(tiles, tiles + 1)[:, :tiles].ravel() + 1
    lines += [f"f {a} {a + tiles + 1} {a + tiles + 2} {a + 1}" for a in k]
    count = (tiles + 1) ** 2
    n_faces = tiles * tiles
    for b in range(n_boxes):
        i, j = divmod(b, int(side))
        lo = np.array([j + 0.1, 0.0, i + 0.1])
        if b % 7 == 3:
            lo[1] = 0.5  # stacked on the box below it in spirit: floating at 0.5 over its own cell
        size = np.array([rng.uniform(0.3, 0.8), 0.5, rng.uniform(0.3, 0.8)])
        if b % 5 == 1:
            size[0] = 0.9  # touches the next box's side
        hi = lo + size
        corners = [[lo[0], lo[1], lo[2]], [lo[0], lo[1], hi[2]], [hi[0], lo[1], hi[2]], [hi[0], lo[1], lo[2]],
                   [lo[0], hi[1], lo[2]], [lo[0], hi[1], hi[2]], [hi[0], hi[1], hi[2]], [hi[0], hi[1], lo[2]]]
        lines += [f"o box{b}", "usemtl grey"] + [f"v {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}" for p in corners]
        for face in (BOX[1:] if b % 3 == 2 else BOX):
            lines.append("f " + " ".join(str(count + 1 + c) for c in face))
            n_faces += 1
        count += 8
    path.write_text("\n".join(lines) + "\n")
    path.with_name("bench_load.mtl").write_text("newmtl grey\nKd 0.5 0.5 0.5\nKe 1 1 1\n")
    return n_faces


def _timed(load) -> tuple[float, object]:
    t0 = time.perf_counter()
    scene = load()
    return time.perf_counter() - t0, scene


def main(argv=None) -> None:
    def extra(parser):
        parser.add_argument("--sizes", type=int, nargs="+", default=None, help="face counts")
        parser.add_argument("--all-pairs", type=int, nargs="*", default=[1000],
                        help="sizes at which the all-pairs imprint is also timed (default: 1000)")

    args = parse_args(__doc__.splitlines()[0], argv, extra)
    sizes = args.sizes or ([1000, 8000] if args.quick else [1000, 8000, 50_000, 300_000])

    import radiosity
    import radiosity.imprint as imprint

    warnings.simplefilter("ignore", radiosity.RadiosityWarning)
    original = imprint.imprint_faces
    radiosity.load_scene(radiosity.bundled_scene("cornell_box"))  # warm-up: compiled kernels load once
    rows = []
    folder = Path(__file__).resolve().parent / "results" / "_bench_load"
    folder.mkdir(parents=True, exist_ok=True)
    for size in sizes:
        path = folder / f"scene_{size}.obj"
        faces = generate(path, size)
        t_plain, plain = _timed(lambda: radiosity.load_scene(path, imprint=False))
        t_index, indexed = _timed(lambda: radiosity.load_scene(path))
        row = {"faces": faces, "no_imprint_s": round(t_plain, 2), "indexed_s": round(t_index, 2),
               "indexed_over_plain": round(t_index / t_plain, 2), "patches": indexed.n_patches,
               "hidden": int(indexed.patch_hidden.sum())}
        if size in args.all_pairs:
            imprint.imprint_faces = lambda *a, **k: original(*a, _all_pairs=True, **k)
            try:
                t_all, slow = _timed(lambda: radiosity.load_scene(path))
            finally:
                imprint.imprint_faces = original
            row["all_pairs_s"] = round(t_all, 2)
            row["all_pairs_over_indexed"] = round(t_all / t_index, 1)
            row["same_patches"] = bool(np.array_equal(slow.patch_quads, indexed.patch_quads)
                                       and np.array_equal(slow.patch_hidden, indexed.patch_hidden))
        rows.append(row)
        print_table([row], title=f"{faces} faces")
    print_table(rows, title="load_scene (seconds; ratios measured in this run)")
    write_json("load", {"rows": rows, "machine": machine_info()}, args.out)


if __name__ == "__main__":
    main()

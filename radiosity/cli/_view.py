"""``radiosity view``: open the interactive pyvista viewer on a solved result."""

from __future__ import annotations

from pathlib import Path

from .._errors import SceneError

NAME = "view"
HELP = "open the interactive viewer on a solved result (OUTDIR or its solution.vtp)"


def add_args(parser) -> None:
    parser.add_argument("result", type=Path, help="output folder of 'radiosity solve' or a .vtp file")
    parser.add_argument("--screenshot", type=Path, default=None, help="save a PNG instead of opening a window")


def run(args) -> int:
    import numpy as np
    import pyvista as pv

    from ..viz import tone_map

    path = args.result / "solution.vtp" if args.result.is_dir() else args.result
    if not path.exists():
        raise SceneError(f"{path}: no such result; run 'radiosity solve -o OUTDIR' first")
    mesh = pv.read(str(path))
    if "radiosity" not in mesh.point_data:
        raise SceneError(f"{path}: not a radiosity result (no 'radiosity' point data)")
    radiance = np.asarray(mesh.point_data["radiosity"]) / np.pi
    level = np.percentile(radiance.max(axis=1), 90) or 1.0
    mesh.point_data["rgb"] = tone_map(radiance, 0.85 / level)
    plotter = pv.Plotter(off_screen=args.screenshot is not None)
    plotter.add_mesh(mesh, scalars="rgb", rgb=True, lighting=False)
    if args.screenshot is not None:
        plotter.screenshot(str(args.screenshot))
        plotter.close()
    else:
        plotter.show()
    return 0

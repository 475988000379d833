"""``radiosity view``: open the interactive pyvista viewer on a solved result."""

from __future__ import annotations

from pathlib import Path

from .._errors import SceneError
from ._common import add_camera_arg

NAME = "view"
HELP = "open the interactive viewer on a solved result (OUTDIR or its solution.vtp)"


def add_args(parser) -> None:
    parser.add_argument("result", type=Path, help="output folder of 'radiosity solve' or a .vtp file")
    parser.add_argument("--screenshot", type=Path, default=None, help="save a PNG instead of opening a window")
    add_camera_arg(parser)


def read_result(path: Path):
    """The solved mesh of ``radiosity solve`` (a VTK XML .vtp with 'radiosity' point data)."""
    import logging
    import warnings

    import pyvista as pv

    if not path.exists():
        raise SceneError(f"{path}: no such result; run 'radiosity solve -o OUTDIR' first")
    try:
        with open(path, "rb") as fh:
            head = fh.read(256).lstrip()
    except OSError as exc:
        raise SceneError(f"cannot read result '{path}': {exc.strerror or exc}") from None
    if not (head.startswith(b"<?xml") or head.startswith(b"<VTKFile")):
        raise SceneError(f"{path}: not a radiosity result (not a VTK .vtp file)")
    # A damaged file makes VTK log errors and warn; we report it as one line instead.
    previous = logging.root.manager.disable
    logging.disable(logging.CRITICAL)
    try:
        with warnings.catch_warnings(), pv.vtk_verbosity("off"):
            warnings.simplefilter("ignore")
            mesh = pv.read(str(path))
    finally:
        logging.disable(previous)
    if mesh.n_points == 0 or "radiosity" not in mesh.point_data:
        raise SceneError(f"{path}: not a radiosity result (no 'radiosity' point data; damaged or another file)")
    return mesh


def result_camera(mesh, path: Path, camera: str | None):
    """``--camera``, else the camera ``solve`` recorded in summary.json beside the result, else
    :func:`radiosity.viz.auto_camera` on the mesh (None: the exterior view)."""
    import json

    import numpy as np

    from ..viz import Camera, auto_camera, parse_camera

    points = np.asarray(mesh.points, dtype=float)
    if camera is not None:
        return parse_camera(camera, focal_default=0.5 * (points.min(axis=0) + points.max(axis=0)))
    summary = path.parent / "summary.json"
    try:
        recorded = json.loads(summary.read_text()).get("camera") if summary.exists() else None
    except (OSError, ValueError):
        recorded = None
    if isinstance(recorded, dict) and "position" in recorded:
        try:
            return Camera(tuple(recorded["position"]), tuple(recorded["focal_point"]), tuple(recorded["up"]),
                          float(recorded["view_angle"]), recorded.get("how", "summary.json"))
        except (KeyError, TypeError, ValueError):
            pass
    elif isinstance(recorded, dict):
        return None  # solve used the exterior view
    triangles = mesh.triangulate()
    faces = np.asarray(triangles.faces).reshape(-1, 4)[:, 1:]
    return auto_camera(np.asarray(triangles.points, dtype=float)[faces])


def run(args) -> int:
    import numpy as np
    import pyvista as pv

    from ..viz import _quiet_vtk, apply_camera, tone_map

    _quiet_vtk()
    path = args.result / "solution.vtp" if args.result.is_dir() else args.result
    mesh = read_result(path)
    radiance = np.asarray(mesh.point_data["radiosity"]) / np.pi
    level = np.percentile(radiance.max(axis=1), 90) or 1.0
    mesh.point_data["rgb"] = tone_map(radiance, 0.85 / level)
    plotter = pv.Plotter(off_screen=args.screenshot is not None)
    plotter.add_mesh(mesh, scalars="rgb", rgb=True, lighting=False)
    apply_camera(plotter, result_camera(mesh, path, args.camera))
    if args.screenshot is not None:
        plotter.screenshot(str(args.screenshot))
        plotter.close()
    else:
        plotter.show()
    return 0

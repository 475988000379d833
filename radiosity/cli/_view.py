"""``radiosity view``: open the interactive pyvista viewer on a solved result.

Without a display (no ``DISPLAY`` or ``WAYLAND_DISPLAY`` on Linux) no window can open: the
command refuses with one line and exit status 2 instead of VTK's log lines, and names the
options that work off-screen (``--screenshot``).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from .._errors import RadiosityError, SceneError
from ._common import add_camera_arg

NAME = "view"
HELP = "open the interactive viewer on a solved result (OUTDIR or its solution.vtp)"


def add_args(parser) -> None:
    parser.add_argument("result", type=Path, help="output folder of 'radiosity solve' or a .vtp file")
    parser.add_argument("--screenshot", type=Path, default=None, metavar="OUT.png",
                        help="render off-screen and save a PNG instead of opening a window (works without a display)")
    parser.add_argument("--html", type=Path, default=None, metavar="OUT.html",
                        help="write a self-contained interactive page (opens offline in any browser) instead of "
                             "opening a window")
    add_camera_arg(parser)


def has_display() -> bool:
    """Whether a window can open: on Linux and the BSDs an X11 or Wayland display must be set."""
    if sys.platform.startswith(("linux", "freebsd", "openbsd", "netbsd")):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


def read_result(path: Path):
    """The solved mesh of ``radiosity solve`` (a VTK XML .vtp with 'radiosity' point data)."""
    import logging
    import warnings

    from ..viz import pyvista

    pv = pyvista()

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


def _summary_beside(path: Path) -> dict:
    """The ``summary.json`` written with a result (for its exposure and scene), or {}."""
    import json

    try:
        record = json.loads((path.parent / "summary.json").read_text())
    except (OSError, ValueError):
        return {}
    return record if isinstance(record, dict) else {}


def _write_page(mesh, path: Path, target: Path) -> int:
    import numpy as np

    from ..io.html import page_data_from_result, write_page

    record = _summary_beside(path)
    radiance = np.asarray(mesh.point_data["radiosity"]) / np.pi
    exposure = record.get("exposure") or 0.85 / (np.percentile(radiance.max(axis=1), 90) or 1.0)
    write_page(page_data_from_result(mesh, record, exposure=float(exposure)), target)
    print(f"wrote {target}")
    return 0


def run(args) -> int:
    import numpy as np
    from ..viz import pyvista

    pv = pyvista()

    from ..viz import _quiet_vtk, apply_camera, tone_map

    path = args.result / "solution.vtp" if args.result.is_dir() else args.result
    mesh = read_result(path)
    if args.html is not None:
        return _write_page(mesh, path, args.html)
    if args.screenshot is None and not has_display():
        raise RadiosityError("no display to open a window on (DISPLAY is not set); use --screenshot OUT.png "
                             "to render off-screen, or --html OUT.html for a page")
    _quiet_vtk()
    record = _summary_beside(path)
    radiance = np.asarray(mesh.point_data["radiosity"]) / np.pi
    exposure = record.get("exposure") or 0.85 / (np.percentile(radiance.max(axis=1), 90) or 1.0)
    mesh.point_data["rgb"] = tone_map(radiance, exposure)  # the picture's tone map, when known
    plotter = pv.Plotter(off_screen=args.screenshot is not None)
    plotter.set_background("black")
    plotter.add_mesh(mesh, scalars="rgb", rgb=True, lighting=False, culling="back")
    apply_camera(plotter, result_camera(mesh, path, args.camera))
    if args.screenshot is not None:
        plotter.screenshot(str(args.screenshot))
        plotter.close()
    else:
        plotter.show()
    return 0

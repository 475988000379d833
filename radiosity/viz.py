"""Pictures and pyvista meshes of a solution: the only module that imports pyvista (lazily)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["to_polydata", "tone_map", "render", "scene_camera", "white_balanced"]

# The Cornell box's published camera: position, focal point, up (metres), vertical view angle.
CORNELL_CAMERA = ((0.278, 0.273, -0.8), (0.278, 0.273, 0.0), (0.0, 1.0, 0.0), 39.3)


def tone_map(radiance: np.ndarray, exposure: float) -> np.ndarray:
    """Linear radiance (..., 3) times exposure, clipped, to 8-bit sRGB."""
    x = np.clip(radiance * exposure, 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(255 * srgb).astype(np.uint8)


def auto_exposure(solution) -> float:
    """Exposure putting the 98th percentile of non-emitting radiance at 0.85 of white."""
    lit = ~solution.scene.emission.any(axis=1)
    radiance = solution.radiosity[lit] / np.pi if lit.any() else solution.radiosity / np.pi
    luminance = radiance @ np.array([0.2126, 0.7152, 0.0722])
    level = np.percentile(luminance, 98) if len(luminance) else 0.0
    return float(0.85 / level) if level > 0 else 1.0


def light_gains(solution) -> np.ndarray:
    """Per-channel gains (3,) that make the emitters' mean colour grey at the same luminance.

    The colour is the area-weighted mean emission of the emitting patches; each gain is that
    colour's luminance over its channel, so a surface lit by the light alone looks neutral, as a
    camera's white balance would make it. All ones when nothing emits or a channel is dark.
    """
    scene = solution.scene
    emitting = scene.emission.any(axis=1)
    if not emitting.any():
        return np.ones(3)
    colour = (scene.patch_area[emitting, None] * scene.emission[emitting]).sum(axis=0)
    if (colour <= 0).any():
        return np.ones(3)
    return float(colour @ np.array([0.2126, 0.7152, 0.0722])) / colour


def white_balanced(solution):
    """(a copy of ``solution`` whose radiosity is scaled by :func:`light_gains`, the gains),
    for pictures only: the physical values stay in the original."""
    from dataclasses import replace

    gains = light_gains(solution)
    return replace(solution, radiosity=solution.radiosity * gains), gains


def to_polydata(solution):
    """pyvista.PolyData of the solved patches with per-face and per-vertex radiosity.

    Cell data: ``radiosity`` (n, 3) W/m^2, ``object`` (n,) index into the field data
    ``object_names``; point data: ``radiosity`` (area-weighted over the patches of the same
    object meeting at the vertex).
    """
    import pyvista as pv

    vertices, faces, vertex_b = solution.vertex_mesh
    cells = np.concatenate([np.concatenate([[len(f)], f]) for f in faces]).astype(np.int64)
    mesh = pv.PolyData(vertices, cells)
    mesh.cell_data["radiosity"] = solution.radiosity
    mesh.cell_data["object"] = solution.scene.patch_object
    mesh.point_data["radiosity"] = vertex_b
    mesh.field_data["object_names"] = np.array(solution.scene.objects, dtype=str)
    return mesh


def _render_mesh(solution):
    """Triangles for the picture: each patch outline fanned from its first corner.

    Outlines carry the T-junction vertices of their neighbours (``Solution.vertex_mesh``), so
    they have collinear points, which VTK's polygon triangulation mishandles (stray pixels);
    a fan from a corner gives only proper or zero-area triangles.
    """
    import pyvista as pv

    vertices, faces, vertex_b = solution.vertex_mesh
    tris = np.concatenate([np.column_stack([np.full(len(f) - 2, f[0]), f[1:-1], f[2:]]) for f in faces])
    a, b, c = (vertices[tris[:, k]] for k in range(3))
    twice_area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    tris = tris[twice_area > 1e-12 * solution.scene.scale**2]  # collinear corners: no triangle
    mesh = pv.PolyData(vertices, np.column_stack([np.full(len(tris), 3), tris]).ravel().astype(np.int64))
    mesh.point_data["radiosity"] = vertex_b
    return mesh


def scene_camera(source: str):
    """Camera written in the OBJ as ``# camera: px py pz fx fy fz ux uy uz fov``, if any."""
    try:
        with open(source, encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if line.startswith("# camera:"):
                    v = [float(t) for t in line.split(":", 1)[1].split()]
                    return tuple(v[0:3]), tuple(v[3:6]), tuple(v[6:9]), v[9]
    except (OSError, ValueError, IndexError):
        return None
    return None


def _quiet_vtk() -> None:
    """Keep VTK's warnings off stderr: without a display it logs 'bad X server connection'
    before falling back to off-screen (EGL) rendering, which works; real errors still show."""
    try:
        from vtkmodules.vtkCommonCore import vtkLogger

        vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_ERROR)
    except ImportError:  # pragma: no cover - older VTK
        pass


def render(solution, path: str | Path | None = None, *, window_size=(800, 800), exposure: float | None = None,
           off_screen: bool = True):
    """Render the solution (radiance B/pi, tone-mapped to sRGB) and save a PNG if ``path``."""
    import pyvista as pv

    _quiet_vtk()
    mesh = _render_mesh(solution)
    exposure = auto_exposure(solution) if exposure is None else exposure
    mesh.point_data["rgb"] = tone_map(mesh.point_data["radiosity"] / np.pi, exposure)
    plotter = pv.Plotter(off_screen=off_screen, window_size=list(window_size))
    plotter.set_background("black")
    plotter.add_mesh(mesh, scalars="rgb", rgb=True, lighting=False, show_scalar_bar=False)
    camera = scene_camera(solution.scene.source)
    if camera is not None:
        position, focal, up, angle = camera
        plotter.camera.position = position
        plotter.camera.focal_point = focal
        plotter.camera.up = up
        plotter.camera.view_angle = angle
    else:
        plotter.camera_position = "iso"
        plotter.reset_camera()
    if path is not None:
        plotter.screenshot(str(path))
        plotter.close()
        return exposure
    plotter.show()
    return exposure

"""Pictures and pyvista meshes of a solution: the only module that imports pyvista (lazily)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["to_polydata", "tone_map", "render", "scene_camera", "parse_camera", "auto_camera", "choose_camera",
           "Camera", "white_balanced"]

# The Cornell box's published camera: position, focal point, up (metres), vertical view angle.
CORNELL_CAMERA = ((0.278, 0.273, -0.8), (0.278, 0.273, 0.0), (0.0, 1.0, 0.0), 39.3)


def pyvista():
    """The pyvista module, first imported with Ctrl-C and SIGTERM held back (see
    :func:`radiosity._startup.signals_held`): a signal inside VTK's initialisation segfaulted."""
    import sys

    if "pyvista" not in sys.modules:
        from ._startup import signals_held

        with signals_held():
            import pyvista as pv  # noqa: F401 - loads VTK with signals held
    return sys.modules["pyvista"]


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
    ``object_names``, ``hidden`` (n,) 1 for patches covered by a contact (never seen; threshold
    them away to look at the surfaces); point data: ``radiosity`` (area-weighted over the
    patches of the same object meeting at the vertex).
    """
    pv = pyvista()

    vertices, faces, vertex_b = solution.vertex_mesh
    cells = np.concatenate([np.concatenate([[len(f)], f]) for f in faces]).astype(np.int64)
    mesh = pv.PolyData(vertices, cells)
    mesh.cell_data["radiosity"] = solution.radiosity
    mesh.cell_data["object"] = solution.scene.patch_object
    mesh.cell_data["hidden"] = solution.scene.patch_hidden.astype(np.uint8)
    mesh.point_data["radiosity"] = vertex_b
    mesh.field_data["object_names"] = np.array(solution.scene.objects, dtype=str)
    return mesh


def _render_mesh(solution):
    """Triangles for the picture: each visible patch outline fanned from its first corner.

    Outlines carry the T-junction vertices of their neighbours (``Solution.vertex_mesh``), so
    they have collinear points, which VTK's polygon triangulation mishandles (stray pixels);
    a fan from a corner gives only proper or zero-area triangles. Hidden patches (covered by a
    contact) are left out: never seen, they z-fought where what covers them is coplanar (two
    overlapping table tops of a generated room drew black streaks across the visible one).
    """
    pv = pyvista()

    vertices, faces, vertex_b = solution.vertex_mesh
    shown = [f for f, hidden in zip(faces, solution.scene.patch_hidden) if not hidden] or faces
    tris = np.concatenate([np.column_stack([np.full(len(f) - 2, f[0]), f[1:-1], f[2:]]) for f in shown])
    a, b, c = (vertices[tris[:, k]] for k in range(3))
    twice_area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    tris = tris[twice_area > 1e-12 * solution.scene.scale**2]  # collinear corners: no triangle
    mesh = pv.PolyData(vertices, np.column_stack([np.full(len(tris), 3), tris]).ravel().astype(np.int64))
    mesh.point_data["radiosity"] = vertex_b
    return mesh


@dataclass(frozen=True)
class Camera:
    """A pinhole camera: position and focal point (metres), up vector, vertical view angle (degrees).

    ``how`` says where it came from (``--camera``, the OBJ's ``# camera:`` line, or which
    automatic view), for the summary.
    """

    position: tuple[float, float, float]
    focal_point: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    view_angle: float = 40.0
    how: str = ""

    def as_dict(self) -> dict:
        return {"position": [float(x) for x in self.position], "focal_point": [float(x) for x in self.focal_point],
                "up": [float(x) for x in self.up], "view_angle": float(self.view_angle), "how": self.how}


# View angle of the automatic views (degrees): the Cornell box's camera is 39.3; inside a
# closed room a wider lens shows more of it from near a wall.
_VIEW_ANGLE_OPENING = 40.0
_VIEW_ANGLE_INSIDE = 70.0
_VIEW_ANGLE_USER = 50.0
# A viewpoint is inside a room when at least this share of rays from it hit the fronts of faces.
_ROOM_FRONT_SHARE = 0.6
# ... and the room is closed when at most this share escapes (else its open side is looked through).
_ROOM_OPEN_SHARE = 0.05
# ... and is no room at all when this share escapes in no one direction: under the lamp of a
# 50 m terrain 45% of the rays leave sideways, and the view "inside" looked straight down.
_OPEN_ALL_ROUND_SHARE = 0.25
# An axis other than y is taken as up when it is the shortest and under this share of y's extent.
_VERTICAL_SHORTER = 0.9
# Rays per viewpoint: 256, fewer on big scenes (at least 64) so a probe stays near 4e7
# ray-triangle tests (about a second).
_PROBE_RAYS = 256
_PROBE_TESTS = 4e7


def parse_camera(text: str, focal_default=None) -> Camera:
    """A camera from ``X,Y,Z[:TX,TY,TZ[:ANGLE]]`` (metres; angle in degrees, default 50).

    Without a target the camera looks at ``focal_default`` (the scene's centre). The up vector is
    +y, or +z when looking straight up or down.

    Raises
    ------
    ValueError
        Not three numbers, then optionally three more and an angle, all finite; or the target
        equals the position.

    Examples
    --------
    >>> from radiosity.viz import parse_camera
    >>> camera = parse_camera("0.278,0.273,-0.8:0.278,0.273,0:39.3")
    >>> camera.position, camera.view_angle
    ((0.278, 0.273, -0.8), 39.3)
    """
    parts = text.split(":")
    msg = (f"camera must be 'X,Y,Z' or 'X,Y,Z:TX,TY,TZ' or 'X,Y,Z:TX,TY,TZ:ANGLE' (metres, degrees), got {text!r}")
    try:
        vectors = [[float(t) for t in part.split(",")] for part in parts[:2]]
        angle = float(parts[2]) if len(parts) == 3 else _VIEW_ANGLE_USER
    except ValueError:
        raise ValueError(msg) from None
    numbers = np.concatenate([np.ravel(v) for v in vectors] + [[angle]])
    if len(parts) > 3 or any(len(v) != 3 for v in vectors) or not np.isfinite(numbers).all():
        raise ValueError(msg)
    if not 0 < angle < 180:
        raise ValueError(f"camera view angle must be between 0 and 180 degrees, got {angle:g}")
    position = tuple(vectors[0])
    if len(vectors) == 2:
        focal = tuple(vectors[1])
        if np.allclose(position, focal):
            raise ValueError(f"camera target equals its position ({text!r}); give a target elsewhere")
    else:
        focal = tuple(focal_default) if focal_default is not None else (0.0, 0.0, 0.0)
        if np.allclose(position, focal):  # at the centre itself: look along +z
            focal = (position[0], position[1], position[2] + 1.0)
    return Camera(position, focal, _up_for(np.subtract(focal, position)), angle, "--camera")


def _up_for(direction, vertical: int = 1) -> tuple[float, float, float]:
    """The ``vertical`` axis as the camera's up, unless it looks (nearly) along it."""
    d = np.asarray(direction, float)
    d = d / max(np.linalg.norm(d), 1e-300)
    axis = vertical if abs(d[vertical]) <= 0.98 else (2 if vertical != 2 else 1)
    return tuple(float(c) for c in np.eye(3)[axis])


def _vertical_axis(size: np.ndarray) -> int:
    """The scene's up axis: y (OBJ's convention) unless another axis is clearly the shortest
    (under 90% of y's extent and the smallest): rooms are wider than tall, so a room modelled
    z-up (a thermal model, a CAD export) stands on its floor too."""
    k = int(np.argmin(size))
    return k if k != 1 and size[k] < _VERTICAL_SHORTER * size[1] else 1


def _fibonacci_directions(n: int) -> np.ndarray:
    """(n, 3) unit vectors spread evenly over the sphere."""
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = np.pi * (1 + 5**0.5) * k
    r = np.sqrt(1 - z * z)
    return np.column_stack([r * np.cos(phi), z, r * np.sin(phi)])


def _probe(point, directions, triangles, offset):
    """(front, back, escaped) share of rays from a point, and (n,) hit distances (inf: escaped)."""
    from ._lightpaths import _first_hits

    origins = np.broadcast_to(point, directions.shape)
    hit, side = _first_hits(origins, directions, triangles, offset)
    found = hit >= 0
    n = len(hit)
    front = found & (side < 0)
    return front.sum() / n, (found & ~front).sum() / n, (~found).sum() / n, hit


def auto_camera(triangles: np.ndarray) -> Camera | None:
    """A view that shows the modelled (front) sides: inside a room if the scene is one, else None.

    Parameters
    ----------
    triangles : (t, 3, 3) float
        The scene's triangles, wound counter-clockwise seen from their front, metres.

    Returns
    -------
    Camera or None
        None when no point of the scene's box sees mostly front faces (objects seen from
        outside), or when the light leaves such points all round (a terrain): the caller's
        exterior view shows them.

    Notes
    -----
    Rays from 27 points of the scene's bounding box (a 3 x 3 x 3 grid at 25/50/75%) find the one
    that sees the most front faces. If that share is at least 60%, the scene is a room. A room
    letting more than 5% of the rays escape (over all the points inside it) is open (the Cornell
    box's front): the camera looks in through the opening, from outside it, level, with a
    40 degree lens framing the room. A closed room is looked at from inside, near the middle of
    one wall at 60% of the height, across its longest horizontal extent, with a 70 degree lens;
    a wall spot inside an object is skipped. Up is y, OBJ's convention, unless another axis is
    clearly the shortest (a room modelled z-up, as thermal models and CAD exports often are).
    """
    pts = triangles.reshape(-1, 3)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    size = hi - lo
    scale = float(np.linalg.norm(size))
    if scale == 0:
        return None
    offset = 1e-6 * scale
    n_rays = int(np.clip(_PROBE_TESTS / (27 * max(len(triangles), 1)), 64, _PROBE_RAYS))
    directions = _fibonacci_directions(n_rays)
    grid = np.array([(a, b, c) for a in (0.25, 0.5, 0.75) for b in (0.25, 0.5, 0.75) for c in (0.25, 0.5, 0.75)])
    best = None
    escaping = []  # escaping directions seen from every point inside the room
    for frac in grid[np.argsort(np.abs(grid - 0.5).sum(axis=1), kind="stable")]:  # the centre first
        point = lo + frac * size
        front, _, escaped, hit = _probe(point, directions, triangles, offset)
        if front >= _ROOM_FRONT_SHARE:
            escaping.append(directions[hit < 0])
        if best is None or front > best[0] + 1e-9:
            best = (front, point)
    front, point = best
    if front < _ROOM_FRONT_SHARE:
        return None
    center = 0.5 * (lo + hi)
    out = np.concatenate(escaping)
    # Seen from all the points inside, more than 5% of the rays leave the room: it is open, and
    # the mean escaping direction points out through the opening (unless it leaks all round).
    vertical = _vertical_axis(size)
    if len(out) > _ROOM_OPEN_SHARE * n_rays * len(escaping) and np.linalg.norm(out.mean(axis=0)) > 0.3:
        return _through_opening(out.mean(axis=0), lo, hi, vertical)
    if len(out) > _OPEN_ALL_ROUND_SHARE * n_rays * len(escaping):
        return None  # light leaves all round (a terrain under a lamp): no room to stand in
    return _inside(lo, hi, triangles, offset, directions, vertical) or Camera(
        tuple(point), tuple(center), _up_for(center - point, vertical), _VIEW_ANGLE_INSIDE, "inside the room")


def _axis(vector) -> np.ndarray:
    """The coordinate axis (signed unit vector) closest to ``vector``."""
    k = int(np.argmax(np.abs(vector)))
    out = np.zeros(3)
    out[k] = np.sign(vector[k])
    return out


def _through_opening(out: np.ndarray, lo: np.ndarray, hi: np.ndarray, vertical: int = 1) -> Camera:
    """Look into an open room from outside its opening (``out``: the way light escapes)."""
    out = _axis(out)  # rooms are built along the axes; a level camera reads best
    k = int(np.argmax(np.abs(out)))
    center = 0.5 * (lo + hi)
    half = 0.5 * (hi - lo)
    across = max(half[j] for j in range(3) if j != k) * 1.05
    distance = across / np.tan(np.radians(_VIEW_ANGLE_OPENING / 2))
    position = center + out * (half[k] + distance)
    return Camera(tuple(position), tuple(center), _up_for(out, vertical), _VIEW_ANGLE_OPENING,
                  "outside the room's open side, looking in")


def _inside(lo, hi, triangles, offset, directions, vertical: int = 1) -> Camera | None:
    """Near the middle of a wall, looking across the room's longest horizontal extent; a spot
    whose view is blocked close by (a partition before it) gives way to the next wall's."""
    size = hi - lo
    center = 0.5 * (lo + hi)
    v = vertical
    first = None
    for k in sorted((j for j in range(3) if j != v), key=lambda j: -size[j]):
        for sign in (1.0, -1.0):
            position = center.copy()
            position[v] = lo[v] + 0.6 * size[v]
            position[k] = center[k] - sign * 0.42 * size[k]
            front, _, _, _ = _probe(position, directions, triangles, offset)
            if front < 0.9:
                continue
            focal = center.copy()
            focal[v] = lo[v] + 0.4 * size[v]
            camera = Camera(tuple(position), tuple(focal), _up_for(focal - position, v), _VIEW_ANGLE_INSIDE,
                            "inside the room, near a wall")
            if _clear_view(position, focal, size, triangles, offset):
                return camera
            first = first or camera
    return first


def _clear_view(position, focal, size, triangles, offset) -> bool:
    """Whether most of 9 rays towards the focal point and around it (a quarter of the room
    either side) travel at least half-way to it before they hit a face."""
    from ._lightpaths import _first_hits

    step = 0.25 * np.diag(size)  # a quarter of the room along each axis
    targets = focal + np.concatenate([-step, step, np.zeros((1, 3))])
    directions = targets - position
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    origins = np.repeat(position[None], len(targets), axis=0)
    hit, _ = _first_hits(origins, directions, triangles, offset)
    tri = triangles[np.maximum(hit, 0)]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.einsum("nc,nc->n", normal, tri[:, 0] - origins) / np.einsum("nc,nc->n", normal, directions)
    t = np.where(hit >= 0, t, np.inf)
    return float(np.mean(t >= 0.5 * np.linalg.norm(focal - position))) >= 2 / 3



def choose_camera(solution, camera: Camera | str | None = None) -> Camera | None:
    """The camera of a picture: ``camera`` if given, else the OBJ's ``# camera:`` line, else
    :func:`auto_camera`; None means the exterior (isometric) view.

    Parameters
    ----------
    solution : Solution
        Only ``solution.scene`` is used (its source file and patches).
    camera : Camera or str, optional
        A camera, or its ``--camera`` text (``X,Y,Z[:TX,TY,TZ[:ANGLE]]``).

    Returns
    -------
    Camera or None
    """
    if isinstance(camera, str):
        camera = parse_camera(camera, focal_default=_center(solution.scene.patch_quads))
    if camera is not None:
        return camera
    hint = scene_camera(solution.scene.source)
    if hint is not None:
        position, focal, up, angle = hint
        return Camera(position, focal, up, angle, "the OBJ's '# camera:' line")
    from ._lightpaths import _triangles

    visible = ~solution.scene.patch_hidden
    return auto_camera(_triangles(solution.scene.patch_quads[visible])[0])


def _center(quads) -> tuple[float, float, float]:
    pts = quads.reshape(-1, 3)
    return tuple(0.5 * (pts.min(axis=0) + pts.max(axis=0)))


def apply_camera(plotter, camera: Camera | None) -> None:
    """Set a pyvista plotter's camera; None: the isometric view from outside."""
    if camera is None:
        plotter.camera_position = "iso"
        plotter.reset_camera()
        return
    plotter.camera.position = camera.position
    plotter.camera.focal_point = camera.focal_point
    plotter.camera.up = camera.up
    plotter.camera.view_angle = camera.view_angle
    plotter.reset_camera_clipping_range()


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
           off_screen: bool = True, camera: Camera | str | None = None):
    """Render the solution (radiance B/pi, tone-mapped to sRGB) and save a PNG if ``path``.

    ``camera``: a :class:`Camera` or ``"X,Y,Z[:TX,TY,TZ[:ANGLE]]"``; default: the OBJ's
    ``# camera:`` line, else a view from inside the room (:func:`auto_camera`), else from outside.
    """
    pv = pyvista()

    _quiet_vtk()
    mesh = _render_mesh(solution)
    exposure = auto_exposure(solution) if exposure is None else exposure
    mesh.point_data["rgb"] = tone_map(mesh.point_data["radiosity"] / np.pi, exposure)
    plotter = pv.Plotter(off_screen=off_screen, window_size=list(window_size))
    plotter.set_background("black")
    # front faces only: a surface is one-sided, and a two-sided sheet (two coincident faces wound
    # opposite ways, a partition) z-fought in stripes of its two sides' colours
    plotter.add_mesh(mesh, scalars="rgb", rgb=True, lighting=False, show_scalar_bar=False, culling="back")
    apply_camera(plotter, choose_camera(solution, camera))
    if path is not None:
        plotter.screenshot(str(path))
        plotter.close()
        return exposure
    plotter.show()
    return exposure

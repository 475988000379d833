"""View3D (NIST/LBNL) ``.vs3`` models: read surfaces, subsurfaces and obstructions; write them back.

A ``.vs3`` file (View3D 3.x, documented in its user manual, section "Input File Format") is a
sequence of records, each starting with one letter::

    T  title                                    ! comments start with ! or / (also after data)
    C  encl=1 emit=0 eps=1e-4 ...               control line: encl and emit are read here
    F  3                                        geometry format: 3 (vertices) or 3a (shapes)
    V  n  x  y  z                               vertex n (numbered from 1, in order; F 3)
    S  n  v1 v2 v3 v4  base cmb emit  name      radiating surface; v4 = 0 for a triangle
    O  n  v1 v2 v3 v4                           obstruction only (blocks, never exchanges)
    E                                           end of data (also '*')

In format ``F 3a`` a surface gives its shape instead of vertex numbers, followed (on the same
or the next lines) by its plane and its outline in that plane::

    S  n  R|Q|T  base cmb emit  name
       x0 y0 z0  azimuth tilt  (w h | u1 v1 ... u4 v4 | u1 v1 ... u3 v3)

The plane's origin is ``(x0, y0, z0)``; its first axis points along azimuth (degrees clockwise
from +y, "north") turned by 90 degrees, its second axis climbs at the tilt (0: the surface
faces up, 90: vertical, 180: faces down). A rectangle ``R`` of width w and height h has its
lower-left corner (seen from the front) at the origin. Obstructions (``O n R|Q|T``) have no
base, cmb, emit or name.

``base`` names the surface a subsurface lies in (a window in a wall); ``cmb`` the surface it is
combined with in the output (the pieces of a non-convex wall). What they mean for the scene
is applied by :func:`radiosity.scene.load_vs3`. Mask (``M``) and null (``N``) surfaces are
refused; ``X`` (coordinate transformation) lines are skipped with a note, as View3D skips them.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._errors import SceneError
from ..geometry import vector_area
from ._text import decode, excerpt, parse_float, read_input, split_lines
from .obj import MAX_COORDINATE

__all__ = ["View3DModel", "SeparatedModel", "read_vs3", "separate_and_combine", "write_vs3"]

# View3D clamps emissivities into this range (with a warning); so do we.
EMISSIVITY_RANGE = (0.001, 0.999)
# Emissivity of obstructions and of surfaces that give none (never used by a black fill).
DEFAULT_EMISSIVITY = 0.9


@dataclass
class View3DModel:
    """A parsed ``.vs3`` file: one entry per ``S``/``O`` record, in file order (0-based)."""

    path: Path
    title: str = ""
    vertices: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    surfaces: list[list[int]] = field(default_factory=list)  # vertex indices (0-based) of each surface
    names: list[str] = field(default_factory=list)
    obstruction: list[bool] = field(default_factory=list)
    emissivity: list[float] = field(default_factory=list)
    base: list[int] = field(default_factory=list)  # 0 or the base surface's number (1-based)
    combine: list[int] = field(default_factory=list)  # 0 or the number of the surface it joins
    line: list[int] = field(default_factory=list)  # line of each surface record
    control: dict[str, str] = field(default_factory=dict)  # the C line's name=value pairs
    notes: list[str] = field(default_factory=list)

    @property
    def enclosure(self) -> bool:
        """``encl=1``: the model says its surfaces form a closed enclosure."""
        return _flag(self.control.get("encl", "0"))

    @property
    def emittances(self) -> bool:
        """``emit=1``: View3D would write Hottel's script-F (reflections included)."""
        return _flag(self.control.get("emit", "0"))

    def __getitem__(self, key: str):  # the dict-style access earlier callers used
        value = getattr(self, key)
        return np.asarray(value) if key in ("obstruction", "emissivity") else value


def _flag(text: str) -> bool:
    try:
        return int(float(text)) != 0
    except ValueError:
        return False


def _strip_comment(raw: str) -> str:
    """The record without its comment: ``!`` anywhere, or ``/`` starting a word."""
    text = raw.split("!", 1)[0]
    return re.split(r"(?:^|\s)/", text, maxsplit=1)[0]


_INTEGER = re.compile(r"[+-]?\d+", re.ASCII)


def _number(token: str, where: str, what: str, kind=float):
    """``token`` as a float (or int), in the ASCII grammar of ``io._text``; SceneError naming it."""
    try:
        if kind is int and not _INTEGER.fullmatch(token):
            raise ValueError(token)
        value = kind(token) if kind is int else parse_float(token)
    except ValueError:
        raise SceneError(f"{where}: {what} must be a number, got {excerpt(token)!r}") from None
    if kind is float and not np.isfinite(value):
        raise SceneError(f"{where}: {what} is not finite: {excerpt(token)!r}")
    return value


def _coordinate(token: str, where: str) -> float:
    value = _number(token, where, "a coordinate")
    if abs(value) > MAX_COORDINATE:  # beyond it, areas and distances overflow in the kernels
        raise SceneError(f"{where}: a coordinate is beyond {MAX_COORDINATE:g}: {excerpt(token)!r}")
    return value


class _Tokens:
    """Words of the data records after the current one, for the 3a geometry that may span lines."""

    def __init__(self, lines: list[str], path: Path):
        self.lines, self.path = lines, path
        self.index = 0  # next line to read
        self.pending: list[str] = []
        self.where = f"{path}"

    def take(self, what: str) -> float:
        while not self.pending:
            if self.index >= len(self.lines):
                raise SceneError(f"{self.where}: the file ends before {what}")
            text = _strip_comment(self.lines[self.index]).split()
            self.index += 1
            self.where = f"{self.path}:{self.index}"
            if text and text[0][0].isalpha():
                raise SceneError(f"{self.where}: expected {what}, got the record {excerpt(text[0])!r}")
            self.pending = text
        return _number(self.pending.pop(0), self.where, what)


def read_vs3(path) -> View3DModel:
    """Parse a ``.vs3`` file (formats ``F 3`` and ``F 3a``) into a :class:`View3DModel`.

    Raises
    ------
    SceneError
        Out-of-sequence numbers, bad vertex, base or combine references, unknown records,
        unsupported formats; the message names the file and line.
    """
    path = Path(path)
    try:
        lines = split_lines(decode(read_input(path, "View3D")))
    except FileNotFoundError:
        raise SceneError(f"View3D file '{path}' does not exist") from None
    except OSError as exc:
        raise SceneError(f"cannot read View3D file '{path}': {exc.strerror or exc}") from None
    model = View3DModel(path)
    vertices: list[list[float]] = []
    geometry = "3"
    tokens = _Tokens(lines, path)
    while tokens.index < len(lines):
        number = tokens.index + 1
        raw = lines[tokens.index]
        tokens.index += 1
        tokens.pending = []
        where = f"{path}:{number}"
        words = _strip_comment(raw).split()
        if not words:
            continue
        key = words[0][0].upper()
        if key == "T":
            model.title = _strip_comment(raw).strip()[1:].strip()
        elif key == "C":
            model.control.update(_control(" ".join(words)[1:]))
        elif key == "X":  # View3D's 3-D reader skips these too
            model.notes.append(f"{where}: coordinate transformation (X) ignored, as View3D does for 3-D models")
        elif key == "F":
            geometry = words[1].lower() if len(words) > 1 else "3"
            if geometry not in ("3", "3a"):
                raise SceneError(f"{where}: only 3-D View3D models (F 3 or F 3a) are supported, "
                                 f"got F {excerpt(words[1])}")
        elif key == "V":
            if len(words) < 5:
                raise SceneError(f"{where}: a vertex line needs 'V n x y z', got {excerpt(raw)!r}")
            n = _number(words[1], where, "vertex number", int)
            if n != len(vertices) + 1:
                raise SceneError(f"{where}: vertex {n} out of sequence (expected {len(vertices) + 1})")
            vertices.append([_coordinate(t, where) for t in words[2:5]])
        elif key in "SO":
            if geometry == "3a":
                corners = _shape_surface(words, where, key, model, tokens)
                first = len(vertices)
                vertices.extend(corners.tolist())
                refs = list(range(first, first + len(corners)))
            else:
                refs = _vertex_surface(words, where, key, model, len(vertices))
            model.surfaces.append(refs)
            model.line.append(number)
        elif key in "E*":
            break
        elif key in "MN":
            raise SceneError(f"{where}: View3D mask/null surfaces ({key}) are not supported")
        else:
            raise SceneError(f"{where}: unknown View3D identifier {excerpt(words[0])!r}")
    if not model.surfaces:
        raise SceneError(f"{path}: the model has no surfaces")
    model.vertices = np.asarray(vertices, float).reshape(-1, 3)
    _check_references(model)
    return model


def _control(text: str) -> dict[str, str]:
    words = [w for w in re.split(r"[=,\s]+", text) if w]
    return {k.lower(): v for k, v in zip(words[0::2], words[1::2])}


def _surface_number(words: list[str], where: str, model: View3DModel) -> int:
    n = _number(words[1], where, "surface number", int)
    if n != len(model.surfaces) + 1:
        raise SceneError(f"{where}: surface {n} out of sequence (expected {len(model.surfaces) + 1})")
    return n


def _surface_data(words: list[str], where: str, key: str, n: int, model: View3DModel) -> None:
    """base, cmb, emit and name (words after the geometry); obstructions have none."""
    if key == "O":
        model.base.append(0)
        model.combine.append(0)
        model.emissivity.append(DEFAULT_EMISSIVITY)
        model.names.append(f"obstruction_{n}")
        model.obstruction.append(True)
        return
    if any(model.obstruction):
        raise SceneError(f"{where}: surface {n} comes after an obstruction; View3D lists every "
                         "radiating surface (S) before the obstructions (O)")
    base = _number(words[0], where, "base surface number", int) if len(words) > 0 else 0
    combine = _number(words[1], where, "combine surface number", int) if len(words) > 1 else 0
    emit = _number(words[2], where, "emissivity") if len(words) > 2 else DEFAULT_EMISSIVITY
    if not 0 < emit <= 1:
        raise SceneError(f"{where}: surface {n} emissivity must be in (0, 1], got {emit}")
    model.base.append(base)
    model.combine.append(combine)
    model.emissivity.append(min(max(emit, EMISSIVITY_RANGE[0]), EMISSIVITY_RANGE[1]))
    model.names.append(" ".join(words[3:]) if len(words) > 3 else f"surface_{n}")
    model.obstruction.append(False)


def _vertex_surface(words, where, key, model, n_vertices) -> list[int]:
    if len(words) < 6:
        raise SceneError(f"{where}: a surface line needs '{key} n v1 v2 v3 v4 ...', got {excerpt(' '.join(words))!r}")
    n = _surface_number(words, where, model)
    refs = [_number(t, where, "a vertex reference", int) for t in words[2:6]]
    if refs[3] == 0:
        refs = refs[:3]
    for r in refs:
        if not 1 <= r <= n_vertices:
            raise SceneError(f"{where}: surface {n} uses vertex {r}, but {n_vertices} vertices are defined before it")
    _surface_data(words[6:], where, key, n, model)
    return [r - 1 for r in refs]


def _shape_surface(words, where, key, model, tokens: _Tokens) -> np.ndarray:
    """Corners (k, 3) of an ``F 3a`` surface: shape letter, data, then plane and outline."""
    if len(words) < 3:
        raise SceneError(f"{where}: a 3a surface needs '{key} n R|Q|T ...', got {excerpt(' '.join(words))!r}")
    n = _surface_number(words, where, model)
    shape = words[2].upper()
    if shape not in ("R", "Q", "T"):
        raise SceneError(f"{where}: surface {n} has shape {excerpt(words[2])!r}; F 3a shapes are R, Q and T")
    _surface_data(words[3:], where, key, n, model)
    tokens.where = where
    origin = np.array([tokens.take(f"the origin of surface {n}") for _ in range(3)])
    azimuth = math.radians(tokens.take(f"the azimuth of surface {n}"))
    tilt = math.radians(tokens.take(f"the tilt of surface {n}"))
    if shape == "R":
        width, height = (tokens.take(f"the {w} of rectangle {n}") for w in ("width", "height"))
        uv = np.array([[0.0, height], [0.0, 0.0], [width, 0.0], [width, height]])
    else:
        k = 4 if shape == "Q" else 3
        uv = np.array([[tokens.take(f"corner {c + 1} of surface {n}") for _ in range(2)] for c in range(k)])
    # The plane's axes (View3D manual, F = 3a): u horizontal, v up the slope at the tilt.
    u_axis = np.array([-math.cos(azimuth), math.sin(azimuth), 0.0])
    v_axis = np.array([-math.cos(tilt) * math.sin(azimuth), -math.cos(tilt) * math.cos(azimuth), math.sin(tilt)])
    with np.errstate(over="ignore", invalid="ignore"):
        corners = origin + uv[:, :1] * u_axis + uv[:, 1:] * v_axis
    # The shape's numbers are bounded like V lines' coordinates: beyond, areas overflow later.
    if not (np.isfinite(corners).all() and np.abs(corners).max() <= MAX_COORDINATE):
        raise SceneError(f"{where}: surface {n} has a corner beyond {MAX_COORDINATE:g} (its origin, size or "
                         "outline is too large)")
    return corners


def _check_references(model: View3DModel) -> None:
    """base and cmb point at surfaces that can take them (View3D's rules, its messages)."""
    count = len(model.surfaces)
    for k in range(count):
        n, where = k + 1, f"{model.path}:{model.line[k]}"
        base, combine = model.base[k], model.combine[k]
        if not 0 <= base <= count or base == n:
            raise SceneError(f"{where}: surface {n} has base {base}; it must be 0 or another surface's number (1..{count})")
        if base and not model.obstruction[base - 1] and base > n:
            raise SceneError(f"{where}: subsurface {n} comes before its base {base}; list a base first")
        if not 0 <= combine < n:
            raise SceneError(f"{where}: surface {n} combines with {combine}; it must be 0 or an earlier surface's number")
        if combine and (model.obstruction[combine - 1] or model.combine[combine - 1]):
            why = "an obstruction" if model.obstruction[combine - 1] else "itself combined (do not chain combinations)"
            raise SceneError(f"{where}: surface {n} combines with {combine}, which is {why}")


# A subsurface's corners may lie this far off its base's plane, relative to the subsurface's
# radius (View3D's own test, TestSubSrf: 1e-5 x radius).
SUBSURFACE_PLANE_REL = 1e-5
# A subsurface must face the way its base does: cosine between the normals at least this (View3D).
SUBSURFACE_FACING_COS = 0.999
# In-plane coordinates are snapped to this fraction of the base's size before clipping, so that
# a door on the wall's bottom edge leaves no round-off sliver along it.
SNAP_REL = 1e-9
# Pieces of a separated base smaller than this fraction of its area are round-off and dropped.
SLIVER_AREA_REL = 1e-9


@dataclass
class SeparatedModel:
    """A model as View3D's post-processing means it: subsurfaces cut out of their bases, and
    combined surfaces mapped to one output surface."""

    vertices: np.ndarray  # (v, 3) float
    faces: list[np.ndarray]  # vertex indices of each planar convex face, counter-clockwise
    face_surface: np.ndarray  # (m,) int: the model's surface (0-based) each face belongs to
    objects: list[str]  # output surfaces: every surface that is not combined into another
    surface_object: np.ndarray  # (n_surfaces,) int: output surface of each model surface
    separated_area: np.ndarray  # (n_surfaces,) m^2 left to each surface after separation
    notes: list[str] = field(default_factory=list)


def separate_and_combine(model: View3DModel) -> SeparatedModel:
    """Cut every subsurface out of its base and group combined surfaces, in View3D's order.

    View3D computes view factors for whole surfaces and then, in post-processing, *separates*
    each subsurface from its base (the base loses the subsurface's area and the view factors it
    had through it), *combines* the surfaces joined by ``cmb`` into one, and finally
    *normalises* an enclosure (``encl=1``). We do the first step geometrically: each base keeps
    only the region outside its direct subsurfaces, cut into convex pieces. The result is the
    same view-factor algebra, and the patches no longer overlap, so a radiosity solve on them
    is right too. Combining is the object map: combined surfaces are patches of one object, and
    summing F over objects (:meth:`radiosity.factors.ViewFactors.grouped`) merges them.
    Normalising is ``enforce="closure"`` (see :mod:`radiosity.enclosure`).

    Raises
    ------
    SceneError
        A subsurface not in its base's plane, facing the other way, not inside its base, or
        overlapping a sibling.
    """
    n_surfaces = len(model.surfaces)
    children: dict[int, list[int]] = {}
    for k, base in enumerate(model.base):
        if base:
            children.setdefault(base - 1, []).append(k)
    vertices = [model.vertices]
    count = len(model.vertices)
    faces: list[np.ndarray] = []
    face_surface: list[int] = []
    areas = np.zeros(n_surfaces)
    for k, refs in enumerate(model.surfaces):
        polygon = model.vertices[refs]
        if k not in children:
            faces.append(np.asarray(refs))
            face_surface.append(k)
            areas[k] = float(np.linalg.norm(vector_area(polygon)))
            continue
        pieces, areas[k] = _cut_out(model, k, children[k])
        for piece in pieces:
            vertices.append(piece)
            faces.append(np.arange(count, count + len(piece)))
            face_surface.append(k)
            count += len(piece)
    notes = [f"{model.path}:{model.line[k]}: surface {k + 1} ({model.names[k]}) is entirely covered by its "
             "subsurfaces; nothing of it is left" for k in children if areas[k] <= 0]
    objects, surface_object = [], np.zeros(n_surfaces, np.int64)
    for k in range(n_surfaces):
        if model.combine[k]:
            surface_object[k] = surface_object[model.combine[k] - 1]
        else:
            surface_object[k] = len(objects)
            objects.append(model.names[k])
    return SeparatedModel(np.concatenate(vertices), faces, np.asarray(face_surface, np.int64), objects,
                          surface_object, areas, notes)


def _cut_out(model: View3DModel, k: int, subs: list[int]) -> tuple[list[np.ndarray], float]:
    """Convex pieces (3-D corners) of surface k outside its subsurfaces, and their total area."""
    from shapely.errors import GEOSException

    try:
        return _cut_out_pieces(model, k, subs)
    except GEOSException as exc:  # a self-crossing base or subsurface the checks did not catch
        raise SceneError(f"{model.path}:{model.line[k]}: surface {k + 1} ({model.names[k]}): its subsurfaces "
                         f"cannot be cut out of it; check that it and they are simple polygons "
                         f"(GEOS: {excerpt(str(exc), 60)})") from None


def _cut_out_pieces(model: View3DModel, k: int, subs: list[int]) -> tuple[list[np.ndarray], float]:
    import shapely
    from shapely.geometry import Polygon

    from ..imprint import convex_pieces

    base = model.vertices[model.surfaces[k]]
    normal = vector_area(base)
    length = float(np.linalg.norm(normal))
    if not (math.isfinite(length) and length > 0):  # e.g. corners 1e-160 apart: the area underflows
        raise SceneError(f"{model.path}:{model.line[k]}: surface {k + 1} ({excerpt(model.names[k])}) has zero area "
                         "(or one too small for float64); its subsurfaces cannot be cut out of it")
    normal = normal / length
    origin = base[0]
    u = base[1] - base[0]
    u = u - (u @ normal) * normal
    u = u / np.linalg.norm(u)
    v = np.cross(normal, u)
    size = float(np.ptp(base, axis=0).max())
    grid = SNAP_REL * size

    def flat(points: np.ndarray):
        xy = np.column_stack([(points - origin) @ u, (points - origin) @ v])
        return shapely.set_precision(Polygon(xy), grid)

    region = flat(base)
    holes = []
    for s in subs:
        corners = model.vertices[model.surfaces[s]]
        where = f"{model.path}:{model.line[s]}"
        off = float(np.abs((corners - origin) @ normal).max())
        radius = float(np.linalg.norm(corners - corners.mean(axis=0), axis=1).max())
        if off > SUBSURFACE_PLANE_REL * radius:
            raise SceneError(f"{where}: subsurface {s + 1} ({model.names[s]}) is not in the plane of its base "
                             f"{k + 1} ({model.names[k]}): off by {off:.3g} m")
        facing = vector_area(corners)
        if facing @ normal < SUBSURFACE_FACING_COS * np.linalg.norm(facing):
            raise SceneError(f"{where}: subsurface {s + 1} ({model.names[s]}) must face the same way as its base "
                             f"{k + 1} ({model.names[k]}); list its vertices the other way round")
        hole = flat(corners)
        if not hole.is_valid:  # GEOS cannot subtract a polygon whose edges cross
            raise SceneError(f"{where}: subsurface {s + 1} ({model.names[s]}) is not a simple polygon (its edges "
                             "cross or its corners coincide); its base cannot be cut along it")
        if not region.buffer(10 * grid).covers(hole):
            raise SceneError(f"{where}: subsurface {s + 1} ({model.names[s]}) is not entirely within its base "
                             f"{k + 1} ({model.names[k]})")
        for other, earlier in holes:
            if hole.intersection(earlier).area > SLIVER_AREA_REL * region.area:
                raise SceneError(f"{where}: subsurfaces {other + 1} and {s + 1} of base {k + 1} ({model.names[k]}) "
                                 "overlap; View3D would subtract the overlap twice")
        holes.append((s, hole))
    left = region.difference(shapely.union_all([h for _, h in holes]))
    pieces = []
    for polygon in getattr(left, "geoms", [left]):
        if polygon.geom_type != "Polygon" or polygon.area <= SLIVER_AREA_REL * region.area:
            continue
        for xy in convex_pieces(polygon):
            pieces.append(origin + xy[:, :1] * u + xy[:, 1:2] * v)
    return pieces, float(sum(np.linalg.norm(vector_area(p)) for p in pieces))


def write_vs3(scene, path, *, title: str = "exported by radiosity") -> None:
    """Write a scene's patches as a View3D model: one ``S`` surface per patch, ``O`` for obstructions.

    Surface names are ``object:k``; View3D requires radiating surfaces before obstructions, so
    patches are reordered that way (the order is ``S`` patches in scene order, then ``O``).
    """
    from ._files import atomic_path

    quads = scene.patch_quads
    is_tri = (quads[:, 3] == quads[:, 2]).all(axis=1)
    obstruction = getattr(scene, "patch_obstruction", np.zeros(len(quads), bool))
    order = np.concatenate([np.flatnonzero(~obstruction), np.flatnonzero(obstruction)])
    emissivity = 1.0 - scene.reflectance.mean(axis=1)
    lines = [f"T {title}", "C eps=1.e-6 col=0 list=0", "F 3", "!  #   x   y   z"]
    vid = 0
    surface_lines = ["!  #  v1  v2  v3  v4  base  cmbn  emit  name"]
    for rank, p in enumerate(order, start=1):
        count = 3 if is_tri[p] else 4
        refs = []
        for v in quads[p, :count]:
            vid += 1
            lines.append(f"V {vid} {v[0]:.17g} {v[1]:.17g} {v[2]:.17g}")
            refs.append(vid)
        refs += [0] * (4 - count)
        name = f"{scene.objects[scene.patch_object[p]]}:{rank}".replace(" ", "_")
        if obstruction[p]:  # View3D reads no base, cmb, emit or name on an obstruction
            surface_lines.append(f"O {rank} {' '.join(map(str, refs))}")
        else:
            emit = min(EMISSIVITY_RANGE[1], max(EMISSIVITY_RANGE[0], emissivity[p]))
            surface_lines.append(f"S {rank} {' '.join(map(str, refs))} 0 0 {emit:.6g} {name}")
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines + surface_lines + ["E"]) + "\n")

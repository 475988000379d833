"""Imprinting: cut faces along the outlines of the faces that touch them, and flag covered parts.

Light changes abruptly where one object touches another: the floor is lit right up to a block's
foot and dark under it; the ceiling is dark behind a light mounted just under it. A patch that
straddles such an outline averages light and dark, and uniform refinement converges only at
first order there. Imprinting cuts every receiving face along its contact outlines first, so
later subdivision never crosses one, and flags the regions that can never exchange light as
*hidden*.

Two kinds of contact are found between faces of *different* objects (``CONTACT_REL``):

- **overlap**: a face lies in (or within the tolerance of) the receiver's plane, parallel to it
  (``CONTACT_TILT``), and overlaps it in projection: a light just under a ceiling, a picture on
  a wall, a block's bottom face on the floor. The receiver's overlapped region is hidden when
  the other face lies in front of it (on its lit side). For exactly coplanar faces facing the
  same way the smaller face covers the larger one (a picture covers the wall); facing opposite
  ways, both are covered.
- **footprint**: edges of an object's faces lie in the receiver's plane (within the tolerance
  and ``CONTACT_TILT``) and close into loops: the bottom edges of a block without a bottom face
  standing on the floor. The polygon the loops enclose is cut out; it is hidden when the
  object's faces in front of the receiver that turn their back to it (a block's top) cover it
  in projection, and none of its faces turns to it from the plane at a tilt (the cap of a
  tessellated sphere inside a ring of edges just above the floor). An open tube standing on the
  floor is cut but not hidden; open chains of edges (a single partition wall) are not cut.

Pieces are built in each receiving face's plane with shapely (clipping) and mapbox_earcut
(triangles of regions with holes), then pairs of triangles are merged into convex quads where
the union is convex, removing the longest diagonals first.
"""

from __future__ import annotations

import warnings
from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

from ._errors import RadiosityWarning
from .geometry import flat_faces, vector_area
from .patches import FaceReport, Patches, planar_parts, subdivide_faces, used_vertices

__all__ = ["Contact", "Imprinted", "imprint_faces", "subdivide_imprinted", "CONTACT_REL"]

# Distance from a face's plane, relative to the scene's bounding-box diagonal, within which
# another face or edge counts as touching it. 1e-3 of a 1 m scene is 1 mm: it catches a light
# lowered 0.5 mm under a ceiling (the Cornell box) and modelling gaps of that order, and is far
# below any gap that light can get through in a way a patch of 1/50 of the scene could resolve.
CONTACT_REL = 1e-3

# A face, or an edge, lies in a receiver's plane only if it is also parallel to it: the sine of
# the angle between them at most this (0.57 degrees). Within CONTACT_REL alone, the six bottom
# triangles of an icosphere resting on a floor (tilted 4.5 degrees, their far corners 5 mm up in a
# 4 x 3 x 2.5 m room) counted as lying on it: the floor under them was hidden, they were not,
# and they saw through the hole (-46% in a furnace room). A sphere touches at a point.
CONTACT_TILT = 1e-2

# Signed distances below this fraction of the scene's diagonal count as exactly coplanar.
COPLANAR_REL = 1e-9

# Pieces smaller than this fraction of their face's area are round-off slivers and dropped.
SLIVER_AREA_REL = 1e-9

# A cut region covered in projection up to this fraction of its area counts as covered.
COVER_AREA_REL = 1e-6

# Contact outlines with more edges than this on one face are cut along the outlines only;
# up to it, along the full lines through their edges (better-shaped pieces, O(lines^2) of them).
MAX_EXTENSION_LINES = 24

# Triangles that miss a polygon's area by more than this fraction of it are not a tiling
# (earcut skips what it cannot cut, such as a hole touching the outer ring): triangulate again.
TILE_AREA_REL = 1e-9

# Earcut triangles smaller than this fraction of their polygon are flat (collinear corners
# left by the overlays): their winding is round-off, so they are dropped.
FLAT_TRIANGLE_REL = 1e-12

# Grid (relative to the face's size) of the snap-rounded overlays used when round-off broke the
# partition of a face into cells: far below any length that matters, far above round-off.
SNAP_REL = 1e-12

# Corners of a piece closer than this fraction of its size to the line through its neighbours
# are dropped before it is cut into convex pieces: extension lines that should meet in one
# point miss each other by round-off (5e-9 m where the scene lies 1e6 m from the origin), and
# each near-duplicate corner left a sliver triangle of 1e-12 to 1e-9 m^2 (a room's floor cut
# into 138 pieces there, 127 at the origin).
SIMPLIFY_REL = 1e-8

# A merged quad is kept only if each corner turns by at least this much (sine of the angle,
# times both edge lengths): avoids quads that are triangles with a flat corner.
CONVEX_TURN_REL = 1e-6


def _geos_error() -> type[Exception]:
    """shapely's GEOS error class, imported only when an exception is being matched (shapely
    stays out of ``import radiosity``)."""
    from shapely.errors import GEOSException

    return GEOSException


@dataclass(frozen=True)
class Contact:
    """One contact region imprinted on a face."""

    face: int  # receiving face (index into the input faces)
    other_object: int  # object touching it
    kind: str  # "overlap" or "footprint"
    hidden: bool  # the region can neither receive nor send light
    outline: np.ndarray  # (k, 3) exterior ring of the region on the face, metres
    area: float  # region area on the face, m^2


@dataclass(frozen=True)
class Imprinted:
    """Faces cut along their contacts: planar pieces, each with its face and hidden flag.

    ``vertices[pieces[i]]`` is piece ``i``; faces without contacts are passed through whole
    (same vertices, same order), so subdivision treats them exactly as before.
    """

    vertices: np.ndarray  # (v, 3) float
    pieces: list[np.ndarray]  # vertex indices of each piece, counter-clockwise from the front
    piece_face: np.ndarray  # (m,) int, source face of each piece
    piece_hidden: np.ndarray  # (m,) bool
    contacts: list[Contact] = field(default_factory=list)
    nonplanar: list[tuple[int, float]] = field(default_factory=list)  # imprinted non-planar faces
    uncut: bool = False  # no face was cut: ``vertices`` and ``pieces`` are the input's vertices and faces
    # (face, face) pairs of different objects that pass through each other (:func:`_crossing_faces`),
    # lower face first; such faces are not cut along the crossing
    crossings: list[tuple[int, int]] = field(default_factory=list)


@dataclass
class _Part:
    """A planar part of a face (the face itself, or a triangle of a non-planar face)."""

    face: int
    obj: int
    poly: np.ndarray  # (k, 3)
    normal: np.ndarray  # (3,) unit
    origin: np.ndarray  # (3,)
    u: np.ndarray  # (3,) in-plane axes; (u, v, normal) is right handed
    v: np.ndarray
    area: float

    def to_2d(self, points: np.ndarray) -> np.ndarray:
        rel = points - self.origin
        return np.column_stack([rel @ self.u, rel @ self.v])

    def to_3d(self, xy: np.ndarray) -> np.ndarray:
        return self.origin + xy[:, :1] * self.u + xy[:, 1:2] * self.v


class _BoxIndex:
    """Boxes (lo, hi) that meet a query box, without testing them all.

    Boxes up to a few times the median size go in a k-d tree on their centres (a ball query
    of the query's half diagonal plus the largest of them finds every candidate); the few
    larger ones (a room's shell) are tested directly. The answer is then filtered exactly, so
    it is the same set as testing every box.
    """

    def __init__(self, lo: np.ndarray, hi: np.ndarray) -> None:
        from scipy.spatial import cKDTree

        self.lo, self.hi = lo, hi
        centre, radius = 0.5 * (lo + hi), 0.5 * np.linalg.norm(hi - lo, axis=1)
        small = radius <= 4.0 * float(np.median(radius)) if len(radius) else np.zeros(0, bool)
        self.small = np.flatnonzero(small)
        self.large = np.flatnonzero(~small)
        self.reach = float(radius[self.small].max()) if len(self.small) else 0.0
        self.tree = cKDTree(centre[self.small]) if len(self.small) else None

    def meeting(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Indices (ascending) of the boxes that meet the box (lo, hi)."""
        found = [self.large]
        if self.tree is not None:
            centre, radius = 0.5 * (lo + hi), 0.5 * float(np.linalg.norm(hi - lo))
            near = self.tree.query_ball_point(centre, radius + self.reach + 1e-12 * (1.0 + radius))
            found.append(self.small[np.asarray(near, dtype=np.int64)])
        index = np.sort(np.concatenate(found))
        meets = ~((self.hi[index] < lo).any(axis=1) | (self.lo[index] > hi).any(axis=1))
        return index[meets]


def _near_other_objects(vertices: np.ndarray, faces: list[np.ndarray], face_object: np.ndarray,
                        pad: float) -> np.ndarray:
    """(f,) bool: the faces of objects whose box, padded by ``pad``, meets another object's box.

    The others can neither receive a contact nor give one (:class:`_Candidates` looks only at
    objects whose box meets the receiver's), so they need no parts: a scene of one mesh, or
    objects standing apart, costs nothing here.
    """
    if not faces:
        return np.zeros(0, bool)
    flat, sizes = flat_faces(faces)
    if (sizes == 0).any():
        return np.ones(len(faces), bool)  # an empty face: let the parts decide, as before
    points = vertices[flat]
    starts = np.cumsum(sizes) - sizes
    lo = np.minimum.reduceat(points, starts, axis=0)
    hi = np.maximum.reduceat(points, starts, axis=0)
    objects, which = np.unique(face_object, return_inverse=True)
    which = which.reshape(-1)
    # Each object's box: faces grouped by object (ufunc.at took a second on 581k faces).
    order = np.argsort(which, kind="stable")
    first = np.searchsorted(which[order], np.arange(len(objects)))
    obj_lo = np.minimum.reduceat(lo[order], first, axis=0)
    obj_hi = np.maximum.reduceat(hi[order], first, axis=0)
    index = _BoxIndex(obj_lo, obj_hi)
    near = np.array([len(index.meeting(obj_lo[k] - pad, obj_hi[k] + pad)) > 1 for k in range(len(objects))],
                    dtype=bool)  # itself and another
    return near[which]


def _make_parts(vertices: np.ndarray, faces: list[np.ndarray], face_object: np.ndarray,
                active: np.ndarray | None = None) -> tuple[list[_Part], list[float]]:
    parts: list[_Part] = []
    deviations = [0.0] * len(faces)
    for index in (range(len(faces)) if active is None else np.flatnonzero(active).tolist()):
        face = faces[index]
        poly = vertices[face]
        size = float(np.ptp(poly, axis=0).max()) if len(poly) else 0.0
        newell = vector_area(poly)
        area = float(np.linalg.norm(newell))
        if not area > 1e-12 * size**2:
            continue  # degenerate: subdivision reports it
        pieces, deviation = planar_parts(poly, size)
        deviations[index] = deviation
        for piece in pieces:
            normal = vector_area(piece)
            area = float(np.linalg.norm(normal))
            if not area > 1e-12 * size**2:
                continue
            normal = normal / area
            u = piece[1] - piece[0]
            u = u - (u @ normal) * normal
            u = u / np.linalg.norm(u)
            parts.append(_Part(index, int(face_object[index]), piece, normal, piece[0].copy(), u,
                               np.cross(normal, u), area))
    return parts, deviations


def _polygon(xy: np.ndarray):
    import shapely

    poly = shapely.Polygon(xy)
    if not poly.is_valid:
        poly = shapely.make_valid(poly)
    return poly


def _polygons(geometry) -> list:
    """The polygons of any shapely geometry (collections and lines are flattened or dropped)."""
    import shapely

    out = []
    for part in shapely.get_parts(geometry):
        if isinstance(part, shapely.Polygon):
            out.append(part)
        elif isinstance(part, (shapely.MultiPolygon, shapely.GeometryCollection)):
            out.extend(_polygons(part))
    return out


def _chains(geometry) -> list:
    """The rings of any shapely geometry's polygons and its line strings (contact outlines and cuts)."""
    import shapely

    out = []
    for part in shapely.get_parts(geometry):
        if isinstance(part, shapely.Polygon):
            out.extend([part.exterior, *part.interiors])
        elif isinstance(part, shapely.LineString):
            out.append(part)
        elif isinstance(part, (shapely.MultiPolygon, shapely.MultiLineString, shapely.GeometryCollection)):
            out.extend(_chains(part))
    return out


def _snap(points: np.ndarray, tol: float) -> np.ndarray:
    """Merge 2-D points closer than ``tol`` to the first of their cluster (few points)."""
    out = points.copy()
    for i in range(len(out)):
        close = np.linalg.norm(out[:i] - out[i], axis=1) <= tol
        if close.any():
            out[i] = out[:i][close][0]
    return out


def _footprint(segments: list[np.ndarray], tol: float):
    """Union of the polygons that 2-D segments (s, 2, 2) close into, or None."""
    import shapely
    from shapely.ops import polygonize

    ends = _snap(np.concatenate(segments).reshape(-1, 2), tol).reshape(-1, 2, 2)
    lines = [shapely.LineString(s) for s in ends if np.linalg.norm(s[1] - s[0]) > tol]
    if len(lines) < 3:
        return None
    polys = list(polygonize(shapely.unary_union(lines)))
    if not polys:
        return None
    return shapely.unary_union(polys)


class _Candidates:
    """Which parts can touch a receiver, found without looking at all pairs.

    A contact region of ``other`` on the receiver is either an overlap (``other``'s own box
    meets the receiver's) or a footprint: a polygon closed by ``other``'s object's edges in the
    receiver's plane, which may enclose the receiver without any of those edges meeting its box
    (a tile under a bottomless block). Both lie inside the bounding box of ``other``'s object.
    So the candidates are all parts of the objects whose box, padded by the tolerance, meets
    the receiver's padded box, and of those only the parts whose box reaches the receiver's
    plane (within the tolerance), less those lying flat in it whose own box misses the
    receiver's (overlaps are only counted where boxes meet): a superset of the parts that ``_regions_of`` would keep from
    all pairs, in the same order, so the regions are the same.
    """

    def __init__(self, parts: list[_Part], tol: float) -> None:
        self.pad = 2.0 * tol  # twice: the projections onto the plane move points by up to tol
        obj = np.array([p.obj for p in parts], dtype=np.int64)
        self.lo = np.array([p.poly.min(axis=0) for p in parts]).reshape(-1, 3)
        self.hi = np.array([p.poly.max(axis=0) for p in parts]).reshape(-1, 3)
        self.objects, first = np.unique(obj, return_inverse=True)
        order = np.argsort(first, kind="stable")  # parts of each object, in part order
        counts = np.bincount(first, minlength=len(self.objects))
        self.members = np.split(order, np.cumsum(counts)[:-1])
        self.obj_lo = np.array([self.lo[m].min(axis=0) for m in self.members]).reshape(-1, 3)
        self.obj_hi = np.array([self.hi[m].max(axis=0) for m in self.members]).reshape(-1, 3)
        self.index = _BoxIndex(self.obj_lo, self.obj_hi)

    def of(self, receiver: _Part) -> tuple[np.ndarray, np.ndarray]:
        """Indices (ascending) of the parts of the other objects near ``receiver``, and of those
        that reach its plane (the first set is what may cover a footprint: a block's top)."""
        box_lo = receiver.poly.min(axis=0) - self.pad
        box_hi = receiver.poly.max(axis=0) + self.pad
        meets = self.index.meeting(box_lo, box_hi)
        meets = meets[self.objects[meets] != receiver.obj]
        if not len(meets):
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        index = np.concatenate([self.members[k] for k in meets])
        index.sort()
        # the range of n . x over each part's box: does it reach the receiver's plane?
        n = receiver.normal
        centre = 0.5 * (self.lo[index] + self.hi[index]) - receiver.origin
        half = 0.5 * (self.hi[index] - self.lo[index])
        mid = centre @ n
        reach = half @ np.abs(n)
        reaching = np.abs(mid) <= reach + self.pad
        # Parts lying well inside the plane's tolerance are overlaps, which count only where
        # their own box meets the receiver's (a floor's far tiles under a box's bottom face).
        flat = np.abs(mid) + reach <= 0.25 * self.pad
        apart = (self.hi[index] < box_lo).any(axis=1) | (self.lo[index] > box_hi).any(axis=1)
        return index, index[reaching & ~(flat & apart)]


def _local(receiver: _Part, parts: list[_Part], candidates: _Candidates | None):
    """The parts to test against ``receiver``, their points and point owners, and the parts
    that may cover a footprint on it."""
    if candidates is None:
        chosen = covers = parts
    else:
        near, reaching = candidates.of(receiver)
        chosen = [parts[i] for i in reaching]
        covers = [parts[i] for i in near]
    if not chosen:
        return chosen, np.zeros((0, 3)), np.zeros(0, np.int64), covers
    points = np.concatenate([p.poly for p in chosen])
    owner = np.repeat(np.arange(len(chosen)), [len(p.poly) for p in chosen])
    return chosen, points, owner, covers


def _regions_of(receiver: _Part, parts: list[_Part], part_points: np.ndarray, part_of_point: np.ndarray,
                scale: float, cover_parts: list[_Part] | None = None) -> list[tuple[object, bool, str, int]]:
    """Contact regions (shapely geometry in the receiver's frame, hidden, kind, object).

    ``parts`` may be any subset of the parts that holds every part able to touch the receiver,
    and ``cover_parts`` (default: ``parts``) any that holds every part able to cover a footprint
    on it (:class:`_Candidates`), in their original order: the result does not depend on the others.
    """
    tol = CONTACT_REL * scale
    exact = COPLANAR_REL * scale
    dist = (part_points - receiver.origin) @ receiver.normal
    lo = np.full(len(parts), np.inf)
    hi = np.full(len(parts), -np.inf)
    np.minimum.at(lo, part_of_point, dist)
    np.maximum.at(hi, part_of_point, dist)
    near = np.zeros(len(parts), bool)
    np.logical_or.at(near, part_of_point, np.abs(dist) <= tol)
    box_lo, box_hi = receiver.poly.min(axis=0) - tol, receiver.poly.max(axis=0) + tol
    shape = _polygon(receiver.to_2d(receiver.poly))
    regions = []
    segments: dict[int, list[np.ndarray]] = defaultdict(list)
    for index in np.flatnonzero(near):
        other = parts[index]
        if other.obj == receiver.obj:
            continue
        in_plane = lo[index] >= -tol and hi[index] <= tol
        if in_plane and np.linalg.norm(np.cross(other.normal, receiver.normal)) <= CONTACT_TILT:  # overlap
            if (other.poly.max(axis=0) < box_lo).any() or (other.poly.min(axis=0) > box_hi).any():
                continue
            region = shape.intersection(_polygon(receiver.to_2d(other.poly)))
            if region.area <= SLIVER_AREA_REL * shape.area:
                continue
            height = 0.5 * (lo[index] + hi[index])
            if height < -exact:
                continue  # behind the receiver: its lit side is untouched
            facing = float(other.normal @ receiver.normal)
            if height > exact or facing < 0:
                hidden = True
            else:  # exactly coplanar, facing the same way: the smaller face lies on top
                hidden = (other.area, other.face) < (receiver.area, receiver.face)
            if hidden:  # a face under the receiver changes nothing on its lit side
                regions.append((region, hidden, "overlap", other.obj))
            continue
        d = dist[part_of_point == index]
        on = np.abs(d) <= tol
        length = np.linalg.norm(np.roll(other.poly, -1, axis=0) - other.poly, axis=1)
        both = on & np.roll(on, -1) & (np.abs(np.roll(d, -1) - d) <= CONTACT_TILT * length + exact)
        if both.any():
            xy = receiver.to_2d(other.poly)
            starts = np.flatnonzero(both)
            segments[other.obj].extend(np.stack([xy[starts], xy[(starts + 1) % len(xy)]], axis=1))
    for obj, segs in segments.items():
        regions.extend(_footprint_regions(segs, shape, receiver, parts if cover_parts is None else cover_parts, obj,
                                          tol))
    return regions


def _footprint_regions(segments: list[np.ndarray], shape, receiver: _Part, parts: list[_Part], obj: int,
                       tol: float) -> list[tuple[object, bool, str, int]]:
    """Contact regions of one object's edges lying in the receiver's plane (2-D segments).

    Edges that close into loops enclose a footprint (a bottomless block). Edges that do not (a
    partition standing on the floor, a cabinet open at the back against two walls) still cut the
    receiver along their lines (kind ``"line"``): light jumps across a partition's foot, and a
    patch straddling it averaged both sides (a floor patch's factor to the wall beside it 3.6e-4
    off). Where such edges and the receiver's boundary enclose a part that the object covers (the
    cabinet's corner of the floor), that part is a footprint too.
    """
    import shapely

    out = []
    minimum = SLIVER_AREA_REL * shape.area
    foot = _footprint(segments, tol)
    if foot is not None:
        region = shape.intersection(foot)
        if region.area > minimum:
            out.append((region, _is_covered(region, receiver, parts, obj, tol), "footprint", obj))
    edges = [shapely.LineString(e) for e in segments if np.linalg.norm(e[1] - e[0]) > tol]
    rim = None if foot is None else foot.boundary.buffer(tol)
    # an edge along the receiver's own boundary (a wall's foot on the floor's rim) cuts nothing
    inside = shape.buffer(-tol)
    loose = [e for e in edges if (rim is None or not rim.contains(e)) and e.intersection(inside).length > tol]
    if not loose:
        return out
    lines = shapely.unary_union(loose)
    out.append((lines, False, "line", obj))
    cells = _arrangement_cells(shape, [lines], minimum)
    if len(cells) > 1:
        for cell in cells:
            if (foot is None or cell.intersection(foot).area <= minimum) and _is_covered(cell, receiver, parts, obj,
                                                                                           tol):
                out.append((cell, True, "footprint", obj))
    return out


def _arrangement_cells(shape, lines: list, minimum: float) -> list:
    """The cells into which ``lines`` (shapely lines) cut the polygon ``shape``, larger than
    ``minimum`` (slivers of round-off dropped)."""
    import shapely
    from shapely.ops import polygonize

    return [c for c in polygonize(shapely.unary_union([shape.exterior, *lines]))
            if c.area > minimum and shape.contains(c.representative_point())]


def _is_covered(region, receiver: _Part, parts: list[_Part], obj: int, tol: float) -> bool:
    """Whether ``obj``'s faces in front of the receiver, backs towards it, cover ``region``, and
    none of its faces opens onto it.

    A face that turns to the receiver, rises from within ``tol`` of its plane at a tilt (not an
    overlap) and overlaps the region in projection opens the pocket: the bottom cap of a finely
    tessellated sphere resting on a floor, inside a ring of edges 0.3 mm up. The cap sees the
    floor under it, so that floor is not hidden.
    """
    import shapely

    covers = []
    for part in parts:
        if part.obj != obj:
            continue
        facing = float(part.normal @ receiver.normal)
        height = (part.poly - receiver.origin) @ receiver.normal
        if _opens_onto(part, facing, height, region, receiver, tol):
            return False
        if facing <= 1e-9:
            continue
        # behind the receiver, or in its plane (an overlap, decided as one: a ceiling just above
        # a lamp mounted under it is not a block's top over the lamp)
        if height.min() < -tol or height.max() <= tol:
            continue
        covers.append(_polygon(receiver.to_2d(part.poly)))
    if not covers:
        return False
    left = region.difference(shapely.unary_union(covers))
    return left.area <= COVER_AREA_REL * region.area


def _opens_onto(part: _Part, facing: float, height: np.ndarray, region, receiver: _Part, tol: float) -> bool:
    """Whether ``part`` turns to the receiver from within ``tol`` of its plane, tilted, over ``region``."""
    tilted = np.sqrt(max(0.0, 1.0 - facing * facing)) > CONTACT_TILT
    if facing >= -1e-9 or not tilted or height.min() < -tol or height.min() > tol:
        return False
    return region.intersection(_polygon(receiver.to_2d(part.poly))).area > COVER_AREA_REL * region.area


def _turns_ok(poly: np.ndarray) -> bool:
    edges = np.roll(poly, -1, axis=0) - poly
    nxt = np.roll(edges, -1, axis=0)
    cross = edges[:, 0] * nxt[:, 1] - edges[:, 1] * nxt[:, 0]
    lengths = np.linalg.norm(edges, axis=1) * np.linalg.norm(nxt, axis=1)
    return bool((cross > CONVEX_TURN_REL * lengths).all())


def convex_pieces(polygon) -> list[np.ndarray]:
    """Convex pieces (triangles and quads, counter-clockwise, (k, 2)) of a shapely polygon.

    A convex polygon of at most four corners is kept whole; anything else (more corners,
    non-convex, holes) is triangulated with earcut, and then neighbouring triangles are merged
    into convex quads, longest shared edge first (that removes the sliver-making diagonals).
    """
    import mapbox_earcut
    import shapely
    from shapely.geometry.polygon import orient

    if polygon.is_empty or polygon.area <= 0:
        return []
    x0, y0, x1, y1 = polygon.bounds
    polygon = orient(shapely.simplify(polygon, SIMPLIFY_REL * float(np.hypot(x1 - x0, y1 - y0))), 1.0)
    if polygon.is_empty or polygon.area <= 0:
        return []
    exterior = np.asarray(polygon.exterior.coords)[:-1]
    if not polygon.interiors and len(exterior) <= 4 and _turns_ok(exterior):
        return [exterior]
    rings = [exterior] + [np.asarray(r.coords)[:-1] for r in polygon.interiors]
    points = np.concatenate(rings)
    ends = np.cumsum([len(r) for r in rings]).astype(np.uint32)
    tris = np.asarray(mapbox_earcut.triangulate_float64(points, ends), dtype=np.int64).reshape(-1, 3)
    a, b, c = points[tris[:, 0]], points[tris[:, 1]], points[tris[:, 2]]
    signed = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    if abs(0.5 * np.abs(signed).sum() - polygon.area) > TILE_AREA_REL * polygon.area:
        return _delaunay_pieces(polygon)  # earcut gave up on part of it (a hole touching the rim)
    keep = 0.5 * np.abs(signed) > FLAT_TRIANGLE_REL * polygon.area  # no round-off needles
    tris = np.where((signed < 0)[:, None], tris[:, ::-1], tris)[keep]
    owner: dict[tuple[int, int], int] = {}
    for t, tri in enumerate(tris):
        for k in range(3):
            owner[(int(tri[k]), int(tri[(k + 1) % 3]))] = t
    shared = []
    for (i, j), t in owner.items():
        s = owner.get((j, i))
        if s is not None and t < s:
            shared.append((float(np.linalg.norm(points[i] - points[j])), i, j, t, s))
    shared.sort(reverse=True)
    used = np.zeros(len(tris), bool)
    out = []
    for _, i, j, t, s in shared:
        if used[t] or used[s]:
            continue
        c_t = next(int(x) for x in tris[t] if x not in (i, j))
        c_s = next(int(x) for x in tris[s] if x not in (i, j))
        quad = points[[i, c_s, j, c_t]]  # t holds i -> j, s holds j -> i
        if _turns_ok(quad):
            used[t] = used[s] = True
            out.append(quad)
    out.extend(points[tri] for tri, u in zip(tris, used) if not u)
    return out


def _delaunay_pieces(polygon) -> list[np.ndarray]:
    """Counter-clockwise triangles of a polygon by constrained Delaunay (earcut's fallback)."""
    import shapely

    out = []
    for tri in _polygons(shapely.constrained_delaunay_triangles(polygon)):
        xy = np.asarray(tri.exterior.coords)[:-1]
        a, b, c = xy
        signed = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        if 0.5 * abs(signed) > FLAT_TRIANGLE_REL * polygon.area:
            out.append(xy if signed > 0 else xy[::-1].copy())
    return out


def imprint_faces(vertices: np.ndarray, faces: list[np.ndarray], face_object: np.ndarray, *,
                  scale: float | None = None, _all_pairs: bool = False) -> Imprinted:
    """Cut faces along the outlines of other objects' faces that touch them.

    Parameters
    ----------
    vertices : (v, 3) float
        Metres.
    faces : list of (k,) int
        Vertex indices of each face, counter-clockwise seen from the front.
    face_object : (f,) int
        Object of each face; only faces of different objects imprint each other.
    scale : float, optional
        Length the contact tolerance is relative to (``CONTACT_REL``); default: the diagonal of
        the vertices' bounding box.
    _all_pairs : bool
        Test every part against every other (the old quadratic search), for tests and benches:
        the default finds candidates by bounding boxes (:class:`_Candidates`), same result.

    Returns
    -------
    Imprinted
        Planar pieces with their face and hidden flag; faces without contacts pass whole.

    Examples
    --------
    >>> import numpy as np
    >>> floor = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]], float)
    >>> lid = np.array([[0.5, 0.5, 0], [1.5, 0.5, 0], [1.5, 1.5, 0], [0.5, 1.5, 0]], float)
    >>> cut = imprint_faces(np.concatenate([floor, lid]), [np.arange(4), np.arange(4, 8)], np.array([0, 1]))
    >>> int(cut.piece_hidden.sum()), [c.kind for c in cut.contacts]
    (1, ['overlap'])
    """
    vertices = np.asarray(vertices, dtype=float)
    face_object = np.asarray(face_object)
    if scale is None:
        used = vertices[used_vertices(faces, len(vertices))] if faces else vertices
        scale = float(np.linalg.norm(np.ptp(used, axis=0))) if len(used) else 1.0
    active = np.ones(len(faces), bool) if _all_pairs else _near_other_objects(vertices, faces, face_object,
                                                                              2.0 * CONTACT_REL * scale)
    parts, deviations = _make_parts(vertices, faces, face_object, active)
    candidates = None if _all_pairs or not parts else _Candidates(parts, CONTACT_REL * scale)
    by_face: dict[int, list[tuple[_Part, list]]] = defaultdict(list)
    contacts: list[Contact] = []
    failed: set[int] = set()
    crossings: set[tuple[int, int]] = set()
    for part in parts:
        try:
            local, part_points, part_of_point, covers = _local(part, parts, candidates)
            regions = _regions_of(part, local, part_points, part_of_point, scale, covers) if local else []
            crossings.update((min(part.face, f), max(part.face, f))
                             for f in _crossing_faces(part, local, part_points, part_of_point, CONTACT_REL * scale))
        except _geos_error():  # a degenerate contact GEOS cannot overlay: leave the face uncut
            regions = []
            failed.add(part.face)
        by_face[part.face].append((part, regions))
        for region, hidden, kind, obj in regions:
            for poly in _polygons(region):
                ring = np.asarray(poly.exterior.coords)[:-1]
                contacts.append(Contact(part.face, obj, kind, hidden, part.to_3d(ring), float(poly.area)))

    out_vertices: list[np.ndarray] = []
    pieces: list[np.ndarray] = []
    piece_face: list[int] = []
    piece_hidden: list[bool] = []
    nonplanar: list[tuple[int, float]] = []
    n_points = 0

    def emit(poly3: np.ndarray, face: int, hidden: bool) -> None:
        nonlocal n_points
        out_vertices.append(poly3)
        pieces.append(np.arange(n_points, n_points + len(poly3)))
        n_points += len(poly3)
        piece_face.append(face)
        piece_hidden.append(hidden)

    def emit_whole(first: int, stop: int) -> None:
        """Faces first..stop-1, uncut, at once: a per-face loop cost seconds on 10^5 faces."""
        nonlocal n_points
        if stop <= first:
            return
        run = faces[first:stop]
        ends = np.cumsum([len(face) for face in run])
        out_vertices.append(vertices[np.concatenate(run)])
        numbers = np.arange(n_points, n_points + int(ends[-1]))
        starts = np.concatenate([[0], ends[:-1]])
        pieces.extend(numbers[a:b] for a, b in zip(starts.tolist(), ends.tolist()))
        n_points += int(ends[-1])
        piece_face.extend(range(first, stop))
        piece_hidden.extend([False] * (stop - first))

    cut_faces = sorted(index for index, entries in by_face.items() if any(regions for _, regions in entries))
    done = 0
    for index in cut_faces:
        emit_whole(done, index)
        done = index + 1
        entries = by_face[index]
        if deviations[index]:
            nonplanar.append((index, deviations[index]))
        for part, regions in entries:
            made: list[tuple] = []
            try:
                _emit_part(part, regions, lambda *piece: made.append(piece), CONTACT_REL * scale)
            except _geos_error():
                made = [(part.poly, part.face, False)]
                failed.add(part.face)
            for piece in made:
                emit(*piece)
    if failed:
        faces_text = ", ".join(str(f + 1) for f in sorted(failed)[:5]) + (" ..." if len(failed) > 5 else "")
        warnings.warn(f"imprint: GEOS could not cut {len(failed)} face(s) along their contacts ({faces_text}); "
                      "left uncut", RadiosityWarning, stacklevel=2)
    crossed = sorted(crossings)
    if not cut_faces:  # nothing cut: the faces are the pieces (a per-face copy took seconds on 581k faces)
        return Imprinted(vertices, faces, np.arange(len(faces), dtype=np.int64), np.zeros(len(faces), bool),
                         contacts, [], uncut=True, crossings=crossed)
    emit_whole(done, len(faces))
    verts = np.concatenate(out_vertices) if out_vertices else np.zeros((0, 3))
    return Imprinted(verts, pieces, np.asarray(piece_face, np.int64), np.asarray(piece_hidden, bool),
                     contacts, nonplanar, crossings=crossed)


def _crossing_faces(receiver: _Part, parts: list[_Part], points: np.ndarray, owner: np.ndarray, tol: float
                    ) -> list[int]:
    """Faces of other objects among ``parts`` that pass through the receiver: vertices farther
    than the contact tolerance ``tol`` on both sides of its plane, and the line where they meet
    the plane running more than ``tol`` through its inside. Imprinting cuts along contacts only;
    a box sunk 5 cm into a floor (9 contact tolerances) is not cut where it enters, so the
    patches straddling the crossing average the light of both sides (its floor neighbours read
    2.3% low in a furnace room). ``points``, ``owner``: the parts' vertices and the part of each
    (:func:`_local`)."""
    import shapely

    if not len(points):
        return []
    height = (points - receiver.origin) @ receiver.normal
    high = np.full(len(parts), -np.inf)
    low = np.full(len(parts), np.inf)
    np.maximum.at(high, owner, height)
    np.minimum.at(low, owner, height)
    out = []
    shape = None
    for k in np.flatnonzero((high > tol) & (low < -tol)):
        q = parts[k]
        if q.obj == receiver.obj:
            continue
        h = height[owner == k]
        nxt = np.roll(np.arange(len(h)), -1)
        cut = (h * h[nxt]) < 0
        on = q.poly[cut] + (h[cut] / (h[cut] - h[nxt][cut]))[:, None] * (q.poly[nxt][cut] - q.poly[cut])
        meet = np.concatenate([on, q.poly[np.abs(h) <= 0.0]])
        if len(meet) < 2:
            continue
        # the receiver shrunk by the tolerance: a face standing on it along an edge only touches
        shape = _polygon(receiver.to_2d(receiver.poly)).buffer(-tol) if shape is None else shape
        line = shapely.LineString(receiver.to_2d(meet[np.lexsort(receiver.to_2d(meet).T)]))
        if shapely.intersection(line, shape).length > tol:
            out.append(q.face)
    return out


def _extension_lines(regions, shape, tol: float) -> list:
    """Lines through every edge of the contact regions, reaching past the receiving shape.

    The lines are not clipped to the shape: a clipped line's end is computed on the boundary
    only to round-off, and an end a hair inside it is a dangle that ``polygonize`` drops, which
    merged the cells on either side of it (a contact's cell then took its neighbours with it
    when hidden cells were removed). Lines crossing the boundary are always noded with it.
    """
    import shapely

    seen: list[tuple[float, float, float]] = []
    lines = []
    x0, y0, x1, y1 = shape.bounds
    reach = 2.0 * float(np.hypot(x1 - x0, y1 - y0)) + 1.0 * tol
    for region in regions:
        for chain in _chains(region):
            xy = np.asarray(chain.coords)
            for p, q in zip(xy[:-1], xy[1:]):
                d = q - p
                length = float(np.hypot(*d))
                if length <= tol:
                    continue
                d = d / length
                normal = np.array([-d[1], d[0]])
                offset = float(normal @ p)
                if normal[0] < -1e-12 or (abs(normal[0]) <= 1e-12 and normal[1] < 0):
                    normal, offset = -normal, -offset
                key = (float(normal[0]), float(normal[1]), offset)
                if any(abs(key[0] - k[0]) + abs(key[1] - k[1]) < 1e-9 and abs(key[2] - k[2]) <= tol
                       for k in seen):
                    continue
                seen.append(key)
                line = shapely.LineString([p - reach * d, q + reach * d])
                if line.intersects(shape):
                    lines.append(line)
    return lines


def _emit_part(part: _Part, regions, emit, tol: float) -> None:
    import shapely

    shape = _polygon(part.to_2d(part.poly))
    if shape.geom_type != "Polygon":
        # A self-touching or self-intersecting face is not a simple polygon: leave it uncut
        # (subdivision triangulates it as it stands) rather than imprint a guess.
        emit(part.poly, part.face, False)
        return
    minimum = SLIVER_AREA_REL * shape.area
    cuts = [region for region, _, kind, _ in regions if kind == "line"]
    clipped = [(region.intersection(shape), hidden) for region, hidden, kind, _ in regions if kind != "line"]
    clipped = [(r, h) for r, h in clipped if not r.is_empty and r.area > minimum]
    hidden_union = shapely.unary_union([r for r, h in clipped if h]) if any(h for _, h in clipped) else None
    if len(clipped) == 1 and abs(clipped[0][0].area - shape.area) <= minimum:
        emit(part.poly, part.face, clipped[0][1])  # the contact covers the whole part: no cut
        return
    if not clipped and not cuts:
        emit(part.poly, part.face, False)
        return
    # Cut along the full lines through the contact edges: in a convex face every cell of that
    # arrangement is convex and lies on one side of every outline, and most cells are
    # parallelograms or trapezoids, which subdivide into well-shaped patches.
    lines = _extension_lines([r for r, _ in clipped] + cuts, shape, tol)
    if len(lines) <= MAX_EXTENSION_LINES:
        cells = _arrangement_cells(shape, lines, minimum)
    else:  # too many outlines: cut along the outlines only
        cells = []
        taken = shapely.Polygon()
        for region, _ in clipped:
            cells.extend(_polygons(region.difference(taken)))
            taken = taken.union(region)
        cells.extend(_polygons(shape.difference(taken)))
    if hidden_union is not None:  # hidden regions stay whole: their patches never enter the solve
        for poly in _polygons(hidden_union):
            for xy in convex_pieces(poly):
                emit(part.to_3d(xy), part.face, True)
    for cell in _visible_cells(shape, cells, hidden_union, minimum):
        for xy in convex_pieces(cell):
            emit(part.to_3d(xy), part.face, False)


def _visible_cells(shape, cells: list, hidden_union, minimum: float) -> list:
    """The cells outside the hidden regions, made to tile ``shape - hidden`` exactly.

    Cells lie on one side of every outline, so a cell is hidden when an interior point of it
    is. That partition is checked by area: when round-off in the arrangement leaves a cell
    straddling a hidden region, or part of the face in no cell, the cells are clipped to the
    visible face and completed by what they miss, with snap-rounding overlays (``grid_size``),
    which GEOS computes robustly; its plain overlays can misreport near-coincident vertices
    (an intersection that returns a whole neighbour it only touches).
    """
    if hidden_union is None:
        out, hidden_area = list(cells), 0.0
    else:
        out = [c for c in cells if not hidden_union.contains(c.representative_point())]
        hidden_area = hidden_union.area
    if abs(sum(c.area for c in out) + hidden_area - shape.area) <= minimum:
        return out
    return _tile_visible(shape, cells, hidden_union, minimum)


def _tile_visible(shape, cells: list, hidden_union, minimum: float) -> list:
    """Visible pieces of the cells plus what they miss, by snap-rounded overlays."""
    import shapely

    x0, y0, x1, y1 = shape.bounds
    grid = SNAP_REL * float(np.hypot(x1 - x0, y1 - y0))
    visible = shape if hidden_union is None else shapely.difference(shape, hidden_union, grid_size=grid)
    out = []
    for cell in cells:
        out.extend(p for p in _polygons(shapely.intersection(cell, visible, grid_size=grid)) if p.area > minimum)
    covered = shapely.union_all(out, grid_size=grid) if out else shapely.Polygon()
    out.extend(p for p in _polygons(shapely.difference(visible, covered, grid_size=grid)) if p.area > minimum)
    return out


def subdivide_imprinted(vertices: np.ndarray, faces: list[np.ndarray], face_object: np.ndarray,
                        max_patch_size: float | None, *, scale: float | None = None
                        ) -> tuple[Patches, FaceReport, Imprinted]:
    """Imprint contacts (:func:`imprint_faces`), then subdivide the pieces.

    Returns patches whose ``patch_face`` are the input faces and whose ``patch_hidden`` follow
    the pieces, the face report in input-face indices, and the imprint itself.
    """
    cut = imprint_faces(vertices, faces, face_object, scale=scale)
    patches, report = subdivide_faces(cut.vertices, cut.pieces, max_patch_size)
    piece = patches.patch_face
    nonplanar = sorted({(int(cut.piece_face[i]), d) for i, d in report.nonplanar} | set(cut.nonplanar))
    present = np.zeros(len(faces), bool)  # a mask, not a set of every patch's face
    present[cut.piece_face[piece]] = True
    degenerate = sorted({int(cut.piece_face[i]) for i in report.degenerate if not present[cut.piece_face[i]]})
    face_report = FaceReport(degenerate, nonplanar)
    return (Patches(patches.quads, cut.piece_face[piece], cut.piece_hidden[piece]), face_report, cut)

"""Patches: faces cut into planar convex triangles and quads no longer than a given size.

A patch is stored as four vertices, ``(n, 4, 3)``; a triangle repeats its third vertex, so the
kernels handle both shapes without masks. ``patch_face`` maps every patch to the face it was cut
from (trimesh's ``return_index`` idea), which in turn maps to its object and material.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import _tol
from ._ngon import GRADED_MIN_CORNERS, graded_pieces
from ._patches_bulk import DEGENERATE, WHOLE, whole_faces
from .geometry import centroids_and_areas, flat_faces, triangulate, vector_area

__all__ = ["Patches", "subdivide_faces"]


@dataclass(frozen=True)
class Patches:
    """Struct of arrays for n patches."""

    quads: np.ndarray  # (n, 4, 3) float, triangles repeat the third vertex
    patch_face: np.ndarray  # (n,) int, index of the source face
    # (n,) bool: covered by another object (imprint.py); never receives or sends light.
    patch_hidden: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

    def __post_init__(self):
        if len(self.patch_hidden) != len(self.quads):
            object.__setattr__(self, "patch_hidden", np.zeros(len(self.quads), bool))

    @property
    def n_patches(self) -> int:
        return len(self.quads)


@dataclass
class FaceReport:
    """What subdivision did to faces that were not usable as they stand."""

    degenerate: list[int]  # face indices dropped for zero area
    nonplanar: list[tuple[int, float]]  # (face index, deviation in metres), split into triangles


def _is_convex(poly: np.ndarray, normal: np.ndarray) -> bool:
    edges = np.roll(poly, -1, axis=0) - poly
    turns = np.cross(edges, np.roll(edges, -1, axis=0)) @ normal
    return bool((turns > 0).all())


def _split_triangle(tri: np.ndarray, max_size: float | None) -> np.ndarray:
    """Cells of a triangle no longer than ``max_size``, as few as the candidate splits allow.

    Candidates:

    1. Strips: for each vertex ``c``, the bilinear grid of the quad ``(a, b, c, c)`` collapsed
       at ``c``, ``ku`` columns along the opposite edge ``ab`` and ``kv`` rows towards ``c``.
       Every cell is a trapezoid (rows are parallel to ``ab``) or, next to ``c``, a triangle;
       row edges are at most ``|ab| / ku``, the others at most ``max(|ca|, |cb|) / kv``.
    2. The two right triangles on either side of the altitude onto the longest edge, each cut
       into strips along the altitude: an obtuse sliver becomes about ``length / size`` cells
       instead of ``k**2`` smaller slivers.
    3. Three quads through the centroid and the edge midpoints, each on its bilinear grid.

    The split with the fewest cells wins (ties: the earlier). Same winding; a triangle that
    needs no cut is returned as it is.
    """
    if max_size is None or _strips(tri, max_size)[0] == 1:
        return np.concatenate([tri, tri[2:3]])[None]
    candidates = [(_strips(tri, max_size)[0], lambda: _strips(tri, max_size)[1]())]
    lengths = np.linalg.norm(np.roll(tri, -1, axis=0) - tri, axis=1)  # tri[i] -> tri[i + 1]
    i = int(np.argmax(lengths))
    a, b, c = tri[i], tri[(i + 1) % 3], tri[(i + 2) % 3]
    t = float((c - a) @ (b - a) / (lengths[i] ** 2))
    if 0.0 < t < 1.0:
        foot = a + t * (b - a)
        halves = (np.stack([a, foot, c]), np.stack([foot, b, c]))
        parts = [_strips(h, max_size) for h in halves]
        candidates.append((sum(n for n, _ in parts), lambda: np.concatenate([make() for _, make in parts])))
    centre = tri.mean(axis=0)
    mids = 0.5 * (tri + np.roll(tri, -1, axis=0))  # mids[k] between tri[k] and tri[k + 1]
    quads = [np.stack([tri[k], mids[k], centre, mids[k - 1]]) for k in range(3)]
    cuts = [_quad_cuts(q, max_size) for q in quads]
    candidates.append((sum(ku * kv for ku, kv in cuts),
                       lambda: np.concatenate([_split_quad(q, ku, kv) for q, (ku, kv) in zip(quads, cuts)])))
    best = min(range(len(candidates)), key=lambda k: candidates[k][0])
    return candidates[best][1]()


def _strips(tri: np.ndarray, max_size: float):
    """(cell count, maker) of the best collapsed-quad strip split of a triangle (candidate 1)."""
    best = None
    for first in range(3):
        a, b, c = tri[first], tri[(first + 1) % 3], tri[(first + 2) % 3]
        ku = _cuts(float(np.linalg.norm(b - a)), max_size)
        kv = _cuts(max(float(np.linalg.norm(c - a)), float(np.linalg.norm(c - b))), max_size)
        if best is None or ku * kv < best[0]:
            best = (ku * kv, a, b, c, ku, kv)
    count, a, b, c, ku, kv = best

    def make() -> np.ndarray:
        if count == 1:
            return np.stack([a, b, c, c])[None]
        cells = _split_quad(np.stack([a, b, c, c]), ku, kv).reshape(ku, kv, 4, 3)
        cells[:, -1, 2:] = c  # the cells touching c are triangles (p, q, c, c), bit for bit
        return cells.reshape(-1, 4, 3)

    return count, make


def _quad_cuts(quad: np.ndarray, max_size: float | None) -> tuple[int, int]:
    a, b, c, d = quad
    ku = _cuts(max(float(np.linalg.norm(b - a)), float(np.linalg.norm(c - d))), max_size)
    kv = _cuts(max(float(np.linalg.norm(d - a)), float(np.linalg.norm(c - b))), max_size)
    return ku, kv


def _split_quad(quad: np.ndarray, ku: int, kv: int) -> np.ndarray:
    """ku*kv bilinear cells of a planar convex quad, same winding."""
    a, b, c, d = quad
    u = np.linspace(0, 1, ku + 1)[:, None, None]
    v = np.linspace(0, 1, kv + 1)[None, :, None]
    grid = (1 - u) * (1 - v) * a + u * (1 - v) * b + u * v * c + (1 - u) * v * d
    cells = np.stack([grid[:-1, :-1], grid[1:, :-1], grid[1:, 1:], grid[:-1, 1:]], axis=2)
    return cells.reshape(-1, 4, 3)


def _fold_cells(quad: np.ndarray, max_size: float) -> np.ndarray:
    """Cells of a non-planar quad folded along its ``v0 v2`` diagonal (the fan triangles
    ``v0 v1 v2`` and ``v0 v2 v3``), meeting vertex to vertex across the fold.

    One k x k grid of the unit square is mapped affinely onto each flat half (``u >= v`` onto
    the first, ``v >= u`` onto the second). Cells off the diagonal are planar quads; a cell on
    it is cut along the fold into two triangles, or four (through the fold's midpoint) when the
    fold segment is longer than ``max_size``. Cutting the two halves separately leaves
    T-junctions along the fold, which show as a crease in per-vertex shading.
    """
    v0, v1, v2, v3 = quad
    k = max(_cuts(float(np.linalg.norm(b - a)), max_size) for a, b in ((v0, v1), (v1, v2), (v3, v2), (v0, v3)))
    t = np.linspace(0.0, 1.0, k + 1)
    u, v = (x[..., None] for x in np.meshgrid(t, t, indexing="ij"))
    first = v0 + u * (v1 - v0) + v * (v2 - v1)  # (0,0) -> v0, (1,0) -> v1, (1,1) -> v2
    second = v0 + v * (v3 - v0) + u * (v2 - v3)  # (0,1) -> v3, (1,1) -> v2
    grid = np.where(u >= v, first, second)
    cells = []
    for i in range(k):
        for j in range(k):
            a, b, c, d = grid[i, j], grid[i + 1, j], grid[i + 1, j + 1], grid[i, j + 1]
            if i != j:
                cells.append(np.stack([a, b, c, d]))
            elif np.linalg.norm(c - a) <= max_size * (1 + 1e-9):
                cells += [np.stack([a, b, c, c]), np.stack([a, c, d, d])]
            else:
                m = 0.5 * (a + c)
                cells += [np.stack(t) for t in ((a, b, m, m), (b, c, m, m), (a, m, d, d), (m, c, d, d))]
    return np.stack(cells)


def _cuts(length: float, max_size: float | None) -> int:
    if max_size is None:
        return 1
    return max(1, math.ceil(length / max_size - 1e-9))


def planar_parts(poly: np.ndarray, size: float) -> tuple[list[np.ndarray], float]:
    """The face itself if it is planar, else its fan triangles; and its non-planarity (metres).

    A face is planar when no vertex is farther than ``PLANAR_REL * size`` from the plane
    through its centroid with its Newell normal. A non-planar face is split by a fan from its
    first vertex (``v0 v1 v2``, ``v0 v2 v3``, ...): a documented, deterministic choice that
    keeps every original edge (see ``docs/meshing.md``).
    """
    if len(poly) == 3:
        return [poly], 0.0
    normal = vector_area(poly)
    unit = normal / np.linalg.norm(normal)
    deviation = float(np.abs((poly - poly.mean(axis=0)) @ unit).max())
    if deviation > _tol.PLANAR_REL * size:
        return [np.stack([poly[0], poly[i], poly[i + 1]]) for i in range(1, len(poly) - 1)], deviation
    return [poly], 0.0


def _pieces(poly: np.ndarray, size: float) -> tuple[list[np.ndarray], float]:
    """Planar convex pieces (triangles or one quad) of a face, and its non-planarity."""
    parts, deviation = planar_parts(poly, size)
    if deviation or len(poly) == 3:
        return parts, deviation
    unit = vector_area(poly)
    unit = unit / np.linalg.norm(unit)
    if len(poly) == 4 and _is_convex(poly, unit):
        return [poly], 0.0
    if len(poly) >= GRADED_MIN_CORNERS and _is_convex(poly, unit):
        pieces = graded_pieces(poly, unit)  # earcut would fan out slivers from the corners
        if pieces is not None:
            return pieces, 0.0
    return list(triangulate(poly)), 0.0


def used_vertices(faces: list[np.ndarray], n_vertices: int) -> np.ndarray:
    """(v,) bool: the vertices some face uses (a mask: ``np.unique`` of all corners sorted
    1.7M indices on a 581k-face scene for the same set)."""
    used = np.zeros(n_vertices, bool)
    used[flat_faces(faces)[0]] = True
    return used


def subdivide_faces(vertices: np.ndarray, faces: list[np.ndarray], max_patch_size: float | None
                    ) -> tuple[Patches, FaceReport]:
    """Cut every face into patches whose longest edge is at most ``max_patch_size``.

    Parameters
    ----------
    vertices : (v, 3) float
    faces : list of (k,) int
        Vertex indices of each face, counter-clockwise seen from the front.
    max_patch_size : float or None
        Longest patch edge in metres; None keeps each face whole (non-planar or non-convex
        faces are still split into triangles).

    Returns
    -------
    Patches, FaceReport
    """
    report = FaceReport([], [])
    # Most faces are triangles or convex quads that stay one patch: decided at once (_patches_bulk).
    verdict, whole = whole_faces(vertices, faces, max_patch_size)
    counts = (verdict == WHOLE).astype(np.int64)
    made: dict[int, np.ndarray] = {}
    for index in np.flatnonzero(verdict != WHOLE).tolist():
        if verdict[index] == DEGENERATE:
            report.degenerate.append(index)
            continue
        cells = _face_cells(vertices[faces[index]], index, max_patch_size, report)
        if cells is not None:
            made[index] = cells
            counts[index] = len(cells)
    owner = np.repeat(np.arange(len(faces), dtype=np.int64), counts)
    quads = np.empty((len(owner), 4, 3))
    first = np.cumsum(counts) - counts
    single = verdict == WHOLE
    quads[first[single]] = whole[single]
    for index, cells in made.items():
        quads[first[index]:first[index] + len(cells)] = cells
    # Cells of the per-face path may have no area (a fan triangle of collinear vertices that
    # imprinting left on a cut table top: 1e-17 m^2 and no normal, a leaf the hierarchy could
    # never light); a whole face's patch is its face, whose area is far above its round-off
    # (whole_faces), so only the former are measured, as _face_cells measures faces.
    keep = np.ones(len(quads), bool)
    cut = ~np.repeat(single, counts)
    if cut.any():
        cells = quads[cut]
        extent = np.ptp(cells, axis=1).max(axis=1)
        keep[cut] = centroids_and_areas(cells)[1] > _tol.DEGENERATE_REL * 1e2 * extent ** 2
    if keep.all():
        return Patches(quads, owner), report
    return Patches(quads[keep], owner[keep]), report


def _face_cells(poly: np.ndarray, index: int, max_patch_size: float | None, report: FaceReport
                ) -> np.ndarray | None:
    """Cells of one face (None if it has zero area); notes it in ``report`` if it is degenerate
    or non-planar."""
    size = float(np.ptp(poly, axis=0).max())
    area = float(np.linalg.norm(vector_area(poly)))
    if not area > _tol.DEGENERATE_REL * 1e2 * size**2:
        report.degenerate.append(index)
        return None
    pieces, deviation = _pieces(poly, size)
    if deviation:
        report.nonplanar.append((index, deviation))
    if deviation and len(poly) == 4 and max_patch_size is not None:
        return _fold_cells(poly, max_patch_size)
    out = []
    for piece in pieces:
        if len(piece) == 4:
            out.append(_split_quad(piece, *_quad_cuts(piece, max_patch_size)))
        else:
            out.append(_split_triangle(piece, max_patch_size))
    return np.concatenate(out, axis=0) if out else np.zeros((0, 4, 3))

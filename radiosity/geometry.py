"""Polygon geometry that every stage uses: Newell normals, areas and centroids, triangulation.

The bottom of the pipeline: it imports nothing of the package but the tolerances. Patches are
stored as (n, 4, 3) quads (a triangle repeats a vertex); polygons as (k, 3) or padded (..., k, 3).
"""

from __future__ import annotations

import numpy as np

from . import _tol

__all__ = ["vector_area", "vector_areas", "polygon_normals", "centroids_and_areas", "triangulate", "clip_slots",
           "FaceList", "flat_faces", "convex_groups"]


class FaceList(list):
    """Faces, a list of (k,) int arrays, that also holds them end to end: ``flat`` (every corner,
    face after face) and ``sizes`` (corners per face).

    The OBJ reader makes one, so the stages that work on all faces at once need not concatenate
    581k small arrays again each (:func:`flat_faces`). Any plain list works as well. Treat it as
    read-only: an item assigned in place is not seen by ``flat``.
    """

    def __init__(self, faces, flat: np.ndarray, sizes: np.ndarray):
        super().__init__(faces)
        self.flat, self.sizes = flat, sizes


def flat_faces(faces: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(c,) int64 corners of all faces end to end and (f,) int64 corners per face."""
    if isinstance(faces, FaceList) and len(faces.sizes) == len(faces):
        return faces.flat, faces.sizes
    sizes = np.fromiter(map(len, faces), np.int64, len(faces))
    flat = np.concatenate(faces).astype(np.int64, copy=False) if len(faces) else np.zeros(0, np.int64)
    return flat, sizes


def vector_areas(polys: np.ndarray) -> np.ndarray:
    """Vector areas (Newell) of polygons (..., k, 3): half the sum of cross products of
    consecutive corners, centred first so huge coordinates do not cancel catastrophically.

    The one Newell sum of the package: :func:`vector_area` (one polygon, written out for speed)
    and the earlier copies in ``patches``, ``_patches_bulk``, ``io/view3d`` gave these same bits
    (same products and differences, sums in the same order).
    """
    centred = polys - polys.mean(axis=-2, keepdims=True)
    return 0.5 * np.cross(centred, np.roll(centred, -1, axis=-2)).sum(axis=-2)


def vector_area(poly: np.ndarray) -> np.ndarray:
    """:func:`vector_areas` of one polygon (k, 3), the same bits.

    Written out rather than with ``np.cross`` / ``np.roll``, whose per-call overhead dominated
    loading large scenes (it is called a few times per face).
    """
    if len(poly) <= 8:
        return _vector_area_small(poly)
    a = poly - poly.mean(axis=0)
    b = np.concatenate([a[1:], a[:1]])
    cross = np.empty_like(a)
    cross[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    cross[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    cross[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return 0.5 * cross.sum(axis=0)


def _vector_area_small(poly: np.ndarray) -> np.ndarray:
    """:func:`vector_area` in Python floats for a few corners (numpy's per-call cost is most of
    it there): numpy reduces axis 0 row after row, so these sums run in the same order."""
    rows = poly.tolist()
    k = len(rows)
    if k < 3:  # no area (a face left with one or two corners: the fuzzer's zero-area faces)
        return np.zeros(3)
    mx, my, mz = rows[0]
    for x, y, z in rows[1:]:
        mx += x
        my += y
        mz += z
    mx, my, mz = mx / k, my / k, mz / k
    a = [(x - mx, y - my, z - mz) for x, y, z in rows]
    (ax, ay, az), (bx, by, bz) = a[0], a[1]
    sx, sy, sz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    for i in range(1, k):
        ax, ay, az = a[i]
        bx, by, bz = a[(i + 1) % k]
        sx += ay * bz - az * by
        sy += az * bx - ax * bz
        sz += ax * by - ay * bx
    return np.array([0.5 * sx, 0.5 * sy, 0.5 * sz])


def polygon_normals(polys: np.ndarray) -> np.ndarray:
    """Unit normals by Newell's method (right-hand rule on the winding); zero if degenerate.

    Parameters
    ----------
    polys : (..., k, 3) float
        Polygons, repeated vertices allowed.
    """
    centred = polys - polys.mean(axis=-2, keepdims=True)
    area = vector_areas(polys)
    length = np.linalg.norm(area, axis=-1, keepdims=True)
    scale = (np.linalg.norm(centred, axis=-1).max(axis=-1, keepdims=True)) ** 2
    ok = length > _tol.DEGENERATE_REL * np.maximum(scale, np.finfo(float).tiny)
    return np.where(ok, area / np.where(ok, length, 1.0), 0.0)


def centroids_and_areas(quads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Area centroids and areas of patches stored as (n, 4, 3) (triangles repeat a vertex)."""
    a, b, c, d = (quads[:, i] for i in range(4))
    cross1 = np.cross(b - a, c - a)
    cross2 = np.cross(c - a, d - a)
    area1 = 0.5 * np.linalg.norm(cross1, axis=1)
    area2 = 0.5 * np.linalg.norm(cross2, axis=1)
    area = area1 + area2
    safe = np.where(area > 0, area, 1.0)
    centroid = ((a + b + c) * area1[:, None] + (a + c + d) * area2[:, None]) / (3 * safe[:, None])
    centroid = np.where(area[:, None] > 0, centroid, quads.mean(axis=1))
    return centroid, area


def convex_groups(quads: np.ndarray, normals: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """(g,) bool for each group id 0 .. ``groups.max()``: whether its patches lie on their own
    convex hull, facing out (the surface of a convex body, or a flat sheet), so that no two of
    them see each other and the group exchanges no light with itself.

    Each patch must lie in the plane of a facet of the group's hull, with that facet's outward
    normal, within ``PLANAR_REL`` of the group's size; then every vertex of the group lies on or
    behind it. Hull facets are matched by their nearest normal, so the test costs
    O(n log n) per group, not a height for each (patch, vertex) pair: a 20,480-triangle sphere
    has 2 x 10^8 of those. A group that fails (a table of five boxes, a room seen from inside,
    a sphere facing in) is simply not convex.

    Parameters
    ----------
    quads : (n, 4, 3) float
        Patches (a triangle repeats a vertex).
    normals : (n, 3) float
        Their unit normals.
    groups : (n,) int
        The group (object) of each patch, >= 0.
    """
    groups = np.asarray(groups, np.int64)
    n_groups = int(groups.max()) + 1 if len(groups) else 0
    order = np.argsort(groups, kind="stable")
    bounds = np.searchsorted(groups[order], np.arange(n_groups + 1))
    out = np.zeros(n_groups, bool)
    for g in range(n_groups):
        members = order[bounds[g]:bounds[g + 1]]
        out[g] = len(members) > 0 and _on_own_hull(quads[members], normals[members])
    return out


def _on_own_hull(quads: np.ndarray, normals: np.ndarray) -> bool:
    """:func:`convex_groups` for the patches of one group."""
    from scipy.spatial import ConvexHull, QhullError, cKDTree

    points = np.unique(quads.reshape(-1, 3), axis=0)
    tol = _tol.PLANAR_REL * float(np.ptp(points, axis=0).max())
    centroid = quads.mean(axis=1)
    first = int(np.argmax(np.einsum("ij,ij->i", normals, normals)))  # a patch with a normal
    if not normals[first].any():
        return False
    if np.abs((points - centroid[first]) @ normals[first]).max() <= tol:
        return True  # flat: patches in one plane see nothing of each other
    try:
        hull = ConvexHull(points)
    except (QhullError, ValueError):
        return False
    unit, offset = hull.equations[:, :3], hull.equations[:, 3]
    gap, nearest = cKDTree(unit).query(normals)
    # the normals agree to PLANAR_REL (the height this leaves across the group is within tol)
    # and the patch lies in the facet's plane
    height = np.einsum("ij,ij->i", centroid, unit[nearest]) + offset[nearest]
    return bool(np.all(gap <= _tol.PLANAR_REL) and np.all(np.abs(height) <= tol))


def clip_slots(poly: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One Sutherland-Hodgman step on many polygons at once, before compaction.

    poly (r, k, 3) with values h (r, k) at its vertices; keeps h >= 0. Returns slots (r, 2k, 3)
    (vertex k, then where edge k crosses h = 0) and which of them the clipped polygon keeps
    (r, 2k); callers compact or pad the kept slots as their kernel needs.
    """
    r, k, _ = poly.shape
    nxt = np.roll(poly, -1, axis=1)
    h_next = np.roll(h, -1, axis=1)
    keep = h >= 0.0
    crosses = ((h > 0.0) & (h_next < 0.0)) | ((h < 0.0) & (h_next > 0.0))
    t = np.where(crosses, h / np.where(crosses, h - h_next, 1.0), 0.0)
    cut = poly + t[..., None] * (nxt - poly)
    slots = np.stack([poly, cut], axis=2).reshape(r, 2 * k, 3)
    valid = np.stack([keep, crosses], axis=2).reshape(r, 2 * k)
    return slots, valid


def triangulate(polygon: np.ndarray) -> np.ndarray:
    """Triangles (t, 3, 3) of a planar simple polygon (k, 3), convex or not (earcut).

    Every triangle is wound like the polygon (counter-clockwise around its Newell normal), so
    the pieces face the way the face does. Earcut works on the polygon projected onto the
    coordinate plane its normal is most aligned with, and that projection mirrors polygons
    facing -x, +y or -z; the winding is therefore restored per triangle, by the sign of its
    normal along the polygon's.
    """
    import mapbox_earcut

    if len(polygon) == 3:
        return polygon[None].copy()
    centred = polygon - polygon.mean(axis=0)
    normal = vector_area(polygon)  # half the old unscaled sum: the same argmax and signs below
    axis = int(np.argmax(np.abs(normal)))
    plane = np.delete(centred, axis, axis=1)
    rings = np.array([len(polygon)], dtype=np.uint32)
    index = np.asarray(mapbox_earcut.triangulate_float64(plane, rings), dtype=np.int64).reshape(-1, 3)
    if len(index) == 0:
        return np.zeros((0, 3, 3))
    a, b, c = (centred[index[:, k]] for k in range(3))
    backwards = np.cross(b - a, c - a) @ normal < 0
    index[backwards] = index[backwards][:, ::-1]
    return polygon[index]

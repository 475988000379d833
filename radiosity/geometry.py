"""Polygon geometry that every stage uses: Newell normals, areas and centroids, triangulation.

The bottom of the pipeline: it imports nothing of the package but the tolerances. Patches are
stored as (n, 4, 3) quads (a triangle repeats a vertex); polygons as (k, 3) or padded (..., k, 3).
"""

from __future__ import annotations

import numpy as np

from . import _tol

__all__ = ["polygon_normals", "centroids_and_areas", "triangulate"]


def polygon_normals(polys: np.ndarray) -> np.ndarray:
    """Unit normals by Newell's method (right-hand rule on the winding); zero if degenerate.

    Parameters
    ----------
    polys : (..., k, 3) float
        Polygons, repeated vertices allowed.
    """
    # Centre first so huge coordinates do not cancel catastrophically.
    centred = polys - polys.mean(axis=-2, keepdims=True)
    vector_area = 0.5 * np.cross(centred, np.roll(centred, -1, axis=-2)).sum(axis=-2)
    length = np.linalg.norm(vector_area, axis=-1, keepdims=True)
    scale = (np.linalg.norm(centred, axis=-1).max(axis=-1, keepdims=True)) ** 2
    ok = length > _tol.DEGENERATE_REL * np.maximum(scale, np.finfo(float).tiny)
    return np.where(ok, vector_area / np.where(ok, length, 1.0), 0.0)


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
    normal = np.cross(centred, np.roll(centred, -1, axis=0)).sum(axis=0)
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

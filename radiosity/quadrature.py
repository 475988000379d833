"""Quadrature over patches and polygons: Gauss-Legendre rules on (collapsed) squares.

A patch is a triangle or a convex planar quad stored as four vertices (a triangle repeats its
last vertex). The bilinear map of the unit square onto ``(a, b, c, d)`` becomes the Duffy
(collapsed square) map when ``c == d``, so one tensor Gauss rule with the Jacobian in its
weights serves both shapes.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache

import numpy as np

__all__ = ["patch_points", "integrate_over_polygon", "triangulate"]


@lru_cache(maxsize=None)
def gauss_legendre_01(order: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on [0, 1]."""
    x, w = np.polynomial.legendre.leggauss(order)
    return 0.5 * (x + 1.0), 0.5 * w


def patch_points(quads: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature points and area weights on each patch.

    Parameters
    ----------
    quads : (n, 4, 3) float
        Patches; a triangle repeats its third vertex.
    order : int
        Points per direction; ``order**2`` points per patch. Order 1 uses the area centroid.

    Returns
    -------
    points : (n, order**2, 3) float
    weights : (n, order**2) float
        Weights sum to each patch's area.
    """
    if order == 1:
        centroid, area = centroids_and_areas(quads)
        return centroid[:, None, :], area[:, None]
    nodes, w = gauss_legendre_01(order)
    u = np.repeat(nodes, order)
    v = np.tile(nodes, order)
    wuv = np.repeat(w, order) * np.tile(w, order)
    a, b, c, d = (quads[:, i, None, :] for i in range(4))
    uu, vv = u[None, :, None], v[None, :, None]
    points = (1 - uu) * (1 - vv) * a + uu * (1 - vv) * b + uu * vv * c + (1 - uu) * vv * d
    du = (1 - vv) * (b - a) + vv * (c - d)
    dv = (1 - uu) * (d - a) + uu * (c - b)
    jac = np.linalg.norm(np.cross(du, dv), axis=-1)
    return points, jac * wuv[None, :]


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
    """Triangles (t, 3, 3) of a planar simple polygon (k, 3), convex or not (earcut)."""
    import mapbox_earcut

    if len(polygon) == 3:
        return polygon[None].copy()
    centred = polygon - polygon.mean(axis=0)
    normal = np.cross(centred, np.roll(centred, -1, axis=0)).sum(axis=0)
    axis = int(np.argmax(np.abs(normal)))
    plane = np.delete(centred, axis, axis=1)
    rings = np.array([len(polygon)], dtype=np.uint32)
    index = np.asarray(mapbox_earcut.triangulate_float64(plane, rings)).reshape(-1, 3)
    if len(index) == 0:
        return np.zeros((0, 3, 3))
    return polygon[index]


def split_triangles(tris: np.ndarray) -> np.ndarray:
    """Split each triangle (t, 3, 3) into four by its edge midpoints."""
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    ab, bc, ca = (a + b) / 2, (b + c) / 2, (c + a) / 2
    parts = [np.stack(p, axis=1) for p in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))]
    return np.concatenate(parts, axis=0)


def integrate_over_polygon(
    integrand: Callable[[np.ndarray], np.ndarray],
    polygon: np.ndarray,
    *,
    rtol: float,
    max_points: int = 4_000_000,
) -> float:
    """Adaptive integral of ``integrand(points) -> values`` over a planar polygon.

    The estimate sequence raises the Gauss order (4, 8, 16) and then splits the triangles in
    four at order 16, until two successive estimates agree to ``rtol`` relative (or to
    ``rtol * 1e-3`` absolute, for integrals that are essentially zero). Each estimate is far
    more accurate than the one before, so the returned (last) one is conservative.
    """
    tris = triangulate(polygon)
    if len(tris) == 0:
        return 0.0
    quads = np.concatenate([tris, tris[:, 2:3]], axis=1)
    area = float(centroids_and_areas(quads)[1].sum())
    if area == 0.0:
        return 0.0
    previous = None
    for order, splits in ((4, 0), (8, 0), (16, 0), (16, 1), (16, 2), (16, 3), (16, 4), (16, 5)):
        parts = tris
        for _ in range(splits):
            parts = split_triangles(parts)
        if len(parts) * order**2 > max_points:
            break
        quads = np.concatenate([parts, parts[:, 2:3]], axis=1)
        points, weights = patch_points(quads, order)
        values = integrand(points.reshape(-1, 3)).reshape(weights.shape)
        estimate = float((values * weights).sum()) / area
        if previous is not None and abs(estimate - previous) <= max(rtol * abs(estimate), 1e-3 * rtol):
            return estimate
        previous = estimate
    return previous

"""Polygon-to-polygon form factors: the receiver cut into quadrature pieces, each integrated
adaptively (``_quadrature.pair_factors``) against the source clipped to its front side."""

from __future__ import annotations

import numpy as np

from .._validate import as_polygon, check_rtol
from ..geometry import centroids_and_areas, polygon_normals, triangulate
from ._quadrature import pair_factors

__all__ = ["polygon_to_polygon"]


def _receiver_pieces(receiver: np.ndarray, normal: np.ndarray, source: np.ndarray) -> np.ndarray:
    """The receiver as (t, 4, 3) quadrature pieces: itself if it is a convex quad or a triangle,
    else its earcut triangles. A triangle's collapsed (Duffy) vertex is put on the vertex nearest
    the source, where a touching vertex makes the integrand singular: the collapse smooths it."""
    k = len(receiver)
    if k == 4:
        e = np.roll(receiver, -1, axis=0) - receiver
        turns = np.cross(e, np.roll(e, -1, axis=0)) @ normal
        if (turns > 0).all() or (turns < 0).all():
            return receiver[None].copy()
    tris = receiver[None] if k == 3 else triangulate(receiver)
    if len(tris) == 0:
        return np.zeros((0, 4, 3))
    centred = source - source.mean(axis=0)
    d = np.linalg.norm(tris[:, :, None, :] - source[None, None], axis=-1).min(axis=2)
    del centred
    nearest = d.argmin(axis=1)
    order = (np.arange(3)[None, :] + nearest[:, None] + 1) % 3  # nearest vertex goes last
    tris = np.take_along_axis(tris, order[..., None], axis=1)
    return np.concatenate([tris, tris[:, 2:3]], axis=1)


def polygon_to_polygon(receiver, source, *, rtol: float = 1e-6) -> float:
    """Unoccluded area-averaged form factor F(receiver -> source) between two planar polygons.

    The receiver is triangulated (earcut, so non-convex receivers work) and each piece is
    integrated by :func:`radiosity.formfactors._quadrature.pair_factors`: an a-priori Gauss order for
    well-separated pieces, otherwise adaptive refinement graded toward touching edges and
    corners until the error estimate meets ``rtol`` (see ``docs/formfactors.md``).

    Parameters
    ----------
    receiver, source : (k, 3) float
        Planar simple polygons, metres. The receiver's winding gives its front side
        (counter-clockwise seen from the front); the source's winding is ignored, as in
        :func:`point_to_polygon`: a receiver crossing the source's plane sees one face of the
        source from each side, and both count.
    rtol : float, default: 1e-6
        Relative accuracy requested, down to 1e-10.

    Returns
    -------
    float
        The fraction of the power leaving the receiver's front that reaches the source.

    Examples
    --------
    Parallel unit squares one apart, facing each other:

    >>> import radiosity
    >>> lower = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    >>> upper = [[0, 0, 1], [0, 1, 1], [1, 1, 1], [1, 0, 1]]
    >>> round(radiosity.polygon_to_polygon(lower, upper, rtol=1e-9), 9)
    0.199824896
    """
    receiver = as_polygon(receiver, "receiver")
    source = as_polygon(source, "source")
    check_rtol(rtol)
    # Work relative to a receiver vertex: quadrature nodes formed at 1e9 would lose 9 digits,
    # and for nearby vertices this subtraction is exact.
    origin = receiver[0].copy()
    receiver, source = receiver - origin, source - origin
    normal = polygon_normals(receiver[None])[0]
    source_normal = polygon_normals(source[None])[0]
    if not normal.any() or not source_normal.any():
        return 0.0
    total_area = float(np.linalg.norm(np.cross(receiver, np.roll(receiver, -1, axis=0)).sum(axis=0))) / 2
    total = 0.0
    for part in _sides_of_plane(receiver, source[0], source_normal):
        part_area = float(np.linalg.norm(np.cross(part, np.roll(part, -1, axis=0)).sum(axis=0))) / 2
        if part_area > 1e-14 * total_area:
            total += part_area * _one_side(part, normal, source, rtol)
    return total / total_area


def _sides_of_plane(poly: np.ndarray, point: np.ndarray, normal: np.ndarray) -> list[np.ndarray]:
    """``poly`` cut by the plane (point, normal) into its parts on either side (Sutherland-
    Hodgman); a polygon on one side (or touching the plane) is returned whole."""
    height = (poly - point) @ normal
    tol = 1e-12 * float(np.abs(poly - point).max())
    if not (height.max() > tol and height.min() < -tol):
        return [poly]
    parts = []
    for sign in (1.0, -1.0):
        h = sign * height
        kept = []
        for i in range(len(poly)):
            j = (i + 1) % len(poly)
            if h[i] >= 0:
                kept.append(poly[i])
            if (h[i] > 0 > h[j]) or (h[i] < 0 < h[j]):
                kept.append(poly[i] + h[i] / (h[i] - h[j]) * (poly[j] - poly[i]))
        if len(kept) >= 3:
            parts.append(np.array(kept))
    return parts


def _one_side(receiver: np.ndarray, normal: np.ndarray, source: np.ndarray, rtol: float) -> float:
    """F(receiver -> source) for a receiver on one side of the source's plane."""
    quads = _receiver_pieces(receiver, normal, source)
    if len(quads) == 0:
        return 0.0
    centroid, area = centroids_and_areas(quads)
    if not area.sum() > 0.0:
        return 0.0
    t = np.arange(len(quads))
    values = pair_factors(quads, np.broadcast_to(normal, (len(quads), 3)).copy(), centroid, area, t,
                          np.zeros(len(quads), dtype=np.int64), rtol=rtol, sources=source[None])
    return float((values * area).sum() / area.sum())

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
    return split_patch_points(quads, order, 1)


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


def split_patch_points(quads: np.ndarray, order: int, splits: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss points on each patch cut into ``splits x splits`` parameter sub-squares.

    The bilinear (or, for triangles, collapsed) map of the unit square restricted to an
    axis-aligned sub-square is again such a map, so the rule stays exact for the same
    polynomial degree on every piece.

    Parameters
    ----------
    quads : (n, 4, 3) float
        Patches; a triangle repeats its third vertex.
    order : int
        Gauss-Legendre points per direction on each piece.
    splits : int
        Pieces per direction (1 gives :func:`patch_points` for ``order >= 2``).

    Returns
    -------
    points : (n, (splits * order)**2, 3) float
    weights : (n, (splits * order)**2) float
        Weights sum to each patch's area.
    """
    nodes, w = gauss_legendre_01(order)
    nodes = ((np.arange(splits)[:, None] + nodes[None, :]) / splits).ravel()
    w = np.tile(w / splits, splits)
    q = len(nodes)
    u = np.repeat(nodes, q)
    v = np.tile(nodes, q)
    wuv = np.repeat(w, q) * np.tile(w, q)
    a, b, c, d = (quads[:, i, None, :] for i in range(4))
    uu, vv = u[None, :, None], v[None, :, None]
    points = (1 - uu) * (1 - vv) * a + uu * (1 - vv) * b + uu * vv * c + (1 - uu) * vv * d
    du = (1 - vv) * (b - a) + vv * (c - d)
    dv = (1 - uu) * (d - a) + uu * (c - b)
    jac = np.linalg.norm(np.cross(du, dv), axis=-1)
    return points, jac * wuv[None, :]


# Refinement ladder of the adaptive pair quadrature: (Gauss order, splits per direction).
# Successive rungs are compared; a pair stops at the first rung that agrees with the previous one.
_LADDER = ((4, 1), (8, 1), (8, 2), (8, 4), (8, 8), (8, 16), (8, 32))  # (2, 1) vs (4, 1) agree by chance on touching pairs

# A-priori rule for well-separated pairs: with rho = (distance from the receiver's centroid to the
# source's bounding sphere) / (receiver radius) times the smaller of the two cosines between the
# normals and the centre line, an order-p tensor Gauss rule on the receiver errs by at most about
# _APRIORI_C * rho**(-2 p) relative. Measured on 4000 random triangle/parallelogram pairs
# (rho 1.5..5000, sizes 0.1..10): the largest ratio error * rho**(2p) was 0.49 for p = 1 and below
# 0.35 at the 99th percentile for p = 2, 3 wherever the error was above float rounding (1e-12).
# The smallest p meeting rtol / _APRIORI_SAFETY is used alone.
_APRIORI_C = 1.0
_APRIORI_SAFETY = 10.0
_APRIORI_ORDERS = (1, 2, 3, 4, 6)


def _radius(quads: np.ndarray, centroid: np.ndarray) -> np.ndarray:
    return np.linalg.norm(quads - centroid[:, None, :], axis=2).max(axis=1)


def _touching(rquads, squads, i, j, scale):
    """Pairs whose patches share a vertex or whose vertex lies on the other's edge (or nearly)."""
    ri = rquads[i]
    sj = squads[j]
    d = np.linalg.norm(ri[:, :, None, :] - sj[:, None, :, :], axis=-1).min(axis=(1, 2))
    return d <= 1e-9 * scale


def _evaluate(rquads, rnormals, sources, i, j, order, splits, mode):
    """F(i -> j) with a fixed rule on the receiver, via the fused numba quadrature kernel."""
    from .formfactors import HAVE_NUMBA, _MODES, _quadrature_kernel, lambert_pairs

    out = np.empty(len(i))
    if not len(i):
        return out
    uniq, slot = np.unique(i, return_inverse=True)
    if order == 1 and splits == 1:
        pts, w = patch_points(rquads[uniq], 1)
    else:
        pts, w = split_patch_points(rquads[uniq], order, splits)
    nq = pts.shape[1]
    flat = np.ascontiguousarray(pts.reshape(-1, 3))
    nrm = np.ascontiguousarray(np.repeat(rnormals[uniq], nq, axis=0))
    wts = np.ascontiguousarray(w.reshape(-1))
    if HAVE_NUMBA:
        _quadrature_kernel(flat, nrm, wts, nq, slot.astype(np.int64), np.ascontiguousarray(sources),
                           np.ascontiguousarray(j, dtype=np.int64), _MODES[mode], out)
        return out
    vals = lambert_pairs(flat[(slot[:, None] * nq + np.arange(nq)).ravel()],  # pragma: no cover
                         nrm[(slot[:, None] * nq + np.arange(nq)).ravel()],
                         np.repeat(sources[j], nq, axis=0)).reshape(-1, nq)
    return (vals * w[slot]).sum(axis=1) / w[slot].sum(axis=1)  # pragma: no cover


def _clipped_receivers(quads, normals, srcs, i, j, height, *, rtol, max_points):
    """F(i -> j) for receivers straddling the source's plane: only their front part counts.

    Each receiver is clipped to height >= 0 above the source's plane (up to 5 vertices),
    fanned into triangles, and each triangle is integrated as a receiver of its own; the
    results are combined by area.
    """
    from .formfactors import _clip_to_upper

    slots = _clip_to_upper(quads[i], height)  # (m, 8, 3), removed slots repeat a kept vertex
    k = slots.shape[1]
    a = np.repeat(slots[:, :1], k - 2, axis=1)
    tris = np.stack([a, slots[:, 1:-1], slots[:, 2:]], axis=2)  # (m, k-2, 3, 3)
    tri_area = 0.5 * np.linalg.norm(np.cross(tris[..., 1, :] - tris[..., 0, :], tris[..., 2, :] - tris[..., 0, :]), axis=-1)
    _, rec_area = centroids_and_areas(quads[i])
    keep = tri_area > 1e-14 * rec_area[:, None]
    pair, piece = np.nonzero(keep)
    pieces = tris[pair, piece]
    pieces = np.concatenate([pieces, pieces[:, 2:3]], axis=1)
    p_cen, p_area = centroids_and_areas(pieces)
    f, info = pair_factors(pieces, normals[i[pair]], p_cen, p_area, np.arange(len(pair)), j[pair], rtol=rtol,
                           sources=srcs, return_info=True, max_points=max_points, _clipped=True)
    out = np.zeros(len(i))
    np.add.at(out, pair, f * p_area)
    used = np.zeros(len(i), dtype=np.int64)
    np.add.at(used, pair, info["points"])
    converged = np.ones(len(i), dtype=bool)
    np.logical_and.at(converged, pair, info["converged"])
    return out / np.where(rec_area > 0, rec_area, 1.0), used, converged


def _src_normals(polys: np.ndarray) -> np.ndarray:
    from .formfactors import polygon_normals

    return polygon_normals(polys)


def pair_factors(quads, normals, centroid, area, i, j, *, rtol: float = 1e-6, sources=None,
                 return_info: bool = False, max_points: int | None = None, _clipped: bool = False):
    """Unoccluded F(i -> j) for many patch pairs, each to a relative tolerance.

    F(i -> j) = (1/A_i) ∫_{A_i} F_pt(x -> P_j) dA, with Lambert's closed form for the inner
    factor (:func:`radiosity.formfactors.lambert_pairs`), i.e. the semantics of
    ``assembly.unoccluded_factors``. Each pair gets its own rule:

    - well separated pairs (receiver far from the source's bounding sphere compared with its
      own size) take the cheapest Gauss order that an a-priori bound says meets ``rtol``
      (the centroid alone when far enough);
    - the others (near, touching, sharing an edge or a vertex, or with the receiver inside the
      source's bounding sphere) climb a ladder of rules, order 2, 4, 8, then the receiver cut
      into 2x2, 4x4, ... pieces at order 8, until two successive rungs agree to
      ``rtol * F + PAIR_ATOL``; the finer estimate is returned.

    Parameters
    ----------
    quads : (n, 4, 3) float
        Patches (receivers, and sources unless ``sources`` is given); triangles repeat a vertex.
    normals : (n, 3) float
        Unit normals of the patches (their front sides).
    centroid : (n, 3) float
        Area centroids of the patches.
    area : (n,) float
        Patch areas (accepted for signature compatibility with the fill; the rules carry their
        own weights).
    i, j : (m,) int
        Receiver and source patch of each pair.
    rtol : float, default: 1e-6
        Relative accuracy per pair, 1e-10 <= rtol < 1.
    sources : (n_s, k, 3) float, optional
        Source polygons indexed by ``j`` when they differ from ``quads``.
    return_info : bool, default: False
        Also return a dict with the rung each pair stopped at and whether it converged.
    max_points : int, optional
        Most receiver points one pair may use (the ladder stops there, unconverged). Touching
        pairs converge slowly (the integrand is log-singular along the shared edge), so this
        bounds the fill's cost; None climbs the whole ladder.

    Returns
    -------
    (m,) float
        F(i -> j), the fraction of the power leaving patch i's front that reaches patch j.
    info : dict
        Only with ``return_info``: ``"points"`` (m,) receiver points used by the final rule,
        ``"converged"`` (m,) bool (False only where the ladder ran out).

    Examples
    --------
    Two perpendicular unit squares sharing an edge (Howell C-14), 0.2000437761:

    >>> import numpy as np
    >>> from radiosity.quadrature import centroids_and_areas, pair_factors
    >>> floor = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    >>> wall = [[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]]
    >>> quads = np.array([floor, wall], dtype=float)
    >>> normals = np.array([[0, 0, 1], [1, 0, 0]], dtype=float)
    >>> c, a = centroids_and_areas(quads)
    >>> f = pair_factors(quads, normals, c, a, np.array([0]), np.array([1]), rtol=1e-9)
    >>> round(float(f[0]), 10)
    0.2000437761
    """
    from . import _tol

    quads = np.asarray(quads, dtype=float)
    normals = np.asarray(normals, dtype=float)
    centroid = np.asarray(centroid, dtype=float)
    i = np.asarray(i, dtype=np.int64)
    j = np.asarray(j, dtype=np.int64)
    if not (1e-12 <= rtol < 1):
        raise ValueError(f"rtol must be in [1e-12, 1), got {rtol}")
    srcs = quads if sources is None else np.asarray(sources, dtype=float)
    m = len(i)
    out = np.zeros(m)
    used = np.zeros(m, dtype=np.int64)
    converged = np.ones(m, dtype=bool)
    if m == 0:
        return (out, {"points": used, "converged": converged}) if return_info else out
    r_rec = _radius(quads, centroid)
    s_cen = srcs.mean(axis=1) if sources is not None else centroid
    r_src = _radius(srcs, s_cen)
    dist = np.linalg.norm(centroid[i] - s_cen[j], axis=1)
    rho = (dist - r_src[j]) / np.maximum(r_rec[i], np.finfo(float).tiny)
    u = (s_cen[j] - centroid[i]) / np.maximum(dist, np.finfo(float).tiny)[:, None]
    s_nrm = normals if sources is None else _src_normals(srcs)
    cos_min = np.minimum(np.abs(np.einsum("mc,mc->m", normals[i], u)),
                         np.abs(np.einsum("mc,mc->m", s_nrm[j], u)))
    rho = rho * cos_min
    # A receiver crossing the source's plane sees the source's back from part of its area,
    # which gives nothing (surfaces are one-sided), and the integrand has a kink there: clip
    # the receiver to the source's front half-space and integrate the pieces.
    h = np.einsum("mkc,mc->mk", quads[i] - s_cen[j][:, None, :], s_nrm[j])
    tol_h = 1e-12 * (r_rec[i] + r_src[j])
    crossing = (h.max(axis=1) > tol_h) & (h.min(axis=1) < -tol_h)
    clipped_here = crossing if not _clipped else np.zeros(m, dtype=bool)
    if clipped_here.any():
        sel = np.flatnonzero(clipped_here)
        out[sel], used[sel], converged[sel] = _clipped_receivers(
            quads, normals, srcs, i[sel], j[sel], h[sel], rtol=rtol, max_points=max_points)
    # A-priori orders for separated pairs.
    order = np.zeros(m, dtype=np.int64)
    ok_rho = (rho > 1.5) & ~crossing
    for p in _APRIORI_ORDERS[::-1]:
        meets = ok_rho & (_APRIORI_C * np.where(ok_rho, rho, 1.0) ** (-2.0 * p) <= rtol / _APRIORI_SAFETY)
        order[meets] = p
    if sources is None:
        touch = _touching(quads, srcs, i, j, r_rec[i] + r_src[j])
        order[touch] = 0
    order[clipped_here] = -1  # already integrated piecewise
    for p in np.unique(order[order > 0]):
        sel = np.flatnonzero(order == p)
        out[sel] = _evaluate(quads, normals, srcs, i[sel], j[sel], int(p), 1, "auto")
        used[sel] = p * p
    # Ladder for the rest.
    pending = np.flatnonzero(order == 0)
    previous = None
    for order_l, splits in _LADDER:
        if not len(pending) or (max_points is not None and (order_l * splits) ** 2 > max_points):
            break
        est = _evaluate(quads, normals, srcs, i[pending], j[pending], order_l, splits, "auto")
        out[pending] = est
        used[pending] = (order_l * splits) ** 2
        if previous is not None:
            done = np.abs(est - previous) <= rtol * np.abs(est) + _tol.PAIR_ATOL
            pending = pending[~done]
            previous = est[~done]
        else:
            previous = est
    converged[pending] = False
    if return_info:
        return out, {"points": used, "converged": converged}
    return out

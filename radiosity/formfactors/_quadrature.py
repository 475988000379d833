"""Quadrature over patches and polygons: Gauss-Legendre rules on (collapsed) squares.

A patch is a triangle or a convex planar quad stored as four vertices (a triangle repeats its
last vertex). The bilinear map of the unit square onto ``(a, b, c, d)`` becomes the Duffy
(collapsed square) map when ``c == d``, so one tensor Gauss rule with the Jacobian in its
weights serves both shapes.
"""

from __future__ import annotations

from functools import lru_cache

import numba as _numba
import numpy as np

from .._validate import check_rtol
from ..geometry import centroids_and_areas, polygon_normals
from ._closed_form import _MODES, _clip_to_upper
from ._lambert import _quadrature_kernel, _quadrature_source_kernel

__all__ = ["patch_points"]

_prange = _numba.prange


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
    points, jac = _map_square(quads, u[None], v[None])
    return points, jac * wuv[None, :]


def square_cell_points(quads: np.ndarray, u0: np.ndarray, v0: np.ndarray, size: np.ndarray, order: int
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Gauss points on parameter cells ``[u0, u0 + su] x [v0, v0 + sv]`` of patches.

    The cell-by-cell form of :func:`split_patch_points`, for adaptive receiver integrals: row c
    is the cell of patch ``quads[c]`` (n, 4, 3) at ``u0[c], v0[c]`` with sides ``size[c]``,
    (n,) for squares or (n, 2) for ``(su, sv)``.

    Returns
    -------
    points : (n, order**2, 3) float
    weights : (n, order**2) float
        Weights sum to each cell's area.
    """
    nodes, w = gauss_legendre_01(order)
    su, sv = _cell_sides(size)
    u = u0[:, None] + su[:, None] * np.repeat(nodes, order)[None, :]
    v = v0[:, None] + sv[:, None] * np.tile(nodes, order)[None, :]
    wuv = (np.repeat(w, order) * np.tile(w, order))[None, :] * (su * sv)[:, None]
    points, jac = _map_square(quads, u, v)
    return points, jac * wuv


def square_cell_corners(quads: np.ndarray, u0: np.ndarray, v0: np.ndarray, size: np.ndarray) -> np.ndarray:
    """(n, 4, 3) corners of the parameter cells of :func:`square_cell_points`, in the patches' order."""
    su, sv = _cell_sides(size)
    u = u0[:, None] + su[:, None] * np.array([0.0, 1.0, 1.0, 0.0])[None, :]
    v = v0[:, None] + sv[:, None] * np.array([0.0, 0.0, 1.0, 1.0])[None, :]
    return _map_square(quads, u, v)[0]


def tip_collapsed(quads: np.ndarray) -> np.ndarray:
    """(n, 4, 3) copy of ``quads`` whose triangles repeat the vertex opposite their shortest edge.

    The collapsed map of a triangle (a, b, c, c) fans its u-lines out of c and runs its v-lines
    parallel to ab, so parameter cells cut across the triangle only along ab. Collapsed at a
    needle's sharp tip, its v-lines cross the needle and about square cells fit along it
    (``Visibility._root_cells``); collapsed at a blunt corner, every line of both families runs
    along the needle and the cells stay as long as the needle is long. A floor triangle 2.6 m
    long and 8 cm wide, touching a cylinder's foot in a closed room, summed to 1 + 2.8e-6 with
    squares to 7 levels, its squared pairs still moving by 2e-6 at 8; collapsed at its tip, they
    agree to 1e-8 from 6 levels to 9 and the row closes. Quads, and triangles already collapsed
    at their tip, keep their corners.
    """
    q = np.array(quads, dtype=float)
    repeat = np.all(q == np.roll(q, -1, axis=1), axis=2)  # vertex k is vertex k + 1
    tri = np.flatnonzero(repeat.sum(axis=1) == 1)
    if not len(tri):
        return q
    first = (np.argmax(repeat[tri], axis=1)[:, None] + np.arange(1, 4)) % 4
    v = q[tri[:, None], first]  # the three corners in their cyclic order
    opposite = np.linalg.norm(v[:, [1, 2, 0]] - v[:, [2, 0, 1]], axis=2)
    tip = np.argmin(opposite, axis=1)
    q[tri] = v[np.arange(len(tri))[:, None], (tip[:, None] + np.array([1, 2, 0, 0])) % 3]
    return q


def _cell_sides(size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The (u, v) sides of parameter cells given as one side each (squares) or two."""
    size = np.asarray(size, dtype=float)
    return (size, size) if size.ndim == 1 else (size[:, 0], size[:, 1])


def _map_square(quads: np.ndarray, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points and area Jacobian of each patch's bilinear (or collapsed) map at (u, v).

    ``quads`` is (n, 4, 3); ``u`` and ``v`` are (n, q) or (1, q) parameters in [0, 1].
    Returns points (n, q, 3) and the Jacobian |dx/du x dx/dv| (n, q).

    Compiled: in numpy its temporaries took a tenth of a furnished room's hierarchical solve
    (the receivers' Gauss points of every link).
    """
    quads = np.ascontiguousarray(quads, dtype=np.float64)
    n = quads.shape[0]
    u, v = np.broadcast_arrays(np.asarray(u, np.float64), np.asarray(v, np.float64))
    if u.shape[0] != n and u.shape[0] != 1:
        raise ValueError(f"parameters of shape {u.shape} for {n} patches")
    points = np.empty((n, u.shape[1], 3))
    jac = np.empty((n, u.shape[1]))
    _map_square_loop(quads, np.ascontiguousarray(u), np.ascontiguousarray(v), points, jac)
    return points, jac


def _map_square_loop(quads, u, v, points, jac):
    """points = a + u ab + v (ad + u twist); jac = |j0 + u ju + v jv| (see :func:`_map_square`)."""
    step = 0 if u.shape[0] == 1 else 1  # one row of parameters for every patch, or one each
    for i in _prange(quads.shape[0]):
        row = i * step
        a, b, c, d = quads[i, 0], quads[i, 1], quads[i, 2], quads[i, 3]
        ab0, ab1, ab2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
        ad0, ad1, ad2 = d[0] - a[0], d[1] - a[1], d[2] - a[2]
        tw0, tw1, tw2 = a[0] - b[0] + c[0] - d[0], a[1] - b[1] + c[1] - d[1], a[2] - b[2] + c[2] - d[2]
        # dx/du x dx/dv = (ab + v twist) x (ad + u twist) is linear in u and v (twist x twist = 0)
        j00, j01, j02 = ab1 * ad2 - ab2 * ad1, ab2 * ad0 - ab0 * ad2, ab0 * ad1 - ab1 * ad0
        ju0, ju1, ju2 = ab1 * tw2 - ab2 * tw1, ab2 * tw0 - ab0 * tw2, ab0 * tw1 - ab1 * tw0
        jv0, jv1, jv2 = tw1 * ad2 - tw2 * ad1, tw2 * ad0 - tw0 * ad2, tw0 * ad1 - tw1 * ad0
        for k in range(u.shape[1]):
            uu, vv = u[row, k], v[row, k]
            points[i, k, 0] = a[0] + uu * ab0 + vv * (ad0 + uu * tw0)
            points[i, k, 1] = a[1] + uu * ab1 + vv * (ad1 + uu * tw1)
            points[i, k, 2] = a[2] + uu * ab2 + vv * (ad2 + uu * tw2)
            x, y, z = j00 + uu * ju0 + vv * jv0, j01 + uu * ju1 + vv * jv1, j02 + uu * ju2 + vv * jv2
            jac[i, k] = np.sqrt(x * x + z * z + y * y)  # numpy's einsum order: the same bits


_map_square_loop = _numba.njit(cache=True, parallel=True, fastmath=False)(_map_square_loop)


def _map_frame(frames: np.ndarray, s: np.ndarray, t: np.ndarray):
    """Parameters (u, v) and Jacobian |d(u, v)/d(s, t)| of bilinear frames (n, 4, 2) at (n, q)."""
    a, b, c, d = (frames[:, k, None, :] for k in range(4))
    ab, ad, twist = b - a, d - a, a - b + c - d
    uv = a + s[..., None] * ab + t[..., None] * (ad + s[..., None] * twist)

    def cross(x, y):
        return x[..., 0] * y[..., 1] - x[..., 1] * y[..., 0]

    jac = cross(ab, ad) + s * cross(ab, twist) + t * cross(twist, ad)
    return uv[..., 0], uv[..., 1], np.abs(jac)


def rect_points(quads: np.ndarray, rects: np.ndarray, order: int, frames: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """Gauss points and area weights on parameter rectangles of patches.

    Parameters
    ----------
    quads : (n, 4, 3) float
        One patch per rectangle; a triangle repeats its third vertex.
    rects : (n, 4) float
        ``(u0, v0, du, dv)``: the rectangle ``[u0, u0 + du] x [v0, v0 + dv]`` of the patch's
        parameter square, or of the frame's when ``frames`` is given.
    order : int
        Gauss-Legendre points per direction.
    frames : (n, 4, 2) float, optional
        The corners of a bilinear map of the unit square into the patch's parameter square, one
        per rectangle. A frame whose last two corners coincide is a Duffy (collapsed) triangle:
        an integrand that depends on the direction to that corner becomes smooth in the frame.

    Returns
    -------
    points : (n, order**2, 3) float
    weights : (n, order**2) float
        Weights sum to the area of each rectangle's image.
    """
    nodes, w = gauss_legendre_01(order)
    # one pass, no temporaries: numpy's ~25 passes (_rect_points_numpy) cost as much as the kernel
    n = len(rects)
    points, weights = np.empty((n, order * order, 3)), np.empty((n, order * order))
    _rect_points_loop(np.ascontiguousarray(quads, dtype=float), np.ascontiguousarray(rects, dtype=float),
                      np.zeros((0, 4, 2)) if frames is None else np.ascontiguousarray(frames, dtype=float),
                      nodes, w, points, weights)
    return points, weights


def _rect_points_loop(quads, rects, frames, nodes, w, points, weights):
    """Loop body of :func:`rect_points` (compiled by numba when available)."""
    order = nodes.shape[0]
    framed = frames.shape[0] > 0
    for r in range(rects.shape[0]):
        q = quads[r]
        ab, ad, tw = q[1] - q[0], q[3] - q[0], q[0] - q[1] + q[2] - q[3]
        j0 = np.cross(ab, ad)
        ju = np.cross(ab, tw)
        jv = np.cross(tw, ad)
        for a in range(order):
            s = rects[r, 0] + rects[r, 2] * nodes[a]
            for b in range(order):
                t = rects[r, 1] + rects[r, 3] * nodes[b]
                wt = rects[r, 2] * rects[r, 3] * w[a] * w[b]
                u, v = s, t
                if framed:
                    f = frames[r]
                    fab0, fab1 = f[1, 0] - f[0, 0], f[1, 1] - f[0, 1]
                    fad0, fad1 = f[3, 0] - f[0, 0], f[3, 1] - f[0, 1]
                    ftw0, ftw1 = f[0, 0] - f[1, 0] + f[2, 0] - f[3, 0], f[0, 1] - f[1, 1] + f[2, 1] - f[3, 1]
                    u = f[0, 0] + s * fab0 + t * (fad0 + s * ftw0)
                    v = f[0, 1] + s * fab1 + t * (fad1 + s * ftw1)
                    wt *= abs(fab0 * fad1 - fab1 * fad0 + s * (fab0 * ftw1 - fab1 * ftw0)
                              + t * (ftw0 * fad1 - ftw1 * fad0))
                k = a * order + b
                jac2 = 0.0
                for c in range(3):
                    points[r, k, c] = q[0, c] + u * ab[c] + v * (ad[c] + u * tw[c])
                    jc = j0[c] + u * ju[c] + v * jv[c]
                    jac2 += jc * jc
                weights[r, k] = wt * np.sqrt(jac2)


_rect_points_loop = _numba.njit(cache=True, fastmath=False)(_rect_points_loop)


def _inverse_map(quads: np.ndarray, points: np.ndarray, steps: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Parameters (u, v) of points on their patches (Gauss-Newton on the bilinear map)."""
    a, b, c, d = (quads[:, k] for k in range(4))
    ab, ad, twist = b - a, d - a, a - b + c - d
    u = np.full(len(points), 0.5)
    v = np.full(len(points), 0.5)
    for _ in range(steps):
        du, dv = ab + v[:, None] * twist, ad + u[:, None] * twist
        r = points - (a + u[:, None] * ab + v[:, None] * dv)
        g11, g12, g22 = (du * du).sum(1), (du * dv).sum(1), (dv * dv).sum(1)
        r1, r2 = (du * r).sum(1), (dv * r).sum(1)
        det = g11 * g22 - g12 * g12
        det = np.where(det > 0, det, np.inf)  # a triangle's collapsed corner: stay put
        u, v = u + (g22 * r1 - g12 * r2) / det, v + (g11 * r2 - g12 * r1) / det
    return u, v


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
_TINY = float(np.finfo(float).tiny)


def _radius(quads: np.ndarray, centroid: np.ndarray) -> np.ndarray:
    return np.linalg.norm(quads - centroid[:, None, :], axis=2).max(axis=1)


def _pair_setup(quads, normals, centroid, r_rec, s_cen, s_nrm, r_src, i, j, rtol):
    """Per pair (i, j): does receiver i cross source j's plane, and its a-priori Gauss order.

    ``crossing`` (m,) marks receivers with vertices more than ``1e-12 (r_rec + r_src)`` on both
    sides of the plane through the source's centre; ``order`` (m,) is the smallest of
    ``_APRIORI_ORDERS`` whose bound ``_APRIORI_C rho**(-2 p)`` meets ``rtol / _APRIORI_SAFETY``
    for pairs with rho > 1.5 that do not cross, else 0 (refine adaptively). rho is the distance
    from the receiver's centroid to the source's bounding sphere over the receiver's radius,
    times the smaller cosine between the normals and the centre line.

    A compiled loop over the pairs: in numpy these few flags took ~15 passes over (m, 4, 3) and
    (m, 3) gathers, ~1 s of the Cornell box fill's 4-5 s form-factor stage (the loop: 0.1 s).
    """
    m = len(i)
    i, j = np.ascontiguousarray(i, dtype=np.int64), np.ascontiguousarray(j, dtype=np.int64)
    crossing, order = np.empty(m, dtype=bool), np.empty(m, dtype=np.int64)
    orders = np.array(_APRIORI_ORDERS, dtype=np.int64)
    _pair_setup_loop(quads, normals, centroid, r_rec, s_cen, s_nrm, r_src, i, j, orders, rtol / _APRIORI_SAFETY,
          crossing, order)
    return crossing, order


def _pair_rho(quads, normals, centroid, r_rec, s_cen, s_nrm, r_src, a, b):
    """(rho, crossing) of receiver a and source b, as :func:`_pair_setup` defines them.

    The one place this geometry is computed: the fill's pair listing
    (``methods/uniform/_fill_kernel._apriori_order``) calls it too, so both choose the same orders.
    """
    d0, d1, d2 = s_cen[b, 0] - centroid[a, 0], s_cen[b, 1] - centroid[a, 1], s_cen[b, 2] - centroid[a, 2]
    dist = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    safe = max(dist, _TINY)
    u0, u1, u2 = d0 / safe, d1 / safe, d2 / safe
    cos_rec = abs(normals[a, 0] * u0 + normals[a, 1] * u1 + normals[a, 2] * u2)
    cos_src = abs(s_nrm[b, 0] * u0 + s_nrm[b, 1] * u1 + s_nrm[b, 2] * u2)
    rho = (dist - r_src[b]) / max(r_rec[a], _TINY) * min(cos_rec, cos_src)
    h_lo, h_hi = np.inf, -np.inf
    for k in range(quads.shape[1]):
        h = ((quads[a, k, 0] - s_cen[b, 0]) * s_nrm[b, 0] + (quads[a, k, 1] - s_cen[b, 1]) * s_nrm[b, 1]
             + (quads[a, k, 2] - s_cen[b, 2]) * s_nrm[b, 2])
        h_lo, h_hi = min(h_lo, h), max(h_hi, h)
    tol_h = 1e-12 * (r_rec[a] + r_src[b])
    return rho, (h_hi > tol_h and h_lo < -tol_h)


def _pair_setup_loop(quads, normals, centroid, r_rec, s_cen, s_nrm, r_src, i, j, orders, limit,
                     crossing, order):
    """Loop body of :func:`_pair_setup` (compiled by numba when available)."""
    for p in _prange(len(i)):
        rho, crossing[p] = _pair_rho(quads, normals, centroid, r_rec, s_cen, s_nrm, r_src, i[p], j[p])
        order[p] = 0
        if rho > 1.5 and not crossing[p]:
            for q in range(len(orders)):  # the bound falls with p: the first order meeting it
                if _APRIORI_C * rho ** (-2.0 * orders[q]) <= limit:
                    order[p] = orders[q]
                    break


def _receiver_heights(quads, s_cen, s_nrm, i, j):
    """(m, 4) heights of receiver i's vertices above the plane through source j's centre."""
    return np.einsum("mkc,mc->mk", quads[i] - s_cen[j][:, None, :], s_nrm[j])


_pair_rho = _numba.njit(cache=True, inline="always", error_model="numpy")(_pair_rho)
_pair_setup_loop = _numba.njit(cache=True, parallel=True, error_model="numpy")(_pair_setup_loop)


def _evaluate(rquads, rnormals, sources, i, j, order, splits, mode):
    """F(i -> j) with a fixed rule on the receiver, via the fused numba quadrature kernel."""
    out = np.empty(len(i))
    if not len(i):
        return out
    uniq, slot = np.unique(i, return_inverse=True)
    if order == 1 and splits == 1:
        pts, w = patch_points(rquads[uniq], 1)
    else:
        pts, w = split_patch_points(rquads[uniq], order, splits)
    return _weighted_means(pts, rnormals[uniq], w, slot, sources, j, mode)


def _weighted_means(pts, nrm, w, slot, sources, j, mode):
    """sum_q w F(pts[slot, q] -> sources[j]) / sum_q w for each pair (slot, j).

    ``pts`` (u, nq, 3) and ``w`` (u, nq) are the points and weights of u receiver pieces,
    ``nrm`` (u, 3) their normals; ``slot`` and ``j`` (t,) pick a piece and a source per pair.
    """
    out = np.empty(len(slot))
    nq = pts.shape[1]
    flat = np.ascontiguousarray(pts.reshape(-1, 3))
    normals = np.ascontiguousarray(np.repeat(nrm, nq, axis=0))
    if sources.shape[1] <= 4:
        # grouped by source, so that each source meets its receivers' points in SIMD lanes together
        order = np.argsort(j, kind="stable")
        sorted_out = np.empty(len(slot))
        _quadrature_source_kernel(flat, normals, np.ascontiguousarray(w.reshape(-1)), nq,
                                  slot[order].astype(np.int64), np.ascontiguousarray(sources),
                                  np.ascontiguousarray(j[order], dtype=np.int64), _MODES[mode], sorted_out)
        out[order] = sorted_out
        return out
    _quadrature_kernel(flat, normals, np.ascontiguousarray(w.reshape(-1)), nq, slot.astype(np.int64),
                       np.ascontiguousarray(sources), np.ascontiguousarray(j, dtype=np.int64),
                       _MODES[mode], out)
    return out


# --- Adaptive refinement of near pairs ----------------------------------------------------------
# A near pair's receiver is cut into pieces, rectangles (u0, v0, du, dv) of a frame: the receiver's
# parameter square itself, or a Duffy triangle of it collapsed at a source vertex that touches the
# receiver (there Lambert's integrand depends on the direction to the vertex, which the collapse
# makes smooth, so those pieces converge like smooth ones instead of only with their area).
# Next to its own Gauss integral Q, each piece carries the integrals over its two u-halves and its
# two v-halves (same order): |Q(u-halves) - Q| and |Q(v-halves) - Q| estimate Q's error along u
# and along v. A piece whose error exceeds its share of the pair's tolerance is split along the
# direction(s) with the error, so refinement grades itself towards a thin layer (cuts across it
# only) or a corner (cuts both ways), and a split along one direction reuses the halves as the
# children's Q.

# Gauss points per direction on each piece, by rtol: low orders refine layers in smaller steps
# and cost less per estimate, high orders need fewer pieces where the integrand is smooth. This
# table gave the fewest points on the Cornell box's near pairs (order 3 at 1e-4: 45 points a
# pair instead of 71 with order 4; order 3 at 1e-6 missed by 8x rtol) and on the closed-form
# cases of docs/formfactors.md (order 6 below 1e-7: 12% fewer points than order 8).
_ADAPT_ORDERS = ((1e-5, 3), (1e-7, 4), (0.0, 6))  # (smallest rtol, order)

# Fraction of a pair's tolerance shared out among its pieces by frame area: a piece below its
# share is final; the rest of the tolerance absorbs pieces whose error shrinks with their area
# only (a kink or a singularity that no frame smooths), so a purely local test would never stop.
_ADAPT_SHARE = 0.5

# A piece is split along u (v) when that direction carries at least this fraction of its error.
_ADAPT_DIRECTION = 0.2

# Near misses: a source edge a small height g above the receiver's plane makes a layer of width
# ~g in the integrand that Gauss points farther than ~g from it do not see, so every estimate
# agrees and is wrong (parallel squares 0.001 apart: estimate 4e-5, error 2e-3). Pieces are
# therefore split, whatever their estimate, along a direction in which they extend further than
# _ADAPT_REACH times their centre's distance to such an edge (counting only the extent across the
# edge) or to such a vertex, until their extent is _ADAPT_LAYER times the edge's (vertex's)
# height: then the halves' Gauss points fall inside the layer and the estimates take over. The
# usual neighbours in a mesh (a wall patch one row above a floor patch) are never forced. A
# vertex on the receiver's plane is a point singularity: pieces of its Duffy frames need no
# forcing, but plain pieces are graded towards it the same way (without end), which catches a
# touching vertex just outside the receiver or just beside a piece's corner.
_ADAPT_REACH = 1.0
_ADAPT_LAYER = 8.0

# Pieces are not split below this width in their frame (about 1e-12 of the patch), nor past this
# many receiver points per pair when the caller gives no budget.
_ADAPT_MIN_SIDE = 2.0**-40
_ADAPT_MAX_POINTS = 1 << 20

# Relative distance (to the pair's size) within which a source vertex touches the receiver.
_TOUCH_REL = 1e-9

# Duffy frames hold smooth integrands: two orders more there saves pieces (closed cube of 96
# patches at rtol 1e-6: 90 points a pair instead of 96; T-junction cases: 9% fewer points).
_DUFFY_ORDER_STEP = 2

_UNIT_RECT = np.array([0.0, 0.0, 1.0, 1.0])
_IDENTITY_FRAME = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


def _adapt_order(rtol: float) -> int:
    return next(order for smallest, order in _ADAPT_ORDERS if rtol >= smallest)


def _halves(rects: np.ndarray) -> np.ndarray:
    """(n, 4, 4): the u-halves, then the v-halves of each rectangle (u0, v0, du, dv)."""
    u0, v0, du, dv = rects.T
    return np.stack([np.column_stack(r) for r in ((u0, v0, du / 2, dv), (u0 + du / 2, v0, du / 2, dv),
                                                  (u0, v0, du, dv / 2), (u0, v0 + dv / 2, du, dv / 2))], axis=1)


def _quarters(rects: np.ndarray) -> np.ndarray:
    """(n, 4, 4): the four quarters of each rectangle."""
    u0, v0, du, dv = rects.T
    return np.stack([np.column_stack((u0 + a * du / 2, v0 + b * dv / 2, du / 2, dv / 2))
                     for a, b in ((0, 0), (1, 0), (0, 1), (1, 1))], axis=1)


def _root_integrals(quads, normals, sources, i, j, order, mode):
    """Integrals of F_pt over the whole receiver and its four halves (m, 5), and its area (m,).

    Receivers repeat across pairs, so their points are made once per receiver."""
    rects = np.vstack([_UNIT_RECT, _halves(_UNIT_RECT[None])[0]])
    if not len(i):
        return np.zeros((0, len(rects))), np.zeros(0)
    uniq, slot = np.unique(i, return_inverse=True)
    r = len(rects)
    pts, w = rect_points(np.repeat(quads[uniq], r, axis=0), np.tile(rects, (len(uniq), 1)), order)
    wsum = w.sum(axis=1)
    slots = (slot[:, None] * r + np.arange(r)).ravel()
    means = _weighted_means(pts, np.repeat(normals[uniq], r, axis=0), w, slots, sources, np.repeat(j, r), mode)
    return (means * wsum[slots]).reshape(-1, r), wsum[slot * r]


def _piece_integrals(quads, normals, sources, rec, src, rects, frame, frames, orders, mode):
    """Integrals of F(x -> sources[src]) over rectangles of frames ``frames[frame]`` (0 is the
    identity) of receivers ``rec``, and the rectangles' areas. ``orders`` are the Gauss orders
    in the identity frame and in the others."""
    from .. import _tol

    out, area = np.empty(len(rec)), np.empty(len(rec))
    for rows, order in zip((np.flatnonzero(frame == 0), np.flatnonzero(frame != 0)), orders):
        chunk = max(1, _tol.CHUNK_PAIRS // order**2)
        for lo in range(0, len(rows), chunk):
            sl = rows[lo:lo + chunk]
            fr = frames[frame[sl]] if frame[sl[0]] else None
            pts, w = rect_points(quads[rec[sl]], rects[sl], order, fr)
            area[sl] = w.sum(axis=1)
            out[sl] = _weighted_means(pts, normals[rec[sl]], w, np.arange(len(sl)), sources, src[sl], mode) * area[sl]
    return out, area


def _source_heights(quads, normals, sources, i, j, size):
    """(m, k) heights of the source vertices above each receiver's plane, 0 where touching it."""
    height = np.einsum("mkc,mc->mk", sources[j] - quads[i][:, :1], normals[i])
    return np.where(height > _TOUCH_REL * size[:, None], height, 0.0)


def _near_flags(quads, sources, i, j, height, size):
    """(m,) flags of near pairs from their source heights (:func:`_source_heights`).

    ``lifted``: a source vertex lies above the receiver's plane but below ``2 size /
    _ADAPT_LAYER``; ``touching``: a vertex touching the plane lies within twice the receiver's
    radius of its vertex mean; ``collapsed``: the receiver is a triangle (its last two vertices
    coincide) and a touching vertex lies on that collapsed corner.

    A compiled loop over the pairs: numpy needs ~20 passes over (m, k, 3) gathers for them
    (0.4 s of the Cornell box fill's form factors; the loop: 0.01 s).
    """
    m = len(i)
    lifted, touching, collapsed = np.empty(m, dtype=bool), np.empty(m, dtype=bool), np.empty(m, dtype=bool)
    _near_flags_loop(quads, sources, i, j, height, size, lifted, touching, collapsed)
    return lifted, touching, collapsed


def _near_flags_loop(quads, sources, i, j, height, size, lifted, touching, collapsed):
    """Loop body of :func:`_near_flags` (compiled by numba when available)."""
    nv = quads.shape[1]
    for p in _prange(len(i)):
        a, b = i[p], j[p]
        centre = np.zeros(3)
        for k in range(nv):
            centre += quads[a, k]
        centre /= nv
        radius = 0.0
        for k in range(nv):
            radius = max(radius, _distance(quads[a, k], centre))
        touch = _TOUCH_REL * size[p]
        on_corner = _distance(quads[a, 2], quads[a, 3]) <= touch
        lifted[p] = touching[p] = collapsed[p] = False
        for k in range(sources.shape[1]):
            h = height[p, k]
            lifted[p] |= h > 0 and h < 2 * size[p] / _ADAPT_LAYER
            if h == 0:
                touching[p] |= _distance(sources[b, k], centre) < 2 * radius
                collapsed[p] |= on_corner and _distance(sources[b, k], quads[a, 3]) <= touch


def _distance(x, y):
    d0, d1, d2 = x[0] - y[0], x[1] - y[1], x[2] - y[2]
    return np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


_distance = _numba.njit(cache=True, inline="always")(_distance)
_near_flags_loop = _numba.njit(cache=True, parallel=True, error_model="numpy")(_near_flags_loop)


def _singular_points(quads, sources, height, size):
    """Pairs and receiver parameters (u, v) of the source vertices touching the receivers.

    A triangle's collapsed corner is skipped: its Duffy map already smooths a singularity there."""
    if not (height == 0).any():
        return np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0)
    centre = quads.mean(axis=1)
    radius = np.linalg.norm(quads - centre[:, None, :], axis=2).max(axis=1)
    reach = np.linalg.norm(sources - centre[:, None, :], axis=2) <= radius[:, None] * (1 + 1e-6)
    p, k = np.nonzero((height == 0) & reach)
    q, x = quads[p], sources[p, k]
    u, v = _inverse_map(q, x)
    y, _ = _map_square(q, u[:, None], v[:, None])
    tol = _TOUCH_REL * size[p]
    on = (np.linalg.norm(y[:, 0] - x, axis=1) <= tol) & (np.minimum(u, v) >= -1e-9) & (np.maximum(u, v) <= 1 + 1e-9)
    collapsed = (np.linalg.norm(q[:, 2] - q[:, 3], axis=1) <= tol) & (np.linalg.norm(x - q[:, 3], axis=1) <= tol)
    keep = on & ~collapsed
    uv = np.clip(np.column_stack([u[keep], v[keep]]), 0.0, 1.0)
    uv = np.where(uv < 1e-9, 0.0, np.where(uv > 1 - 1e-9, 1.0, uv))
    rows = np.unique(np.column_stack([p[keep], uv]), axis=0)
    return rows[:, 0].astype(np.int64), rows[:, 1], rows[:, 2]


def _merge_cuts(pair, coord, tag, n):
    """Sorted distinct cuts of n pairs' parameter ranges [0, 1] (0 and 1 added) from cuts
    ``coord`` of pairs ``pair``; ``tag`` >= 0 marks singular coordinates (by point index).

    Returns the cuts' pairs, coordinates, singular flags, and each tagged point's cut index."""
    p = np.concatenate([pair, np.repeat(np.arange(n), 2)])
    c = np.concatenate([coord, np.tile([0.0, 1.0], n)])
    tag = np.concatenate([tag, np.full(2 * n, -1)])
    order = np.lexsort((c, p))
    p, c, tag = p[order], c[order], tag[order]
    first = np.r_[True, (p[1:] != p[:-1]) | (c[1:] != c[:-1])]
    group = np.cumsum(first) - 1
    singular = np.zeros(group[-1] + 1, dtype=bool)
    singular[group[tag >= 0]] = True
    where = np.zeros(tag.max() + 1, dtype=np.int64)
    where[tag[tag >= 0]] = group[tag >= 0]
    return p[first], c[first], singular, where


def _cuts(pair, coord, n):
    """Cuts of n pairs' parameter ranges: 0, 1, the singular coordinates, and the midpoint of two
    consecutive singular ones (so that no cell of the grid has two singular corners)."""
    tag = np.arange(len(pair))
    cut_pair, cut, singular, _ = _merge_cuts(pair, coord, tag, n)
    both = (cut_pair[1:] == cut_pair[:-1]) & singular[1:] & singular[:-1]
    mid_pair, mid = cut_pair[1:][both], (cut[1:][both] + cut[:-1][both]) / 2
    cut_pair, cut, _, where = _merge_cuts(np.r_[pair, mid_pair], np.r_[coord, mid],
                                          np.r_[tag, np.full(len(mid), -1)], n)
    return cut_pair, cut, where


def _grid_cells(u_pair, v_pair, n):
    """Cells of each pair's grid of cuts: their pair and the cut indices of their low corner."""
    iu = np.flatnonzero(u_pair[1:] == u_pair[:-1])
    iv = np.flatnonzero(v_pair[1:] == v_pair[:-1])
    nu, nv = np.bincount(u_pair[iu], minlength=n), np.bincount(v_pair[iv], minlength=n)
    count = nu * nv
    cell_pair = np.repeat(np.arange(n), count)
    k = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    a = iu[(np.cumsum(nu) - nu)[cell_pair] + k // nv[cell_pair]]
    b = iv[(np.cumsum(nv) - nv)[cell_pair] + k % nv[cell_pair]]
    return cell_pair, a, b


def _singular_pieces(quads, pair, u, v, n):
    """First pieces of pairs with singular points: the grid of cuts through the points, each cell
    with a singular corner made about square (the rest of a long cell becomes a plain cell) and
    cut into two Duffy triangles collapsed on that corner. (A long cell would give a needle whose
    frame crowds the directions from the point into a thin layer that the estimates miss: a
    T-junction 1e-4 from a receiver's corner on the Cornell box was 3x rtol off. The plain rest
    is graded towards the point by :func:`_forced_splits`.)

    ``quads`` (n, 4, 3) are the pairs' receivers. Returns the pieces' pairs (into 0..n-1),
    rectangles, frames, and which are Duffy triangles."""
    if n == 0:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 4)), np.zeros((0, 4, 2)), np.zeros(0, dtype=bool)
    u_pair, u_cut, su = _cuts(pair, u, n)
    v_pair, v_cut, sv = _cuts(pair, v, n)
    cell_pair, a, b = _grid_cells(u_pair, v_pair, n)
    ca, cb = np.stack([a, a + 1, a + 1, a], axis=1), np.stack([b, b, b + 1, b + 1], axis=1)
    singular = np.isin(ca * len(v_cut) + cb, su * len(v_cut) + sv)
    rects = np.column_stack([u_cut[a], v_cut[b], u_cut[a + 1] - u_cut[a], v_cut[b + 1] - v_cut[b]])
    duffy = singular.any(axis=1)
    corner = np.argmax(singular, axis=1)  # 0..3 counter-clockwise from (u0, v0)
    rects, corner, cell_pair, duffy = _square_at_corner(quads[cell_pair], rects, corner, cell_pair, duffy)
    plain = ~duffy
    c = _rect_corners(rects[duffy])
    roll = (corner[duffy][:, None] + np.arange(4)) % 4
    c = np.take_along_axis(c, roll[..., None], axis=1)  # singular corner first
    tri = [np.stack([c[:, k], c[:, k + 1], c[:, 0], c[:, 0]], axis=1) for k in (1, 2)]
    n_plain, n_duffy = plain.sum(), 2 * duffy.sum()
    frames = np.concatenate([np.broadcast_to(_IDENTITY_FRAME, (n_plain, 4, 2))] + tri)
    rects = np.concatenate([rects[plain], np.broadcast_to(_UNIT_RECT, (n_duffy, 4))])
    is_duffy = np.r_[np.zeros(n_plain, dtype=bool), np.ones(n_duffy, dtype=bool)]
    return np.concatenate([cell_pair[plain], np.tile(cell_pair[duffy], 2)]), rects, frames, is_duffy


def _rect_corners(rects):
    """(n, 4, 2) corners of rectangles (u0, v0, du, dv), counter-clockwise from (u0, v0)."""
    u0, v0, du, dv = rects.T
    return np.stack([np.column_stack(c) for c in ((u0, v0), (u0 + du, v0), (u0 + du, v0 + dv), (u0, v0 + dv))],
                    axis=1)


def _square_at_corner(quads, rects, corner, cell_pair, duffy):
    """Cut each Duffy cell over twice as long as wide (on the receiver) into a square at its
    singular ``corner`` (still Duffy) and the rest (plain)."""
    x = _rect_corners(rects)
    at = np.take_along_axis(x, corner[:, None, None], axis=1)[:, 0]
    a, b, c, d = (quads[:, k] for k in range(4))
    du = rects[:, 2] * np.linalg.norm((1 - at[:, 1, None]) * (b - a) + at[:, 1, None] * (c - d), axis=1)
    dv = rects[:, 3] * np.linalg.norm((1 - at[:, 0, None]) * (d - a) + at[:, 0, None] * (c - b), axis=1)
    long_u = duffy & (du > 2 * dv)
    long_v = duffy & (dv > 2 * du)
    keep_u = np.where(long_u, rects[:, 2] * dv / np.where(du > 0, du, 1.0), rects[:, 2])  # square's u side
    keep_v = np.where(long_v, rects[:, 3] * du / np.where(dv > 0, dv, 1.0), rects[:, 3])
    high_u, high_v = np.isin(corner, (1, 2)), np.isin(corner, (2, 3))  # corner at u0 + du, v0 + dv
    square = rects.copy()
    square[:, 0] += np.where(high_u, rects[:, 2] - keep_u, 0.0)
    square[:, 1] += np.where(high_v, rects[:, 3] - keep_v, 0.0)
    square[:, 2], square[:, 3] = keep_u, keep_v
    rest = rects.copy()
    rest[:, 0] += np.where(long_u & ~high_u, keep_u, 0.0)
    rest[:, 2] -= np.where(long_u, keep_u, 0.0)
    rest[:, 1] += np.where(long_v & ~high_v, keep_v, 0.0)
    rest[:, 3] -= np.where(long_v, keep_v, 0.0)
    cut = long_u | long_v
    return (np.concatenate([square, rest[cut]]), np.concatenate([corner, corner[cut]]),
            np.concatenate([cell_pair, cell_pair[cut]]), np.concatenate([duffy, np.zeros(cut.sum(), dtype=bool)]))


def _forced_splits(quads, sources, height, rects, frames, plain, at_collapse):
    """(n,) u and v masks: pieces too wide for their distance to a near-miss edge or vertex, or
    (``plain`` pieces, in the identity frame) to a touching vertex.

    ``quads`` (n, 4, 3) and ``sources`` (n, k, 3) are each piece's receiver and source,
    ``height`` (n, k) the source vertices' heights above the receiver's plane (0: touching).
    An edge rising from a touching vertex is ignored by pieces closer to that vertex than their
    extent, where its layer narrows with the distance and cutting cannot catch up with it, except
    by pieces ``at_collapse`` of a Duffy frame on the vertex, which it makes smooth (they are
    cut across the directions from the vertex only, by the caller)."""
    uc, vc = rects[:, 0] + rects[:, 2] / 2, rects[:, 1] + rects[:, 3] / 2
    u = np.column_stack([uc, rects[:, 0], rects[:, 0] + rects[:, 2], uc, uc])
    v = np.column_stack([vc, vc, vc, rects[:, 1], rects[:, 1] + rects[:, 3]])
    u, v, _ = _map_frame(frames, u, v)
    x, _ = _map_square(quads, u, v)
    centre, extent_u, extent_v = x[:, 0], x[:, 2] - x[:, 1], x[:, 4] - x[:, 3]
    rel = centre[:, None, :] - sources  # (n, k, 3)
    edge = np.roll(sources, -1, axis=1) - sources
    length2 = np.einsum("nkc,nkc->nk", edge, edge)
    t = np.clip(np.einsum("nkc,nkc->nk", rel, edge) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
    d_edge = np.linalg.norm(rel - t[..., None] * edge, axis=-1)
    h_edge = (1 - t) * height + t * np.roll(height, -1, axis=1)  # the layer's width near the centre
    lifted = (height > 0) | (np.roll(height, -1, axis=1) > 0)  # not lying in the receiver's plane
    d_vert = np.linalg.norm(rel, axis=-1)
    unit = edge / np.sqrt(np.where(length2 > 0, length2, 1.0))[..., None]
    force = []
    for extent in (extent_u, extent_v):
        across = np.linalg.norm(np.cross(extent[:, None, :], unit), axis=-1)
        along = np.linalg.norm(extent, axis=-1)[:, None]
        near_end = (height == 0) & (d_vert < along)
        from_end = (near_end | np.roll(near_end, -1, axis=1)) & ~at_collapse[:, None]
        by_edge = lifted & ~from_end & (_ADAPT_REACH * across > d_edge) & (across > _ADAPT_LAYER * h_edge)
        by_vert = (height > 0) & (_ADAPT_REACH * along > d_vert) & (along > _ADAPT_LAYER * height)
        by_touch = plain[:, None] & (height == 0) & (_ADAPT_REACH * along > d_vert)
        force.append((by_edge | by_vert | by_touch).any(axis=1))
    return force[0], force[1]


def _within_budget(pair, err, cost, room):
    """Which of the pieces (with their cost) fit in their pair's room, the worst pieces first."""
    order = np.lexsort((-err, pair))
    c = np.cumsum(cost[order])
    p = pair[order]
    first = np.r_[0, np.flatnonzero(p[1:] != p[:-1]) + 1]
    start = np.repeat(c[first] - cost[order][first], np.diff(np.r_[first, len(p)]))
    fits = np.empty(len(pair), dtype=bool)
    fits[order] = c - start <= room[p]
    return fits


def _split_pieces(pair, frame, rects, h, split_u, split_v):
    """Children of the pieces to split: pair, frame, rectangle, and Q (NaN for the quarters)."""
    both = split_u & split_v
    only_u, only_v = split_u & ~both, split_v & ~both
    halves = _halves(rects)
    kid_pair = np.concatenate([np.repeat(pair[only_u], 2), np.repeat(pair[only_v], 2), np.repeat(pair[both], 4)])
    kid_frame = np.concatenate([np.repeat(frame[only_u], 2), np.repeat(frame[only_v], 2), np.repeat(frame[both], 4)])
    kid_rect = np.concatenate([halves[only_u, :2].reshape(-1, 4), halves[only_v, 2:].reshape(-1, 4),
                               _quarters(rects[both]).reshape(-1, 4)])
    kid_q = np.concatenate([h[only_u, :2].ravel(), h[only_v, 2:].ravel(), np.full(4 * both.sum(), np.nan)])
    return kid_pair, kid_frame, kid_rect, kid_q


def _first_pieces(quads, normals, sources, i, j, height, size, orders, cap, mode):
    """Starting pieces of every pair with their Q and halves: the whole receiver, or for pairs
    with touching source vertices the Duffy grid of :func:`_singular_pieces` (where it fits in
    the pair's budget ``cap``).

    Returns piece pair, frame index, rectangle, Q, halves (n, 4), the frames (f, 4, 2) and the
    receivers' areas (m,)."""
    m = len(i)
    sp, su, sv = _singular_points(quads[i], sources[j], height, size)
    special = np.unique(sp)
    s_pair, s_rect, s_frame, duffy = _singular_pieces(quads[i[special]], np.searchsorted(special, sp), su, sv,
                                                      len(special))
    s_pair = special[s_pair]
    cost = np.bincount(s_pair, np.where(duffy, 5 * orders[1] ** 2, 5 * orders[0] ** 2), minlength=m)
    fits = (cost <= cap)[s_pair]
    s_pair, s_rect, s_frame, duffy = s_pair[fits], s_rect[fits], s_frame[fits], duffy[fits]
    plain = np.flatnonzero(np.bincount(s_pair, minlength=m) == 0)
    area = np.zeros(m)
    values, area[plain] = _root_integrals(quads, normals, sources, i[plain], j[plain], orders[0], mode)
    s_id = np.where(duffy, np.cumsum(duffy), 0)  # plain cells stay in the identity frame 0
    frames = np.concatenate([_IDENTITY_FRAME[None], s_frame[duffy]])
    todo = np.concatenate([s_rect[:, None, :], _halves(s_rect)], axis=1).reshape(-1, 4)
    owner = np.repeat(s_pair, 5)
    s_values, s_area = _piece_integrals(quads, normals, sources, i[owner], j[owner], todo, np.repeat(s_id, 5),
                                        frames, orders, mode)
    np.add.at(area, s_pair, s_area[::5])
    pair = np.concatenate([plain, s_pair])
    frame = np.concatenate([np.zeros(len(plain), dtype=np.int64), s_id])
    rects = np.concatenate([np.broadcast_to(_UNIT_RECT, (len(plain), 4)), s_rect])
    values = np.concatenate([values, s_values.reshape(-1, 5)])
    return pair, frame, rects, values[:, 0], values[:, 1:], frames, area


def _estimates(q, h):
    """Each piece's refined integral (Q corrected along u and along v) and Q's error along u, v."""
    err_u = np.abs(h[:, 0] + h[:, 1] - q)
    err_v = np.abs(h[:, 2] + h[:, 3] - q)
    return h.sum(axis=1) - q, err_u, err_v


def _forced_near_misses(quads, sources, i, j, height, pair, frame, rects, frames, collapsed):
    """(n,) u and v masks of :func:`_forced_splits` for pieces of near-miss pairs; ``collapsed``
    (m,) marks pairs whose receiver is a triangle with a touching vertex on its collapsed corner."""
    from .. import _tol

    # a layer widening from a touching vertex (an edge rising from it) looks the same at every
    # distance from the vertex: cutting towards it (along v in its Duffy frame, or in a receiver
    # triangle's own collapsed map) never resolves it, cutting across the directions from it
    # (along u) does
    at_vertex = ((frame > 0) | collapsed[pair]) & (rects[:, 1] + rects[:, 3] >= 1)
    force_u, force_v = np.empty(len(pair), dtype=bool), np.empty(len(pair), dtype=bool)
    chunk = _tol.CHUNK_PAIRS // 4  # (chunk, k, 3) temporaries stay ~20 MB
    for lo in range(0, len(pair), chunk):
        sl, p = slice(lo, lo + chunk), pair[lo:lo + chunk]
        force_u[sl], force_v[sl] = _forced_splits(quads[i[p]], sources[j[p]], height[p], rects[sl],
                                                  frames[frame[sl]], frame[sl] == 0, at_vertex[sl])
    return force_u, force_v & ~at_vertex


def _adaptive_factors(quads, normals, sources, i, j, *, rtol, cap, size, mode):
    """F(i -> j) of near pairs by adaptive refinement of receiver pieces.

    ``cap`` (m,) is each pair's budget of receiver points, ``size`` (m,) its scale (receiver plus
    source radius). Returns the factors (m,), the receiver points evaluated per pair (m,) and
    whether each pair's error estimate met ``rtol * F + PAIR_ATOL`` (m,).
    """
    from .. import _tol

    m = len(i)
    order = min(_adapt_order(rtol), max(1, int(np.sqrt(cap.min() / 5))))  # the first estimate fits
    orders = (order, order + _DUFFY_ORDER_STEP)
    height = _source_heights(quads, normals, sources, i, j, size)
    lifted, touching, collapsed = _near_flags(quads, sources, i, j, height, size)
    pair, frame, rects, q, h, frames, area = _first_pieces(quads, normals, sources, i, j, height, size, orders,
                                                           cap, mode)
    points = np.where(frame == 0, orders[0] ** 2, orders[1] ** 2)  # per rectangle, by frame
    used = np.bincount(pair, 5 * points, minlength=m).astype(np.int64)
    frame_area = _map_frame(frames, np.full((len(frames), 1), 0.5), np.full((len(frames), 1), 0.5))[2][:, 0]
    done_val, done_err = np.zeros(m), np.zeros(m)
    starved = np.zeros(m, dtype=bool)
    atol = _tol.PAIR_ATOL * area
    while len(pair):
        best, err_u, err_v = _estimates(q, h)
        err = err_u + err_v
        tau = rtol * np.abs(done_val + np.bincount(pair, best, m)) + atol
        share = _ADAPT_SHARE * tau[pair] * rects[:, 2] * rects[:, 3] * frame_area[frame]
        split = (done_err + np.bincount(pair, err, m) > tau)[pair] & (err > share)
        split_u = split & (err_u >= _ADAPT_DIRECTION * err)
        split_v = split & (err_v >= _ADAPT_DIRECTION * err)
        sel = np.flatnonzero(lifted[pair] | (touching[pair] & (frame == 0)))
        if len(sel):
            force_u, force_v = _forced_near_misses(quads, sources, i, j, height, pair[sel], frame[sel], rects[sel],
                                                   frames, collapsed)
            split_u[sel] |= force_u
            split_v[sel] |= force_v
        wanted = split_u | split_v
        split_u &= rects[:, 2] > _ADAPT_MIN_SIDE
        split_v &= rects[:, 3] > _ADAPT_MIN_SIDE
        cost = np.where(split_u & split_v, 20, 8) * (split_u | split_v) * points
        split = (split_u | split_v) & _within_budget(pair, err, cost, cap - used)
        starved[pair[wanted & ~split]] = True  # (a forced split left out can hide an error)
        done_val += np.bincount(pair[~split], best[~split], m)
        done_err += np.bincount(pair[~split], err[~split], m)
        used += np.bincount(pair[split], cost[split], m).astype(np.int64)
        pair, frame, rects, q = _split_pieces(pair[split], frame[split], rects[split], h[split],
                                              split_u[split], split_v[split])
        q, h = _complete_pieces(quads, normals, sources, i[pair], j[pair], frame, rects, q, frames, orders, mode)
        points = np.where(frame == 0, orders[0] ** 2, orders[1] ** 2)
    converged = (done_err <= rtol * np.abs(done_val) + atol) & ~starved
    return done_val / np.where(area > 0, area, 1.0), used, converged


def _complete_pieces(quads, normals, sources, rec, src, frame, rects, q, frames, orders, mode):
    """Q where missing (NaN) and the four halves' integrals (n, 4) of new pieces."""
    unknown = np.flatnonzero(np.isnan(q))
    todo = np.concatenate([rects[unknown], _halves(rects).reshape(-1, 4)])
    owner = np.concatenate([unknown, np.repeat(np.arange(len(rects)), 4)])
    vals, _ = _piece_integrals(quads, normals, sources, rec[owner], src[owner], todo, frame[owner], frames, orders, mode)
    q = q.copy()
    q[unknown] = vals[:len(unknown)]
    return q, vals[len(unknown):].reshape(-1, 4)


def _clipped_receivers(quads, normals, srcs, i, j, height, *, rtol, max_points, mode):
    """F(i -> j) for receivers straddling the source's plane: only their front part counts.

    Each receiver is clipped to height >= 0 above the source's plane (up to 5 vertices),
    fanned into triangles, and each triangle is integrated as a receiver of its own; the
    results are combined by area.
    """
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
                           sources=srcs, return_info=True, max_points=max_points, mode=mode, _clipped=True)
    out = np.zeros(len(i))
    np.add.at(out, pair, f * p_area)
    used = np.zeros(len(i), dtype=np.int64)
    np.add.at(used, pair, info["points"])
    converged = np.ones(len(i), dtype=bool)
    np.logical_and.at(converged, pair, info["converged"])
    return out / np.where(rec_area > 0, rec_area, 1.0), used, converged


def _src_normals(polys: np.ndarray) -> np.ndarray:
    return polygon_normals(polys)


def pair_factors(quads, normals, centroid, area, i, j, *, rtol: float = 1e-6, sources=None,
                 return_info: bool = False, max_points: int | None = None, mode: str = "auto",
                 _clipped: bool = False):
    """Unoccluded F(i -> j) for many patch pairs, each to a relative tolerance.

    F(i -> j) = (1/A_i) ∫_{A_i} F_pt(x -> P_j) dA, with Lambert's closed form for the inner
    factor (:func:`radiosity.formfactors.lambert_pairs`), i.e. the semantics of
    ``assembly.unoccluded_factors``. Each pair gets its own rule:

    - well separated pairs (receiver far from the source's bounding sphere compared with its
      own size) take the cheapest Gauss order that an a-priori bound says meets ``rtol``
      (the centroid alone when far enough);
    - the others (near, touching, sharing an edge or a vertex, or with the receiver inside the
      source's bounding sphere) are refined adaptively: the receiver's parameter square is cut
      into pieces, each with its Gauss integral and an error estimate from its halves, and the
      pieces whose error exceeds their share of ``rtol * F + PAIR_ATOL`` are split along the
      direction(s) that carry the error, until the pair's summed estimate meets it. Source
      vertices touching the receiver (T-junctions, shared corners) start a grid of Duffy
      triangles collapsed on them, which makes the integrand smooth there; pieces near a source
      edge or vertex that passes just above the receiver are split down to that height
      whatever their estimate (see the notes in the source).

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
        Also return a dict with the points each pair used and whether it converged.
    max_points : int, optional
        Most receiver points one pair may evaluate, at least 5 (for a receiver crossing the
        source's plane: per part of it). Refinement stops there, unconverged, after spending
        the budget on the worst pieces; the Gauss orders are lowered when even the first
        estimate would not fit. None allows up to 2**20 points.
    mode : {"auto", "fill"}, default: "auto"
        The point kernel's mode. ``"fill"`` leaves out its grazing forms (for sources seen just
        above a receiver point's horizon or nearly edge-on), whose raw-sum stand-in errs by
        ~1e-16 absolute per point: negligible unless F itself is below ~1e-16 / rtol. The
        matrix fill uses it; the grazing forms cost it a third of its time on the Cornell box.

    Returns
    -------
    (m,) float
        F(i -> j), the fraction of the power leaving patch i's front that reaches patch j.
    info : dict
        Only with ``return_info``: ``"points"`` (m,) receiver points evaluated (every estimate
        counted), ``"converged"`` (m,) bool (False where the error estimate did not meet the
        tolerance within ``max_points``).

    Examples
    --------
    Two perpendicular unit squares sharing an edge (Howell C-14), 0.2000437761:

    >>> import numpy as np
    >>> from radiosity.formfactors._quadrature import centroids_and_areas, pair_factors
    >>> floor = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    >>> wall = [[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]]
    >>> quads = np.array([floor, wall], dtype=float)
    >>> normals = np.array([[0, 0, 1], [1, 0, 0]], dtype=float)
    >>> c, a = centroids_and_areas(quads)
    >>> f = pair_factors(quads, normals, c, a, np.array([0]), np.array([1]), rtol=1e-9)
    >>> round(float(f[0]), 10)
    0.2000437761
    """
    # contiguous: a strided view would compile a second copy of each compiled pass it reaches
    quads = np.ascontiguousarray(quads, dtype=float)
    normals = np.ascontiguousarray(normals, dtype=float)
    centroid = np.ascontiguousarray(centroid, dtype=float)
    i = np.ascontiguousarray(i, dtype=np.int64)
    j = np.ascontiguousarray(j, dtype=np.int64)
    check_rtol(rtol)
    if max_points is not None and not np.all(np.asarray(max_points) >= 5):
        raise ValueError(f"max_points must be at least 5, got {max_points}")
    srcs = quads if sources is None else np.ascontiguousarray(sources, dtype=float)
    m = len(i)
    out = np.zeros(m)
    used = np.zeros(m, dtype=np.int64)
    converged = np.ones(m, dtype=bool)
    if m == 0:
        return (out, {"points": used, "converged": converged}) if return_info else out
    r_rec = _radius(quads, centroid)
    s_cen = srcs.mean(axis=1) if sources is not None else centroid
    r_src = _radius(srcs, s_cen)
    s_nrm = normals if sources is None else _src_normals(srcs)
    # A receiver crossing the source's plane sees the source's back from part of its area,
    # which gives nothing (surfaces are one-sided), and the integrand has a kink there: clip
    # the receiver to the source's front half-space and integrate the pieces. Separated pairs
    # take their a-priori orders.
    crossing, order = _pair_setup(quads, normals, centroid, r_rec, s_cen, s_nrm, r_src, i, j, rtol)
    clipped_here = crossing if not _clipped else np.zeros(m, dtype=bool)
    if clipped_here.any():
        sel = np.flatnonzero(clipped_here)
        h = _receiver_heights(quads, s_cen, s_nrm, i[sel], j[sel])
        out[sel], used[sel], converged[sel] = _clipped_receivers(
            quads, normals, srcs, i[sel], j[sel], h, rtol=rtol, max_points=max_points, mode=mode)
    if max_points is not None:
        over = order > int(np.sqrt(max_points))
        order[over], converged[over] = int(np.sqrt(max_points)), False
    order[clipped_here] = -1  # already integrated piecewise
    for p in np.unique(order[order > 0]):
        sel = np.flatnonzero(order == p)
        out[sel] = _evaluate(quads, normals, srcs, i[sel], j[sel], int(p), 1, mode)
        used[sel] = p * p
    # Adaptive refinement for the rest.
    near = np.flatnonzero(order == 0)
    if len(near):
        cap = np.broadcast_to(_ADAPT_MAX_POINTS if max_points is None else max_points, m)[near]
        out[near], used[near], converged[near] = _adaptive_factors(
            quads, normals, srcs, i[near], j[near], rtol=rtol, cap=cap, size=r_rec[i[near]] + r_src[j[near]],
            mode=mode)
    if return_info:
        return out, {"points": used, "converged": converged}
    return out

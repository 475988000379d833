"""Unoccluded form factors: Lambert's closed form from points to polygons, and its integrals.

The kernel is Lambert's formula (seeds 000 and 001; Stark 2000, eq. 3)::

    F(x -> P) = 1/(2 pi) | sum_e  theta_e  (a_e x b_e)/|a_e x b_e| . n |

over the edges ``e = (v_i, v_{i+1})`` of the polygon ``P`` clipped to the receiver's upper
half-space, with ``a_e = v_i - x``, ``b_e = v_{i+1} - x`` and the edge angle
``theta_e = atan2(|a_e x b_e|, a_e . b_e)`` (atan2 stays accurate for tiny and for nearly
opposite angles, where acos loses half its digits).
"""

from __future__ import annotations

import numpy as np

from . import _tol
from ._validate import as_points, as_polygon, as_unit_vectors

__all__ = ["point_to_polygon", "polygon_to_polygon"]

_TWO_PI = 2.0 * np.pi


def point_to_polygon(points, normals, polygon) -> np.ndarray:
    """Unoccluded form factor from differential receivers to one planar polygon.

    Parameters
    ----------
    points : (m, 3) float
        Receiver positions, metres.
    normals : (m, 3) float
        Unit normals of the receivers (their front sides).
    polygon : (k, 3) float
        Vertices of a planar, simple polygon, k >= 3, in either winding.

    Returns
    -------
    (m,) float
        Form factor from each differential receiver to the polygon, in [0, 1]. Only the part
        of the polygon above each receiver's tangent plane counts. Degenerate input gives 0.

    Examples
    --------
    A point under the corner of a unit square at height 1 (Howell's catalogue):

    >>> import numpy as np, radiosity
    >>> square = [[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    >>> f = radiosity.point_to_polygon([[0, 0, 0]], [[0, 0, 1]], square)
    >>> round(float(f[0]), 10)
    0.138531606
    """
    points = as_points(points, "points")
    normals = as_unit_vectors(normals, "normals")
    polygon = as_polygon(polygon, "polygon")
    if len(points) != len(normals):
        msg = f"points and normals must have the same length, got {len(points)} and {len(normals)}"
        raise ValueError(msg)
    polys = np.broadcast_to(polygon, (len(points),) + polygon.shape)
    return lambert_pairs(points, normals, polys)


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


def lambert_pairs(points: np.ndarray, normals: np.ndarray, polys: np.ndarray, *,
                  backend: str = "auto", mode: str = "auto") -> np.ndarray:
    """Form factor of each (receiver point, polygon) row; the private, trusting kernel.

    Parameters
    ----------
    points, normals : (m, 3) float
        Receivers and their unit normals.
    polys : (m, k, 3) float
        One polygon per receiver (repeated vertices allowed, e.g. triangles padded to k = 4).
    backend : {"auto", "numba", "numpy"}, default: "auto"
        ``"numba"`` is the parallel compiled kernel (``"auto"`` picks it when numba imports);
        ``"numpy"`` is the plain vectorised reference (raw Lambert sum only).
    mode : {"auto", "raw"}, default: "auto"
        ``"raw"`` forces Lambert's raw edge sum everywhere (it cancels catastrophically for far
        sources; kept for comparisons). ``"auto"`` switches to the cancellation-free far branch.

    Returns
    -------
    (m,) float
    """
    if backend == "auto":
        backend = "numba" if HAVE_NUMBA else "numpy"
    if backend == "numba":
        points, normals, polys = (np.ascontiguousarray(a, dtype=float) for a in (points, normals, polys))
        out = np.empty(len(points))
        if len(points):
            _lambert_rows_kernel(points, normals, polys, _MODES[mode], out)
        return out
    return _lambert_numpy(points, normals, polys)


_MODES = {"auto": 0, "raw": 1}


def lambert_indexed(points: np.ndarray, normals: np.ndarray, polys: np.ndarray, pi: np.ndarray,
                    qi: np.ndarray, *, mode: str = "auto") -> np.ndarray:
    """F(points[pi[t]] -> polys[qi[t]]) for index arrays, without materialising the pairs.

    Parameters
    ----------
    points, normals : (u, 3) float
        Receivers and their unit normals.
    polys : (n, k, 3) float
        Source polygons (triangles padded by repeating a vertex).
    pi, qi : (m,) int
        Receiver and source index of each pair.
    mode : {"auto", "raw"}, default: "auto"
        As in :func:`lambert_pairs`.

    Returns
    -------
    (m,) float
    """
    points, normals, polys = (np.ascontiguousarray(a, dtype=float) for a in (points, normals, polys))
    pi = np.ascontiguousarray(pi, dtype=np.int64)
    qi = np.ascontiguousarray(qi, dtype=np.int64)
    out = np.empty(len(pi))
    if not len(pi):
        return out
    if not HAVE_NUMBA:  # pragma: no cover
        return _lambert_numpy(points[pi], normals[pi], polys[qi])
    _lambert_indexed_kernel(points, normals, polys, pi, qi, _MODES[mode], out)
    return out


def _lambert_numpy(points: np.ndarray, normals: np.ndarray, polys: np.ndarray) -> np.ndarray:
    """Plain-numpy Lambert (raw edge sum), chunked: the reference and the fallback."""
    m = len(points)
    out = np.zeros(m)
    for start in range(0, m, _tol.CHUNK_PAIRS):
        stop = min(m, start + _tol.CHUNK_PAIRS)
        out[start:stop] = _lambert_chunk(points[start:stop], normals[start:stop], polys[start:stop])
    return out


def _lambert_chunk(x: np.ndarray, n: np.ndarray, polys: np.ndarray) -> np.ndarray:
    rel = polys - x[:, None, :]
    height = np.einsum("mkc,mc->mk", rel, n)
    size2 = np.einsum("mkc,mkc->mk", rel, rel)
    normal = polygon_normals(polys)
    # A receiver in the source's own plane sees it edge-on: exactly 0 (also covers receivers
    # on an edge or a vertex, where Lambert's terms are 0/0).
    off_plane = np.abs(np.einsum("mkc,mc->mk", rel, normal).mean(axis=1)) / np.sqrt(np.maximum(size2.max(axis=1), np.finfo(float).tiny))
    out = np.zeros(len(x))
    above = (height.max(axis=1) > 0.0) & (off_plane > _tol.IN_PLANE_REL) & normal.any(axis=1)
    straddles = above & (height.min(axis=1) < 0.0)
    plain = above & ~straddles
    if plain.any():
        out[plain] = _edge_sum(rel[plain], n[plain])
    if straddles.any():
        verts = _clip_to_upper(rel[straddles], height[straddles])
        out[straddles] = _edge_sum(verts, n[straddles])
    return np.clip(out, 0.0, 1.0)


def _edge_sum(rel: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Lambert's edge sum for polygons given relative to the receiver (rows, k, 3)."""
    nxt = np.roll(rel, -1, axis=1)
    c = np.cross(rel, nxt)
    s = np.sqrt(np.einsum("mkc,mkc->mk", c, c))
    dot = np.einsum("mkc,mkc->mk", rel, nxt)
    theta = np.arctan2(s, dot)
    cn = np.einsum("mkc,mc->mk", c, n)
    la = np.einsum("mkc,mkc->mk", rel, rel)
    lb = np.einsum("mkc,mkc->mk", nxt, nxt)
    edge_ok = s > _tol.DEGENERATE_REL * np.sqrt(la * lb)
    term = np.where(edge_ok, theta * cn / np.where(edge_ok, s, 1.0), 0.0)
    return np.abs(term.sum(axis=1)) / _TWO_PI


def _clip_to_upper(rel: np.ndarray, height: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman clip of each polygon to height >= 0, padded to 2k vertices.

    Slots that the clip removes repeat the previous kept vertex, so they add zero-length edges
    and the edge sum needs no masks.
    """
    rows, k, _ = rel.shape
    nxt = np.roll(rel, -1, axis=1)
    h_next = np.roll(height, -1, axis=1)
    keep = height >= 0.0
    crosses = (height > 0.0) & (h_next < 0.0) | (height < 0.0) & (h_next > 0.0)
    t = np.where(crosses, height / np.where(crosses, height - h_next, 1.0), 0.0)
    cut = rel + t[..., None] * (nxt - rel)
    slots = np.stack([rel, cut], axis=2).reshape(rows, 2 * k, 3)
    valid = np.stack([keep, crosses], axis=2).reshape(rows, 2 * k)
    # Rotate each row so that slot 0 is valid, then forward-fill the invalid slots.
    first = valid.argmax(axis=1)
    order = (first[:, None] + np.arange(2 * k)[None, :]) % (2 * k)
    slots = np.take_along_axis(slots, order[..., None], axis=1)
    valid = np.take_along_axis(valid, order, axis=1)
    for s in range(1, 2 * k):
        slots[:, s] = np.where(valid[:, s, None], slots[:, s], slots[:, s - 1])
    return slots


# ---------------------------------------------------------------------------------------------
# The numba kernel. One receiver point and one polygon per call of ``_ff_point``; the callers
# loop over blocks of pairs in parallel (``prange``) and give each block its own scratch space.
# ---------------------------------------------------------------------------------------------

try:  # numba is a dependency; the numpy path below stays as the reference and as a fallback.
    import numba as _numba

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover - exercised only without numba
    _numba = None
    HAVE_NUMBA = False


def _jit(**kwargs):
    if HAVE_NUMBA:
        return _numba.njit(cache=True, fastmath=False, **kwargs)
    return lambda f: f  # pragma: no cover


_DEG = _tol.DEGENERATE_REL
_INPLANE = _tol.IN_PLANE_REL
_FAR_RATIO = _tol.FAR_FIELD_RATIO
_SERIES_SINE = _tol.FAR_SERIES_SINE
_SERIES_RTOL = _tol.FAR_SERIES_RTOL
_BLOCK = _tol.KERNEL_BLOCK
_INV_2PI = 1.0 / _TWO_PI


# atan2 for y >= 0 in double precision (max error 2 ulp against numpy's, measured on 1e7 random
# arguments spanning 1e-8..1e3): the argument is reduced to |t| <= tan(pi/8) and atan(t) =
# t + t z R(z), z = t², with R an 11-term Chebyshev fit (error 3e-17; mpmath.chebyfit). numba's
# np.arctan2 calls libm's scalar atan2 (~19 ns); this one costs ~1.5 ns vectorised, ~5 ns scalar.
_ATAN_R = (-0.01917688711906226, 0.03923165829558719, -0.0508544973794026, 0.0585814891280221,
           -0.06664511447381948, 0.07692183190826087, -0.09090904578123903, 0.11111111015256361,
           -0.14285714284666542, 0.1999999999999552, -0.3333333333333333)
_TAN_PI8 = 0.41421356237309503
_PIO4 = np.pi / 4
_PIO2_HI, _PIO2_LO = np.pi / 2, 6.123233995736766e-17
_PI_HI, _PI_LO = np.pi, 1.2246467991473532e-16
(_R0, _R1, _R2, _R3, _R4, _R5, _R6, _R7, _R8, _R9, _R10) = _ATAN_R


@_jit(inline="always")
def _atan2p(y, x):
    """atan2(y, x) for y >= 0 (the edge angle: y = |a x b|, x = a·b)."""
    ax = abs(x)
    num = min(y, ax)
    den = max(y, ax)
    big = num > _TAN_PI8 * den
    p = num - den if big else num
    q = num + den if big else den
    q = q if q > 0.0 else 1.0
    t = p / q
    z = t * t
    r = _R0
    r = r * z + _R1
    r = r * z + _R2
    r = r * z + _R3
    r = r * z + _R4
    r = r * z + _R5
    r = r * z + _R6
    r = r * z + _R7
    r = r * z + _R8
    r = r * z + _R9
    r = r * z + _R10
    a = t + t * z * r
    a = a + _PIO4 if big else a
    a = (_PIO2_HI - a) + _PIO2_LO if y > ax else a
    a = (_PI_HI - a) + _PI_LO if x < 0.0 else a
    return a


@_jit(inline="always")
def _asin_ratio_m1(y):
    """arcsin(x)/x - 1 for y = x² small, by its series (four terms), and the remainder bound."""
    value = y * (1.0 / 6.0 + y * (3.0 / 40.0 + y * (5.0 / 112.0 + y * (35.0 / 1152.0))))
    y5 = y * y * y * y * y
    return value, (63.0 / 2816.0) * y5 / (1.0 - y)


@_jit(inline="always")
def _radius2_area(verts, count):
    """Largest squared distance of the first ``count`` vertices from the origin (the first
    vertex), and twice the polygon's vector area (Newell), for the scalar path."""
    r2max = 0.0
    A0 = 0.0
    A1 = 0.0
    A2 = 0.0
    for i in range(count):
        r2 = verts[i, 0] * verts[i, 0] + verts[i, 1] * verts[i, 1] + verts[i, 2] * verts[i, 2]
        if r2 > r2max:
            r2max = r2
        j = i + 1 if i + 1 < count else 0
        A0 += verts[i, 1] * verts[j, 2] - verts[i, 2] * verts[j, 1]
        A1 += verts[i, 2] * verts[j, 0] - verts[i, 0] * verts[j, 2]
        A2 += verts[i, 0] * verts[j, 1] - verts[i, 1] * verts[j, 0]
    return r2max, A0, A1, A2


@_jit()
def _ff_point(points, normals, polys, p, qsrc, k, w, h, wc, mode):
    """Lambert form factor from receiver ``x`` (normal ``nr``) to ``poly[:k]``; scratch w, h, wc.

    Everything is computed relative to the polygon's first vertex ``o``: ``c = o - x`` and
    ``w_i = v_i - o``, so translating the scene loses no digits. mode 0: automatic (far branch
    with series where its error estimate allows); 1: raw Lambert sum only (for comparisons).
    """
    o0, o1, o2 = polys[qsrc, 0, 0], polys[qsrc, 0, 1], polys[qsrc, 0, 2]
    c0, c1, c2 = o0 - points[p, 0], o1 - points[p, 1], o2 - points[p, 2]
    n0, n1, n2 = normals[p, 0], normals[p, 1], normals[p, 2]
    for i in range(k):
        w[i, 0] = polys[qsrc, i, 0] - o0
        w[i, 1] = polys[qsrc, i, 1] - o1
        w[i, 2] = polys[qsrc, i, 2] - o2
    # Twice the vector area (Newell), origin free.
    r2max, A0, A1, A2 = _radius2_area(w, k)
    alen = np.sqrt(A0 * A0 + A1 * A1 + A2 * A2)
    if not (alen > _DEG * r2max) or r2max == 0.0:
        return 0.0  # degenerate polygon
    # Receiver in the source's plane (on it, on an edge or a vertex, or beside it): 0.
    hw = 0.0
    for i in range(k):
        hw += w[i, 0] * A0 + w[i, 1] * A1 + w[i, 2] * A2
    hs = abs(c0 * A0 + c1 * A1 + c2 * A2 + hw / k) / alen
    dmax2 = 0.0
    for i in range(k):
        a0, a1, a2 = c0 + w[i, 0], c1 + w[i, 1], c2 + w[i, 2]
        d2 = a0 * a0 + a1 * a1 + a2 * a2
        if d2 > dmax2:
            dmax2 = d2
    if not (hs > _INPLANE * np.sqrt(dmax2)):
        return 0.0
    # Heights above the receiver's plane; clip to the upper half-space if needed.
    hc = c0 * n0 + c1 * n1 + c2 * n2
    hmax = -np.inf
    hmin = np.inf
    for i in range(k):
        h[i] = hc + w[i, 0] * n0 + w[i, 1] * n1 + w[i, 2] * n2
        if h[i] > hmax:
            hmax = h[i]
        if h[i] < hmin:
            hmin = h[i]
    if not (hmax > 0.0):
        return 0.0
    if hmin < 0.0:
        kc = 0
        for i in range(k):
            j = i + 1 if i + 1 < k else 0
            if h[i] >= 0.0:
                wc[kc, 0] = w[i, 0]
                wc[kc, 1] = w[i, 1]
                wc[kc, 2] = w[i, 2]
                kc += 1
            if (h[i] > 0.0 and h[j] < 0.0) or (h[i] < 0.0 and h[j] > 0.0):
                t = h[i] / (h[i] - h[j])
                wc[kc, 0] = w[i, 0] + t * (w[j, 0] - w[i, 0])
                wc[kc, 1] = w[i, 1] + t * (w[j, 1] - w[i, 1])
                wc[kc, 2] = w[i, 2] + t * (w[j, 2] - w[i, 2])
                kc += 1
        verts = wc
        r2max, A0, A1, A2 = _radius2_area(verts, kc)
    else:
        kc = k
        verts = w
    C2 = c0 * c0 + c1 * c1 + c2 * c2
    if mode == 1 or not (C2 > (_FAR_RATIO * _FAR_RATIO) * r2max):
        return _raw_sum(c0, c1, c2, n0, n1, n2, verts, kc)
    value = _far_sum(c0, c1, c2, n0, n1, n2, verts, kc, C2, A0, A1, A2, True)
    if value < 0.0:  # the series' error estimate was too large: redo with atan2 everywhere
        value = _far_sum(c0, c1, c2, n0, n1, n2, verts, kc, C2, A0, A1, A2, False)
    return value


@_jit(inline="always")
def _raw_sum(c0, c1, c2, n0, n1, n2, verts, kc):
    """Lambert's edge sum, sum_e theta_e (a_e x e_e)·n / |a_e x e_e|, for a near polygon."""
    total = 0.0
    for i in range(kc):
        j = i + 1 if i + 1 < kc else 0
        e0 = verts[j, 0] - verts[i, 0]
        e1 = verts[j, 1] - verts[i, 1]
        e2 = verts[j, 2] - verts[i, 2]
        if e0 == 0.0 and e1 == 0.0 and e2 == 0.0:
            continue
        a0, a1, a2 = c0 + verts[i, 0], c1 + verts[i, 1], c2 + verts[i, 2]
        x0 = a1 * e2 - a2 * e1
        x1 = a2 * e0 - a0 * e2
        x2 = a0 * e1 - a1 * e0
        s = np.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
        la = a0 * a0 + a1 * a1 + a2 * a2
        ae = a0 * e0 + a1 * e1 + a2 * e2
        b0, b1, b2 = a0 + e0, a1 + e1, a2 + e2
        lb = b0 * b0 + b1 * b1 + b2 * b2
        if not (s > _DEG * np.sqrt(la * lb)):
            continue  # receiver on the edge's line: the edge plane is undefined, its term is 0
        theta = _atan2p(s, la + ae)
        total += theta / s * (x0 * n0 + x1 * n1 + x2 * n2)
    value = abs(total) * _INV_2PI
    return min(value, 1.0)


@_jit(inline="always")
def _far_sum(c0, c1, c2, n0, n1, n2, verts, kc, C2, A0, A1, A2, series):
    """Cancellation-free edge sum for a receiver far from the polygon (|c| > ratio · radius).

    With q_e = theta_e / |a_e x e_e| = (theta_e / sin theta_e) / (|a_i| |a_j|), split
    q_e = 1/|c|² + delta2_e + delta1_e / (|a_i||a_j|), where delta1 = theta/sin theta - 1 and
    delta2 = 1/(|a_i||a_j|) - 1/|c|² is formed without subtraction of nearly equal numbers.
    Since sum_e a_e x e_e = 2A exactly, sum_e q_e (a_e x e_e) = 2A/|c|² + sum_e (...)(a_e x e_e):
    the large O(size/distance) terms of Lambert's sum never appear. Returns -1 when ``series``
    is set and the series' error estimate exceeds FAR_SERIES_RTOL of the result.
    """
    total = (A0 * n0 + A1 * n1 + A2 * n2) / C2
    corr = 0.0
    est = 0.0
    for i in range(kc):
        j = i + 1 if i + 1 < kc else 0
        e0 = verts[j, 0] - verts[i, 0]
        e1 = verts[j, 1] - verts[i, 1]
        e2 = verts[j, 2] - verts[i, 2]
        if e0 == 0.0 and e1 == 0.0 and e2 == 0.0:
            continue
        wi0, wi1, wi2 = verts[i, 0], verts[i, 1], verts[i, 2]
        wj0, wj1, wj2 = verts[j, 0], verts[j, 1], verts[j, 2]
        ali = 2.0 * (c0 * wi0 + c1 * wi1 + c2 * wi2) + (wi0 * wi0 + wi1 * wi1 + wi2 * wi2)
        alj = 2.0 * (c0 * wj0 + c1 * wj1 + c2 * wj2) + (wj0 * wj0 + wj1 * wj1 + wj2 * wj2)
        P = np.sqrt((C2 + ali) * (C2 + alj))
        d2 = -(C2 * (ali + alj) + ali * alj) / (P * C2 * (C2 + P))
        a0, a1, a2 = c0 + wi0, c1 + wi1, c2 + wi2
        x0 = a1 * e2 - a2 * e1
        x1 = a2 * e0 - a0 * e2
        x2 = a0 * e1 - a1 * e0
        s = np.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
        xn = x0 * n0 + x1 * n1 + x2 * n2
        sine = s / P
        dot = C2 + ali + (a0 * e0 + a1 * e1 + a2 * e2)
        if series and sine < _SERIES_SINE and dot > 0.0:
            d1, rem = _asin_ratio_m1(sine * sine)
            est += rem * sine
        elif s > 0.0:
            theta = _atan2p(s, dot)
            d1 = theta / sine - 1.0
        else:
            d1 = 0.0
        corr += (d2 + d1 / P) * xn
    total += corr
    value = abs(total) * _INV_2PI
    if series and est * _INV_2PI > _SERIES_RTOL * value:
        return -1.0
    return min(value, 1.0)


@_jit(inline="always")
def _fmax(a, b):
    return a if a > b else b


@_jit(inline="always")
def _fmin(a, b):
    return a if a < b else b


@_jit()
def _quads_phased(points, normals, polys, pidx, qidx, lo, hi, out, special, S, D, XN, PP, D2, TH,
                  BASE, FLAGS):
    """Lambert from receivers ``points[pidx[t]]`` to quads ``polys[qidx[t]]``, t in [lo, hi).

    Three loops over the block, each short enough for the CPU to overlap iterations and the
    middle one (the edge angles) simple enough for LLVM to vectorise: (A) per pair and edge the
    cross product, dot product and far-branch pieces; (B) all edge angles by ``_atan2p``;
    (C) the raw and far sums. ``special[t - lo]`` flags rows needing the scalar clipping path.
    """
    nb = hi - lo
    for u in range(nb):  # (A)
        p = pidx[lo + u]
        q = qidx[lo + u]
        o0 = polys[q, 0, 0]
        o1 = polys[q, 0, 1]
        o2 = polys[q, 0, 2]
        c0 = o0 - points[p, 0]
        c1 = o1 - points[p, 1]
        c2 = o2 - points[p, 2]
        n0 = normals[p, 0]
        n1 = normals[p, 1]
        n2 = normals[p, 2]
        C2 = c0 * c0 + c1 * c1 + c2 * c2
        A0 = 0.0
        A1 = 0.0
        A2 = 0.0
        r2 = 0.0
        hw = 0.0
        hmax = c0 * n0 + c1 * n1 + c2 * n2
        hmin = hmax
        hc = hmax
        d2max = C2
        wi0 = 0.0
        wi1 = 0.0
        wi2 = 0.0
        ali = 0.0
        for e in range(4):
            if e < 3:
                wj0 = polys[q, e + 1, 0] - o0
                wj1 = polys[q, e + 1, 1] - o1
                wj2 = polys[q, e + 1, 2] - o2
            else:
                wj0 = 0.0
                wj1 = 0.0
                wj2 = 0.0
            A0 += wi1 * wj2 - wi2 * wj1
            A1 += wi2 * wj0 - wi0 * wj2
            A2 += wi0 * wj1 - wi1 * wj0
            wj2n = wj0 * wj0 + wj1 * wj1 + wj2 * wj2
            r2 = _fmax(r2, wj2n)
            h = hc + wj0 * n0 + wj1 * n1 + wj2 * n2
            hmax = _fmax(hmax, h)
            hmin = _fmin(hmin, h)
            alj = 2.0 * (c0 * wj0 + c1 * wj1 + c2 * wj2) + wj2n
            d2max = _fmax(d2max, C2 + alj)
            e0 = wj0 - wi0
            e1 = wj1 - wi1
            e2 = wj2 - wi2
            a0 = c0 + wi0
            a1 = c1 + wi1
            a2 = c2 + wi2
            x0 = a1 * e2 - a2 * e1
            x1 = a2 * e0 - a0 * e2
            x2 = a0 * e1 - a1 * e0
            la = C2 + ali
            lb = C2 + alj
            P = np.sqrt(la * lb)
            S[e, u] = np.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
            D[e, u] = la + (a0 * e0 + a1 * e1 + a2 * e2)
            XN[e, u] = x0 * n0 + x1 * n1 + x2 * n2
            PP[e, u] = P
            D2[e, u] = -(C2 * (ali + alj) + ali * alj) / (P * C2 * (C2 + P)) if P * C2 > 0.0 else 0.0
            wi0 = wj0
            wi1 = wj1
            wi2 = wj2
            ali = alj
        hw = (c0 * A0 + c1 * A1 + c2 * A2)  # receiver height over the source plane, times |A|
        for e in range(3):
            hw += (polys[q, e + 1, 0] - o0) * A0 * 0.25 + (polys[q, e + 1, 1] - o1) * A1 * 0.25 \
                + (polys[q, e + 1, 2] - o2) * A2 * 0.25
        alen = np.sqrt(A0 * A0 + A1 * A1 + A2 * A2)
        live = (alen > _DEG * r2) and (abs(hw) > _INPLANE * np.sqrt(d2max) * alen) and hmax > 0.0
        FLAGS[u] = (0 if not live else (2 if hmin < 0.0 else 1)) + (4 if C2 > (_FAR_RATIO * _FAR_RATIO) * r2 else 0)
        BASE[u] = (A0 * n0 + A1 * n1 + A2 * n2) / C2 if C2 > 0.0 else 0.0
    for e in range(4):  # (B)
        for u in range(nb):
            TH[e, u] = _atan2p(S[e, u], D[e, u])
    for u in range(nb):  # (C)
        flag = FLAGS[u]
        state = flag & 3
        special[u] = state == 2
        if state != 1:
            out[lo + u] = 0.0
            continue
        total = 0.0
        if flag & 4:
            total = BASE[u]
            for e in range(4):
                s = S[e, u]
                P = PP[e, u]
                if not (s > _DEG * P):
                    continue
                sine = s / P
                if sine < _SERIES_SINE and D[e, u] > 0.0:
                    y = sine * sine
                    d1 = y * (1.0 / 6.0 + y * (3.0 / 40.0 + y * (5.0 / 112.0 + y * (35.0 / 1152.0))))
                else:
                    d1 = TH[e, u] / sine - 1.0
                total += (D2[e, u] + d1 / P) * XN[e, u]
        else:
            for e in range(4):
                s = S[e, u]
                if s > _DEG * PP[e, u]:
                    total += TH[e, u] / s * XN[e, u]
        out[lo + u] = _fmin(abs(total) * _INV_2PI, 1.0)


if HAVE_NUMBA:
    _prange = _numba.prange
else:  # pragma: no cover
    _prange = range


@_jit(inline="always")
def _scratch(n):
    return (np.empty((4, n)), np.empty((4, n)), np.empty((4, n)), np.empty((4, n)), np.empty((4, n)),
            np.empty((4, n)), np.empty(n), np.empty(n, dtype=np.int64))


@_jit(parallel=True)
def _lambert_indexed_kernel(points, normals, polys, pi, qi, mode, out):
    """out[t] = F(points[pi[t]] -> polys[qi[t]]), in parallel blocks of pairs.

    Quads (k = 4) take the vectorised branch-free path first; rows it flags (sources straddling
    the receiver's plane), other k and ``mode == 1`` take the scalar path ``_ff_point``.
    """
    m = pi.shape[0]
    k = polys.shape[1]
    nblocks = (m + _BLOCK - 1) // _BLOCK
    for b in _prange(nblocks):
        w = np.empty((k, 3))
        h = np.empty(k)
        wc = np.empty((2 * k, 3))
        S, D, XN, PP, D2, TH, BASE, FLAGS = _scratch(_BLOCK)
        lo = b * _BLOCK
        hi = min(m, lo + _BLOCK)
        if k == 4 and mode == 0:
            special = np.empty(hi - lo, dtype=np.bool_)
            _quads_phased(points, normals, polys, pi, qi, lo, hi, out, special, S, D, XN, PP, D2, TH,
                          BASE, FLAGS)
            for t in range(lo, hi):
                if special[t - lo]:
                    out[t] = _ff_point(points, normals, polys, pi[t], qi[t], k, w, h, wc, mode)
        else:
            for t in range(lo, hi):
                out[t] = _ff_point(points, normals, polys, pi[t], qi[t], k, w, h, wc, mode)


def _lambert_rows_kernel(points, normals, polys, mode, out):
    """out[p] = F(points[p] -> polys[p]): the indexed kernel with the identity pairing."""
    rows = np.arange(points.shape[0], dtype=np.int64)
    _lambert_indexed_kernel(points, normals, polys, rows, rows, mode, out)


@_jit(parallel=True)
def _quadrature_kernel(pts, nrm, wts, nq, slot, polys, j, mode, out):
    """out[t] = sum_r wts[s nq + r] F(pts[s nq + r] -> polys[j[t]]) / sum_r wts[...], s = slot[t].

    ``pts``, ``nrm`` are (u nq, 3) receiver points and normals (nq per receiver patch, in
    order), ``wts`` (u nq,) their weights.
    """
    m = slot.shape[0]
    k = polys.shape[1]
    per = max(1, _BLOCK // nq)
    nblocks = (m + per - 1) // per
    for b in _prange(nblocks):
        w = np.empty((k, 3))
        h = np.empty(k)
        wc = np.empty((2 * k, 3))
        t0 = b * per
        t1 = min(m, t0 + per)
        n = (t1 - t0) * nq
        pidx = np.empty(n, dtype=np.int64)
        qidx = np.empty(n, dtype=np.int64)
        for t in range(t0, t1):
            for r in range(nq):
                pidx[(t - t0) * nq + r] = slot[t] * nq + r
                qidx[(t - t0) * nq + r] = j[t]
        vals = np.empty(n)
        if k == 4 and mode == 0:
            S, D, XN, PP, D2, TH, BASE, FLAGS = _scratch(n)
            special = np.empty(n, dtype=np.bool_)
            _quads_phased(pts, nrm, polys, pidx, qidx, 0, n, vals, special, S, D, XN, PP, D2, TH,
                          BASE, FLAGS)
            for u in range(n):
                if special[u]:
                    vals[u] = _ff_point(pts, nrm, polys, pidx[u], qidx[u], k, w, h, wc, mode)
        else:
            for u in range(n):
                vals[u] = _ff_point(pts, nrm, polys, pidx[u], qidx[u], k, w, h, wc, mode)
        for t in range(t0, t1):
            acc = 0.0
            wsum = 0.0
            for r in range(nq):
                wq = wts[pidx[(t - t0) * nq + r]]
                acc += wq * vals[(t - t0) * nq + r]
                wsum += wq
            out[t] = acc / wsum if wsum > 0.0 else 0.0


def _receiver_pieces(receiver: np.ndarray, normal: np.ndarray, source: np.ndarray) -> np.ndarray:
    """The receiver as (t, 4, 3) quadrature pieces: itself if it is a convex quad or a triangle,
    else its earcut triangles. A triangle's collapsed (Duffy) vertex is put on the vertex nearest
    the source, where a touching vertex makes the integrand singular: the collapse smooths it."""
    from .quadrature import triangulate

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

    The receiver is triangulated (earcut, so non-convex receivers work) and each triangle is
    integrated by :func:`radiosity.quadrature.pair_factors`: an a-priori Gauss order for
    well-separated pieces, otherwise a ladder of Gauss rules (order 2, 4, 8, then the piece cut
    into 2x2, 4x4, ... at order 8) until two successive rungs agree to ``rtol``. Touching and
    nearly touching pairs converge because Lambert's integrand is smooth inside the receiver
    and only log-singular on its boundary.

    Parameters
    ----------
    receiver, source : (k, 3) float
        Planar simple polygons, metres. The receiver's winding gives its front side
        (counter-clockwise seen from the front); the source's winding is ignored.
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
    from .quadrature import centroids_and_areas, pair_factors

    receiver = as_polygon(receiver, "receiver")
    source = as_polygon(source, "source")
    if not (1e-12 <= rtol < 1):
        raise ValueError(f"rtol must be in [1e-12, 1), got {rtol}")
    normal = polygon_normals(receiver[None])[0]
    if not normal.any() or not polygon_normals(source[None])[0].any():
        return 0.0
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

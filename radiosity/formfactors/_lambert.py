"""Numba kernels for Lambert's point-to-polygon form factor (used by ``formfactors``).

Three paths share the same conventions (everything relative to the polygon's first vertex,
degenerate and in-plane cases give 0, sources straddling the receiver's plane are clipped):

- ``_ff_point``: one receiver point and one polygon, any vertex count, with clipping and the
  cancellation-free far branch; the reference for the vectorised paths and their fallback;
- the one-source lane loops (``_triangle_lanes``, ``_quad_lanes``): one triangle or quad against
  many receivers, everything in registers; ``point_to_polygon(s)`` and the fill's quadrature;
- the block kernels: independent pairs (each lane its own source) in blocks, laid out
  structure-of-arrays so that LLVM vectorises the edge loops; also polygons of > 4 vertices.
Lanes the vectorised paths cannot finish (the source straddles the receiver's plane) go to
``_ff_point``.
"""

from __future__ import annotations

import numba as _numba
import numpy as np

from .. import _tol
from .._geometry_kernels import newell

_TWO_PI = 2.0 * np.pi

# ---------------------------------------------------------------------------------------------
# The numba kernel. One receiver point and one polygon per call of ``_ff_point``; the callers
# loop over blocks of pairs in parallel (``prange``) and give each block its own scratch space.
# ---------------------------------------------------------------------------------------------

def _jit(**kwargs):
    return _numba.njit(cache=True, fastmath=False, error_model="numpy", **kwargs)


_DEG = _tol.DEGENERATE_REL
_INPLANE = _tol.IN_PLANE_REL
_FAR_RATIO = _tol.FAR_FIELD_RATIO
_SERIES_SINE = _tol.FAR_SERIES_SINE
_BLOCK = _tol.KERNEL_BLOCK
_GRAZING2 = _tol.GRAZING_SINE * _tol.GRAZING_SINE
_NONPLANAR_REL = 1e-9  # a source whose vertices leave its plane by more (times its radius) is not flat
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
def _atan_reduced(t):
    """atan(t) for |t| <= tan(pi/8)."""
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
    return t + t * z * r


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
    a = _atan_reduced(t)
    a = a + _PIO4 if big else a
    a = (_PIO2_HI - a) + _PIO2_LO if y > ax else a
    a = (_PI_HI - a) + _PI_LO if x < 0.0 else a
    return a


@_jit(inline="always")
def _asin_ratio_m1(y):
    """arcsin(x)/x - 1 for y = x² small, by its series (four terms; the remainder is below
    63/2816 y^5 / (1 - y), 1.3e-17 at x = FAR_SERIES_SINE)."""
    return y * (1.0 / 6.0 + y * (3.0 / 40.0 + y * (5.0 / 112.0 + y * (35.0 / 1152.0))))


@_jit(inline="always")
def _radius2_area(verts, count):
    """Largest squared distance of the first ``count`` vertices from the origin (the first
    vertex), and twice the polygon's vector area (Newell), for the scalar path."""
    r2max = 0.0
    for i in range(count):
        r2 = verts[i, 0] * verts[i, 0] + verts[i, 1] * verts[i, 1] + verts[i, 2] * verts[i, 2]
        if r2 > r2max:
            r2max = r2
    A0, A1, A2 = newell(verts, count)
    return r2max, A0, A1, A2


@_jit()
def _ff_point(points, normals, polys, p, qsrc, k, w, h, wc, mode):
    """Lambert form factor from receiver ``x`` (normal ``nr``) to ``poly[:k]``; scratch w, h, wc.

    Everything is computed relative to the polygon's first vertex ``o``: ``c = o - x`` and
    ``w_i = v_i - o``, so translating the scene loses no digits. mode 0: automatic (far form
    for far sources, the near-plane and horizon forms for grazing ones, else the raw sum);
    1: raw Lambert sum only (for comparisons); 2: as 0 without the grazing forms (the fill).
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
    far = C2 > (_FAR_RATIO * _FAR_RATIO) * r2max
    if mode == 0:
        near, value = _near_plane_sum(c0, c1, c2, n0, n1, n2, verts, kc, A0, A1, A2, C2 if far else 0.0, r2max)
        if near:
            return value
        grazing, total, rise2 = _horizon_signed(c0, c1, c2, n0, n1, n2, verts, kc)
        # A far source: the far form loses ~1/elevation² digits, the horizon form ~elevation times
        # distance/size (its small terms cancel once more); take the smaller.
        if grazing and (not far or rise2 * rise2 * rise2 * C2 < r2max):
            return min(abs(total) * _INV_2PI, 1.0)
    if mode == 1 or not far:
        return _raw_sum(c0, c1, c2, n0, n1, n2, verts, kc)
    return _far_sum(c0, c1, c2, n0, n1, n2, verts, kc, C2, A0, A1, A2)


@_jit(inline="always")
def _horizon_signed(c0, c1, c2, n0, n1, n2, verts, kc):
    """Lambert's signed sum (2 pi F up to sign) for a source seen just above the horizon of a
    receiver with normal n, and the largest squared elevation sine (bound) of its edges; or
    (False, 0, 0) if some edge rises higher than GRAZING_SINE.

    Lambert's edge terms theta_e C_e (C_e the cosine between the edge plane's normal and the
    receiver's) are O(1) near the horizon while F ~ elevation²: their sum cancels. The azimuths
    the edges sweep around the receiver's normal, dphi_e, add up to 2 pi times the winding number
    w, so S = sum_e theta_e C_e = 2 pi w - sum_e T_e with T_e = dphi_e - C_e theta_e, which is
    O(elevation²) for an edge near the horizon. With X = a.b, Y = |a x b|, eps = h_a h_b (heights)
    and d = 1 - |C| = |x_h|²/Y²/(1 + |C|), x_h = (h_b a - h_a b) x n the horizontal part of a x b:

        T_e = sign(C) [atan2(Y (eps - d X), X² - eps X + |C| Y²) + d theta]   (|C| >= 1/2)
        T_e = dphi_e - C theta                                                (|C| < 1/2)

    (the first is dphi - theta, one angle difference, plus d theta; the second has no
    cancellation where the edge plane is steep). Each edge's elevation is bounded by
    max(h_a, h_b) / (distance from the receiver to the segment).
    """
    tsum = 0.0
    wsum = 0.0
    rise2 = 0.0
    for i in range(kc):
        j = i + 1 if i + 1 < kc else 0
        e0 = verts[j, 0] - verts[i, 0]
        e1 = verts[j, 1] - verts[i, 1]
        e2 = verts[j, 2] - verts[i, 2]
        if e0 == 0.0 and e1 == 0.0 and e2 == 0.0:
            continue
        a0, a1, a2 = c0 + verts[i, 0], c1 + verts[i, 1], c2 + verts[i, 2]
        b0, b1, b2 = c0 + verts[j, 0], c1 + verts[j, 1], c2 + verts[j, 2]
        x0 = a1 * e2 - a2 * e1
        x1 = a2 * e0 - a0 * e2
        x2 = a0 * e1 - a1 * e0
        s2 = x0 * x0 + x1 * x1 + x2 * x2
        la = a0 * a0 + a1 * a1 + a2 * a2
        lb = b0 * b0 + b1 * b1 + b2 * b2
        ha = a0 * n0 + a1 * n1 + a2 * n2
        hb = b0 * n0 + b1 * n1 + b2 * n2
        # the edge's points are no higher than max(h_a, h_b) and no nearer than the segment
        ae = a0 * e0 + a1 * e1 + a2 * e2
        ee = e0 * e0 + e1 * e1 + e2 * e2
        nearest = _fmin(1.0, _fmax(0.0, -ae / ee))
        p0, p1, p2 = a0 + nearest * e0, a1 + nearest * e1, a2 + nearest * e2
        hm = _fmax(abs(ha), abs(hb))
        dseg2 = p0 * p0 + p1 * p1 + p2 * p2
        if hm * hm > _GRAZING2 * dseg2:
            return False, 0.0, 0.0
        rise2 = _fmax(rise2, hm * hm / dseg2) if dseg2 > 0.0 else rise2
        if not (s2 > (_DEG * _DEG) * (la * lb)):
            continue  # receiver on the edge's line (in the horizon): the term is 0
        s = np.sqrt(s2)
        X = la + ae
        theta = _atan2p(s, X)
        xn = x0 * n0 + x1 * n1 + x2 * n2
        eps = ha * hb
        dphi = np.arctan2(xn, X - eps)
        cabs = abs(xn) / s
        if cabs < 0.5:
            tsum += dphi - (xn / s) * theta
        else:
            v0, v1, v2 = hb * a0 - ha * b0, hb * a1 - ha * b1, hb * a2 - ha * b2
            d = (v0 * v0 + v1 * v1 + v2 * v2) / s2 / (1.0 + cabs)
            t = np.arctan2(s * (eps - d * X), X * X - eps * X + cabs * s2) + d * theta
            tsum += t if xn > 0.0 else -t
        wsum += dphi
    return True, _TWO_PI * np.round(wsum / _TWO_PI) - tsum, rise2


@_jit(inline="always")
def _near_plane_sum(c0, c1, c2, n0, n1, n2, verts, kc, A0, A1, A2, far_c2, r2max):
    """F for a receiver near the source's plane and tilted towards it, or (False, 0) if it is not.

    With N the source's unit normal (oriented so that the plane lies at height D > 0 along it)
    and n = nu N + n_perp, every a_i = a_i|| + D N, so (a_i x a_j) . n_perp = D (N x e) . n_perp:

        2 pi F = |nu S_N + D sum_e theta_e (N x e) . n_perp / |a x e||,

    S_N Lambert's sum for the normal N, from which the source lies just above the horizon (the
    horizon form keeps it accurate), and the second sum O(D) term by term. Lambert's sum for n
    instead adds O(nu) terms that cancel to O(D). Used when D is below GRAZING_SINE times the
    distance to the source and nu² above GRAZING_SINE² (a receiver facing the plane sideways has
    no cancellation to remove). For a far source (``far_c2`` = |c|², else 0) S_N cancels by
    distance/size once more, so there only while D |c|² < size³, i.e. the plane nearly through x.
    """
    alen = np.sqrt(A0 * A0 + A1 * A1 + A2 * A2)
    N0, N1, N2 = A0 / alen, A1 / alen, A2 / alen
    nu = n0 * N0 + n1 * N1 + n2 * N2
    if not (nu * nu > _GRAZING2):
        return False, 0.0
    D = 0.0
    lo, hi = np.inf, -np.inf
    for i in range(kc):
        D += (c0 + verts[i, 0]) * N0 + (c1 + verts[i, 1]) * N1 + (c2 + verts[i, 2]) * N2
        off = verts[i, 0] * N0 + verts[i, 1] * N1 + verts[i, 2] * N2
        lo, hi = _fmin(lo, off), _fmax(hi, off)
    D /= kc
    if not (hi - lo <= _NONPLANAR_REL * np.sqrt(r2max)):
        return False, 0.0  # not planar (outside the contract): the decomposition needs a_i . N = D
    if D < 0.0:
        N0, N1, N2, D, nu = -N0, -N1, -N2, -D, -nu
    if far_c2 > 0.0 and not (D * D * far_c2 * far_c2 < r2max * r2max * r2max):
        return False, 0.0
    ok, SN, _ = _horizon_signed(c0, c1, c2, N0, N1, N2, verts, kc)
    if not ok:
        return False, 0.0
    p0, p1, p2 = n0 - nu * N0, n1 - nu * N1, n2 - nu * N2
    across = 0.0
    for i in range(kc):
        q, _, _, _, e0, e1, e2 = _edge_q(c0, c1, c2, verts, i, i + 1 if i + 1 < kc else 0)
        across += q * ((N1 * e2 - N2 * e1) * p0 + (N2 * e0 - N0 * e2) * p1 + (N0 * e1 - N1 * e0) * p2)
    return True, min(abs(nu * SN + D * across) * _INV_2PI, 1.0)


@_jit(inline="always")
def _edge_q(c0, c1, c2, verts, i, j):
    """Edge i -> j of ``verts`` seen from the receiver (c = o - x): q_e = theta_e / |a_e x e_e|,
    the cross product a_e x e_e and the edge e_e; q_e = 0 where the receiver lies on the edge's
    line (the edge plane is undefined, its term is 0) or the edge is null."""
    e0 = verts[j, 0] - verts[i, 0]
    e1 = verts[j, 1] - verts[i, 1]
    e2 = verts[j, 2] - verts[i, 2]
    a0, a1, a2 = c0 + verts[i, 0], c1 + verts[i, 1], c2 + verts[i, 2]
    x0 = a1 * e2 - a2 * e1
    x1 = a2 * e0 - a0 * e2
    x2 = a0 * e1 - a1 * e0
    s = np.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    la = a0 * a0 + a1 * a1 + a2 * a2
    ae = a0 * e0 + a1 * e1 + a2 * e2
    b0, b1, b2 = a0 + e0, a1 + e1, a2 + e2
    lb = b0 * b0 + b1 * b1 + b2 * b2
    q = _atan2p(s, la + ae) / s if s > _DEG * np.sqrt(la * lb) else 0.0
    return q, x0, x1, x2, e0, e1, e2


@_jit(inline="always")
def _raw_sum(c0, c1, c2, n0, n1, n2, verts, kc):
    """Lambert's edge sum, sum_e theta_e (a_e x e_e)·n / |a_e x e_e|, for a near polygon."""
    total = 0.0
    for i in range(kc):
        q, x0, x1, x2, _, _, _ = _edge_q(c0, c1, c2, verts, i, i + 1 if i + 1 < kc else 0)
        total += q * (x0 * n0 + x1 * n1 + x2 * n2)
    value = abs(total) * _INV_2PI
    return min(value, 1.0)


@_jit(inline="always")
def _far_sum(c0, c1, c2, n0, n1, n2, verts, kc, C2, A0, A1, A2):
    """Cancellation-free edge sum for a receiver far from the polygon (|c| > ratio · radius).

    With q_e = theta_e / |a_e x e_e| = (theta_e / sin theta_e) / (|a_i| |a_j|), split
    q_e = 1/|c|² + delta2_e + delta1_e / (|a_i||a_j|), where delta1 = theta/sin theta - 1 and
    delta2 = 1/(|a_i||a_j|) - 1/|c|² is formed without subtraction of nearly equal numbers.
    Since sum_e a_e x e_e = 2A exactly, sum_e q_e (a_e x e_e) = 2A/|c|² + sum_e (...)(a_e x e_e):
    the large O(size/distance) terms of Lambert's sum never appear. delta1 comes from the arcsin
    series where the edge's sine is below FAR_SERIES_SINE (more accurate there than any
    atan2-based value: its remainder is below 1.3e-17, while theta/sin(theta) - 1 formed from
    atan2 carries an absolute rounding error of ~1e-16), from atan2 elsewhere.
    """
    total = (A0 * n0 + A1 * n1 + A2 * n2) / C2
    corr = 0.0
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
        if sine < _SERIES_SINE and dot > 0.0:
            d1 = _asin_ratio_m1(sine * sine)
        elif s > 0.0:
            theta = _atan2p(s, dot)
            d1 = theta / sine - 1.0
        else:
            d1 = 0.0
        corr += (d2 + d1 / P) * xn
    total += corr
    value = abs(total) * _INV_2PI
    return min(value, 1.0)


@_jit(inline="always")
def _fmax(a, b):
    return a if a > b else b


@_jit(inline="always")
def _fmin(a, b):
    return a if a < b else b


_prange = _numba.prange


# ---------------------------------------------------------------------------------------------
# Structure-of-arrays block kernel. A block of up to _LANES pairs is gathered into rows of a
# scratch array (one row per coordinate); every later loop runs over the lanes without branches,
# which LLVM turns into SIMD code (AVX2 or AVX-512, as the CPU has). Near and far lanes share one formula:
#
#     sum_e q_e xn_e = kappa (A . n) + sum_e (q_e - kappa) xn_e,   q_e = theta_e / s_e,
#
# with kappa = 0 near the source (Lambert's raw sum) and kappa = 1/|c|^2 far from it (the
# cancellation-free sum of ``_far_sum``), chosen per lane by selects. Lanes whose source straddles
# the receiver's plane (it must be clipped first) are flagged and finished by ``_ff_point``.
# ---------------------------------------------------------------------------------------------

_LANES = 256
_PAD = 24  # rows 280 doubles apart: rows 2 KiB apart would fall into the same L1 cache sets
# scratch rows, per lane
_ROW_C = 0  # c = o - x (3 rows)
_ROW_N = 3  # receiver normal (3 rows)
_ROW_TOTAL = 6  # accumulated edge sum
_ROW_A = 7  # twice the polygon's vector area (3 rows)
_ROW_R2 = 10  # largest squared vertex distance from o
_ROW_C2 = 11  # |c|^2
_ROW_GAMMA = 12  # 1/|c|
_ROW_FAR = 13  # 1.0 where the lane uses the far formula
_ROW_HMIN = 14  # lowest and highest vertex height above the receiver's plane
_ROW_HMAX = 15
_ROW_D2MAX = 16  # largest squared receiver-vertex distance
_ROW_W = 17  # w_i = v_i - o (3 rows per vertex, w_0 = 0), then per vertex |a_i|^2, |a_i|, rho_i


def _vjit(**kwargs):
    """The block kernels may contract a*b+c into FMAs (one rounding fewer; ~10% faster)."""
    return _numba.njit(cache=True, fastmath={"contract"}, error_model="numpy", **kwargs)


@_vjit()
def _gather(points, normals, polys, pidx, qidx, lo, n, k, sc):
    """Copy lanes lo..lo+n-1 into the scratch rows: c = o - x, n, and w_i = v_i - o.

    Returns the vertex count the block needs: 3 when every lane is a triangle padded to k = 4
    (last vertex repeated), saving a quarter of the work, else k.
    """
    padded = k == 4
    for u in range(n):
        p = pidx[lo + u]
        q = qidx[lo + u]
        for d in range(3):
            o = polys[q, 0, d]
            sc[_ROW_C + d, u] = o - points[p, d]
            sc[_ROW_N + d, u] = normals[p, d]
            sc[_ROW_W + d, u] = 0.0
            for i in range(1, k):
                sc[_ROW_W + 3 * i + d, u] = polys[q, i, d] - o
        if padded:
            padded = polys[q, 3, 0] == polys[q, 2, 0] and polys[q, 3, 1] == polys[q, 2, 1] \
                and polys[q, 3, 2] == polys[q, 2, 2]
    return 3 if padded else k


@_vjit()
def _block_setup(n, k, sc, far_ratio):
    """Per lane: area vector, radius, |c|, the far flag and the kappa (A . n) term.

    Returns the number of far lanes."""
    c0, c1, c2, n0, n1, n2 = sc[_ROW_C], sc[_ROW_C + 1], sc[_ROW_C + 2], sc[_ROW_N], sc[_ROW_N + 1], sc[_ROW_N + 2]
    A0, A1, A2, r2 = sc[_ROW_A], sc[_ROW_A + 1], sc[_ROW_A + 2], sc[_ROW_R2]
    for u in range(n):
        A0[u] = 0.0
        A1[u] = 0.0
        A2[u] = 0.0
        r2[u] = 0.0
    for i in range(1, k):
        j = i + 1 if i + 1 < k else 0
        wi0, wi1, wi2 = sc[_ROW_W + 3 * i], sc[_ROW_W + 3 * i + 1], sc[_ROW_W + 3 * i + 2]
        wj0, wj1, wj2 = sc[_ROW_W + 3 * j], sc[_ROW_W + 3 * j + 1], sc[_ROW_W + 3 * j + 2]
        for u in range(n):
            A0[u] += wi1[u] * wj2[u] - wi2[u] * wj1[u]
            A1[u] += wi2[u] * wj0[u] - wi0[u] * wj2[u]
            A2[u] += wi0[u] * wj1[u] - wi1[u] * wj0[u]
            r2[u] = _fmax(r2[u], wi0[u] * wi0[u] + wi1[u] * wi1[u] + wi2[u] * wi2[u])
    far2 = far_ratio * far_ratio
    total, C2, gamma, far = sc[_ROW_TOTAL], sc[_ROW_C2], sc[_ROW_GAMMA], sc[_ROW_FAR]
    count = 0
    for u in range(n):
        cc = c0[u] * c0[u] + c1[u] * c1[u] + c2[u] * c2[u]
        C2[u] = cc
        gamma[u] = 1.0 / np.sqrt(cc)
        is_far = cc > far2 * r2[u] and far2 > 0.0
        far[u] = 1.0 if is_far else 0.0
        total[u] = (A0[u] * n0[u] + A1[u] * n1[u] + A2[u] * n2[u]) / cc if is_far else 0.0
        count += 1 if is_far else 0
    return count


@_vjit()
def _block_vertices(n, k, sc, any_far):
    """Per lane and vertex: |a_i|^2, and where a lane is far |a_i| and rho_i = 1/|a_i| - 1/|c|
    (formed without cancellation); the heights and distances the flags need."""
    c0, c1, c2, n0, n1, n2 = sc[_ROW_C], sc[_ROW_C + 1], sc[_ROW_C + 2], sc[_ROW_N], sc[_ROW_N + 1], sc[_ROW_N + 2]
    C2, gamma, far = sc[_ROW_C2], sc[_ROW_GAMMA], sc[_ROW_FAR]
    hmin, hmax, d2max = sc[_ROW_HMIN], sc[_ROW_HMAX], sc[_ROW_D2MAX]
    la, ra, rho = sc[_ROW_W + 3 * k], sc[_ROW_W + 4 * k], sc[_ROW_W + 5 * k]
    for u in range(n):  # vertex 0 is o itself: a_0 = c
        h = c0[u] * n0[u] + c1[u] * n1[u] + c2[u] * n2[u]
        hmin[u] = h
        hmax[u] = h
        d2max[u] = C2[u]
        la[u] = C2[u]
        ra[u] = C2[u] * gamma[u]
        rho[u] = 0.0
    for i in range(1, k):
        w0, w1, w2 = sc[_ROW_W + 3 * i], sc[_ROW_W + 3 * i + 1], sc[_ROW_W + 3 * i + 2]
        la, ra, rho = sc[_ROW_W + 3 * k + i], sc[_ROW_W + 4 * k + i], sc[_ROW_W + 5 * k + i]
        for u in range(n):
            a0 = c0[u] + w0[u]
            a1 = c1[u] + w1[u]
            a2 = c2[u] + w2[u]
            # |a_i|^2 directly: |c|^2 + ali cancels for a receiver near vertex i far from o;
            # ali = |a_i|^2 - |c|^2 is formed without cancellation for the far lanes' rho.
            lsq = a0 * a0 + a1 * a1 + a2 * a2
            la[u] = lsq
            rho[u] = 2.0 * (c0[u] * w0[u] + c1[u] * w1[u] + c2[u] * w2[u]) \
                + (w0[u] * w0[u] + w1[u] * w1[u] + w2[u] * w2[u])
            h = a0 * n0[u] + a1 * n1[u] + a2 * n2[u]
            hmin[u] = _fmin(hmin[u], h)
            hmax[u] = _fmax(hmax[u], h)
            d2max[u] = _fmax(d2max[u], lsq)
        if any_far:
            for u in range(n):
                lsq = la[u]
                r = np.sqrt(lsq)
                ra[u] = r
                c = C2[u] * gamma[u]
                v = -rho[u] / (r * c * (c + r))
                rho[u] = v if far[u] > 0.0 else 0.0


@_vjit()
def _block_edges(n, k, sc, any_far):
    """Accumulate (q_e - kappa) xn_e over the edges for every lane."""
    c0, c1, c2, n0, n1, n2 = sc[_ROW_C], sc[_ROW_C + 1], sc[_ROW_C + 2], sc[_ROW_N], sc[_ROW_N + 1], sc[_ROW_N + 2]
    total, gamma, far = sc[_ROW_TOTAL], sc[_ROW_GAMMA], sc[_ROW_FAR]
    for i in range(k):
        j = i + 1 if i + 1 < k else 0
        wi0, wi1, wi2 = sc[_ROW_W + 3 * i], sc[_ROW_W + 3 * i + 1], sc[_ROW_W + 3 * i + 2]
        wj0, wj1, wj2 = sc[_ROW_W + 3 * j], sc[_ROW_W + 3 * j + 1], sc[_ROW_W + 3 * j + 2]
        lai, laj = sc[_ROW_W + 3 * k + i], sc[_ROW_W + 3 * k + j]
        rai, raj = sc[_ROW_W + 4 * k + i], sc[_ROW_W + 4 * k + j]
        rhoi, rhoj = sc[_ROW_W + 5 * k + i], sc[_ROW_W + 5 * k + j]
        # The edge geometry is written out in both loops on purpose: an inlined helper
        # returning it stopped LLVM from vectorising one of them (checked in the assembly).
        if not any_far:
            for u in range(n):
                a0 = c0[u] + wi0[u]
                a1 = c1[u] + wi1[u]
                a2 = c2[u] + wi2[u]
                e0 = wj0[u] - wi0[u]
                e1 = wj1[u] - wi1[u]
                e2 = wj2[u] - wi2[u]
                x0 = a1 * e2 - a2 * e1
                x1 = a2 * e0 - a0 * e2
                x2 = a0 * e1 - a1 * e0
                s2 = x0 * x0 + x1 * x1 + x2 * x2
                ok = s2 > (_DEG * _DEG) * (lai[u] * laj[u])
                s = np.sqrt(s2)
                g = _atan2p(s, lai[u] + (a0 * e0 + a1 * e1 + a2 * e2)) / s
                total[u] += g * (x0 * n0[u] + x1 * n1[u] + x2 * n2[u]) if ok else 0.0
            continue
        for u in range(n):
            a0 = c0[u] + wi0[u]
            a1 = c1[u] + wi1[u]
            a2 = c2[u] + wi2[u]
            e0 = wj0[u] - wi0[u]
            e1 = wj1[u] - wi1[u]
            e2 = wj2[u] - wi2[u]
            x0 = a1 * e2 - a2 * e1
            x1 = a2 * e0 - a0 * e2
            x2 = a0 * e1 - a1 * e0
            s2 = x0 * x0 + x1 * x1 + x2 * x2
            ok = s2 > (_DEG * _DEG) * (lai[u] * laj[u])
            s = np.sqrt(s2)
            dot = lai[u] + (a0 * e0 + a1 * e1 + a2 * e2)
            g = _atan2p(s, dot) / s  # q_e
            xn = x0 * n0[u] + x1 * n1[u] + x2 * n2[u]
            # far lanes: q_e - 1/|c|^2 = d1 / P + d2 with P = |a_i||a_j|, d1 = theta/sin - 1,
            # d2 = 1/P - 1/|c|^2 = gamma (rho_i + rho_j) + rho_i rho_j (rho = 1/|a| - 1/|c|)
            gi = gamma[u] + rhoi[u]
            gj = gamma[u] + rhoj[u]
            sine = s * (gi * gj)
            series = sine < _SERIES_SINE and dot > 0.0
            d1 = _asin_ratio_m1(sine * sine) if series else g * (rai[u] * raj[u]) - 1.0
            d2 = gamma[u] * (rhoi[u] + rhoj[u]) + rhoi[u] * rhoj[u]
            q = d1 * (gi * gj) + d2 if far[u] > 0.0 else g
            total[u] += q * xn if ok else 0.0


@_vjit()
def _block_finish(n, k, sc, out, lo, redo, graze):
    """Form factors of lanes 0..n-1; ``redo[u]`` marks the lanes ``_ff_point`` must finish: the
    source straddles the receiver's plane, or (with ``graze``) the lane needs a grazing form (see
    ``_lane_value``). Returns how many."""
    c0, c1, c2 = sc[_ROW_C], sc[_ROW_C + 1], sc[_ROW_C + 2]
    total, A0, A1, A2, r2 = sc[_ROW_TOTAL], sc[_ROW_A], sc[_ROW_A + 1], sc[_ROW_A + 2], sc[_ROW_R2]
    hmin, hmax, d2max = sc[_ROW_HMIN], sc[_ROW_HMAX], sc[_ROW_D2MAX]
    inv_k = 1.0 / k
    d2min = sc[_ROW_GAMMA]  # free once the edges are summed
    for u in range(n):
        d2min[u] = sc[_ROW_W + 3 * k, u]
    for i in range(1, k):
        la = sc[_ROW_W + 3 * k + i]
        for u in range(n):
            d2min[u] = _fmin(d2min[u], la[u])
    count = 0
    for u in range(n):
        alen2 = A0[u] * A0[u] + A1[u] * A1[u] + A2[u] * A2[u]
        hw = 0.0
        for i in range(1, k):
            hw += sc[_ROW_W + 3 * i, u] * A0[u] + sc[_ROW_W + 3 * i + 1, u] * A1[u] \
                + sc[_ROW_W + 3 * i + 2, u] * A2[u]
        hs = c0[u] * A0[u] + c1[u] * A1[u] + c2[u] * A2[u] + hw * inv_k
        live = (alen2 > (_DEG * _DEG) * r2[u] * r2[u]) and (r2[u] > 0.0) \
            and (hs * hs > (_INPLANE * _INPLANE) * d2max[u] * alen2) and (hmax[u] > 0.0)
        value = abs(total[u]) * _INV_2PI
        low = max(abs(hmin[u]), abs(hmax[u]))
        an = A0[u] * sc[_ROW_N, u] + A1[u] * sc[_ROW_N + 1, u] + A2[u] * sc[_ROW_N + 2, u]
        low_near = low * low <= _GRAZING2 * d2min[u] or _tilted_near(hs, an, _GRAZING2 * alen2, d2min[u])
        flag = live and (hmin[u] < 0.0 or (graze and low_near))
        out[lo + u] = _fmin(value, 1.0) if live else 0.0
        redo[u] = flag
        count += 1 if flag else 0
    return count


@_jit()
def _lambert_block(points, normals, polys, pi, qi, lo, n, mode, out, sc, redo, w, h, wc):
    """out[lo:lo+n] for the pairs (pi, qi)[lo:lo+n], n <= _LANES, with scratch space."""
    k = polys.shape[1]
    kb = _gather(points, normals, polys, pi, qi, lo, n, k, sc)
    any_far = _block_setup(n, kb, sc, _FAR_RATIO if mode != 1 else 0.0) > 0
    _block_vertices(n, kb, sc, any_far)
    _block_edges(n, kb, sc, any_far)
    if _block_finish(n, kb, sc, out, lo, redo, mode == 0):
        for u in range(n):
            if redo[u]:
                out[lo + u] = _ff_point(points, normals, polys, pi[lo + u], qi[lo + u], k, w, h, wc, mode)


@_jit(parallel=True)
def _lambert_indexed_kernel(points, normals, polys, pi, qi, mode, out):
    """out[t] = F(points[pi[t]] -> polys[qi[t]]), in parallel tasks of _BLOCK pairs.

    mode: see ``_ff_point``.
    """
    m = pi.shape[0]
    k = polys.shape[1]
    ntasks = (m + _BLOCK - 1) // _BLOCK
    for task in _prange(ntasks):
        sc = np.empty((_ROW_W + 6 * k, _LANES + _PAD))
        redo = np.empty(_LANES, dtype=np.bool_)
        w, h, wc = np.empty((k, 3)), np.empty(k), np.empty((2 * k, 3))
        for lo in range(task * _BLOCK, min(m, (task + 1) * _BLOCK), _LANES):
            _lambert_block(points, normals, polys, pi, qi, lo, min(_LANES, m - lo), mode, out, sc, redo,
                           w, h, wc)


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
    ntasks = (m + per - 1) // per
    for task in _prange(ntasks):
        sc = np.empty((_ROW_W + 6 * k, _LANES + _PAD))
        redo = np.empty(_LANES, dtype=np.bool_)
        w, h, wc = np.empty((k, 3)), np.empty(k), np.empty((2 * k, 3))
        t0 = task * per
        t1 = min(m, t0 + per)
        n = (t1 - t0) * nq
        pidx = np.empty(n, dtype=np.int64)
        qidx = np.empty(n, dtype=np.int64)
        for t in range(t0, t1):
            for r in range(nq):
                pidx[(t - t0) * nq + r] = slot[t] * nq + r
                qidx[(t - t0) * nq + r] = j[t]
        vals = np.empty(n)
        for lo in range(0, n, _LANES):
            _lambert_block(pts, nrm, polys, pidx, qidx, lo, min(_LANES, n - lo), mode, vals, sc, redo,
                           w, h, wc)
        _pair_means(wts, nq, slot, vals, t0, t1, out)


@_jit()
def _pair_means(wts, nq, slot, vals, t0, t1, out):
    """out[t] = sum_r wts[slot[t] nq + r] vals[(t - t0) nq + r] / sum_r wts[...] for t0 <= t < t1:
    each pair's weighted mean over its receiver's nq points."""
    for t in range(t0, t1):
        acc = 0.0
        wsum = 0.0
        for r in range(nq):
            wq = wts[slot[t] * nq + r]
            acc += wq * vals[(t - t0) * nq + r]
            wsum += wq
        out[t] = acc / wsum if wsum > 0.0 else 0.0


# ---------------------------------------------------------------------------------------------
# One triangle or quad against many receivers (point_to_polygon(s)). The source's geometry is the
# same in every lane, so it is prepared once as scalars (w_i = v_i - o, its area vector, radius
# and plane offset), and each lane's whole computation (vertices, edges, flags) stays in
# registers inside one loop over receivers that stores one value: LLVM vectorises it without
# the run-time alias checks that loops writing several scratch rows need (and fail). Lanes whose
# source straddles their plane are stored as -1 and finished by ``_ff_point``; near-only blocks
# run a copy of the loop without the far terms. Polygons with more vertices use the block path.
# ---------------------------------------------------------------------------------------------

_SRC_LANES = 256
# per-source constants, in ``_source_constants``' array
_G_O = 0  # first vertex o (3)
_G_W = 3  # w_1, w_2, w_3 (3 each)
_G_A = 12  # twice the vector area (3)
_G_BOUND = 15  # far2 * radius^2: lanes with |c|^2 above it are far
_G_HWK = 16  # sum_i w_i . 2A / k: plane offset
_G_INPLANE = 17  # IN_PLANE_REL^2 |2A|^2
_G_OK = 18  # 1.0 unless the source is degenerate
_G_NEAR = 19  # GRAZING_SINE^2 |2A|^2: lanes with hs^2 below it times min |a_i|^2 are near the plane
_G_GRAZE = 20  # 1.0 where grazing lanes go to _ff_point's grazing forms (mode 0)
_G_SIZE = 21


@_jit()
def _source_constants(polys, q, mode, g):
    """Fill ``g`` with source q's constants (see the _G_ offsets)."""
    k = polys.shape[1]
    kb = 3 if k == 3 or (polys[q, 3, 0] == polys[q, 2, 0] and polys[q, 3, 1] == polys[q, 2, 1]
                         and polys[q, 3, 2] == polys[q, 2, 2]) else 4
    w = np.zeros((4, 3))
    for d in range(3):
        g[_G_O + d] = polys[q, 0, d]
        for i in range(1, kb):
            w[i, d] = polys[q, i, d] - polys[q, 0, d]
            g[_G_W + 3 * (i - 1) + d] = w[i, d]
        if kb == 3:
            g[_G_W + 6 + d] = 0.0
    r2, A0, A1, A2 = _radius2_area(w, kb)
    hw = 0.0
    for i in range(1, kb):
        hw += w[i, 0] * A0 + w[i, 1] * A1 + w[i, 2] * A2
    alen2 = A0 * A0 + A1 * A1 + A2 * A2
    g[_G_A], g[_G_A + 1], g[_G_A + 2] = A0, A1, A2
    g[_G_BOUND] = (_FAR_RATIO * _FAR_RATIO) * r2 if mode != 1 else np.inf  # mode 1: never far
    g[_G_HWK] = hw / kb
    g[_G_INPLANE] = (_INPLANE * _INPLANE) * alen2
    g[_G_OK] = 1.0 if (alen2 > (_DEG * _DEG) * r2 * r2 and r2 > 0.0) else 0.0
    g[_G_NEAR] = _GRAZING2 * alen2
    g[_G_GRAZE] = 1.0 if mode == 0 else 0.0
    return kb


@_jit(inline="always")
def _edge_near(a0, a1, a2, e0, e1, e2, lai, laj, n0, n1, n2):
    """Lambert's term q_e xn_e of one edge (a: receiver to the edge's start, e: the edge)."""
    x0 = a1 * e2 - a2 * e1
    x1 = a2 * e0 - a0 * e2
    x2 = a0 * e1 - a1 * e0
    s2 = x0 * x0 + x1 * x1 + x2 * x2
    s = np.sqrt(s2)
    g = _atan2p(s, lai + (a0 * e0 + a1 * e1 + a2 * e2)) / s
    t = g * (x0 * n0 + x1 * n1 + x2 * n2)
    return t if s2 > (_DEG * _DEG) * (lai * laj) else 0.0


@_jit(inline="always")
def _edge_far(a0, a1, a2, e0, e1, e2, lai, laj, rai, raj, rhoi, rhoj, gamma, far, n0, n1, n2):
    """(q_e - kappa) xn_e of one edge: the near term, or for a far lane
    q_e - 1/|c|^2 = d1 / P + d2 with P = |a_i||a_j|, d1 = theta/sin - 1 and
    d2 = 1/P - 1/|c|^2 = gamma (rho_i + rho_j) + rho_i rho_j (see ``_far_sum``)."""
    x0 = a1 * e2 - a2 * e1
    x1 = a2 * e0 - a0 * e2
    x2 = a0 * e1 - a1 * e0
    s2 = x0 * x0 + x1 * x1 + x2 * x2
    s = np.sqrt(s2)
    dot = lai + (a0 * e0 + a1 * e1 + a2 * e2)
    g = _atan2p(s, dot) / s
    gi = gamma + rhoi
    gj = gamma + rhoj
    sine = s * (gi * gj)
    d1 = _asin_ratio_m1(sine * sine) if (sine < _SERIES_SINE and dot > 0.0) else g * (rai * raj) - 1.0
    d2 = gamma * (rhoi + rhoj) + rhoi * rhoj
    qe = d1 * (gi * gj) + d2 if far else g
    t = qe * (x0 * n0 + x1 * n1 + x2 * n2)
    return t if s2 > (_DEG * _DEG) * (lai * laj) else 0.0


@_jit(inline="always")
def _far_vertex(c0, c1, c2, w0, w1, w2, la, cabs):
    """|a_i| and rho_i = 1/|a_i| - 1/|c|, from |a_i|^2 - |c|^2 = 2c.w + |w|^2 (no cancellation)."""
    r = np.sqrt(la)
    ali = 2.0 * (c0 * w0 + c1 * w1 + c2 * w2) + (w0 * w0 + w1 * w1 + w2 * w2)
    return r, -ali / (r * cabs * (cabs + r))


@_jit(inline="always")
def _tilted_near(hs, an, near, d2min):
    """The receiver is near the source's plane (hs = its height times |2A|) and tilted towards it
    (an = n . 2A); near = GRAZING_SINE² |2A|², d2min the smallest squared vertex distance."""
    return hs * hs <= near * d2min and an * an > near


@_jit(inline="always")
def _lane_value(total, hs, hmin, hmax, d2max, d2min, rise, an, inplane, near, graze, ok):
    """The stored value: the form factor, 0 (degenerate or edge-on), or -1 for ``_ff_point``,
    which handles what the lane loops do not: sources that must be clipped (hmin < 0), sources
    whose every vertex is within GRAZING_SINE of the horizon (rise = max_i h_i² - GRAZING_SINE²
    |a_i|² <= 0) and receivers near the source's plane and tilted towards it (hs² below
    GRAZING_SINE² |2A|² d2min and (n . 2A)² above GRAZING_SINE² |2A|²). The last two only with
    ``graze`` (mode 0); ``_ff_point`` decides which form serves."""
    live = ok and (hs * hs > inplane * d2max) and (hmax > 0.0)
    value = _fmin(abs(total) * _INV_2PI, 1.0)
    tilted = _tilted_near(hs, an, near, d2min)  # computed up front: selects, not branches, in the lanes
    value = -1.0 if (hmin < 0.0 or (graze and (rise <= 0.0 or tilted))) else value
    return value if live else 0.0


@_vjit()
def _triangle_lanes(PT, NT, lo, n, g, row, any_far):
    """row[lo + u] for receivers lo..lo+n-1 against the triangle described by ``g``."""
    o0, o1, o2 = g[_G_O], g[_G_O + 1], g[_G_O + 2]
    w10, w11, w12 = g[_G_W], g[_G_W + 1], g[_G_W + 2]
    w20, w21, w22 = g[_G_W + 3], g[_G_W + 4], g[_G_W + 5]
    A0, A1, A2 = g[_G_A], g[_G_A + 1], g[_G_A + 2]
    bound, hwk, inplane, ok = g[_G_BOUND], g[_G_HWK], g[_G_INPLANE], g[_G_OK] > 0.0
    near, graze = g[_G_NEAR], g[_G_GRAZE] > 0.0
    e10, e11, e12 = w20 - w10, w21 - w11, w22 - w12
    for u in range(n):
        n0, n1, n2 = NT[0, lo + u], NT[1, lo + u], NT[2, lo + u]
        c0, c1, c2 = o0 - PT[0, lo + u], o1 - PT[1, lo + u], o2 - PT[2, lo + u]
        b0, b1, b2 = c0 + w10, c1 + w11, c2 + w12
        d0, d1, d2 = c0 + w20, c1 + w21, c2 + w22
        la0 = c0 * c0 + c1 * c1 + c2 * c2
        la1 = b0 * b0 + b1 * b1 + b2 * b2
        la2 = d0 * d0 + d1 * d1 + d2 * d2
        h0 = c0 * n0 + c1 * n1 + c2 * n2
        h1 = b0 * n0 + b1 * n1 + b2 * n2
        h2 = d0 * n0 + d1 * n1 + d2 * n2
        hs = c0 * A0 + c1 * A1 + c2 * A2 + hwk
        if any_far:
            far = la0 > bound
            gamma = 1.0 / np.sqrt(la0)
            cabs = la0 * gamma
            r1, p1 = _far_vertex(c0, c1, c2, w10, w11, w12, la1, cabs)
            r2, p2 = _far_vertex(c0, c1, c2, w20, w21, w22, la2, cabs)
            p1 = p1 if far else 0.0
            p2 = p2 if far else 0.0
            total = (A0 * n0 + A1 * n1 + A2 * n2) / la0 if far else 0.0
            total += _edge_far(c0, c1, c2, w10, w11, w12, la0, la1, cabs, r1, 0.0, p1, gamma, far, n0, n1, n2)
            total += _edge_far(b0, b1, b2, e10, e11, e12, la1, la2, r1, r2, p1, p2, gamma, far, n0, n1, n2)
            total += _edge_far(d0, d1, d2, -w20, -w21, -w22, la2, la0, r2, cabs, p2, 0.0, gamma, far, n0, n1, n2)
        else:
            total = _edge_near(c0, c1, c2, w10, w11, w12, la0, la1, n0, n1, n2)
            total += _edge_near(b0, b1, b2, e10, e11, e12, la1, la2, n0, n1, n2)
            total += _edge_near(d0, d1, d2, -w20, -w21, -w22, la2, la0, n0, n1, n2)
        rise = _fmax(h0 * h0 - _GRAZING2 * la0, _fmax(h1 * h1 - _GRAZING2 * la1, h2 * h2 - _GRAZING2 * la2))
        row[lo + u] = _lane_value(total, hs, _fmin(h0, _fmin(h1, h2)), _fmax(h0, _fmax(h1, h2)),
                                  _fmax(la0, _fmax(la1, la2)), _fmin(la0, _fmin(la1, la2)), rise,
                                  A0 * n0 + A1 * n1 + A2 * n2, inplane, near, graze, ok)


@_vjit()
def _quad_lanes(PT, NT, lo, n, g, row, any_far):
    """row[lo + u] for receivers lo..lo+n-1 against the quad described by ``g``.

    ``_triangle_lanes`` with a fourth vertex, written out rather than shared: a quad loop fed
    padded triangles would spend a quarter more on the null edge, and a loop over vertices
    inside the lane loop would keep LLVM from vectorising it."""
    o0, o1, o2 = g[_G_O], g[_G_O + 1], g[_G_O + 2]
    w10, w11, w12 = g[_G_W], g[_G_W + 1], g[_G_W + 2]
    w20, w21, w22 = g[_G_W + 3], g[_G_W + 4], g[_G_W + 5]
    w30, w31, w32 = g[_G_W + 6], g[_G_W + 7], g[_G_W + 8]
    A0, A1, A2 = g[_G_A], g[_G_A + 1], g[_G_A + 2]
    bound, hwk, inplane, ok = g[_G_BOUND], g[_G_HWK], g[_G_INPLANE], g[_G_OK] > 0.0
    near, graze = g[_G_NEAR], g[_G_GRAZE] > 0.0
    e10, e11, e12 = w20 - w10, w21 - w11, w22 - w12
    e20, e21, e22 = w30 - w20, w31 - w21, w32 - w22
    for u in range(n):
        n0, n1, n2 = NT[0, lo + u], NT[1, lo + u], NT[2, lo + u]
        c0, c1, c2 = o0 - PT[0, lo + u], o1 - PT[1, lo + u], o2 - PT[2, lo + u]
        b0, b1, b2 = c0 + w10, c1 + w11, c2 + w12
        d0, d1, d2 = c0 + w20, c1 + w21, c2 + w22
        f0, f1, f2 = c0 + w30, c1 + w31, c2 + w32
        la0 = c0 * c0 + c1 * c1 + c2 * c2
        la1 = b0 * b0 + b1 * b1 + b2 * b2
        la2 = d0 * d0 + d1 * d1 + d2 * d2
        la3 = f0 * f0 + f1 * f1 + f2 * f2
        h0 = c0 * n0 + c1 * n1 + c2 * n2
        h1 = b0 * n0 + b1 * n1 + b2 * n2
        h2 = d0 * n0 + d1 * n1 + d2 * n2
        h3 = f0 * n0 + f1 * n1 + f2 * n2
        hs = c0 * A0 + c1 * A1 + c2 * A2 + hwk
        if any_far:
            far = la0 > bound
            gamma = 1.0 / np.sqrt(la0)
            cabs = la0 * gamma
            r1, p1 = _far_vertex(c0, c1, c2, w10, w11, w12, la1, cabs)
            r2, p2 = _far_vertex(c0, c1, c2, w20, w21, w22, la2, cabs)
            r3, p3 = _far_vertex(c0, c1, c2, w30, w31, w32, la3, cabs)
            p1 = p1 if far else 0.0
            p2 = p2 if far else 0.0
            p3 = p3 if far else 0.0
            total = (A0 * n0 + A1 * n1 + A2 * n2) / la0 if far else 0.0
            total += _edge_far(c0, c1, c2, w10, w11, w12, la0, la1, cabs, r1, 0.0, p1, gamma, far, n0, n1, n2)
            total += _edge_far(b0, b1, b2, e10, e11, e12, la1, la2, r1, r2, p1, p2, gamma, far, n0, n1, n2)
            total += _edge_far(d0, d1, d2, e20, e21, e22, la2, la3, r2, r3, p2, p3, gamma, far, n0, n1, n2)
            total += _edge_far(f0, f1, f2, -w30, -w31, -w32, la3, la0, r3, cabs, p3, 0.0, gamma, far, n0, n1, n2)
        else:
            total = _edge_near(c0, c1, c2, w10, w11, w12, la0, la1, n0, n1, n2)
            total += _edge_near(b0, b1, b2, e10, e11, e12, la1, la2, n0, n1, n2)
            total += _edge_near(d0, d1, d2, e20, e21, e22, la2, la3, n0, n1, n2)
            total += _edge_near(f0, f1, f2, -w30, -w31, -w32, la3, la0, n0, n1, n2)
        rise = _fmax(_fmax(h0 * h0 - _GRAZING2 * la0, h1 * h1 - _GRAZING2 * la1),
                     _fmax(h2 * h2 - _GRAZING2 * la2, h3 * h3 - _GRAZING2 * la3))
        row[lo + u] = _lane_value(total, hs, _fmin(_fmin(h0, h1), _fmin(h2, h3)),
                                  _fmax(_fmax(h0, h1), _fmax(h2, h3)),
                                  _fmax(_fmax(la0, la1), _fmax(la2, la3)), _fmin(_fmin(la0, la1), _fmin(la2, la3)),
                                  rise, A0 * n0 + A1 * n1 + A2 * n2, inplane, near, graze, ok)


@_vjit()
def _any_far(PT, lo, n, g):
    """Whether any receiver lo..lo+n-1 is far from the source described by ``g``."""
    o0, o1, o2, bound = g[_G_O], g[_G_O + 1], g[_G_O + 2], g[_G_BOUND]
    most = 0.0
    for u in range(n):
        c0, c1, c2 = o0 - PT[0, lo + u], o1 - PT[1, lo + u], o2 - PT[2, lo + u]
        most = _fmax(most, c0 * c0 + c1 * c1 + c2 * c2)
    return most > bound


@_jit()
def _source_block(PT, NT, lo, n, polys, q, mode, row, g, w, h, wc):
    """row[lo + u] = F(receiver lo + u -> polys[q]) for u < n, polys[q] a triangle or quad;
    receivers are the columns of PT, NT (3, m)."""
    kb = _source_constants(polys, q, mode, g)
    any_far = _any_far(PT, lo, n, g)
    if kb == 3:
        _triangle_lanes(PT, NT, lo, n, g, row, any_far)
    else:
        _quad_lanes(PT, NT, lo, n, g, row, any_far)
    for u in range(n):
        if row[lo + u] < 0.0:
            row[lo + u] = _ff_point(PT.T, NT.T, polys, lo + u, q, polys.shape[1], w, h, wc, mode)


@_jit(parallel=True)
def _quadrature_source_kernel(pts, nrm, wts, nq, slot, polys, j, mode, out):
    """``_quadrature_kernel`` for triangles and quads, with the pairs sorted by source ``j``: the
    receiver points of a run of pairs facing one source are copied into (3, n) rows and go
    through the one-source lane loops together."""
    m = slot.shape[0]
    k = polys.shape[1]
    per = max(1, _BLOCK // nq)
    ntasks = (m + per - 1) // per
    for task in _prange(ntasks):
        t0 = task * per
        t1 = min(m, t0 + per)
        n = (t1 - t0) * nq
        PT = np.empty((3, n))
        NT = np.empty((3, n))
        vals = np.empty(n)
        g = np.empty(_G_SIZE)
        w, h, wc = np.empty((k, 3)), np.empty(k), np.empty((2 * k, 3))
        for t in range(t0, t1):
            for r in range(nq):
                for d in range(3):
                    PT[d, (t - t0) * nq + r] = pts[slot[t] * nq + r, d]
                    NT[d, (t - t0) * nq + r] = nrm[slot[t] * nq + r, d]
        t = t0
        while t < t1:
            te = t + 1
            while te < t1 and j[te] == j[t]:
                te += 1
            for lo in range((t - t0) * nq, (te - t0) * nq, _SRC_LANES):
                _source_block(PT, NT, lo, min(_SRC_LANES, (te - t0) * nq - lo), polys, j[t], mode, vals, g,
                              w, h, wc)
            t = te
        _pair_means(wts, nq, slot, vals, t0, t1, out)


@_jit(parallel=True)
def _lambert_matrix_kernel(points, normals, polys, mode, out):
    """out[q, p] = F(points[p] -> polys[q]) for every receiver p and polygon q.

    Tasks are (block of receivers) x (range of polygons), so that a few receivers facing many
    polygons still use every core. Triangles and quads take the one-source lane loops, larger
    polygons the block path.
    """
    m = points.shape[0]
    nsrc = polys.shape[0]
    k = polys.shape[1]
    lanes = _SRC_LANES if k <= 4 else _LANES
    PT = np.ascontiguousarray(points.T)
    NT = np.ascontiguousarray(normals.T)
    nblocks = (m + lanes - 1) // lanes
    nchunks = max(1, min(nsrc, (32 + nblocks - 1) // nblocks))
    per = (nsrc + nchunks - 1) // nchunks
    for task in _prange(nblocks * nchunks):
        lo = (task // nchunks) * lanes
        n = min(lanes, m - lo)
        g = np.empty(_G_SIZE)
        w, h, wc = np.empty((k, 3)), np.empty(k), np.empty((2 * k, 3))
        if k <= 4:
            for q in range((task % nchunks) * per, min(nsrc, (task % nchunks + 1) * per)):
                _source_block(PT, NT, lo, n, polys, q, mode, out[q], g, w, h, wc)
            continue
        sc = np.empty((_ROW_W + 6 * k, _LANES + _PAD))
        redo = np.empty(_LANES, dtype=np.bool_)
        pidx = np.arange(lo, lo + n)
        qidx = np.empty(n, dtype=np.int64)
        for q in range((task % nchunks) * per, min(nsrc, (task % nchunks + 1) * per)):
            qidx[:] = q
            _lambert_block(points, normals, polys, pidx, qidx, 0, n, mode, out[q, lo:lo + n], sc, redo, w, h, wc)

"""numba kernel: the hidden part of a partly occluded pair, integrated over shadow-aligned cells.

For a receiver point x the hidden form factor F(x -> hidden(x)) (``_exact_kernel._point_hidden``)
is continuous in x, but its derivative jumps where the hidden polygon changes shape: where x
crosses a plane through a source vertex and an occluder edge, through an occluder vertex and a
source edge, through a vertex of one occluder and an edge of another, or an occluder's own
plane. A Gauss rule across such a kink converges only at first order (the blocked plates
with a plate cut 3 x 3 erred by 1e-2), so each receiver is cut along these lines first:

1. the receiver, in its plane, is clipped to the source's front half-space (points behind it
   see the source's back, which gives nothing: the fill's one-sided rule, as in
   ``quadrature.pair_factors``);
2. every event line whose event actually happens on the receiver (the central projection of
   the edge through the vertex meets it) cuts the convex cells into convex cells;
3. each cell is fanned into quadrilaterals (and a last triangle where its vertex count is
   odd); a piece close to a source or occluder edge compared with its size is split in four
   (graded towards edges and corners), and the others take the Gauss order that the a-priori
   bound ``(distance / size)**(-2 p)`` says meets the tolerance: a p x p rule through the
   piece's bilinear map of the unit square (collapsed on one side for a triangle). On the
   blocked plates, whose cells are rectangles, a quadrilateral's rule takes half the points of
   its two triangles' at the same order and errs less (n = 32: 9 points a pair instead of 18,
   worst pair 1e-13 instead of 4e-11 from a reference at rtol 1e-13).

Inside a cell the integrand is smooth (up to events involving three edges of two occluders,
which the grading resolves only at a lower rate), so the hidden factor converges spectrally.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .._geometry_kernels import newell_z

# numba's disk cache of this module's kernels holds the _exact_kernel helpers compiled in, and
# is keyed on this file alone: a change there must touch this file too, or stale code runs
# (last: _point_hidden's one-occluder path, _clip, _lambert and _hidden_polygon skip work; session 16).
from ._constants import GOOD, OUT_OF_POINTS, OUT_OF_ROOM
from ._exact_kernel import _classify_one, _hidden_polygon, _lambert, _point_hidden, union_scratch

# Event lines one pair may cut its receiver by, and the cells they may make.
MAX_LINES = 128
MAX_CELLS = 256
# Vertices a cell may have (a convex polygon cut by lines gains at most one per cut).
_CELL_VERTICES = 72
# Pieces (pending and done) and depth of the grading.
MAX_PIECES = 2048
MAX_DEPTH = 7
# Quadrilateral pieces this many circumradii (or more) from the nearest source or occluder edge
# take the Bernstein-ellipse gain in their a-priori bound (below). Blocked plates n = 16: 16 -> 9
# points a pair, worst pair 1.3e-11 off (the triangles' rule erred by 2.1e-12 there, and 4.4e-11
# at n = 32); the office rows (tests/helpers.office_scene) stay at 1.1e-6 and 3.4e-6. With the
# gain on every quadrilateral (rho > 1) the office's worst row went 1.1e-6 -> 3.0e-6.
QUAD_FAR = 6.0
_ORDERS = (1, 2, 3, 4, 5, 6, 8)


def gauss_table(max_order: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """(max_order + 1, max_order) Gauss-Legendre nodes and weights on [0, 1]; row p: order p."""
    nodes = np.zeros((max_order + 1, max_order))
    weights = np.zeros((max_order + 1, max_order))
    for p in range(1, max_order + 1):
        x, w = np.polynomial.legendre.leggauss(p)
        nodes[p, :p] = 0.5 * (x + 1.0)
        weights[p, :p] = 0.5 * w
    return nodes, weights


@njit(cache=True, inline="always")
def _clip2(src, n, dst, a, b, c, eps):
    """Keep a u + b w + c >= 0 of the convex 2-D polygon src[:n] (into dst); returns the count."""
    m = 0
    for k in range(n):
        k2 = k + 1 if k + 1 < n else 0
        h1 = a * src[k, 0] + b * src[k, 1] + c
        h2 = a * src[k2, 0] + b * src[k2, 1] + c
        if abs(h1) <= eps:
            h1 = 0.0
        if abs(h2) <= eps:
            h2 = 0.0
        if h1 >= 0.0:
            dst[m, 0] = src[k, 0]
            dst[m, 1] = src[k, 1]
            m += 1
        if (h1 > 0.0 and h2 < 0.0) or (h1 < 0.0 and h2 > 0.0):
            t = h1 / (h1 - h2)
            dst[m, 0] = src[k, 0] + t * (src[k2, 0] - src[k, 0])
            dst[m, 1] = src[k, 1] + t * (src[k2, 1] - src[k, 1])
            m += 1
    return m


@njit(cache=True, inline="always")
def _polygon_area2(poly, n):
    return 0.5 * newell_z(poly, n)


@njit(cache=True, inline="always")
def _to_plane(px, py, pz, o, e1, e2):
    return ((px - o[0]) * e1[0] + (py - o[1]) * e1[1] + (pz - o[2]) * e1[2],
            (px - o[0]) * e2[0] + (py - o[1]) * e2[1] + (pz - o[2]) * e2[2])


@njit(cache=True, inline="always")
def _project(fx, fy, fz, nx_, ny_, nz_, n, d):
    """Where the ray from F through N meets the plane n . x = d beyond N: (ok, x, y, z)."""
    dx, dy, dz = nx_ - fx, ny_ - fy, nz_ - fz
    den = n[0] * dx + n[1] * dy + n[2] * dz
    if den == 0.0:
        return False, 0.0, 0.0, 0.0
    t = (d - (n[0] * fx + n[1] * fy + n[2] * fz)) / den
    if not t > 1.0:
        return False, 0.0, 0.0, 0.0
    return True, fx + t * dx, fy + t * dy, fz + t * dz


@njit(cache=True)
def _segment_meets(poly, n, ax, ay, bx, by, eps):
    """Whether the 2-D segment a-b meets the convex counter-clockwise polygon poly[:n]."""
    t0, t1 = 0.0, 1.0
    for k in range(n):
        k2 = k + 1 if k + 1 < n else 0
        ex, ey = poly[k2, 0] - poly[k, 0], poly[k2, 1] - poly[k, 1]
        # inward normal of a counter-clockwise edge
        gx, gy = -ey, ex
        ha = gx * (ax - poly[k, 0]) + gy * (ay - poly[k, 1])
        hb = gx * (bx - poly[k, 0]) + gy * (by - poly[k, 1])
        if ha < -eps and hb < -eps:
            return False
        if ha < -eps or hb < -eps:
            t = ha / (ha - hb)
            if ha < hb:
                t0 = max(t0, t)
            else:
                t1 = min(t1, t)
            if t0 > t1:
                return False
    return True


@njit(cache=True, inline="always")
def _plane_splits(mx, my, mz, qx, qy, qz, o, e1, e2, dom, nd):
    """Whether the plane (normal m, through q) has vertices of the domain dom[:nd] (receiver
    coordinates) strictly on both sides: signs only, unnormalised, so no root and no division.
    A plane that fails misses the domain whatever :func:`_trace`'s margin."""
    a = mx * e1[0] + my * e1[1] + mz * e1[2]
    b = mx * e2[0] + my * e2[1] + mz * e2[2]
    c = mx * (o[0] - qx) + my * (o[1] - qy) + mz * (o[2] - qz)
    below, above = False, False
    for k in range(nd):
        h = a * dom[k, 0] + b * dom[k, 1] + c
        below |= h < 0.0
        above |= h > 0.0
    return below and above


@njit(cache=True, inline="always")
def _event_splits(ax, ay, az, bx, by, bz, px, py, pz, o, e1, e2, dom, nd):
    """:func:`_plane_splits` for the plane through the segment a-b and the point p."""
    ex, ey, ez = bx - ax, by - ay, bz - az
    fx, fy, fz = ax - px, ay - py, az - pz
    return _plane_splits(ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx, px, py, pz, o, e1, e2, dom, nd)


@njit(cache=True, inline="always")
def _trace(mx, my, mz, qx, qy, qz, o, e1, e2, dom, nd, eps):
    """The trace a u + b w + c = 0 on the receiver plane of the plane (normal m, through q),
    unit (a, b): (crosses, a, b, c), crosses False where it misses the domain dom[:nd] or the
    planes are parallel."""
    if not _plane_splits(mx, my, mz, qx, qy, qz, o, e1, e2, dom, nd):
        return False, 0.0, 0.0, 0.0
    a = mx * e1[0] + my * e1[1] + mz * e1[2]
    b = mx * e2[0] + my * e2[1] + mz * e2[2]
    s = math.sqrt(a * a + b * b)
    if s <= 1e-9 * math.sqrt(mx * mx + my * my + mz * mz):
        return False, 0.0, 0.0, 0.0
    a /= s
    b /= s
    c = (mx * (o[0] - qx) + my * (o[1] - qy) + mz * (o[2] - qz)) / s
    lo, hi = 0.0, 0.0
    for k in range(nd):
        h = a * dom[k, 0] + b * dom[k, 1] + c
        lo = min(lo, h)
        hi = max(hi, h)
    return lo < -eps and hi > eps, a, b, c


@njit(cache=True, inline="always")
def _append_line(lines, n_lines, a, b, c, eps):
    """Append the line (a, b, c) unless it is there already (either orientation) or lines is
    full; returns the new line count."""
    if n_lines >= lines.shape[0]:
        return n_lines
    for t in range(n_lines):  # the same line twice cuts nothing new
        if abs(lines[t, 0] - a) + abs(lines[t, 1] - b) + abs(lines[t, 2] - c) <= eps:
            return n_lines
        if abs(lines[t, 0] + a) + abs(lines[t, 1] + b) + abs(lines[t, 2] + c) <= eps:
            return n_lines
    lines[n_lines, 0] = a
    lines[n_lines, 1] = b
    lines[n_lines, 2] = c
    return n_lines + 1


@njit(cache=True)
def _add_line(lines, n_lines, mx, my, mz, qx, qy, qz, o, e1, e2, dom, nd, eps):
    """Append the trace on the receiver plane of the plane (normal m, through q) if it crosses
    the domain dom[:nd]; returns the new line count."""
    crosses, a, b, c = _trace(mx, my, mz, qx, qy, qz, o, e1, e2, dom, nd, eps)
    if not crosses:
        return n_lines
    return _append_line(lines, n_lines, a, b, c, eps)


@njit(cache=True)
def _event_line(lines, n_lines, seg_is_far, sax, say, saz, sbx, sby, sbz, ptx, pty, ptz, nrm, d, o, e1, e2, dom, nd,
                eps):
    """Line of the events 'the segment sa-sb and the point pt line up with x' on the receiver.

    ``seg_is_far``: the segment is the far element (a source edge seen past an occluder vertex)
    or the near one (an occluder edge in front of a source vertex). The event happens on the
    receiver only where its line crosses the receiver and the central projection of the
    segment through (or from) the point meets it; other lines are skipped.
    """
    ex, ey, ez = sbx - sax, sby - say, sbz - saz
    fx, fy, fz = sax - ptx, say - pty, saz - ptz
    mx, my, mz = ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx
    if mx * mx + my * my + mz * mz <= 1e-24 * (ex * ex + ey * ey + ez * ez) * (fx * fx + fy * fy + fz * fz):
        return n_lines  # the point lies on the segment's line
    # the cheap test first: most event planes of a small receiver miss it
    crosses, a, b, c = _trace(mx, my, mz, ptx, pty, ptz, o, e1, e2, dom, nd, eps)
    if not crosses:
        return n_lines
    if seg_is_far:
        ok0, x0, y0, z0 = _project(sax, say, saz, ptx, pty, ptz, nrm, d)
        ok1, x1, y1, z1 = _project(sbx, sby, sbz, ptx, pty, ptz, nrm, d)
    else:
        ok0, x0, y0, z0 = _project(ptx, pty, ptz, sax, say, saz, nrm, d)
        ok1, x1, y1, z1 = _project(ptx, pty, ptz, sbx, sby, sbz, nrm, d)
    if not (ok0 or ok1):
        return n_lines
    if ok0 and ok1:
        u0, w0 = _to_plane(x0, y0, z0, o, e1, e2)
        u1, w1 = _to_plane(x1, y1, z1, o, e1, e2)
        if not _segment_meets(dom, nd, u0, w0, u1, w1, eps):
            return n_lines
    return _append_line(lines, n_lines, a, b, c, eps)


@njit(cache=True, inline="always")
def _segment_distance(px, py, pz, a, b):
    ex, ey, ez = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    rx, ry, rz = px - a[0], py - a[1], pz - a[2]
    l2 = ex * ex + ey * ey + ez * ez
    t = 0.0 if l2 == 0.0 else min(1.0, max(0.0, (rx * ex + ry * ey + rz * ez) / l2))
    dx, dy, dz = rx - t * ex, ry - t * ey, rz - t * ez
    return math.sqrt(dx * dx + dy * dy + dz * dz)


@njit(cache=True)
def _pair_hidden(rec, nr, src, sn, occ, t0, t1, opolys, onormal, ocenter, oinward, tol, max_union, rtol, max_points,
                 gn, gw, work, work2):
    """Mean over the receiver (its part in front of the source) of the hidden form factor.

    Returns (hidden, status, points, capped); status is OUT_OF_ROOM where a point needed
    shapely (more than max_union hidden polygons) or the lines, cells or pieces ran out, and
    OUT_OF_POINTS where the budget of max_points cut a piece's order below what the bound asks
    (a strip of floor behind a desk, its edge on the desk's back face: 15% low at rtol 1e-9 and
    4,096 points, silently). Either way the pair stops there and its hidden factor is 0.
    """
    (a, b, s1, s2, hp, hn, levels, lcount, nxt, sa, sb, lines, cells, ccount, tmp, pieces, pdepth, pquad, segs) = work
    (piece3, locc, pocc, si, sj, outside, valid, gi, gj) = work2
    ms = opolys.shape[1]
    ns = src.shape[0]
    # receiver plane frame
    ox = (rec[0, 0] + rec[1, 0] + rec[2, 0] + rec[3, 0]) / 4.0
    oy = (rec[0, 1] + rec[1, 1] + rec[2, 1] + rec[3, 1]) / 4.0
    oz = (rec[0, 2] + rec[1, 2] + rec[2, 2] + rec[3, 2]) / 4.0
    o = np.array((ox, oy, oz))
    if abs(nr[0]) < 0.9:
        hx, hy, hz = 1.0, 0.0, 0.0
    else:
        hx, hy, hz = 0.0, 1.0, 0.0
    e1 = np.array((nr[1] * hz - nr[2] * hy, nr[2] * hx - nr[0] * hz, nr[0] * hy - nr[1] * hx))
    e1 /= math.sqrt(e1[0] ** 2 + e1[1] ** 2 + e1[2] ** 2)
    e2 = np.array((nr[1] * e1[2] - nr[2] * e1[1], nr[2] * e1[0] - nr[0] * e1[2], nr[0] * e1[1] - nr[1] * e1[0]))
    d = nr[0] * ox + nr[1] * oy + nr[2] * oz
    # receiver in 2-D, repeated vertices dropped, counter-clockwise about nr
    nd = 0
    dom = cells[0]
    size = 0.0
    for k in range(4):
        u, w = _to_plane(rec[k, 0], rec[k, 1], rec[k, 2], o, e1, e2)
        if nd > 0 and abs(u - dom[nd - 1, 0]) + abs(w - dom[nd - 1, 1]) <= 0.0:
            continue
        dom[nd, 0] = u
        dom[nd, 1] = w
        nd += 1
        size = max(size, abs(u) + abs(w))
    if nd > 1 and dom[nd - 1, 0] == dom[0, 0] and dom[nd - 1, 1] == dom[0, 1]:
        nd -= 1
    area = _polygon_area2(dom, nd)
    if nd < 3 or area == 0.0:
        return 0.0, GOOD, 0, False
    if area < 0.0:
        for k in range(nd // 2):
            for c in range(2):
                dom[k, c], dom[nd - 1 - k, c] = dom[nd - 1 - k, c], dom[k, c]
        area = -area
    eps = 1e-12 * size
    # 1. the front of the source's plane
    scx = (src[0, 0] + src[1, 0] + src[2, 0] + src[3, 0]) / 4.0
    scy = (src[0, 1] + src[1, 1] + src[2, 1] + src[3, 1]) / 4.0
    scz = (src[0, 2] + src[1, 2] + src[2, 2] + src[3, 2]) / 4.0
    fa = sn[0] * e1[0] + sn[1] * e1[1] + sn[2] * e1[2]
    fb = sn[0] * e2[0] + sn[1] * e2[1] + sn[2] * e2[2]
    fc = sn[0] * (ox - scx) + sn[1] * (oy - scy) + sn[2] * (oz - scz)
    nd = _clip2(dom, nd, tmp, fa, fb, fc, 1e-12 * (size + abs(fc)))
    if nd < 3:
        return 0.0, GOOD, 0, False
    for k in range(nd):
        dom[k, 0] = tmp[k, 0]
        dom[k, 1] = tmp[k, 1]
    # 2. occluders with a part in front of both planes (one entirely on or behind the
    # receiver's plane, or the source's, touches no segment that carries light), event lines
    n_occ = 0
    for t in range(t0, t1):
        K = opolys[occ[t]]
        hr = -np.inf
        hs = -np.inf
        for v in range(ms):
            hr = max(hr, nr[0] * K[v, 0] + nr[1] * K[v, 1] + nr[2] * K[v, 2] - d)
            hs = max(hs, sn[0] * (K[v, 0] - scx) + sn[1] * (K[v, 1] - scy) + sn[2] * (K[v, 2] - scz))
        if hr > tol and hs > tol:
            pocc[n_occ] = occ[t]
            n_occ += 1
    if n_occ == 0:
        return 0.0, GOOD, 0, False
    n_lines = 0
    for t in range(n_occ):
        kk = pocc[t]
        K = opolys[kk]
        kn = onormal[kk]
        n_lines = _add_line(lines, n_lines, kn[0], kn[1], kn[2], K[0, 0], K[0, 1], K[0, 2], o, e1, e2, dom, nd, eps)
        for v in range(ms):
            v2 = v + 1 if v + 1 < ms else 0
            for s in range(ns):
                s2i = s + 1 if s + 1 < ns else 0
                # occluder edge in front of a source vertex; the inlined sign test first, since
                # most planes miss a small receiver and a call of _event_line costs 10x the test
                if _event_splits(K[v, 0], K[v, 1], K[v, 2], K[v2, 0], K[v2, 1], K[v2, 2], src[s, 0], src[s, 1],
                                 src[s, 2], o, e1, e2, dom, nd):
                    n_lines = _event_line(lines, n_lines, False, K[v, 0], K[v, 1], K[v, 2], K[v2, 0], K[v2, 1],
                                          K[v2, 2], src[s, 0], src[s, 1], src[s, 2], nr, d, o, e1, e2, dom, nd, eps)
                # source edge seen past an occluder vertex
                if _event_splits(src[s, 0], src[s, 1], src[s, 2], src[s2i, 0], src[s2i, 1], src[s2i, 2], K[v, 0],
                                 K[v, 1], K[v, 2], o, e1, e2, dom, nd):
                    n_lines = _event_line(lines, n_lines, True, src[s, 0], src[s, 1], src[s, 2], src[s2i, 0],
                                          src[s2i, 1], src[s2i, 2], K[v, 0], K[v, 1], K[v, 2], nr, d, o, e1, e2, dom,
                                          nd, eps)
        if 2 <= n_occ and n_occ * n_occ * ms <= max_points:  # lines between occluders, if affordable
            for t2 in range(n_occ):
                if t2 == t:
                    continue
                K2 = opolys[pocc[t2]]
                for v in range(ms):
                    for e in range(ms):
                        e2i = e + 1 if e + 1 < ms else 0
                        ex = K2[e2i, 0] - K2[e, 0]
                        ey = K2[e2i, 1] - K2[e, 1]
                        ez = K2[e2i, 2] - K2[e, 2]
                        fx = K2[e, 0] - K[v, 0]
                        fy = K2[e, 1] - K[v, 1]
                        fz = K2[e, 2] - K[v, 2]
                        n_lines = _add_line(lines, n_lines, ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx,
                                            K[v, 0], K[v, 1], K[v, 2], o, e1, e2, dom, nd, eps)
    if n_lines >= lines.shape[0]:
        return 0.0, OUT_OF_ROOM, 0, False
    capped = False
    # 3. cut the domain into convex cells
    n_cells = 1
    ccount[0] = nd
    for t in range(n_lines):
        la, lb, lc = lines[t, 0], lines[t, 1], lines[t, 2]
        for c in range(n_cells):
            nc = ccount[c]
            lo, hi = 0.0, 0.0
            for k in range(nc):
                h = la * cells[c, k, 0] + lb * cells[c, k, 1] + lc
                lo = min(lo, h)
                hi = max(hi, h)
            if not (lo < -eps and hi > eps):
                continue
            if n_cells >= cells.shape[0] or nc + 2 > cells.shape[1]:
                return 0.0, OUT_OF_ROOM, 0, False
            m2 = _clip2(cells[c], nc, cells[n_cells], -la, -lb, -lc, eps)
            m1 = _clip2(cells[c], nc, tmp, la, lb, lc, eps)
            if m1 >= 3 and m2 >= 3:
                for k in range(m1):
                    cells[c, k, 0] = tmp[k, 0]
                    cells[c, k, 1] = tmp[k, 1]
                ccount[c] = m1
                ccount[n_cells] = m2
                n_cells += 1
    # singular segments: edges of the source and the occluders, but not those lying in the
    # receiver's plane (the hidden polygon's cone through such an edge is the receiver's plane
    # itself, whatever x; and a hidden part next to x means an occluder edge next to x)
    n_segs = 0
    for s in range(ns):
        s2i = s + 1 if s + 1 < ns else 0
        h1 = nr[0] * src[s, 0] + nr[1] * src[s, 1] + nr[2] * src[s, 2] - d
        h2 = nr[0] * src[s2i, 0] + nr[1] * src[s2i, 1] + nr[2] * src[s2i, 2] - d
        if abs(h1) <= tol and abs(h2) <= tol:
            continue
        for c in range(3):
            segs[n_segs, 0, c] = src[s, c]
            segs[n_segs, 1, c] = src[s2i, c]
        n_segs += 1
    # 4. pieces (a convex cell fanned into quadrilaterals, see below), graded towards
    # those segments, each with its a-priori Gauss order
    n_pieces = 0
    for c in range(n_cells):
        # a convex cell fans from its vertex 0 into quadrilaterals (v0, vk, vk+1, vk+2) and, for
        # an odd count, one last triangle: a tensor Gauss rule on a quadrilateral takes half the
        # points of the two triangles' collapsed rules at the same order, and errs less
        k = 1
        while k < ccount[c] - 1:
            if n_pieces >= pieces.shape[0]:
                return 0.0, OUT_OF_ROOM, 0, False
            quad = k + 2 < ccount[c]
            for cc in range(2):
                pieces[n_pieces, 0, cc] = cells[c, 0, cc]
                pieces[n_pieces, 1, cc] = cells[c, k, cc]
                pieces[n_pieces, 2, cc] = cells[c, k + 1, cc]
                pieces[n_pieces, 3, cc] = cells[c, k + 2, cc] if quad else cells[c, 0, cc]
            pquad[n_pieces] = quad
            pdepth[n_pieces] = 0
            n_pieces += 1
            k += 2 if quad else 1
    hidden = 0.0
    done = 0
    x = np.empty(3)
    while n_pieces > 0:
        n_pieces -= 1
        t = n_pieces
        quad = pquad[t]
        u0, w0 = pieces[t, 0, 0], pieces[t, 0, 1]
        u1, w1 = pieces[t, 1, 0], pieces[t, 1, 1]
        u2, w2 = pieces[t, 2, 0], pieces[t, 2, 1]
        u3, w3 = pieces[t, 3, 0], pieces[t, 3, 1]
        dep = pdepth[t]
        if quad:
            tarea = 0.5 * abs((u2 - u0) * (w3 - w1) - (u3 - u1) * (w2 - w0))
        else:
            tarea = 0.5 * abs((u1 - u0) * (w2 - w0) - (u2 - u0) * (w1 - w0))
        if tarea <= 0.0:
            continue
        for k in range(4 if quad else 3):
            uu, ww = pieces[t, k, 0], pieces[t, k, 1]
            for c in range(3):
                piece3[k, c] = o[c] + uu * e1[c] + ww * e2[c]
        if not quad:
            for c in range(3):
                piece3[3, c] = piece3[2, c]
        # the occluders that may hide part of the source from this piece (exact test); a
        # piece that none can is lit (hidden 0), one that some occluder covers is dark
        n_local = 0
        full = False
        for tt in range(n_occ):
            state = _classify_one(piece3, src, opolys, onormal, ocenter, oinward, pocc[tt], tol, si, sj, outside,
                                  valid, gi, gj)
            if state == 1:
                full = True
                break
            if state == 2:
                locc[n_local] = pocc[tt]
                n_local += 1
        if not full and n_local == 0:
            continue
        if quad:
            cu, cw = (u0 + u1 + u2 + u3) / 4.0, (w0 + w1 + w2 + w3) / 4.0
            rad = max(max(math.hypot(u0 - cu, w0 - cw), math.hypot(u1 - cu, w1 - cw)),
                      max(math.hypot(u2 - cu, w2 - cw), math.hypot(u3 - cu, w3 - cw)))
        else:
            cu, cw = (u0 + u1 + u2) / 3.0, (w0 + w1 + w2) / 3.0
            rad = max(math.hypot(u0 - cu, w0 - cw), math.hypot(u1 - cu, w1 - cw), math.hypot(u2 - cu, w2 - cw))
        px = ox + cu * e1[0] + cw * e2[0]
        py = oy + cu * e1[1] + cw * e2[1]
        pz = oz + cu * e1[2] + cw * e2[2]
        dist = np.inf
        for s in range(n_segs):
            dist = min(dist, _segment_distance(px, py, pz, segs[s, 0], segs[s, 1]))
        if not full:
            for tt in range(n_local):
                K = opolys[locc[tt]]
                for v in range(ms):
                    v2 = v + 1 if v + 1 < ms else 0
                    h1 = nr[0] * K[v, 0] + nr[1] * K[v, 1] + nr[2] * K[v, 2] - d
                    h2 = nr[0] * K[v2, 0] + nr[1] * K[v2, 1] + nr[2] * K[v2, 2] - d
                    if abs(h1) <= tol and abs(h2) <= tol:
                        continue
                    dist = min(dist, _segment_distance(px, py, pz, K[v], K[v2]))
        rho = dist / rad
        if quad and rho >= QUAD_FAR:
            # a p x p rule through a quadrilateral's bilinear map converges with the Bernstein
            # ellipse that clears the singularity: every half-width of the piece is at most rad,
            # so its parameter is at least rho + sqrt(rho^2 - 1) (a triangle's collapsed map
            # squeezes the ellipse, so triangles keep rho)
            rho += math.sqrt(rho * rho - 1.0)
        # the a-priori bound (distance / size)**(-2 p), weighted by the piece's share of the
        # receiver: small pieces (the grading's) need low orders
        share = 0.5 * tarea / area
        p = 0
        # a piece that even the highest order cannot take is split: one pow instead of one
        # per order (rho well above 1, so the orders' bounds keep their order after rounding)
        if rho > 1.0 + 1e-6 and share * rho ** (-2.0 * _ORDERS[len(_ORDERS) - 1]) > rtol:
            pass
        elif rho > 1.0:
            for q in _ORDERS:
                if share * rho ** (-2.0 * q) <= rtol:
                    p = q
                    break
        elif share <= rtol:
            p = 2
        # the budget: no split once pending pieces would take it, and orders shrink to share it
        room = max_points - done
        affordable = n_pieces + 4 <= pieces.shape[0] and room > 4 * (n_pieces + 4)
        if p == 0 and dep < MAX_DEPTH and affordable:
            if quad:
                _split_quad(pieces, pquad, pdepth, n_pieces, u0, w0, u1, w1, u2, w2, u3, w3, dep + 1)
            else:
                _split_triangle(pieces, pquad, pdepth, n_pieces, u0, w0, u1, w1, u2, w2, dep + 1)
            n_pieces += 4
            continue
        if p == 0:
            p = _ORDERS[len(_ORDERS) - 1]
            if dep < MAX_DEPTH:  # the bound asked for a split the budget could not pay
                return 0.0, OUT_OF_POINTS, done, False
            else:  # graded as deep as it goes and still short of the bound
                capped = True
        if p > 1 and p * p * (n_pieces + 1) > room:  # an order below the bound's would do
            return 0.0, OUT_OF_POINTS, done, False
        done += p * p
        # one possible occluder: clip it directly (a call of _point_hidden passes twenty arrays,
        # which cost as much as the clipping; the blocked plates' cells 1.4x faster)
        k_single = locc[0] if n_local == 1 else pocc[0]
        k_one = opolys[k_single]
        kn_one = onormal[k_single]
        # p x p Gauss rule through the piece's bilinear map of the unit square (a triangle's
        # map collapses the side from vertex 3 = vertex 0: the Duffy rule)
        for ia in range(p):
            sa_ = gn[p, ia]
            for ib in range(p):
                tb = gn[p, ib]
                if quad:
                    xu = (1.0 - tb) * (u1 - u0) + tb * (u2 - u3)
                    xw = (1.0 - tb) * (w1 - w0) + tb * (w2 - w3)
                    yu = (1.0 - sa_) * (u3 - u0) + sa_ * (u2 - u1)
                    yw = (1.0 - sa_) * (w3 - w0) + sa_ * (w2 - w1)
                    wq = abs(xu * yw - xw * yu) * gw[p, ia] * gw[p, ib]
                    uu = (1.0 - sa_) * ((1.0 - tb) * u0 + tb * u3) + sa_ * ((1.0 - tb) * u1 + tb * u2)
                    ww = (1.0 - sa_) * ((1.0 - tb) * w0 + tb * w3) + sa_ * ((1.0 - tb) * w1 + tb * w2)
                else:
                    wq = 2.0 * tarea * sa_ * gw[p, ia] * gw[p, ib]
                    uu = u0 + sa_ * (u1 - u0) + sa_ * tb * (u2 - u1)
                    ww = w0 + sa_ * (w1 - w0) + sa_ * tb * (w2 - w1)
                x[0] = ox + uu * e1[0] + ww * e2[0]
                x[1] = oy + uu * e1[1] + ww * e2[1]
                x[2] = oz + uu * e1[2] + ww * e2[2]
                if full:
                    f_h = _lambert(x, nr, src, ns, s2)
                elif n_local == 1:
                    m_h = _hidden_polygon(x, src, ns, sn, k_one, ms, kn_one, tol, a, b, s1, s2)
                    f_h = _lambert(x, nr, s1, m_h, s2) if m_h >= 3 else 0.0
                else:
                    f_h, good = _point_hidden(x, nr, src, sn, locc, 0, n_local, opolys, onormal, tol, max_union, a,
                                              b, s1, s2, hp, hn, levels, lcount, nxt, sa, sb)
                    if not good:
                        return 0.0, OUT_OF_ROOM, done, False
                hidden += wq * f_h
    return hidden / area, GOOD, done, capped


@njit(cache=True, inline="always")
def _put_piece(pieces, pquad, pdepth, t, quad, depth, au, aw, bu, bw, cu, cw, du, dw):
    pieces[t, 0, 0] = au
    pieces[t, 0, 1] = aw
    pieces[t, 1, 0] = bu
    pieces[t, 1, 1] = bw
    pieces[t, 2, 0] = cu
    pieces[t, 2, 1] = cw
    pieces[t, 3, 0] = du
    pieces[t, 3, 1] = dw
    pquad[t] = quad
    pdepth[t] = depth


@njit(cache=True)
def _split_triangle(pieces, pquad, pdepth, t, u0, w0, u1, w1, u2, w2, depth):
    """The triangle's four children (edge midpoints) into pieces[t:t + 4]."""
    m01u, m01w = 0.5 * (u0 + u1), 0.5 * (w0 + w1)
    m12u, m12w = 0.5 * (u1 + u2), 0.5 * (w1 + w2)
    m20u, m20w = 0.5 * (u2 + u0), 0.5 * (w2 + w0)
    _put_piece(pieces, pquad, pdepth, t, False, depth, u0, w0, m01u, m01w, m20u, m20w, u0, w0)
    _put_piece(pieces, pquad, pdepth, t + 1, False, depth, m01u, m01w, u1, w1, m12u, m12w, m01u, m01w)
    _put_piece(pieces, pquad, pdepth, t + 2, False, depth, m20u, m20w, m12u, m12w, u2, w2, m20u, m20w)
    _put_piece(pieces, pquad, pdepth, t + 3, False, depth, m12u, m12w, m20u, m20w, m01u, m01w, m12u, m12w)


@njit(cache=True)
def _split_quad(pieces, pquad, pdepth, t, u0, w0, u1, w1, u2, w2, u3, w3, depth):
    """The quadrilateral's four children (images of the unit square's quarters under its
    bilinear map: edge midpoints and the vertices' mean) into pieces[t:t + 4]."""
    m01u, m01w = 0.5 * (u0 + u1), 0.5 * (w0 + w1)
    m12u, m12w = 0.5 * (u1 + u2), 0.5 * (w1 + w2)
    m23u, m23w = 0.5 * (u2 + u3), 0.5 * (w2 + w3)
    m30u, m30w = 0.5 * (u3 + u0), 0.5 * (w3 + w0)
    cu, cw = 0.25 * (u0 + u1 + u2 + u3), 0.25 * (w0 + w1 + w2 + w3)
    _put_piece(pieces, pquad, pdepth, t, True, depth, u0, w0, m01u, m01w, cu, cw, m30u, m30w)
    _put_piece(pieces, pquad, pdepth, t + 1, True, depth, m01u, m01w, u1, w1, m12u, m12w, cu, cw)
    _put_piece(pieces, pquad, pdepth, t + 2, True, depth, cu, cw, m12u, m12w, u2, w2, m23u, m23w)
    _put_piece(pieces, pquad, pdepth, t + 3, True, depth, m30u, m30w, cu, cw, m23u, m23w, u3, w3)


_PAIR_BLOCK = 16


@njit(cache=True)
def _cells_block(s, e, quads, normals, i, j, starts, occ, opolys, onormal, ocenter, oinward, tol, max_union, rtol,
                 max_points, gn, gw, hidden, status, n_points, capped):
    ms = opolys.shape[1]
    ns = quads.shape[1]
    work = union_scratch(ns, ms, max_union) + (
            np.empty((MAX_LINES, 3)), np.empty((MAX_CELLS, _CELL_VERTICES, 2)),
            np.empty(MAX_CELLS, np.int64), np.empty((_CELL_VERTICES, 2)), np.empty((MAX_PIECES, 4, 2)),
            np.empty(MAX_PIECES, np.int64), np.empty(MAX_PIECES, np.bool_), np.empty((ns, 2, 3)))
    most = 1
    for p in range(s, e):
        most = max(most, starts[p + 1] - starts[p])
    work2 = (np.empty((4, 3)), np.empty(most, np.int64), np.empty(most, np.int64), np.empty(4), np.empty(4), np.zeros(ms, np.bool_),
             np.zeros(ms, np.bool_), np.empty((4, ms)), np.empty((4, ms)))
    for p in range(s, e):
        hidden[p], status[p], n_points[p], capped[p] = _pair_hidden(
            quads[i[p]], normals[i[p]], quads[j[p]], normals[j[p]], occ, starts[p], starts[p + 1], opolys, onormal,
            ocenter, oinward, tol, max_union, rtol, max_points, gn, gw, work, work2)


@njit(cache=True, parallel=True)
def cell_pairs(quads, normals, i, j, starts, occ, opolys, onormal, ocenter, oinward, tol, max_union, rtol, max_points,
               gn, gw):
    """Hidden form factors of partly occluded pairs, integrated over shadow-aligned cells.

    Pair p (receiver i[p], source j[p], both rows of ``quads``) may be blocked by
    ``opolys[occ[starts[p]:starts[p + 1]]]`` (an ``Occluders``' polys, normal, center, inward).
    Gauss orders aim at ``rtol``; a pair evaluates at most about ``max_points`` points (the
    grading stops and the orders shrink to fit).

    Returns
    -------
    hidden : (m,) float
        Mean over receiver i of F(x -> the part of j hidden from x), over x in front of j's
        plane (points behind it see j's back: nothing).
    status : (m,) int8
        GOOD; OUT_OF_POINTS where the point budget ran out (a larger one may do); OUT_OF_ROOM
        where the lines, cells, pieces or the compiled union did. A pair that is not GOOD has
        hidden 0 (the caller falls back to the other side, then to adaptive squares).
    points : (m,) int
        Receiver points evaluated.
    capped : (m,) bool
        True where a piece graded to ``MAX_DEPTH`` still missed the bound: the hidden factor is
        not smooth there at any scale (an occluder's edge ending on the receiver, whose shadow
        then turns about that point), and the pair may err far more than ``rtol``.
    """
    m = i.shape[0]
    hidden = np.zeros(m)
    status = np.zeros(m, np.int8)
    n_points = np.zeros(m, np.int64)
    capped = np.zeros(m, np.bool_)
    n_blocks = (m + _PAIR_BLOCK - 1) // _PAIR_BLOCK
    for blk in prange(n_blocks):
        _cells_block(blk * _PAIR_BLOCK, min(m, (blk + 1) * _PAIR_BLOCK), quads, normals, i, j, starts, occ, opolys,
                     onormal, ocenter, oinward, tol, max_union, rtol, max_points, gn, gw, hidden, status, n_points,
                     capped)
    return hidden, status, n_points, capped

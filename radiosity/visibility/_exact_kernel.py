"""numba kernels of the exact shadows (imported lazily by ``_exact``; compiled once, cached).

One row is (receiver point x, its normal, a convex source polygon, a convex occluder polygon).
The row's hidden polygon is the source clipped by the cone from x over the part of the
occluder that lies between x and the source's plane; see ``_exact`` for the geometry.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .._geometry_kernels import newell

_TWO_PI = 2.0 * math.pi


@njit(cache=True, inline="always")
def _clip(src, n, dst, ax, ay, az, d):
    """Sutherland-Hodgman step of a convex polygon src[:n] to a*v + d >= 0, into dst."""
    if n == 0:
        return 0
    hmax = 0.0
    for k in range(n):
        h = ax * src[k, 0] + ay * src[k, 1] + az * src[k, 2] + d
        if abs(h) > hmax:
            hmax = abs(h)
    eps = 1e-13 * hmax
    h_first = ax * src[0, 0] + ay * src[0, 1] + az * src[0, 2] + d
    if abs(h_first) <= eps:
        h_first = 0.0
    h1 = h_first
    m = 0
    for k in range(n):
        # each vertex's offset once: the next vertex's is this edge's far end
        if k + 1 < n:
            k2 = k + 1
            h2 = ax * src[k2, 0] + ay * src[k2, 1] + az * src[k2, 2] + d
            if abs(h2) <= eps:
                h2 = 0.0
        else:
            k2 = 0
            h2 = h_first
        if h1 >= 0.0:
            dst[m, 0] = src[k, 0]
            dst[m, 1] = src[k, 1]
            dst[m, 2] = src[k, 2]
            m += 1
        if (h1 > 0.0 and h2 < 0.0) or (h1 < 0.0 and h2 > 0.0):
            t = h1 / (h1 - h2)
            dst[m, 0] = src[k, 0] + t * (src[k2, 0] - src[k, 0])
            dst[m, 1] = src[k, 1] + t * (src[k2, 1] - src[k, 1])
            dst[m, 2] = src[k, 2] + t * (src[k2, 2] - src[k, 2])
            m += 1
        h1 = h2
    return m


@njit(cache=True, inline="always")
def _keeps_all(src, n, ax, ay, az, d):
    """True if :func:`_clip` to a*v + d >= 0 would keep src[:n] as it is (no vertex below
    its snapping margin)."""
    hmin = np.inf
    hmax = 0.0
    for k in range(n):
        h = ax * src[k, 0] + ay * src[k, 1] + az * src[k, 2] + d
        hmin = min(hmin, h)
        hmax = max(hmax, abs(h))
    return hmin >= -1e-13 * hmax


@njit(cache=True, inline="always")
def _edge_term(x, nx, p, q, t0=0.0, t1=1.0):
    """Lambert's term of the piece [t0, t1] of the edge p -> q seen from x (normal nx): the angle
    it subtends times the cosine of its plane through x. A polygon's terms sum to 2 pi times its
    form factor, and the terms of pieces of one edge add up to the edge's (one plane through x)."""
    ax = p[0] + t0 * (q[0] - p[0]) - x[0]
    ay = p[1] + t0 * (q[1] - p[1]) - x[1]
    az = p[2] + t0 * (q[2] - p[2]) - x[2]
    bx = p[0] + t1 * (q[0] - p[0]) - x[0]
    by = p[1] + t1 * (q[1] - p[1]) - x[1]
    bz = p[2] + t1 * (q[2] - p[2]) - x[2]
    cx = ay * bz - az * by
    cy = az * bx - ax * bz
    cz = ax * by - ay * bx
    s = math.sqrt(cx * cx + cy * cy + cz * cz)
    la = ax * ax + ay * ay + az * az
    lb = bx * bx + by * by + bz * bz
    if s <= 1e-14 * math.sqrt(la * lb):
        return 0.0
    theta = math.atan2(s, ax * bx + ay * by + az * bz)
    return theta * (cx * nx[0] + cy * nx[1] + cz * nx[2]) / s


@njit(cache=True)
def _lambert(x, nx, poly, n, scratch):
    """Lambert's form factor from point x (normal nx) to polygon poly[:n], horizon-clipped."""
    d = -(nx[0] * x[0] + nx[1] * x[1] + nx[2] * x[2])
    if n >= 3 and _keeps_all(poly, n, nx[0], nx[1], nx[2], d):
        # wholly above the horizon (up to _clip's snapping): the clip would copy it
        return _polygon_term(x, nx, poly, n)
    m = _clip(poly, n, scratch, nx[0], nx[1], nx[2], d)
    if m < 3:
        return 0.0
    return _polygon_term(x, nx, scratch, m)


@njit(cache=True, inline="always")
def _polygon_term(x, nx, poly, n):
    """Lambert's sum over the edges of poly[:n] (all above x's horizon), as a form factor."""
    total = 0.0
    for k in range(n):
        total += _edge_term(x, nx, poly[k], poly[k + 1 if k + 1 < n else 0])
    return min(abs(total) / _TWO_PI, 1.0)


@njit(cache=True, parallel=True)
def point_factors(x, nx, polys, counts):
    """Lambert form factor of each row (x (r,3), nx (r,3), polys (r,k,3) with counts (r,))."""
    r = x.shape[0]
    out = np.zeros(r)
    for row in prange(r):
        scratch = np.empty((polys.shape[1] + 2, 3))
        out[row] = _lambert(x[row], nx[row], polys[row], counts[row], scratch)
    return out


@njit(cache=True, inline="always")
def _thinner_than(poly, n, tol):
    """True if the planar polygon poly[:n] is no wider than tol (area <= tol x longest edge)."""
    ax, ay, az = newell(poly, n)
    longest = 0.0
    for k in range(n):
        k2 = k + 1 if k + 1 < n else 0
        ex = poly[k2, 0] - poly[k, 0]
        ey = poly[k2, 1] - poly[k, 1]
        ez = poly[k2, 2] - poly[k, 2]
        longest = max(longest, math.sqrt(ex * ex + ey * ey + ez * ez))
    area = 0.5 * math.sqrt(ax * ax + ay * ay + az * az)
    return area <= tol * longest


@njit(cache=True, inline="always")
def _mean_vertex(poly, n):
    """Mean of the vertices poly[:n] (a point inside a convex polygon)."""
    cx = 0.0
    cy = 0.0
    cz = 0.0
    for v in range(n):
        cx += poly[v, 0]
        cy += poly[v, 1]
        cz += poly[v, 2]
    return cx / n, cy / n, cz / n


@njit(cache=True, inline="always")
def _apex_normal(x, p, q):
    """u x v for u = p - x and v = q - x (the normal of the plane through x, p and q), |u|^2, |v|^2."""
    ux = p[0] - x[0]
    uy = p[1] - x[1]
    uz = p[2] - x[2]
    vx = q[0] - x[0]
    vy = q[1] - x[1]
    vz = q[2] - x[2]
    return (uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx, ux * ux + uy * uy + uz * uz,
            vx * vx + vy * vy + vz * vz)


@njit(cache=True, inline="always")
def _inside_slab(occ, ms, px, py, pz, off, dx):
    """True if every vertex of occ[:ms] lies strictly between the planes p . v + off = 0 and
    = dx, clear of both by more than :func:`_clip`'s snapping margin: clipping to the slab
    between x and the source would keep the polygon as it is."""
    lo = np.inf
    hi = -np.inf
    hmax = 0.0
    for v in range(ms):
        h = px * occ[v, 0] + py * occ[v, 1] + pz * occ[v, 2] + off
        lo = min(lo, h)
        hi = max(hi, h)
        hmax = max(hmax, abs(h), abs(dx - h))
    return lo > 1e-12 * hmax and hi < dx - 1e-12 * hmax


@njit(cache=True, inline="always")
def _facing_plane(x, src, ns, sn):
    """The source src[:ns]'s plane as seen from x: (px, py, pz) its unit normal turned towards
    x, off its offset (p . v + off is v's height above the plane on x's side) and x's height."""
    cx, cy, cz = _mean_vertex(src, ns)
    side = (x[0] - cx) * sn[0] + (x[1] - cy) * sn[1] + (x[2] - cz) * sn[2]
    flip = -1.0 if side < 0 else 1.0
    px, py, pz = sn[0] * flip, sn[1] * flip, sn[2] * flip
    return px, py, pz, -(px * cx + py * cy + pz * cz), abs(side)


@njit(cache=True, inline="always")
def _clip_to_slab(occ, ms, a, b, px, py, pz, off, depth):
    """occ[:ms] cut to the slab 0 <= p . v + off <= depth, into b (a: scratch); its vertex count.
    A polygon well inside it is copied as it is (:func:`_inside_slab`)."""
    if _inside_slab(occ, ms, px, py, pz, off, depth):
        for v in range(ms):
            b[v, 0] = occ[v, 0]
            b[v, 1] = occ[v, 1]
            b[v, 2] = occ[v, 2]
        return ms
    n1 = _clip(occ, ms, a, px, py, pz, off)
    return _clip(a, n1, b, -px, -py, -pz, depth - off)


@njit(cache=True)
def _hidden_polygon(xr, src, ns, sn, occ, ms, on, tol, a, b, s1, s2):
    """Part of the source src[:ns] hidden from xr by the convex occluder occ[:ms], into s1.

    Returns its vertex count (0: nothing hidden). a, b: scratch (ms + 3, 3); s1, s2: (ns + ms + 3, 3).
    """
    px, py, pz, off, dx = _facing_plane(xr, src, ns, sn)
    if dx <= tol:
        return 0
    # apex in the occluder's plane: the cone is flat
    ox, oy, oz = _mean_vertex(occ, ms)
    if abs((xr[0] - ox) * on[0] + (xr[1] - oy) * on[1] + (xr[2] - oz) * on[2]) <= tol:
        return 0
    n2 = _clip_to_slab(occ, ms, a, b, px, py, pz, off, dx)
    if n2 < 3 or _thinner_than(b, n2, tol):
        # An occluder that only touches the slab (a cap sharing the receiver's edge, clipped
        # at x's own depth) leaves a sliver of round-off width: its cone from x is flat, but
        # the planes through x and its edges are arbitrary and can cut away the whole source.
        return 0
    ix, iy, iz = _mean_vertex(b, n2)
    ix = ix - xr[0]
    iy = iy - xr[1]
    iz = iz - xr[2]
    # source into s1
    for k in range(ns):
        s1[k, 0] = src[k, 0]
        s1[k, 1] = src[k, 1]
        s1[k, 2] = src[k, 2]
    m = ns
    flat = True
    # clip back and forth between s1 and s2, and copy once at the end if the result is in s2
    cur, out = s1, s2
    in_s1 = True
    for e in range(n2):
        e2 = e + 1 if e + 1 < n2 else 0
        mx, my, mz, uu, vv = _apex_normal(xr, b[e], b[e2])
        if mx * mx + my * my + mz * mz <= (1e-14 * (uu + vv)) ** 2:
            continue  # zero-length edge
        if mx * ix + my * iy + mz * iz < 0:
            mx, my, mz = -mx, -my, -mz
        flat = False
        off_e = -(mx * xr[0] + my * xr[1] + mz * xr[2])
        if _keeps_all(cur, m, mx, my, mz, off_e):
            continue  # the source's part so far lies inside this plane: the clip would copy it
        m = _clip(cur, m, out, mx, my, mz, off_e)
        cur, out = out, cur
        in_s1 = not in_s1
        if m < 3:
            break
    if flat or m < 3:
        return 0
    if not in_s1:
        for k in range(m):
            s1[k, 0] = s2[k, 0]
            s1[k, 1] = s2[k, 1]
            s1[k, 2] = s2[k, 2]
    return m


@njit(cache=True, parallel=True)
def hidden_rows(x, nx, source, source_normal, occluder, occluder_normal, tol, keep_polygons):
    """Hidden polygon and its form factor for each row.

    Returns
    -------
    factor : (r,) float
    polys : (r, L, 3) float (only filled where keep_polygons), counts : (r,) int
    """
    r = x.shape[0]
    ms = occluder.shape[1]
    ns = source.shape[1]
    cap = ns + ms + 3
    factor = np.zeros(r)
    polys = np.zeros((r if keep_polygons else 1, cap, 3))
    counts = np.zeros(r, np.int64)
    for row in prange(r):
        a = np.empty((ms + 3, 3))
        b = np.empty((ms + 3, 3))
        s1 = np.empty((cap, 3))
        s2 = np.empty((cap, 3))
        m = _hidden_polygon(x[row], source[row], ns, source_normal[row], occluder[row], ms, occluder_normal[row],
                            tol, a, b, s1, s2)
        if m < 3:
            continue
        factor[row] = _lambert(x[row], nx[row], s1, m, s2)
        counts[row] = m
        if keep_polygons:
            for k in range(cap):
                kk = k if k < m else m - 1
                polys[row, k, 0] = s1[kk, 0]
                polys[row, k, 1] = s1[kk, 1]
                polys[row, k, 2] = s1[kk, 2]
    return factor, polys, counts


# Relative length (to the polygon's size) below which an edge of a hidden polygon gives no
# clipping line when two hidden polygons are intersected (its direction would be rounding noise).
_EDGE_REL = 1e-9


@njit(cache=True)
def _intersect(pa, na, pb, nb, sn, out, sa, sb):
    """Convex pa[:na] intersected with convex pb[:nb] (both in the plane with normal sn), into out."""
    bx, by, bz = _mean_vertex(pb, nb)
    size = 0.0
    for k in range(nb):
        size = max(size, abs(pb[k, 0] - bx) + abs(pb[k, 1] - by) + abs(pb[k, 2] - bz))
    for k in range(na):
        sa[k, 0] = pa[k, 0]
        sa[k, 1] = pa[k, 1]
        sa[k, 2] = pa[k, 2]
    m = na
    for e in range(nb):
        e2 = e + 1 if e + 1 < nb else 0
        ex = pb[e2, 0] - pb[e, 0]
        ey = pb[e2, 1] - pb[e, 1]
        ez = pb[e2, 2] - pb[e, 2]
        if abs(ex) + abs(ey) + abs(ez) <= _EDGE_REL * size:
            continue
        mx = sn[1] * ez - sn[2] * ey
        my = sn[2] * ex - sn[0] * ez
        mz = sn[0] * ey - sn[1] * ex
        if mx * (bx - pb[e, 0]) + my * (by - pb[e, 1]) + mz * (bz - pb[e, 2]) < 0:
            mx, my, mz = -mx, -my, -mz
        m = _clip(sa, m, sb, mx, my, mz, -(mx * pb[e, 0] + my * pb[e, 1] + mz * pb[e, 2]))
        if m < 3:
            return 0
        for k in range(m):
            sa[k, 0] = sb[k, 0]
            sa[k, 1] = sb[k, 1]
            sa[k, 2] = sb[k, 2]
    for k in range(m):
        out[k, 0] = sa[k, 0]
        out[k, 1] = sa[k, 1]
        out[k, 2] = sa[k, 2]
    return m


# Past this many hidden polygons at a point, their union's form factor is summed over its
# boundary (_union_factor_edges, n^2 edge tests) instead of by inclusion-exclusion (up to 2^n
# intersections: adjacent shadows touch along an edge, so their intersections are not pruned).
IE_MAX_POLYGONS = 4
# Distance from an edge's line, relative to the hidden polygons' extent, within which another
# polygon's edge counts as lying on it (shared edges of adjacent shadows, horizon cuts).
_ON_LINE_REL = 1e-9


@njit(cache=True)
def _union_factor_edges(x, nx, hp, hn, n_polys, sn, poly, count, iv):
    """Form factor from x to the union of the convex polygons hp[k, :hn[k]] (one plane, one
    orientation), summed over the union's boundary.

    Lambert's formula is a sum over edges, and pieces of an edge add up, so the union's factor
    is the sum over every polygon's edges of the pieces that lie outside all the others. Pieces
    on another polygon's edge line count once: where the two lie on opposite sides (a shared
    edge) both are kept and cancel; on the same side (duplicates, the horizon's cut) only the
    lower-numbered polygon's counts. poly (n_polys, >= cap + 1, 3) and count: scratch for the
    horizon-clipped polygons; iv (n_polys, >= 2): scratch for the covered parameter intervals.
    """
    d = -(nx[0] * x[0] + nx[1] * x[1] + nx[2] * x[2])
    extent = 0.0
    for k in range(n_polys):
        m = _clip(hp[k], hn[k], poly[k], nx[0], nx[1], nx[2], d)
        count[k] = m if m >= 3 else 0
        for v in range(count[k]):
            extent = max(extent, abs(poly[k, v, 0] - x[0]) + abs(poly[k, v, 1] - x[1]) + abs(poly[k, v, 2] - x[2]))
    eps = _ON_LINE_REL * extent
    for k in range(n_polys):
        # a polygon that only touches x's horizon (its factor round-off: 4e-16) is left a sliver
        # along the horizon line, whose two long edges, each with a large term, need not cancel
        # once other polygons cover part of one (View3D's hall: a point's union 4.3e-6 where
        # the truth is 2.2e-10, and pair 2064's hidden part 0.2% of its factor short)
        high = 0.0
        for v in range(count[k]):
            high = max(high, nx[0] * poly[k, v, 0] + nx[1] * poly[k, v, 1] + nx[2] * poly[k, v, 2] + d)
        if high <= eps:
            count[k] = 0
    inward, box = _edge_frames(poly, count, n_polys, sn)
    total = 0.0
    for k in range(n_polys):
        n = count[k]
        for e in range(n):
            e2 = e + 1 if e + 1 < n else 0
            dx = poly[k, e2, 0] - poly[k, e, 0]
            dy = poly[k, e2, 1] - poly[k, e, 1]
            dz = poly[k, e2, 2] - poly[k, e, 2]
            if abs(dx) + abs(dy) + abs(dz) <= eps:
                continue
            n_iv = _covered_intervals(poly, count, n_polys, k, e, eps, iv, inward, box)
            if n_iv < 0:
                continue
            # walk the uncovered pieces of the edge, intervals in order of their start
            for a in range(1, n_iv):
                lo, hi = iv[a, 0], iv[a, 1]
                b = a - 1
                while b >= 0 and iv[b, 0] > lo:
                    iv[b + 1, 0] = iv[b, 0]
                    iv[b + 1, 1] = iv[b, 1]
                    b -= 1
                iv[b + 1, 0] = lo
                iv[b + 1, 1] = hi
            t = 0.0
            for a in range(n_iv + 1):
                stop = iv[a, 0] if a < n_iv else 1.0
                if stop > t:
                    total += _edge_term(x, nx, poly[k, e], poly[k, e2], t, stop)
                if a < n_iv:
                    t = max(t, iv[a, 1])
    return min(abs(total) / _TWO_PI, 1.0)


@njit(cache=True)
def _edge_frames(poly, count, n_polys, sn):
    """Each polygon's edges' inward in-plane normals and lengths, inward (n_polys, cap, 4), and
    its box, box (n_polys, 6): computed once per union, not once per pair of edges (a point
    behind 80 of View3D's hall's obstructions spent most of its time recomputing them)."""
    cap = poly.shape[1]
    inward = np.empty((n_polys, cap, 4))
    box = np.empty((n_polys, 6))
    for k in range(n_polys):
        n = count[k]
        for c in range(3):
            box[k, c] = np.inf
            box[k, 3 + c] = -np.inf
        for f in range(n):
            mx, my, mz, ln = _inward(poly[k], n, f, sn)
            inward[k, f, 0] = mx
            inward[k, f, 1] = my
            inward[k, f, 2] = mz
            inward[k, f, 3] = ln
            for c in range(3):
                box[k, c] = min(box[k, c], poly[k, f, c])
                box[k, 3 + c] = max(box[k, 3 + c], poly[k, f, c])
    return inward, box


@njit(cache=True, inline="always")
def _inward(poly, n, f, sn):
    """In-plane normal of edge f of the convex polygon poly[:n], pointing into it, and its length."""
    f2 = f + 1 if f + 1 < n else 0
    ex = poly[f2, 0] - poly[f, 0]
    ey = poly[f2, 1] - poly[f, 1]
    ez = poly[f2, 2] - poly[f, 2]
    mx = sn[1] * ez - sn[2] * ey
    my = sn[2] * ex - sn[0] * ez
    mz = sn[0] * ey - sn[1] * ex
    cx, cy, cz = _mean_vertex(poly, n)
    if mx * (cx - poly[f, 0]) + my * (cy - poly[f, 1]) + mz * (cz - poly[f, 2]) < 0:
        mx, my, mz = -mx, -my, -mz
    return mx, my, mz, math.sqrt(mx * mx + my * my + mz * mz)


@njit(cache=True)
def _covered_intervals(poly, count, n_polys, k, e, eps, iv, inward, box):
    """Parameter intervals of edge e of polygon k lying inside the other polygons, into iv; their
    count, or -1 as soon as one polygon holds all of it. ``inward``, ``box``:
    :func:`_edge_frames`. A polygon whose box misses the edge's (padded by the on-line margin)
    holds none of it."""
    n = count[k]
    e2 = e + 1 if e + 1 < n else 0
    p = poly[k, e]
    q = poly[k, e2]
    kx, ky, kz = inward[k, e, 0], inward[k, e, 1], inward[k, e, 2]
    pad = 2.0 * eps
    lo0, lo1, lo2 = min(p[0], q[0]) - pad, min(p[1], q[1]) - pad, min(p[2], q[2]) - pad
    hi0, hi1, hi2 = max(p[0], q[0]) + pad, max(p[1], q[1]) + pad, max(p[2], q[2]) + pad
    n_iv = 0
    for m in range(n_polys):
        if m == k or count[m] == 0:
            continue
        if (box[m, 0] > hi0 or box[m, 1] > hi1 or box[m, 2] > hi2 or box[m, 3] < lo0 or box[m, 4] < lo1
                or box[m, 5] < lo2):
            continue
        lo = 0.0
        hi = 1.0
        for f in range(count[m]):
            mx, my, mz, ln = inward[m, f, 0], inward[m, f, 1], inward[m, f, 2], inward[m, f, 3]
            if ln <= 0.0:
                continue
            a = poly[m, f]
            h0 = (mx * (p[0] - a[0]) + my * (p[1] - a[1]) + mz * (p[2] - a[2])) / ln
            h1 = (mx * (q[0] - a[0]) + my * (q[1] - a[1]) + mz * (q[2] - a[2])) / ln
            if abs(h0) <= eps and abs(h1) <= eps:  # on this edge's line
                if m < k and mx * kx + my * ky + mz * kz > 0:
                    continue  # same side: the lower-numbered polygon's edge counts
                hi = -1.0  # opposite sides (both kept, they cancel), or the other one counts
                break
            if h0 < 0.0 and h1 < 0.0:
                hi = -1.0
                break
            if h0 < 0.0:
                lo = max(lo, h0 / (h0 - h1))
            elif h1 < 0.0:
                hi = min(hi, h0 / (h0 - h1))
            if lo >= hi:
                break
        if hi > lo:
            if lo <= 0.0 and hi >= 1.0:
                return -1  # inside polygon m all along: nothing of it is on the union's boundary
            iv[n_iv, 0] = lo
            iv[n_iv, 1] = hi
            n_iv += 1
    return n_iv


@njit(cache=True)
def _union_factor(x, nx, hp, hn, n_polys, sn, levels, lcount, nxt, sa, sb):
    """Form factor from x to the union of the convex polygons hp[k, :hn[k]] (one plane), k < n_polys."""
    if n_polys > IE_MAX_POLYGONS:
        return _union_factor_edges(x, nx, hp, hn, n_polys, sn, levels, lcount, sa)
    return _union_factor_ie(x, nx, hp, hn, n_polys, sn, levels, lcount, nxt, sa, sb)


@njit(cache=True)
def _union_factor_ie(x, nx, hp, hn, n_polys, sn, levels, lcount, nxt, sa, sb):
    """:func:`_union_factor` by inclusion-exclusion over the intersections (convex polygons), depth
    first; a branch stops where the intersection is empty or out of x's sight (its subsets add
    nothing either)."""
    total = 0.0
    top = 0
    nxt[0] = 0
    while top >= 0:
        k = nxt[top]
        if k >= n_polys:
            top -= 1
            continue
        nxt[top] = k + 1
        if top == 0:
            n = hn[k]
            for v in range(n):
                levels[1, v, 0] = hp[k, v, 0]
                levels[1, v, 1] = hp[k, v, 1]
                levels[1, v, 2] = hp[k, v, 2]
        else:
            n = _intersect(levels[top], lcount[top], hp[k], hn[k], sn, levels[top + 1], sa, sb)
        if n < 3:
            continue
        f = _lambert(x, nx, levels[top + 1], n, sa)
        if f <= 0.0:
            continue
        total += f if top % 2 == 0 else -f
        lcount[top + 1] = n
        top += 1
        nxt[top] = k + 1
    return max(total, 0.0)


# Relative margin of the cone tests (:func:`_cone_planes`, :func:`_outside_cone`): a vertex this close to a cone plane
# counts as touching it, so only occluders clearly apart from the cone are skipped.
_CONE_MARGIN = 1e-9


@njit(cache=True, inline="always")
def _cone_planes(x, src, ns, planes):
    """Into planes[:ns], the inward unit normals of the planes through x and each edge of the
    convex source src[:ns] (zero, meaning no test, where round-off would pick the direction)."""
    cx, cy, cz = _mean_vertex(src, ns)
    wx = cx - x[0]
    wy = cy - x[1]
    wz = cz - x[2]
    for k in range(ns):
        k2 = k + 1 if k + 1 < ns else 0
        mx, my, mz, uu, vv = _apex_normal(x, src[k], src[k2])
        norm = math.sqrt(mx * mx + my * my + mz * mz)
        inward = mx * wx + my * wy + mz * wz
        if norm <= _CONE_MARGIN * math.sqrt(uu * vv) or \
                abs(inward) <= _CONE_MARGIN * norm * math.sqrt(wx * wx + wy * wy + wz * wz):
            norm = 0.0  # a short edge or a flat cone: the plane's direction is round-off
        elif inward < 0:
            norm = -norm
        # unit normals, so that _outside_cone, run per occluder, needs no norm of its own
        scale = 1.0 / norm if norm != 0.0 else 0.0
        planes[k, 0] = mx * scale
        planes[k, 1] = my * scale
        planes[k, 2] = mz * scale


@njit(cache=True, inline="always")
def _outside_cone(x, occ, ms, planes, ns):
    """True if the occluder occ[:ms] lies wholly outside one plane of the cone from x over the
    source (:func:`_cone_planes`): then it hides nothing from x, and the clipping of
    :func:`_hidden_polygon` is skipped. The cone (the convex hull of x and the source) lies
    inside each plane, so a convex occluder outside one misses it."""
    for k in range(ns):
        mx = planes[k, 0]
        my = planes[k, 1]
        mz = planes[k, 2]
        if mx == 0.0 and my == 0.0 and mz == 0.0:
            continue
        outside = True
        for v in range(ms):
            dx = occ[v, 0] - x[0]
            dy = occ[v, 1] - x[1]
            dz = occ[v, 2] - x[2]
            if mx * dx + my * dy + mz * dz >= -_CONE_MARGIN * math.sqrt(dx * dx + dy * dy + dz * dz):
                outside = False
                break
        if outside:
            return True
    return False


@njit(cache=True)
def union_scratch(ns, ms, max_union):
    """Scratch arrays of :func:`_point_hidden` for sources of ns and occluders of ms vertices:
    a, b, s1, s2 (clipping), hp, hn (the hidden polygons), levels, lcount, nxt, sa, sb (unions).

    Inclusion-exclusion intersects at most ``IE_MAX_POLYGONS`` polygons (each intersection has at
    most the sum of their vertex counts); the boundary sum needs one row of ``levels`` and one
    interval of ``sa`` per polygon.
    """
    cap = ns + ms + 3
    width = (IE_MAX_POLYGONS + 1) * cap + 8
    depth = max(max_union, IE_MAX_POLYGONS + 1) + 1
    rows = max(width, max_union) + 2
    return (np.empty((ms + 3, 3)), np.empty((ms + 3, 3)), np.empty((cap, 3)), np.empty((cap, 3)),
            np.empty((max_union, cap, 3)), np.empty(max_union, np.int64), np.empty((depth, width, 3)),
            np.empty(depth, np.int64), np.empty(depth, np.int64), np.empty((rows, 3)), np.empty((rows, 3)))


@njit(cache=True)
def _point_hidden(x, nx, src, sn, occ, t0, t1, opolys, onormal, tol, max_union, a, b, s1, s2, hp, hn, levels,
                  lcount, nxt, sa, sb):
    """Form factor from x of the part of src hidden by the occluders opolys[occ[t0:t1]].

    Returns (factor, ok): ok is False when more than max_union occluders hide something (the
    caller unites those with shapely).
    """
    ms = opolys.shape[1]
    ns = src.shape[0]
    if t1 - t0 == 1:
        # one occluder: its clipping decides alone (the cone test below only spares clipping
        # the occluders that miss the cone; the blocked plates' shadow cells: 1.3-1.5x faster)
        m = _hidden_polygon(x, src, ns, sn, opolys[occ[t0]], ms, onormal[occ[t0]], tol, a, b, s1, s2)
        return (_lambert(x, nx, s1, m, s2) if m >= 3 else 0.0), True
    _cone_planes(x, src, ns, sa)
    count = 0
    single = 0.0
    for t in range(t0, t1):
        k = occ[t]
        if _outside_cone(x, opolys[k], ms, sa, ns):
            continue
        m = _hidden_polygon(x, src, ns, sn, opolys[k], ms, onormal[k], tol, a, b, s1, s2)
        if m < 3:
            continue
        f = _lambert(x, nx, s1, m, s2)
        if f <= 0.0:
            continue
        if count < max_union:
            for v in range(m):
                hp[count, v, 0] = s1[v, 0]
                hp[count, v, 1] = s1[v, 1]
                hp[count, v, 2] = s1[v, 2]
            hn[count] = m
        single = f
        count += 1
    if count <= 1:
        return single, True
    if count > max_union:
        return 0.0, False
    return _union_factor(x, nx, hp, hn, count, sn, levels, lcount, nxt, sa, sb), True


@njit(cache=True)
def _hidden_block(s, e, x, nx, source, source_normal, occ, starts, opolys, onormal, tol, max_union, factor, ok):
    """Groups s..e-1 of :func:`hidden_groups`."""
    ms = opolys.shape[1]
    ns = source.shape[1]
    a, b, s1, s2, hp, hn, levels, lcount, nxt, sa, sb = union_scratch(ns, ms, max_union)
    for grp in range(s, e):
        t0, t1 = starts[grp], starts[grp + 1]
        if t1 == t0:
            continue
        factor[grp], ok[grp] = _point_hidden(x[t0], nx[t0], source[t0], source_normal[t0], occ, t0, t1, opolys,
                                             onormal, tol, max_union, a, b, s1, s2, hp, hn, levels, lcount, nxt,
                                             sa, sb)


@njit(cache=True, parallel=True)
def hidden_groups(x, nx, source, source_normal, occ, starts, opolys, onormal, tol, max_union):
    """Hidden form factor per group of rows ``starts[g]:starts[g + 1]`` (sharing x, nx and source).

    Row t's occluder is ``opolys[occ[t]]``. Returns factor (g,) and ok (g,) (False: more than
    max_union occluders hide something; factor is then 0 and left to the caller).
    """
    g = starts.shape[0] - 1
    factor = np.zeros(g)
    ok = np.ones(g, np.bool_)
    n_blocks = (g + _GROUP_BLOCK - 1) // _GROUP_BLOCK
    for blk in prange(n_blocks):
        _hidden_block(blk * _GROUP_BLOCK, min(g, (blk + 1) * _GROUP_BLOCK), x, nx, source, source_normal, occ, starts,
                      opolys, onormal, tol, max_union, factor, ok)
    return factor, ok


# Groups (or pairs) per parallel task of the exact-shadow kernels.
_GROUP_BLOCK = 64


@njit(cache=True)
def _exact_block(s, e, pts, normals, quads, i, j, starts, occ, opolys, onormal, tol, max_union, unocc, hidden, ok):
    """Pairs s..e-1 of :func:`exact_pairs`."""
    q = pts.shape[1]
    ms = opolys.shape[1]
    ns = quads.shape[1]
    a, b, s1, s2, hp, hn, levels, lcount, nxt, sa, sb = union_scratch(ns, ms, max_union)
    for p in range(s, e):
        src = quads[j[p]]
        sn = normals[j[p]]
        nxp = normals[i[p]]
        off = 0.0
        for k in range(ns):
            off += sn[0] * src[k, 0] + sn[1] * src[k, 1] + sn[2] * src[k, 2]
        off /= ns
        for qa in range(q):
            xq = pts[i[p], qa]
            if sn[0] * xq[0] + sn[1] * xq[1] + sn[2] * xq[2] - off <= tol:
                continue  # behind the source's plane: it sees the source's back, which gives nothing
            unocc[p, qa] = _lambert(xq, nxp, src, ns, s2)
            hidden[p, qa], ok[p, qa] = _point_hidden(xq, nxp, src, sn, occ, starts[p], starts[p + 1], opolys,
                                                     onormal, tol, max_union, a, b, s1, s2, hp, hn, levels,
                                                     lcount, nxt, sa, sb)


@njit(cache=True, parallel=True)
def exact_pairs(pts, normals, quads, i, j, starts, occ, opolys, onormal, tol, max_union):
    """Unoccluded and hidden form factors at the receiver points of partly occluded pairs.

    Pair p (receiver i[p], source j[p]) may be blocked by ``opolys[occ[starts[p]:starts[p + 1]]]``;
    its receiver points are ``pts[i[p]]`` (n, q, 3).

    Returns
    -------
    unoccluded, hidden : (m, q) float
    ok : (m, q) bool
        False where more than max_union occluders hide something (hidden is then 0).
    """
    m = i.shape[0]
    q = pts.shape[1]
    unocc = np.zeros((m, q))
    hidden = np.zeros((m, q))
    ok = np.ones((m, q), np.bool_)
    n_blocks = (m + _GROUP_BLOCK - 1) // _GROUP_BLOCK
    for blk in prange(n_blocks):
        _exact_block(blk * _GROUP_BLOCK, min(m, (blk + 1) * _GROUP_BLOCK), pts, normals, quads, i, j, starts, occ,
                     opolys, onormal, tol, max_union, unocc, hidden, ok)
    return unocc, hidden, ok


# A square counts as hidden when the union of its fused shadows leaves less than this share of
# the source's factor from its centre (the boundary sums of a covered source agree to ~1e-14).
COVER_REL = 1e-9


@njit(cache=True)
def _fused_polygon(xc, src, ns, sn, occ, ms, on, tol, a, b, s1, s2, out, sa, sb):
    """Part of src[:ns] hidden by occ[:ms] from each of the corners xc (4, 3), into out; its count.

    A source point q hidden from every corner is hidden from every point of the corners' hull:
    the points p whose segment to q meets a convex occluder form a convex set (the cone from q
    over it, beyond it), so the intersection of the corners' hidden polygons is hidden from the
    whole square (Durand et al.'s extended projection onto the source's plane).
    """
    m = _hidden_polygon(xc[0], src, ns, sn, occ, ms, on, tol, a, b, s1, s2)
    if m < 3:
        return 0
    for v in range(m):
        out[v, 0] = s1[v, 0]
        out[v, 1] = s1[v, 1]
        out[v, 2] = s1[v, 2]
    for c in range(1, xc.shape[0]):
        m2 = _hidden_polygon(xc[c], src, ns, sn, occ, ms, on, tol, a, b, s1, s2)
        if m2 < 3:
            return 0
        m = _intersect(out, m, s1, m2, sn, out, sa, sb)
        if m < 3:
            return 0
    return m


@njit(cache=True)
def _square_covered(xc, center, nx, src, sn, occ, t0, t1, opolys, onormal, tol, max_union, a, b, s1, s2, hp, hn,
                    levels, lcount, nxt, sa, sb, slab_a, slab_b):
    """True if the occluders opolys[occ[t0:t1]] together hide source src from the whole receiver
    square with corners xc (4, 3), centre ``center`` and normal nx.

    Each occluder is first cut to the slab between the source's plane and the square's nearest
    corner (what lies there is between every point of the square and the source), then fused
    over the corners (:func:`_fused_polygon`); the square is hidden where the union of those
    polygons covers the part of the source above its plane, which its centre's factor measures.
    A union of occluders none of which hides the square alone (a wall of many surfaces) covers
    it here; point by point, squares behind it were split to the deepest level.
    """
    ns = src.shape[0]
    ms = opolys.shape[1]
    px, py, pz, off, _ = _facing_plane(center, src, ns, sn)
    dmin = np.inf
    for c in range(xc.shape[0]):
        dmin = min(dmin, px * xc[c, 0] + py * xc[c, 1] + pz * xc[c, 2] + off)
    if dmin <= tol:
        return False  # a corner on or behind the source's plane
    unocc = _lambert(center, nx, src, ns, s2)
    if unocc <= 0.0:
        return False
    count = 0
    for t in range(t0, t1):
        k = occ[t]
        n2 = _clip_to_slab(opolys[k], ms, slab_a, slab_b, px, py, pz, off, dmin)
        if n2 < 3:
            continue
        if count >= max_union:
            return False
        m = _fused_polygon(xc, src, ns, sn, slab_b, n2, onormal[k], tol, a, b, s1, s2, hp[count], sa, sb)
        if m >= 3:
            hn[count] = m
            count += 1
    if count == 0:
        return False
    covered = _union_factor(center, nx, hp, hn, count, sn, levels, lcount, nxt, sa, sb)
    return covered >= unocc * (1.0 - COVER_REL)


@njit(cache=True)
def _covered_block(s, e, corners, centers, cnormal, sources, snormal, starts, occ, opolys, onormal, tol, max_union,
                   out):
    """Squares s..e-1 of :func:`covered_squares`."""
    ms = opolys.shape[1]
    ns = sources.shape[1]
    # a fused polygon is the source cut by up to four cones over a slab-cut occluder (ms + 2
    # vertices, + 2 more where a corner's own slab cuts it again)
    a, b, s1, s2, hp, hn, levels, lcount, nxt, sa, sb = union_scratch(ns, 4 * (ms + 4), max_union)
    slab_a = np.empty((ms + 3, 3))
    slab_b = np.empty((ms + 3, 3))
    for c in range(s, e):
        out[c] = _square_covered(corners[c], centers[c], cnormal[c], sources[c], snormal[c], occ, starts[c],
                                 starts[c + 1], opolys, onormal, tol, max_union, a, b, s1, s2, hp, hn, levels,
                                 lcount, nxt, sa, sb, slab_a, slab_b)


@njit(cache=True, parallel=True)
def covered_squares(corners, centers, cnormal, sources, snormal, starts, occ, opolys, onormal, tol, max_union):
    """(c,) bool: receiver square c (corners (c, 4, 3), centres (c, 3), normals (c, 3)) is hidden
    from its source (sources (c, ns, 3), snormal (c, 3)) by the union of its possible occluders
    ``opolys[occ[starts[c]:starts[c + 1]]]`` (:func:`_square_covered`). False where unsure."""
    c = corners.shape[0]
    out = np.zeros(c, np.bool_)
    n_blocks = (c + _GROUP_BLOCK - 1) // _GROUP_BLOCK
    for blk in prange(n_blocks):
        _covered_block(blk * _GROUP_BLOCK, min(c, (blk + 1) * _GROUP_BLOCK), corners, centers, cnormal, sources,
                       snormal, starts, occ, opolys, onormal, tol, max_union, out)
    return out


@njit(cache=True, inline="always")
def _classify_one(vi, vj, polys, normal, center, inward, kk, tol, si, sj, outside, valid, gi, gj):
    """FREE (0) / FULL (1) / MAYBE (2) of the segments between the hulls of vi (nvi, 3) and vj
    (nvj, 3) (two patches, or a point or a cluster's box and a patch) and occluder kk.

    si, sj (nvi,), (nvj,), outside, valid (nv,), gi, gj (nvi, nv), (nvj, nv): scratch. The
    nvi * nvj crossing points are tested against the edges through the edge functions at the
    vertices: g is affine, so g(vi + t (vj - vi)) = g(vi) + t (g(vj) - g(vi)).
    """
    nvi, nvj = vi.shape[0], vj.shape[0]
    n0, n1, n2 = normal[kk, 0], normal[kk, 1], normal[kk, 2]
    c0, c1, c2 = center[kk, 0], center[kk, 1], center[kk, 2]
    for a in range(nvi):
        si[a] = (vi[a, 0] - c0) * n0 + (vi[a, 1] - c1) * n1 + (vi[a, 2] - c2) * n2
    for a in range(nvj):
        sj[a] = (vj[a, 0] - c0) * n0 + (vj[a, 1] - c1) * n1 + (vj[a, 2] - c2) * n2
    return _plane_status(vi, nvi, vj, nvj, polys, inward, kk, tol, si, sj, outside, valid, gi, gj)


@njit(cache=True, inline="always")
def _span(values, n):
    """(min, max) of values[:n] (explicit loop: a slice's min/max is slow in a hot loop)."""
    lo = values[0]
    hi = values[0]
    for k in range(1, n):
        lo = min(lo, values[k])
        hi = max(hi, values[k])
    return lo, hi


@njit(cache=True, inline="always")
def _plane_status(vi, nvi, vj, nvj, polys, inward, kk, tol, si, sj, outside, valid, gi, gj):
    """FREE (0) / FULL (1) / MAYBE (2) of the segments between the hulls of vi[:nvi] and
    vj[:nvj] against occluder kk, given their offsets si, sj from its plane.

    Two sets on one side of the plane are free; on either side, the crossing points decide. A
    set that straddles the plane is cut by it (:func:`_straddle_status`): a far triangle's
    plane, extended, cuts many patches of a terrain or a room, and each such pair was MAYBE.
    """
    nv = polys.shape[1]
    imin, imax = _span(si, nvi)
    jmin, jmax = _span(sj, nvj)
    on_plane = max(abs(imin), abs(imax)) <= tol or max(abs(jmin), abs(jmax)) <= tol
    pos_i, neg_i = imin >= -tol, imax <= tol
    pos_j, neg_j = jmin >= -tol, jmax <= tol
    if on_plane or (pos_i and pos_j) or (neg_i and neg_j):
        return 0
    straddle_i, straddle_j = not (pos_i or neg_i), not (pos_j or neg_j)
    if straddle_i and straddle_j:
        return 2
    n_outside = _edge_offsets(polys, inward, kk, vi, nvi, vj, nvj, valid, outside, gi, gj)
    if straddle_i:
        side = 1.0 if pos_j else -1.0
        return _straddle_status(si, gi, nvi, sj, gj, nvj, side, valid, outside, n_outside, nv, tol)
    if straddle_j:
        side = 1.0 if pos_i else -1.0
        return _straddle_status(sj, gj, nvj, si, gi, nvi, side, valid, outside, n_outside, nv, tol)
    return _crossing_status(si, nvi, sj, nvj, gi, gj, valid, outside, n_outside, nv, tol, tol, -tol)


@njit(cache=True, inline="always")
def _straddle_status(sa, ga, na, sb, gb, nb, side, valid, outside, n_outside, nv, tol):
    """FREE (0) or MAYBE (2) of the segments from the hull of points a, which straddles an
    occluder's plane, to the hull of points b, on its ``side`` (+1 or -1).

    Only the part of a beyond the plane (side * s <= 0) sends segments across it. That part is
    the hull of a's vertices there and of the points where the plane cuts the segments between
    a's vertices of strictly opposite signs (every pair, so any hull of points is cut right);
    its offsets (plane 0, edges interpolated: they are affine) go to :func:`_crossing_status`.
    Never FULL: the part of a on b's side sees b past the plane.
    The cut points are allocated here, on this rare path only.
    """
    cs = np.empty(na + (na * na) // 4 + 1)
    cg = np.empty((cs.shape[0], nv))
    m = 0
    for a in range(na):
        if side * sa[a] <= 0.0:
            cs[m] = sa[a]
            for e in range(nv):
                cg[m, e] = ga[a, e]
            m += 1
    for a in range(na):
        for c in range(a + 1, na):
            if (sa[a] < 0.0 < sa[c]) or (sa[c] < 0.0 < sa[a]):
                t = sa[a] / (sa[a] - sa[c])
                cs[m] = 0.0
                for e in range(nv):
                    cg[m, e] = ga[a, e] + t * (ga[c, e] - ga[a, e])
                m += 1
    status = _crossing_status(cs, m, sb, nb, cg, gb, valid, outside, n_outside, nv, tol, tol, tol)
    return 0 if status == 0 else 2


@njit(cache=True, parallel=True)
def classify_rows(vi, vj, polys, normal, center, inward, k, tol):
    """FREE (0) / FULL (1) / MAYBE (2) for rows (patch vertices vi, vj (t, 4, 3); occluder k)."""
    t = k.shape[0]
    out = np.full(t, 2, np.int8)
    nv = polys.shape[1]
    for row in prange(t):
        si = np.empty(4)
        sj = np.empty(4)
        outside = np.zeros(nv, np.bool_)
        valid = np.zeros(nv, np.bool_)
        gi = np.empty((4, nv))
        gj = np.empty((4, nv))
        out[row] = _classify_one(vi[row], vj[row], polys, normal, center, inward, k[row], tol, si, sj,
                                 outside, valid, gi, gj)
    return out


# Pairs handed to one parallel task of the pair classification (scratch is allocated per task).
_PAIR_BLOCK = 256


@njit(cache=True, inline="always")
def _meets(lo, hi, blo, bhi, pad):
    return (lo[0] <= bhi[0] + pad and lo[1] <= bhi[1] + pad and lo[2] <= bhi[2] + pad
            and hi[0] >= blo[0] - pad and hi[1] >= blo[1] - pad and hi[2] >= blo[2] - pad)


@njit(cache=True, inline="always")
def _edge_offsets(polys, inward, kk, P, nP, Q, nQ, valid, outside, gp, gq):
    """Offsets of P[:nP] and Q[:nQ] along occluder kk's inward edge normals, into gp[:, e] and
    gq[:, e]; ``valid[e]``: edge e has a normal (not a repeated vertex); ``outside[e]`` starts as
    ``valid[e]``. Returns the number of valid edges."""
    n_outside = 0
    for e in range(polys.shape[1]):
        valid[e] = inward[kk, e, 0] != 0.0 or inward[kk, e, 1] != 0.0 or inward[kk, e, 2] != 0.0
        outside[e] = valid[e]
        if valid[e]:
            n_outside += 1
            p0, p1, p2 = polys[kk, e, 0], polys[kk, e, 1], polys[kk, e, 2]
            w0, w1, w2 = inward[kk, e, 0], inward[kk, e, 1], inward[kk, e, 2]
            for a in range(nP):
                gp[a, e] = (P[a, 0] - p0) * w0 + (P[a, 1] - p1) * w1 + (P[a, 2] - p2) * w2
            for b in range(nQ):
                gq[b, e] = (Q[b, 0] - p0) * w0 + (Q[b, 1] - p1) * w1 + (Q[b, 2] - p2) * w2
    return n_outside


@njit(cache=True, inline="always")
def _crossing_status(sa, na, sb, nb, ga, gb, valid, outside, n_outside, nv, den_tol, out_lim, in_lim):
    """FREE (0) / FULL (1) / MAYBE (2) of the segments from points a (plane offsets sa[:na], edge
    offsets ga) to points b (sb[:nb], gb) that cross an occluder's plane, from where each
    crosses it: g is affine along a segment, so g(a + t (b - a)) = g(a) + t (g(b) - g(a)).
    ``n_outside``/``outside``: from :func:`_edge_offsets`. A segment (nearly) in the plane
    (|sa - sb| <= den_tol) is MAYBE.

    The crossings are outside an edge where every one has g < ``out_lim`` and inside the
    occluder where every g > ``in_lim``. With ``out_lim`` > 0, crossings on an edge count as
    outside it: touching is not covering. A patch that meets a neighbour at a shared edge
    (a terrain's triangles, a box's top and side) sends segments that cross the neighbour's
    plane at that edge at most, and every such pair was MAYBE; the segments meeting the
    occluder then lie within ``out_lim`` of its boundary, a sliver of measure ~ out_lim.

    With ``in_lim`` < 0, crossings on an edge count as inside too: the hull of the crossings
    then lies in the closed polygon (within ``-in_lim``), and from each point x of one patch
    the segments to the other that cross the polygon's boundary, not its inside, form a set of
    measure zero (x sees the other patch through a central projection, one to one), so the
    pair is hidden but for a sliver of measure ~ ``-in_lim``. Strictly inside (``in_lim`` > 0),
    the fins of View3D's 398-surface hall, which span the same heights as the fins behind them
    and graze each other's edges, left every such pair MAYBE behind every fin, and its adaptive
    squares split to the deepest level to find it dark everywhere: 4.4 s a pair."""
    inside_all = True
    for a in range(na):
        for b in range(nb):
            den = sa[a] - sb[b]
            if abs(den) <= den_tol:
                return 2  # a segment runs (nearly) in the plane: neither inside nor separated
            tt = sa[a] / den
            for e in range(nv):
                if not valid[e]:
                    continue
                g = ga[a, e] + tt * (gb[b, e] - ga[a, e])
                if g >= out_lim and outside[e]:
                    outside[e] = False
                    n_outside -= 1
                if g <= in_lim:
                    inside_all = False
            if n_outside == 0 and not inside_all:
                return 2
    if n_outside > 0:
        return 0
    return 1 if inside_all else 2


@njit(cache=True, inline="always")
def _beyond_planes(blo, bhi, planes, n_planes, pad):
    """The box [blo, bhi] lies beyond one of planes[:n_planes] (unit n, d: outside where
    n . x > d) by more than pad."""
    for k in range(n_planes):
        m = -planes[k, 3]
        for c in range(3):
            m += planes[k, c] * (blo[c] if planes[k, c] > 0.0 else bhi[c])
        if m > pad:
            return True
    return False


@njit(cache=True, inline="always")
def _next_leaf(stack, top, lo, hi, node_lo, node_hi, node_left, node_right, pad, planes, n_planes):
    """One step of a depth-first BVH walk (``stack[:top + 1]`` pending, start with ``stack[0] = 0``,
    ``top = 0``): (top, the next leaf node whose box meets [lo, hi] + pad and lies inside none of
    ``planes[:n_planes]``' outer sides), or (top, -1) when done. Leaves come in the same order as
    the recursive walk (left child first)."""
    while top >= 0:
        node = stack[top]
        top -= 1
        if not _meets(lo, hi, node_lo[node], node_hi[node], pad):
            continue
        if n_planes and _beyond_planes(node_lo[node], node_hi[node], planes, n_planes, pad):
            continue
        if node_left[node] >= 0:
            top += 1
            stack[top] = node_right[node]
            top += 1
            stack[top] = node_left[node]
            continue
        return top, node
    return top, -1


@njit(cache=True, inline="always")
def _next_occluder(stack, top, pos, end, lo, hi, olo, ohi, node_lo, node_hi, node_left, node_right, node_start,
                   node_count, order, pad, planes, n_planes):
    """The next occluder whose box meets [lo, hi] + pad (and lies beyond none of
    ``planes[:n_planes]``), walking the BVH depth first (start with ``stack[0] = 0`` and
    ``top = pos = end = 0``): (top, pos, end, occluder), occluder -1 when done. ``pos:end`` is
    what is left of the current leaf's slots in ``order``."""
    while True:
        while pos < end:
            kk = order[pos]
            pos += 1
            if _meets(lo, hi, olo[kk], ohi[kk], pad) and not (
                    n_planes and _beyond_planes(olo[kk], ohi[kk], planes, n_planes, pad)):
                return top, pos, end, kk
        top, node = _next_leaf(stack, top, lo, hi, node_lo, node_hi, node_left, node_right, pad, planes, n_planes)
        if node < 0:
            return top, pos, end, -1
        pos, end = node_start[node], node_start[node] + node_count[node]


# A pair's walk bounds its occluders by the faces of the hull of its two patches (as well as by
# their box) once it has met this many: an occluder whose box lies beyond a face of the hull
# cannot meet any segment, and is free however _classify_one (conservative) calls it. A pair
# whose box spans a terrain (a light above, a far ground triangle: thousands of triangles in the
# box, a handful near the segments) or a cluttered room stops walking most of it. For the
# hierarchy (hull_always) every undecided occluder is tested against the hull's faces whatever
# the count (_hull_tested), so the walk and classify_listed agree. Until session 32 the hull
# came after 16 occluders and only those met after it were tested: the 300-cube furnace room's
# classification of its cluster links' patch pairs took 10.8 s where it now takes 8.2-8.7 s.
HULL_AFTER = 2
MAX_HULL_PLANES = 34  # both patches' planes and every (edge of one, vertex of the other)


@njit(cache=True, inline="always")
def _hull_planes(vi, vj, planes, tol):
    """Face planes of the hull of the 8 vertices of two quads, into planes (unit n, d: the hull
    lies where n . x <= d, d moved out by tol); returns how many. Candidates: each quad's plane
    and each plane through an edge of one and a vertex of the other (the faces of the hull of
    two convex polygons); a candidate with points on both sides is not a face and is skipped.
    Any subset of the faces bounds a region holding the hull, so a degenerate candidate (a
    triangle's repeated vertex) may be left out."""
    n = 0
    for side in range(2):
        A = vi if side == 0 else vj
        B = vj if side == 0 else vi
        for a in range(4):
            a1 = (a + 1) % 4
            e0, e1, e2 = A[a1, 0] - A[a, 0], A[a1, 1] - A[a, 1], A[a1, 2] - A[a, 2]
            for b in range(5):  # b = 4: the quad's own plane (once, from its first edge)
                if b == 4 and a > 0:
                    continue
                P = A[2] if b == 4 else B[b]
                w0, w1, w2 = P[0] - A[a, 0], P[1] - A[a, 1], P[2] - A[a, 2]
                n0, n1, n2 = e1 * w2 - e2 * w1, e2 * w0 - e0 * w2, e0 * w1 - e1 * w0
                length = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
                scale = math.sqrt((e0 * e0 + e1 * e1 + e2 * e2) * (w0 * w0 + w1 * w1 + w2 * w2))
                if not length > 1e-9 * scale:
                    continue
                n0, n1, n2 = n0 / length, n1 / length, n2 / length
                d = n0 * A[a, 0] + n1 * A[a, 1] + n2 * A[a, 2]
                hmin, hmax = np.inf, -np.inf
                for k in range(8):
                    q = vi[k] if k < 4 else vj[k - 4]
                    h = n0 * q[0] + n1 * q[1] + n2 * q[2] - d
                    hmin, hmax = min(hmin, h), max(hmax, h)
                if hmax <= tol:
                    sign = 1.0
                elif hmin >= -tol:
                    sign = -1.0
                else:
                    continue
                planes[n, 0], planes[n, 1], planes[n, 2] = sign * n0, sign * n1, sign * n2
                planes[n, 3] = sign * d + tol  # the hull's points lie within tol of the face
                n += 1
    return n


@njit(cache=True, inline="always")
def _behind(polys, kk, point, n, tol):
    """Occluder kk has no vertex more than tol in front of the plane through ``point`` with unit
    normal ``n``: no segment from that plane's front side (a one-sided patch sees only there)
    can cross it but at the plane itself, a set of measure zero."""
    for k in range(polys.shape[1]):
        h = ((polys[kk, k, 0] - point[0]) * n[0] + (polys[kk, k, 1] - point[1]) * n[1]
             + (polys[kk, k, 2] - point[2]) * n[2])
        if h > tol:
            return False
    return True


@njit(cache=True, inline="always")
def _box_of(P, nP, Q, nQ, lo, hi):
    """The box of the points P[:nP] and Q[:nQ] (nP >= 1), into lo and hi. Explicit loops: the
    column slices' min and max cost about as much as classifying a pair against one occluder."""
    for c in range(3):
        lo[c] = P[0, c]
        hi[c] = P[0, c]
    for v in range(1, nP):
        for c in range(3):
            lo[c] = min(lo[c], P[v, c])
            hi[c] = max(hi[c], P[v, c])
    for v in range(nQ):
        for c in range(3):
            lo[c] = min(lo[c], Q[v, c])
            hi[c] = max(hi[c], Q[v, c])


@njit(cache=True, inline="always")
def _classify_pair(vi, vj, polys, normal, center, inward, olo, ohi, node_lo, node_hi, node_left, node_right,
                   node_start, node_count, order, pad, tol, out_occ, stack, box, si, sj, outside, valid, gi, gj,
                   planes, nij, behind, cap):
    """Walk the BVH for one pair; write its MAYBE occluders to out_occ (as many as fit).

    Returns (status, number of MAYBE occluders, number of hull faces in ``planes`` or -1 where
    the walk made none); a FULL pair stops at its first full occluder.
    An occluder is MAYBE where :func:`_classify_one` says so and, after ``HULL_AFTER``
    occluders, its box lies beyond no face of the pair's hull (``planes``: scratch; from then on
    the walk leaves out boxes beyond them, and the undecided occluders met before are tested
    too). A walk that met fewer leaves that to :func:`_hull_tested` (``hull_always``). With
    ``behind`` >= 0 an occluder that lies behind the plane of either patch (unit normals
    ``nij[0]``, ``nij[1]``; see :func:`_behind`) is free without a test: the faces of a cube that
    touch one of its faces. With ``cap`` > 0 the walk stops at the ``cap``-th MAYBE occluder
    (status MAYBE, ``cap`` of them, hull-tested since ``cap`` >= ``HULL_AFTER``): its list is
    then not all of them, and a FULL occluder further on is not looked for. ``box`` (2, 3):
    scratch for the pair's box (one argument, not two: a call of more than 30 arguments is
    compiled as ``f(*args)``, which numba cannot inline).
    """
    lo, hi = box[0], box[1]
    _box_of(vi, vi.shape[0], vj, vj.shape[0], lo, hi)
    n_maybe = 0
    met = 0
    n_planes = -1  # the hull's faces are not made yet
    top, pos, end = 0, 0, 0
    stack[0] = 0
    while True:
        top, pos, end, kk = _next_occluder(stack, top, pos, end, lo, hi, olo, ohi, node_lo, node_hi, node_left,
                                           node_right, node_start, node_count, order, pad, planes, max(n_planes, 0))
        if kk < 0:
            break
        met += 1
        if met == HULL_AFTER:
            n_planes = _hull_planes(vi, vj, planes, tol)
            # the undecided occluders met before (at most HULL_AFTER - 1, all in out_occ)
            n_maybe = _outside_hull(out_occ, n_maybe, olo, ohi, planes, n_planes, pad)
            if _beyond_planes(olo[kk], ohi[kk], planes, n_planes, pad):
                continue
        if behind >= 0.0 and (_behind(polys, kk, vi[0], nij[0], behind) or _behind(polys, kk, vj[0], nij[1], behind)):
            continue
        state = _classify_one(vi, vj, polys, normal, center, inward, kk, tol, si, sj, outside, valid, gi, gj)
        if state == 1:
            return 1, 0, n_planes
        if state == 2:
            if n_maybe < out_occ.shape[0]:
                out_occ[n_maybe] = kk
            n_maybe += 1
            if n_maybe == cap:
                return 2, n_maybe, n_planes
    return (2 if n_maybe else 0), n_maybe, n_planes


@njit(cache=True, inline="always")
def _hull_tested(vi, vj, status, n, n_planes, out_occ, olo, ohi, planes, pad, tol, hull_always):
    """(status, n) of a :func:`_classify_pair` walk, its undecided occluders out_occ[:n] tested
    against the pair's hull where it made none (fewer than ``HULL_AFTER`` met; all of them are in
    out_occ) and ``hull_always``: as :func:`classify_listed` tests its candidates, so that the
    hierarchy's children get what their own walk gets. The uniform fill leaves it off: one
    blocker between two plates (a pair meeting one occluder) would pay for the hull for nothing."""
    if not hull_always or status != 2 or n_planes >= 0:
        return status, n
    n = _outside_hull(out_occ, n, olo, ohi, planes, _hull_planes(vi, vj, planes, tol), pad)
    return (2 if n else 0), n


@njit(cache=True, inline="always")
def _outside_hull(found, n, olo, ohi, planes, n_planes, pad):
    """Drop from found[:n] (occluder indices, in place, order kept) those whose box lies beyond
    one of planes[:n_planes]; returns how many are left."""
    kept = 0
    for t in range(n):
        kk = found[t]
        if not _beyond_planes(olo[kk], ohi[kk], planes, n_planes, pad):
            found[kept] = kk
            kept += 1
    return kept


@njit(cache=True)
def on_facet_planes(quads, planes, candidates, tol):
    """(n,) bool: patch p has all its vertices within tol of the plane of some facet
    ``planes[candidates[p, c]]`` (n . x + d, the hull's equations), summed as n0 x + n1 y + n2 z
    then + d."""
    n = quads.shape[0]
    out = np.zeros(n, np.bool_)
    for p in range(n):
        for c in range(candidates.shape[1]):
            f = candidates[p, c]
            on = True
            for k in range(quads.shape[1]):
                h = planes[f, 0] * quads[p, k, 0] + planes[f, 1] * quads[p, k, 1] + planes[f, 2] * quads[p, k, 2]
                if not abs(h + planes[f, 3]) <= tol:
                    on = False
                    break
            if on:
                out[p] = True
                break
    return out


# Runs of pairs sharing a receiver or a source are first classified as a whole (see
# _classify_set): up to _GROUP_MAX pairs at once, halved while undecided down to _GROUP_MIN.
_GROUP_MAX = 32
_GROUP_MIN = 4
# A block of pairs stops testing runs (and halves of runs) as a whole once _GROUP_LEARN tests
# have decided less than this share of them: each undecided test is paid again by the pairs one
# by one. On the blocked plates cut 8 x 8 (one blocker the size of 16 receivers' shadows) most
# runs straddle a shadow's edge and the run tests made the classification 1.3x slower; cut
# 32 x 32, runs halve the time.
_GROUP_LEARN = 8
_GROUP_HIT_SHARE = 0.25


@njit(cache=True, inline="always")
def _grouping_pays(n_tests, n_hits):
    """Whether a block that tested n_tests runs as a whole, n_hits of them decided, goes on."""
    return n_tests < _GROUP_LEARN or _GROUP_HIT_SHARE * n_tests <= n_hits

# A run whose box holds more occluders than this goes to its pairs one by one at once: the box of
# a light and 32 ground triangles spans a terrain, and each halving walked all of it again (the
# pairs' own walks are bounded by their hulls, see _classify_pair).
_GROUP_MAX_MET = 256


@njit(cache=True, inline="always")
def _classify_set(P, nP, Q, nQ, polys, normal, center, inward, kk, tol, sp, sq, outside, valid, gp, gq):
    """FREE (0) / FULL (1) / undecided (2) of occluder kk for every pair (x, y), x a patch inside
    the convex hull of the points P[:nP], y one inside that of Q[:nQ].

    The segments between two convex sets fill the hull of their union, whose section by the
    occluder's plane (when the sets lie strictly on either side) is the hull of the crossings of
    the segments P[a]-Q[b]. Each decision here is :func:`_classify_one`'s with its thresholds
    moved by tol / 2 towards "undecided", far more than the rounding between the two, so a
    decided set gives every pair inside it exactly the status :func:`_classify_one` gives it.
    """
    nv = polys.shape[1]
    n0, n1, n2 = normal[kk, 0], normal[kk, 1], normal[kk, 2]
    c0, c1, c2 = center[kk, 0], center[kk, 1], center[kk, 2]
    for a in range(nP):
        sp[a] = (P[a, 0] - c0) * n0 + (P[a, 1] - c1) * n1 + (P[a, 2] - c2) * n2
    for b in range(nQ):
        sq[b] = (Q[b, 0] - c0) * n0 + (Q[b, 1] - c1) * n1 + (Q[b, 2] - c2) * n2
    pmin, pmax, qmin, qmax = sp[:nP].min(), sp[:nP].max(), sq[:nQ].min(), sq[:nQ].max()
    half = 0.5 * tol
    if (pmin >= -half and qmin >= -half) or (pmax <= half and qmax <= half):
        return 0  # every pair on one side (or in the plane)
    if not ((pmax < -2.0 * tol and qmin > 2.0 * tol) or (pmin > 2.0 * tol and qmax < -2.0 * tol)):
        return 2
    n_outside = _edge_offsets(polys, inward, kk, P, nP, Q, nQ, valid, outside, gp, gq)
    # separated by 2 tol on each side, so no segment lies in the plane (|sp - sq| > 4 tol)
    return _crossing_status(sp, nP, sq, nQ, gp, gq, valid, outside, n_outside, nv, tol, half, half - tol)


@njit(cache=True, inline="always")
def _put_side(v, idx, a, b, fixed, out):
    """Points whose hull holds patches v[idx[a:b]]: the patch's own vertices if ``fixed`` (one
    patch), else the 8 corners of their box. Returns the count."""
    if fixed:
        for k in range(v.shape[1]):
            for c in range(3):
                out[k, c] = v[idx[a], k, c]
        return v.shape[1]
    lo0, lo1, lo2 = np.inf, np.inf, np.inf
    hi0, hi1, hi2 = -np.inf, -np.inf, -np.inf
    for t in range(a, b):
        for k in range(v.shape[1]):
            lo0, hi0 = min(lo0, v[idx[t], k, 0]), max(hi0, v[idx[t], k, 0])
            lo1, hi1 = min(lo1, v[idx[t], k, 1]), max(hi1, v[idx[t], k, 1])
            lo2, hi2 = min(lo2, v[idx[t], k, 2]), max(hi2, v[idx[t], k, 2])
    for k in range(8):
        out[k, 0] = hi0 if k & 1 else lo0
        out[k, 1] = hi1 if k & 2 else lo1
        out[k, 2] = hi2 if k & 4 else lo2
    return 8


@njit(cache=True, inline="always")
def _group_status(P, nP, Q, nQ, polys, normal, center, inward, olo, ohi, node_lo, node_hi, node_left, node_right,
                  node_start, node_count, order, pad, tol, stack, lo, hi, sp, sq, outside, valid, gp, gq,
                  fixed, behind):
    """0 / 1 if every pair of the set (see :func:`_classify_set`) is FREE / FULL, else 2; 3 if
    the set's box holds more than _GROUP_MAX_MET occluders (its pairs are walked one by one).

    The set's box holds every pair's box, so its BVH walk reaches every occluder a pair's walk
    does: all of them free means each pair is free; one full blocks each pair (a pair's walk
    meets a full occluder, which crosses all its segments, and stops there). With ``behind`` >= 0
    an occluder behind the plane of the patch every pair shares (``fixed``: a point of it, its unit
    normal) is free, as in :func:`_classify_pair`."""
    _box_of(P, nP, Q, nQ, lo, hi)
    undecided = False
    met = 0
    top, pos, end = 0, 0, 0
    stack[0] = 0
    while True:
        top, pos, end, kk = _next_occluder(stack, top, pos, end, lo, hi, olo, ohi, node_lo, node_hi, node_left,
                                           node_right, node_start, node_count, order, pad, P, 0)  # no planes: P unread
        if kk < 0:
            break
        met += 1
        if met > _GROUP_MAX_MET:
            return 3
        if behind >= 0.0 and _behind(polys, kk, fixed[0], fixed[1], behind):
            continue
        state = _classify_set(P, nP, Q, nQ, polys, normal, center, inward, kk, tol, sp, sq, outside, valid,
                              gp, gq)
        if state == 1:
            return 1
        if state == 2:
            undecided = True
    return 2 if undecided else 0


@njit(cache=True)
def _classify_block(s, e, va, ia, vb, ib, polys, normal, center, inward, olo, ohi, node_lo, node_hi, node_left,
                    node_right, node_start, node_count, order, pad, tol, status, count, first, starts, occ,
                    na, nb, behind, runs, hull_always, cap):
    """Pairs s..e-1 of :func:`classify_pairs`: first pass (``starts`` empty) or second pass.

    In the first pass, runs of pairs with one receiver or one source are classified as a whole
    first (:func:`_group_status`); only the pairs of undecided runs are walked one by one, with
    the same results bit for bit (the fill's pairs come in runs of one source: on the blocked
    plates of bench_fill cut 32 x 32 most runs of 4-32 pairs are all free or all blocked). A
    block stops testing runs once they mostly stay undecided (:func:`_grouping_pays`). ``runs`` False
    walks every pair alone (the hierarchy's children of a partly visible link: four children
    together span their parent, whose walk was undecided)."""
    nv = polys.shape[1]
    stack = np.empty(2 * node_lo.shape[0] + 2, np.int64)
    box = np.empty((2, 3))
    lo, hi = box[0], box[1]
    si = np.empty(4)
    sj = np.empty(4)
    outside = np.zeros(nv, np.bool_)
    valid = np.zeros(nv, np.bool_)
    gi = np.empty((4, nv))
    gj = np.empty((4, nv))
    planes = np.empty((MAX_HULL_PLANES, 4))
    use_normals = behind >= 0.0
    nij = np.zeros((2, 3))  # the pair's unit normals (behind >= 0)
    fixed = np.zeros((2, 3))  # a run's shared patch: a point, its unit normal (behind >= 0)
    width = first.shape[1]
    second = starts.shape[0] > 0
    if second:
        for p in range(s, e):
            n = count[p]
            if n <= width:
                for t in range(n):
                    occ[starts[p] + t] = first[p, t]
                continue
            out = occ[starts[p]:starts[p + 1]]
            if use_normals:
                nij[0], nij[1] = na[ia[p]], nb[ib[p]]
            st, n, n_planes = _classify_pair(va[ia[p]], vb[ib[p]], polys, normal, center, inward, olo, ohi,
                                             node_lo, node_hi, node_left, node_right, node_start, node_count, order,
                                             pad, tol, out, stack, box, si, sj, outside, valid, gi, gj, planes,
                                             nij, behind, cap)
            _hull_tested(va[ia[p]], vb[ib[p]], st, n, n_planes, out, olo, ohi, planes, pad, tol, hull_always)
        return
    nmax = max(8, va.shape[1], vb.shape[1])
    P, Q = np.empty((nmax, 3)), np.empty((nmax, 3))
    sp, sq = np.empty(nmax), np.empty(nmax)
    gp, gq = np.empty((nmax, nv)), np.empty((nmax, nv))
    ranges = np.empty((64, 2), np.int64)
    n_tests, n_hits = 0, 0  # this block's tests of runs as a whole, and those that decided
    p = s
    while p < e:
        # the run from p: pairs sharing ia[p] (or else ib[p]), at most _GROUP_MAX (none without runs,
        # nor while this block's runs mostly stay undecided)
        grouping = runs and _grouping_pays(n_tests, n_hits)
        q = p + 1
        while grouping and q < e and q - p < _GROUP_MAX and ia[q] == ia[p]:
            q += 1
        same_a = q - p >= _GROUP_MIN
        if not same_a:
            q = p + 1
            while grouping and q < e and q - p < _GROUP_MAX and ib[q] == ib[p]:
                q += 1
        n_ranges = 0
        if q - p >= _GROUP_MIN:
            ranges[0, 0], ranges[0, 1] = p, q
            n_ranges = 1
        else:
            q = p + 1
        single_from, single_to = p, p if n_ranges else q
        while n_ranges > 0 or single_from < single_to:
            if single_from < single_to:  # pairs one by one
                for t in range(single_from, single_to):
                    if use_normals:
                        nij[0], nij[1] = na[ia[t]], nb[ib[t]]
                    st, n, n_planes = _classify_pair(va[ia[t]], vb[ib[t]], polys, normal, center, inward, olo, ohi,
                                                     node_lo, node_hi, node_left, node_right, node_start, node_count,
                                                     order, pad, tol, first[t], stack, box, si, sj, outside, valid,
                                                     gi, gj, planes, nij, behind, cap)
                    status[t], count[t] = _hull_tested(va[ia[t]], vb[ib[t]], st, n, n_planes, first[t], olo, ohi,
                                                       planes, pad, tol, hull_always)
                single_from = single_to
                continue
            n_ranges -= 1
            a, b = ranges[n_ranges, 0], ranges[n_ranges, 1]
            nP = _put_side(va, ia, a, b, same_a, P)
            nQ = _put_side(vb, ib, a, b, not same_a, Q)
            if use_normals:  # the patch every pair of the run shares: a point of it, its normal
                if same_a:
                    fixed[0], fixed[1] = va[ia[a], 0], na[ia[a]]
                else:
                    fixed[0], fixed[1] = vb[ib[a], 0], nb[ib[a]]
            st = _group_status(P, nP, Q, nQ, polys, normal, center, inward, olo, ohi, node_lo, node_hi, node_left,
                               node_right, node_start, node_count, order, pad, tol, stack, lo, hi, sp, sq,
                               outside, valid, gp, gq, fixed, behind)
            n_tests += 1
            if st == 0 or st == 1:
                n_hits += 1
                for t in range(a, b):
                    status[t] = st
                    count[t] = 0
            elif st == 2 and b - a >= 2 * _GROUP_MIN and _grouping_pays(n_tests, n_hits):
                mid = (a + b) // 2
                ranges[n_ranges, 0], ranges[n_ranges, 1] = mid, b
                ranges[n_ranges + 1, 0], ranges[n_ranges + 1, 1] = a, mid
                n_ranges += 2
            else:
                single_from, single_to = a, b
        p = q


@njit(cache=True, parallel=True)
def classify_pairs(va, ia, vb, ib, polys, normal, center, inward, olo, ohi, node_lo, node_hi, node_left,
                   node_right, node_start, node_count, order, pad, tol, na, nb, behind, runs=True, hull_always=False,
                   cap=0):
    """Classify pairs (va[ia[p]], vb[ib[p]]) against every occluder whose box meets theirs.

    The pair's box (vertex min/max) is walked down the occluders' BVH (boxes padded by ``pad``);
    each occluder reached is classified by :func:`_classify_one`. With ``behind`` >= 0, occluders
    within ``behind`` of the back of either patch's plane (unit normals ``na``, ``nb`` per row of
    ``va``, ``vb``) are left out; with ``behind`` < 0, ``na`` and ``nb`` are not read (pass (1, 3)).
    ``runs`` False: no runs of pairs are classified as a whole (see :func:`_classify_block`);
    ``hull_always``, ``cap``: see :func:`_classify_pair` (0: no cap).

    Returns
    -------
    status : (m,) int8
        0 free, 1 full (some occluder blocks every segment), 2 maybe.
    starts : (m + 1,) int64
        The MAYBE occluders of pair p are ``occ[starts[p]:starts[p + 1]]`` (none for full pairs).
    occ : (t,) int64
    """
    m = ia.shape[0]
    status = np.zeros(m, np.int8)
    count = np.zeros(m, np.int64)
    first = np.empty((m, 8), np.int64)  # the first MAYBE occluders; pairs with more walk again
    n_blocks = (m + _PAIR_BLOCK - 1) // _PAIR_BLOCK
    none = np.zeros(0, np.int64)
    for blk in prange(n_blocks):
        _classify_block(blk * _PAIR_BLOCK, min(m, (blk + 1) * _PAIR_BLOCK), va, ia, vb, ib, polys, normal, center,
                        inward, olo, ohi, node_lo, node_hi, node_left, node_right, node_start, node_count, order,
                        pad, tol, status, count, first, none, none, na, nb, behind, runs, hull_always, cap)
    starts = np.zeros(m + 1, np.int64)
    for p in range(m):
        starts[p + 1] = starts[p] + count[p]
    occ = np.empty(starts[m], np.int64)
    for blk in prange(n_blocks):
        _classify_block(blk * _PAIR_BLOCK, min(m, (blk + 1) * _PAIR_BLOCK), va, ia, vb, ib, polys, normal, center,
                        inward, olo, ohi, node_lo, node_hi, node_left, node_right, node_start, node_count, order,
                        pad, tol, status, count, first, starts, occ, na, nb, behind, runs, hull_always, cap)
    return status, starts, occ


@njit(cache=True, parallel=True)
def classify_listed(va, ia, vb, ib, na, nb, cand_starts, cand_occ, polys, normal, center, inward, olo, ohi, pad, tol,
                    behind):
    """:func:`classify_pairs` against given candidates instead of the BVH: pair p against the
    occluders ``cand_occ[cand_starts[p]:cand_starts[p + 1]]`` only.

    For pairs whose segments are a subset of another pair's (an element's children), the
    other's undecided occluders hold every occluder that can be undecided or full for them.
    Each candidate is tested as the walk tests what it reaches: its box against the pair's
    box (padded), behind either patch's plane (``behind`` >= 0; unit normals ``na``, ``nb``), then
    :func:`_classify_one`; the undecided ones, as a walk's with ``hull_always``, against the
    faces of the pair's hull (:func:`_hull_tested`). Returns (status, starts, occ) as
    :func:`classify_pairs` does.
    """
    m = ia.shape[0]
    status = np.zeros(m, np.int8)
    count = np.zeros(m, np.int64)
    found = np.empty(cand_occ.shape[0], np.int64)
    nv = polys.shape[1]
    nvi, nvj = va.shape[1], vb.shape[1]
    n_blocks = (m + _PAIR_BLOCK - 1) // _PAIR_BLOCK
    for blk in prange(n_blocks):
        si, sj = np.empty(nvi), np.empty(nvj)
        outside = np.zeros(nv, np.bool_)
        valid = np.zeros(nv, np.bool_)
        gi, gj = np.empty((nvi, nv)), np.empty((nvj, nv))
        lo, hi = np.empty(3), np.empty(3)
        planes = np.empty((MAX_HULL_PLANES, 4))
        for p in range(blk * _PAIR_BLOCK, min(m, (blk + 1) * _PAIR_BLOCK)):
            vi, vj = va[ia[p]], vb[ib[p]]
            _box_of(vi, vi.shape[0], vj, vj.shape[0], lo, hi)
            first, last = cand_starts[p], cand_starts[p + 1]
            # the hull's faces: every undecided candidate is tested against them in the end, as
            # in the walk (made first where there are many candidates, to leave boxes out early)
            n_planes = _hull_planes(vi, vj, planes, tol) if last - first >= HULL_AFTER else -1
            n = 0
            full = False
            for t in range(first, last):
                kk = cand_occ[t]
                if not _meets(lo, hi, olo[kk], ohi[kk], pad):
                    continue
                if n_planes > 0 and _beyond_planes(olo[kk], ohi[kk], planes, n_planes, pad):
                    continue
                if behind >= 0.0 and (_behind(polys, kk, vi[0], na[ia[p]], behind)
                                      or _behind(polys, kk, vj[0], nb[ib[p]], behind)):
                    continue
                state = _classify_one(vi, vj, polys, normal, center, inward, kk, tol, si, sj, outside, valid, gi, gj)
                if state == 1:
                    full = True
                    break
                if state == 2:
                    found[first + n] = kk
                    n += 1
            status[p], n = _hull_tested(vi, vj, 1 if full else (2 if n else 0), n, n_planes, found[first:], olo,
                                        ohi, planes, pad, tol, True)
            count[p] = 0 if full else n
    starts = np.zeros(m + 1, np.int64)
    for p in range(m):
        starts[p + 1] = starts[p] + count[p]
    occ = np.empty(starts[m], np.int64)
    for p in prange(m):
        for t in range(count[p]):
            occ[starts[p] + t] = found[cand_starts[p] + t]
    return status, starts, occ

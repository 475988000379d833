"""numba kernels of the exact shadows (imported lazily by ``_exact``; compiled once, cached).

One row is (receiver point x, its normal, a convex source polygon, a convex occluder polygon).
The row's hidden polygon is the source clipped by the cone from x over the part of the
occluder that lies between x and the source's plane; see ``_exact`` for the geometry.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

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
    m = 0
    for k in range(n):
        k2 = k + 1 if k + 1 < n else 0
        h1 = ax * src[k, 0] + ay * src[k, 1] + az * src[k, 2] + d
        h2 = ax * src[k2, 0] + ay * src[k2, 1] + az * src[k2, 2] + d
        if abs(h1) <= eps:
            h1 = 0.0
        if abs(h2) <= eps:
            h2 = 0.0
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
    return m


@njit(cache=True)
def _lambert(x, nx, poly, n, scratch):
    """Lambert's form factor from point x (normal nx) to polygon poly[:n], horizon-clipped."""
    m = _clip(poly, n, scratch, nx[0], nx[1], nx[2], -(nx[0] * x[0] + nx[1] * x[1] + nx[2] * x[2]))
    if m < 3:
        return 0.0
    total = 0.0
    for k in range(m):
        k2 = k + 1 if k + 1 < m else 0
        ax = scratch[k, 0] - x[0]
        ay = scratch[k, 1] - x[1]
        az = scratch[k, 2] - x[2]
        bx = scratch[k2, 0] - x[0]
        by = scratch[k2, 1] - x[1]
        bz = scratch[k2, 2] - x[2]
        cx = ay * bz - az * by
        cy = az * bx - ax * bz
        cz = ax * by - ay * bx
        s = math.sqrt(cx * cx + cy * cy + cz * cz)
        la = ax * ax + ay * ay + az * az
        lb = bx * bx + by * by + bz * bz
        if s <= 1e-14 * math.sqrt(la * lb):
            continue
        theta = math.atan2(s, ax * bx + ay * by + az * bz)
        total += theta * (cx * nx[0] + cy * nx[1] + cz * nx[2]) / s
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
    cap = source.shape[1] + ms + 3
    factor = np.zeros(r)
    polys = np.zeros((r if keep_polygons else 1, cap, 3))
    counts = np.zeros(r, np.int64)
    for row in prange(r):
        a = np.empty((ms + 3, 3))
        b = np.empty((ms + 3, 3))
        s1 = np.empty((cap, 3))
        s2 = np.empty((cap, 3))
        xr = x[row]
        sn = source_normal[row]
        cx = 0.0
        cy = 0.0
        cz = 0.0
        ns = source.shape[1]
        for k in range(ns):
            cx += source[row, k, 0]
            cy += source[row, k, 1]
            cz += source[row, k, 2]
        cx /= ns
        cy /= ns
        cz /= ns
        side = (xr[0] - cx) * sn[0] + (xr[1] - cy) * sn[1] + (xr[2] - cz) * sn[2]
        flip = -1.0 if side < 0 else 1.0
        px, py, pz = sn[0] * flip, sn[1] * flip, sn[2] * flip
        dx = abs(side)
        if dx <= tol:
            continue
        # apex in the occluder's plane: the cone is flat
        on = occluder_normal[row]
        ox = 0.0
        oy = 0.0
        oz = 0.0
        for k in range(ms):
            ox += occluder[row, k, 0]
            oy += occluder[row, k, 1]
            oz += occluder[row, k, 2]
        ox /= ms
        oy /= ms
        oz /= ms
        if abs((xr[0] - ox) * on[0] + (xr[1] - oy) * on[1] + (xr[2] - oz) * on[2]) <= tol:
            continue
        off = -(px * cx + py * cy + pz * cz)
        n1 = _clip(occluder[row], ms, a, px, py, pz, off)
        n2 = _clip(a, n1, b, -px, -py, -pz, dx - off)
        if n2 < 3:
            continue
        ix = 0.0
        iy = 0.0
        iz = 0.0
        for k in range(n2):
            ix += b[k, 0]
            iy += b[k, 1]
            iz += b[k, 2]
        ix = ix / n2 - xr[0]
        iy = iy / n2 - xr[1]
        iz = iz / n2 - xr[2]
        # source into s1
        for k in range(ns):
            s1[k, 0] = source[row, k, 0]
            s1[k, 1] = source[row, k, 1]
            s1[k, 2] = source[row, k, 2]
        m = ns
        flat = True
        for e in range(n2):
            e2 = e + 1 if e + 1 < n2 else 0
            ux = b[e, 0] - xr[0]
            uy = b[e, 1] - xr[1]
            uz = b[e, 2] - xr[2]
            vx = b[e2, 0] - xr[0]
            vy = b[e2, 1] - xr[1]
            vz = b[e2, 2] - xr[2]
            mx = uy * vz - uz * vy
            my = uz * vx - ux * vz
            mz = ux * vy - uy * vx
            norm = math.sqrt(mx * mx + my * my + mz * mz)
            if norm <= 1e-14 * (ux * ux + uy * uy + uz * uz + vx * vx + vy * vy + vz * vz):
                continue  # zero-length edge
            if mx * ix + my * iy + mz * iz < 0:
                mx, my, mz = -mx, -my, -mz
            flat = False
            m = _clip(s1, m, s2, mx, my, mz, -(mx * xr[0] + my * xr[1] + mz * xr[2]))
            for k in range(m):
                s1[k, 0] = s2[k, 0]
                s1[k, 1] = s2[k, 1]
                s1[k, 2] = s2[k, 2]
            if m < 3:
                break
        if flat or m < 3:
            continue
        factor[row] = _lambert(xr, nx[row], s1, m, s2)
        counts[row] = m
        if keep_polygons:
            for k in range(cap):
                kk = k if k < m else m - 1
                polys[row, k, 0] = s1[kk, 0]
                polys[row, k, 1] = s1[kk, 1]
                polys[row, k, 2] = s1[kk, 2]
    return factor, polys, counts


@njit(cache=True, parallel=True)
def classify_rows(vi, vj, polys, normal, center, inward, k, tol):
    """FREE (0) / FULL (1) / MAYBE (2) for rows (patch vertices vi, vj (t, 4, 3); occluder k)."""
    t = k.shape[0]
    out = np.full(t, 2, np.int8)
    nv = polys.shape[1]
    for row in prange(t):
        kk = k[row]
        n0, n1, n2 = normal[kk, 0], normal[kk, 1], normal[kk, 2]
        c0, c1, c2 = center[kk, 0], center[kk, 1], center[kk, 2]
        si = np.empty(4)
        sj = np.empty(4)
        for a in range(4):
            si[a] = (vi[row, a, 0] - c0) * n0 + (vi[row, a, 1] - c1) * n1 + (vi[row, a, 2] - c2) * n2
            sj[a] = (vj[row, a, 0] - c0) * n0 + (vj[row, a, 1] - c1) * n1 + (vj[row, a, 2] - c2) * n2
        imin, imax, jmin, jmax = si.min(), si.max(), sj.min(), sj.max()
        on_plane = max(abs(imin), abs(imax)) <= tol or max(abs(jmin), abs(jmax)) <= tol
        pos_i, neg_i = imin >= -tol, imax <= tol
        pos_j, neg_j = jmin >= -tol, jmax <= tol
        if on_plane or (pos_i and pos_j) or (neg_i and neg_j):
            out[row] = 0
            continue
        if not ((pos_i and neg_j) or (neg_i and pos_j)):
            continue  # a patch straddles the plane
        inside_all = True
        outside = np.zeros(nv, np.bool_)
        valid = np.zeros(nv, np.bool_)
        for e in range(nv):
            valid[e] = inward[kk, e, 0] != 0.0 or inward[kk, e, 1] != 0.0 or inward[kk, e, 2] != 0.0
            outside[e] = valid[e]
        for a in range(4):
            for b in range(4):
                den = si[a] - sj[b]
                if abs(den) <= tol:
                    inside_all = False
                    for e in range(nv):
                        outside[e] = False
                    continue
                tt = si[a] / den
                m0 = vi[row, a, 0] + tt * (vj[row, b, 0] - vi[row, a, 0])
                m1 = vi[row, a, 1] + tt * (vj[row, b, 1] - vi[row, a, 1])
                m2 = vi[row, a, 2] + tt * (vj[row, b, 2] - vi[row, a, 2])
                for e in range(nv):
                    if not valid[e]:
                        continue
                    g = ((m0 - polys[kk, e, 0]) * inward[kk, e, 0] + (m1 - polys[kk, e, 1]) * inward[kk, e, 1]
                         + (m2 - polys[kk, e, 2]) * inward[kk, e, 2])
                    if g >= -tol:
                        outside[e] = False
                    if g <= tol:
                        inside_all = False
        separated = False
        for e in range(nv):
            if outside[e]:
                separated = True
        if separated:
            out[row] = 0
        elif inside_all:
            out[row] = 1
    return out

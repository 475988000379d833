"""numba kernels of the shadow rays: stratified samples, kernel weights, segment tests, reduction.

They replace numpy expressions over (pairs, receiver samples, source samples, 3) arrays with
loops over pairs (parallel), so no temporary grows with the number of rays. The arithmetic
follows the numpy reference (``stratified_points`` and ``Visibility._trace_numpy``) operation by
operation. :func:`segment_fractions` tests each ray against its pair's own occluder polygons;
:func:`shadow_rays` and :func:`ray_fractions` wrap an Embree cast instead (``cull=False``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_TWO53 = float(1 << 53)


@njit(cache=True, inline="always")
def _hash_uniform(key):
    """Uniform number in [0, 1) from a uint64 key (splitmix64), as ``visibility._hash_uniform``."""
    z = key + _GOLDEN
    z = (z ^ (z >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    z = z ^ (z >> np.uint64(31))
    return float(z >> np.uint64(11)) / _TWO53


@njit(cache=True)
def _stratified(quad, samples, key, salt, pts, w):
    """One jittered point per cell of a samples x samples grid on quad (4, 3), with area weights."""
    cells = np.uint64(samples * samples)
    p0, p1, p2, p3 = quad[0], quad[1], quad[2], quad[3]
    for c in range(samples * samples):
        base = (key * cells + np.uint64(c)) * np.uint64(8) + np.uint64(salt * 2)
        ju = _hash_uniform(base)
        jv = _hash_uniform(base + np.uint64(1))
        u = ((c // samples) + ju) / samples
        v = ((c % samples) + jv) / samples
        du = np.empty(3)
        dv = np.empty(3)
        for k in range(3):
            pts[c, k] = (1 - u) * (1 - v) * p0[k] + u * (1 - v) * p1[k] + u * v * p2[k] + (1 - u) * v * p3[k]
            du[k] = (1 - v) * (p1[k] - p0[k]) + v * (p2[k] - p3[k])
            dv[k] = (1 - u) * (p3[k] - p0[k]) + u * (p2[k] - p1[k])
        c0 = du[1] * dv[2] - du[2] * dv[1]
        c1 = du[2] * dv[0] - du[0] * dv[2]
        c2 = du[0] * dv[1] - du[1] * dv[0]
        w[c] = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2) / (samples * samples)


@njit(cache=True)
def stratified_points(quads, idx, samples, key, salt):
    """Jittered stratified points on quads[idx] (see ``visibility.stratified_points``)."""
    m = idx.shape[0]
    c = samples * samples
    pts = np.empty((m, c, 3))
    w = np.empty((m, c))
    for p in range(m):
        _stratified(quads[idx[p]], samples, key[p], salt, pts[p], w[p])
    return pts, w


@njit(cache=True, parallel=True)
def shadow_rays(xs, wx, nx, quads, normals, j, samples, key, salt, floor_rel, offset):
    """Weights and ray ends from receiver samples xs (m, a, 3) to stratified samples of j.

    The weight of the ray from x to y is ``wx * wy * max(cos_i, 0) * max(cos_j, 0) / r**4``
    (times r**2 it is the differential form factor); rays whose weight is at most ``floor_rel``
    of the pair's largest are not traced. Traced rays run between the samples pulled off their
    surfaces by ``offset`` along the normals.

    Returns
    -------
    weight : (m, a * b) float
    starts : (m + 1,) int64
        The traced rays of pair p are rows ``starts[p]:starts[p + 1]`` of origins/ends.
    traced : (m, a * b) bool
    origins, ends : (t, 3) float
    """
    m, na = xs.shape[0], xs.shape[1]
    nb = samples * samples
    weight = np.empty((m, na * nb))
    traced = np.zeros((m, na * nb), np.bool_)
    ys = np.empty((m, nb, 3))
    count = np.zeros(m, np.int64)
    for p in prange(m):
        wy = np.empty(nb)
        _stratified(quads[j[p]], samples, key[p], salt, ys[p], wy)
        ny = normals[j[p]]
        top = 0.0
        for a in range(na):
            for b in range(nb):
                d0 = ys[p, b, 0] - xs[p, a, 0]
                d1 = ys[p, b, 1] - xs[p, a, 1]
                d2 = ys[p, b, 2] - xs[p, a, 2]
                r2 = d0 * d0 + d1 * d1 + d2 * d2
                ci = d0 * nx[p, 0] + d1 * nx[p, 1] + d2 * nx[p, 2]
                cj = -(d0 * ny[0] + d1 * ny[1] + d2 * ny[2])
                wt = wx[p, a] * wy[b] * max(ci, 0.0) * max(cj, 0.0) / max(r2, 1e-300) ** 2
                weight[p, a * nb + b] = wt
                top = max(top, wt)
        n = 0
        for r in range(na * nb):
            if weight[p, r] > floor_rel * top:
                traced[p, r] = True
                n += 1
        count[p] = n
    starts = np.zeros(m + 1, np.int64)
    for p in range(m):
        starts[p + 1] = starts[p] + count[p]
    origins = np.empty((starts[m], 3))
    ends = np.empty((starts[m], 3))
    for p in prange(m):
        ny = normals[j[p]]
        t = starts[p]
        for a in range(na):
            for b in range(nb):
                if not traced[p, a * nb + b]:
                    continue
                for k in range(3):
                    origins[t, k] = xs[p, a, k] + offset * nx[p, k]
                    ends[t, k] = ys[p, b, k] + offset * ny[k]
                t += 1
    return weight, starts, traced, origins, ends


@njit(cache=True, parallel=True)
def ray_fractions(weight, traced, starts, blocked):
    """Kernel-weighted unblocked fraction per pair, and whether its traced rays agreed.

    A pair with no weight at all (every sample pair on one or the other's horizon) gets NaN and
    does not agree: its rays say nothing about the part of the patches that see each other.
    """
    m, n = weight.shape
    frac = np.empty(m)
    agree = np.empty(m, np.bool_)
    for p in prange(m):
        total = 0.0
        visible = 0.0
        n_traced = 0
        n_blocked = 0
        t = starts[p]
        for r in range(n):
            wt = weight[p, r]
            total += wt
            hit = False
            if traced[p, r]:
                hit = blocked[t]
                t += 1
                n_traced += 1
                if hit:
                    n_blocked += 1
            if not hit:
                visible += wt
        agree[p] = total > 0 and (n_blocked == 0 or n_blocked == n_traced)
        frac[p] = visible / total if total > 0 else np.nan
    return frac, agree


@njit(cache=True, parallel=True)
def segment_fractions(xs, wx, nx, quads, normals, j, samples, key, salt, floor_rel, offset, tfar, starts, occ,
                      owner, polys, onormal, ocenter, inward, tol):
    """Weighted unblocked fraction per pair, each ray tested against the pair's own occluders.

    Same samples, weights and ray ends as :func:`shadow_rays`, but instead of a scene-wide ray
    cast each segment is intersected, in float64, with the convex occluder polygons
    ``polys[occ[starts[q]:starts[q + 1]]]``, q = ``owner[p]``, that the exact classification
    left undecided for pair p (no other polygon can block any of its segments). ``owner`` lets
    rows share a list (the points of one pair, a subset of pairs) without copying it. A segment
    is blocked when it crosses an occluder's plane strictly between its ends, before ``tfar`` of
    its length, at a point inside the polygon or within ``tol`` of it (so shared edges of
    neighbouring occluders leak nothing).

    Returns
    -------
    frac : (m,) float
        NaN for a pair whose rays carry no weight (see :func:`ray_fractions`).
    agree : (m,) bool
        Whether all traced rays of the pair agreed (all blocked or none); False without weight.
    n_traced : (m,) int64
    """
    m = xs.shape[0]
    frac = np.empty(m)
    agree = np.empty(m, np.bool_)
    n_traced = np.zeros(m, np.int64)
    n_blocks = (m + _BLOCK - 1) // _BLOCK
    for blk in prange(n_blocks):
        _segment_block(blk * _BLOCK, min(m, (blk + 1) * _BLOCK), xs, wx, nx, quads, normals, j, samples, key, salt,
                       floor_rel, offset, tfar, starts, occ, owner, polys, onormal, ocenter, inward, tol, frac,
                       agree, n_traced)
    return frac, agree, n_traced


# Pairs per parallel task of the compiled ray loops.
_BLOCK = 64


@njit(cache=True)
def _segment_block(s, e, xs, wx, nx, quads, normals, j, samples, key, salt, floor_rel, offset, tfar, starts, occ,
                   owner, polys, onormal, ocenter, inward, tol, frac, agree, n_traced_out):
    """Pairs s..e-1 of :func:`segment_fractions`."""
    na = xs.shape[1]
    nb = samples * samples
    nv = polys.shape[1]
    ys = np.empty((nb, 3))
    wy = np.empty(nb)
    weight = np.empty(na * nb)
    xo = np.empty((na, 3))
    yo = np.empty((nb, 3))
    for p in range(s, e):
        k0, k1 = starts[owner[p]], starts[owner[p] + 1]
        nk = k1 - k0
        _stratified(quads[j[p]], samples, key[p], salt, ys, wy)
        ny = normals[j[p]]
        top = 0.0
        for a in range(na):
            for b in range(nb):
                d0 = ys[b, 0] - xs[p, a, 0]
                d1 = ys[b, 1] - xs[p, a, 1]
                d2 = ys[b, 2] - xs[p, a, 2]
                r2 = d0 * d0 + d1 * d1 + d2 * d2
                ci = d0 * nx[p, 0] + d1 * nx[p, 1] + d2 * nx[p, 2]
                cj = -(d0 * ny[0] + d1 * ny[1] + d2 * ny[2])
                wt = wx[p, a] * wy[b] * max(ci, 0.0) * max(cj, 0.0) / max(r2, 1e-300) ** 2
                weight[a * nb + b] = wt
                top = max(top, wt)
        # ray ends pulled off the surfaces, and their heights over each occluder's plane
        for a in range(na):
            for c in range(3):
                xo[a, c] = xs[p, a, c] + offset * nx[p, c]
        for b in range(nb):
            for c in range(3):
                yo[b, c] = ys[b, c] + offset * ny[c]
        hx = np.empty((nk, na))
        hy = np.empty((nk, nb))
        for t in range(nk):
            k = occ[k0 + t]
            for a in range(na):
                hx[t, a] = ((xo[a, 0] - ocenter[k, 0]) * onormal[k, 0] + (xo[a, 1] - ocenter[k, 1]) * onormal[k, 1]
                            + (xo[a, 2] - ocenter[k, 2]) * onormal[k, 2])
            for b in range(nb):
                hy[t, b] = ((yo[b, 0] - ocenter[k, 0]) * onormal[k, 0] + (yo[b, 1] - ocenter[k, 1]) * onormal[k, 1]
                            + (yo[b, 2] - ocenter[k, 2]) * onormal[k, 2])
        total = 0.0
        visible = 0.0
        n_traced = 0
        n_blocked = 0
        for a in range(na):
            for b in range(nb):
                wt = weight[a * nb + b]
                total += wt
                hit = False
                if wt > floor_rel * top:
                    n_traced += 1
                    for t in range(nk):
                        h1 = hx[t, a]
                        h2 = hy[t, b]
                        if not ((h1 > 0.0 and h2 < 0.0) or (h1 < 0.0 and h2 > 0.0)):
                            continue
                        u = h1 / (h1 - h2)
                        if u >= tfar:
                            continue
                        k = occ[k0 + t]
                        m0 = xo[a, 0] + u * (yo[b, 0] - xo[a, 0])
                        m1 = xo[a, 1] + u * (yo[b, 1] - xo[a, 1])
                        m2 = xo[a, 2] + u * (yo[b, 2] - xo[a, 2])
                        inside = True
                        for ed in range(nv):
                            g = ((m0 - polys[k, ed, 0]) * inward[k, ed, 0] + (m1 - polys[k, ed, 1]) * inward[k, ed, 1]
                                 + (m2 - polys[k, ed, 2]) * inward[k, ed, 2])
                            if g < -tol:
                                inside = False
                                break
                        if inside:
                            hit = True
                            break
                    if hit:
                        n_blocked += 1
                if not hit:
                    visible += wt
        agree[p] = total > 0 and (n_blocked == 0 or n_blocked == n_traced)
        frac[p] = visible / total if total > 0 else np.nan  # no weight: see ray_fractions
        n_traced_out[p] = n_traced

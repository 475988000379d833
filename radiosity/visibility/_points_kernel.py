"""numba kernel of sensor irradiance: one receiver point at a time, exact shadows, bounded error.

Each point is computed on its own, in a fixed order over the sources, so its value depends only
on the point, its normal and the solution: never on the other points or on its row in a file.
The kernel reuses the pair classification (``_classify_pair``) and the exact shadows
(``_point_hidden``) of ``_exact_kernel``; see ``_points`` for the error bound.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._exact_kernel import _classify_pair, _lambert, _point_hidden

# Receiver points per parallel task (scratch is allocated per task).
_POINT_BLOCK = 64


@njit(cache=True)
def _point_block(s, e, x, nx, quads, normals, centroid, radiosity, lit, polys, onormal, center, inward, olo, ohi,
                 node_lo, node_hi, node_left, node_right, node_start, node_count, order, pad, tol, rtol,
                 max_union, out, ok, n_exact):
    """Points s..e-1 of :func:`sensor_irradiance`."""
    n_lit = lit.shape[0]
    n_occ = polys.shape[0]
    nv = polys.shape[1]
    ns = quads.shape[1]
    cap = ns + nv + 3
    lcap = 2 * (max_union + 1) * cap + 8
    # scratch of the classification
    stack = np.empty(2 * node_lo.shape[0] + 2, np.int64)
    occ = np.empty(max(n_occ, 1), np.int64)
    lo = np.empty(3)
    hi = np.empty(3)
    si = np.empty(4)
    sj = np.empty(4)
    outside = np.zeros(nv, np.bool_)
    valid = np.zeros(nv, np.bool_)
    gi = np.empty((4, nv))
    gj = np.empty((4, nv))
    # scratch of the exact shadows
    a = np.empty((nv + 3, 3))
    b = np.empty((nv + 3, 3))
    s1 = np.empty((cap, 3))
    s2 = np.empty((cap, 3))
    hp = np.empty((max_union, cap, 3))
    hn = np.empty(max_union, np.int64)
    levels = np.empty((max_union + 1, lcap, 3))
    lcount = np.empty(max_union + 1, np.int64)
    nxt = np.empty(max_union + 1, np.int64)
    sa = np.empty((lcap + 2, 3))
    sb = np.empty((lcap + 2, 3))
    # the partly occluded sources of one point
    cand = np.empty(n_lit, np.int64)
    cand_f = np.empty(n_lit)
    key = np.empty(n_lit)
    rest = np.empty((n_lit + 1, 3))
    vi = np.empty((4, 3))
    h = np.zeros(3)
    for p in range(s, e):
        xp = x[p]
        np_ = nx[p]
        for v in range(4):
            vi[v, 0], vi[v, 1], vi[v, 2] = xp[0], xp[1], xp[2]
        h[:] = 0.0
        n_cand = 0
        for t in range(n_lit):
            j = lit[t]
            # the source must face the point, and reach above the point's horizon
            if ((xp[0] - centroid[j, 0]) * normals[j, 0] + (xp[1] - centroid[j, 1]) * normals[j, 1]
                    + (xp[2] - centroid[j, 2]) * normals[j, 2]) <= 0.0:
                continue
            up = -1e300
            for v in range(ns):
                up = max(up, (quads[j, v, 0] - xp[0]) * np_[0] + (quads[j, v, 1] - xp[1]) * np_[1]
                         + (quads[j, v, 2] - xp[2]) * np_[2])
            if up <= 0.0:
                continue
            f = _lambert(xp, np_, quads[j], ns, s2)
            if f <= 0.0:
                continue
            st = 0
            if n_occ:
                st, _ = _classify_pair(vi, quads[j], polys, onormal, center, inward, olo, ohi, node_lo, node_hi,
                                       node_left, node_right, node_start, node_count, order, pad, tol, occ, stack,
                                       lo, hi, si, sj, outside, valid, gi, gj)
            if st == 0:
                for c in range(3):
                    h[c] += f * radiosity[j, c]
            elif st == 2:
                cand[n_cand] = j
                cand_f[n_cand] = f
                key[n_cand] = -f * (radiosity[j, 0] + radiosity[j, 1] + radiosity[j, 2])
                n_cand += 1
        if n_cand:
            # exact shadows for the largest unoccluded contributions first; the rest are taken
            # half visible once half their sum is below rtol times what is already known
            srt = np.argsort(key[:n_cand], kind="mergesort")
            for c in range(3):
                rest[n_cand, c] = 0.0
            for q in range(n_cand - 1, -1, -1):
                j = cand[srt[q]]
                for c in range(3):
                    rest[q, c] = rest[q + 1, c] + cand_f[srt[q]] * radiosity[j, c]
            for q in range(n_cand):
                done = True
                for c in range(3):
                    if 0.5 * rest[q, c] > rtol * h[c]:
                        done = False
                if done:
                    for c in range(3):
                        h[c] += 0.5 * rest[q, c]
                    break
                j = cand[srt[q]]
                f = cand_f[srt[q]]
                _, n_maybe = _classify_pair(vi, quads[j], polys, onormal, center, inward, olo, ohi, node_lo,
                                            node_hi, node_left, node_right, node_start, node_count, order, pad,
                                            tol, occ, stack, lo, hi, si, sj, outside, valid, gi, gj)
                hidden, good = _point_hidden(xp, np_, quads[j], normals[j], occ, 0, n_maybe, polys, onormal, tol,
                                             max_union, a, b, s1, s2, hp, hn, levels, lcount, nxt, sa, sb)
                n_exact[p] += 1
                if not good:
                    ok[p] = False
                    continue
                seen = f - min(hidden, f)
                for c in range(3):
                    h[c] += seen * radiosity[j, c]
        for c in range(3):
            out[p, c] = h[c]


@njit(cache=True, parallel=True)
def sensor_irradiance(x, nx, quads, normals, centroid, radiosity, lit, polys, onormal, center, inward, olo, ohi,
                      node_lo, node_hi, node_left, node_right, node_start, node_count, order, pad, tol, rtol,
                      max_union):
    """Irradiance (m, 3) at points x with unit normals nx from the lit patches ``lit``.

    Returns
    -------
    irradiance : (m, 3) float
    ok : (m,) bool
        False where a source had more than ``max_union`` hidden polygons at the point (its
        contribution is left out; the caller recomputes those points).
    n_exact : (m,) int64
        Exact shadows computed per point.
    """
    m = x.shape[0]
    out = np.zeros((m, 3))
    ok = np.ones(m, np.bool_)
    n_exact = np.zeros(m, np.int64)
    n_blocks = (m + _POINT_BLOCK - 1) // _POINT_BLOCK
    for blk in prange(n_blocks):
        _point_block(blk * _POINT_BLOCK, min(m, (blk + 1) * _POINT_BLOCK), x, nx, quads, normals, centroid, radiosity,
                     lit, polys, onormal, center, inward, olo, ohi, node_lo, node_hi, node_left, node_right,
                     node_start, node_count, order, pad, tol, rtol, max_union, out, ok, n_exact)
    return out, ok, n_exact

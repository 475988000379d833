"""numba kernel of sensor irradiance: one receiver point at a time, exact shadows, bounded error.

Each point is computed on its own, in a fixed order over the sources, so its value depends only
on the point, its normal and the solution: never on the other points or on its row in a file.
The kernel reuses the pair classification (``_classify_pair``) and the exact shadows
(``_point_hidden``) of ``_exact_kernel``; see ``_points`` for the error bound.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

# numba's disk cache of this module's kernels holds the _exact_kernel helpers compiled in (and
# the _geometry_kernels ones they inline), and is keyed on this file alone: a change there must
# touch this file too, or stale code runs (last: _point_hidden's one-occluder path, _clip, _lambert,
# _hidden_polygon skip work; session 16).
from ._exact_kernel import _classify_one, _lambert, _mean_vertex, _next_occluder, _point_hidden, union_scratch


@njit(cache=True, inline="always")
def _cap(x, poly, n, cap):
    """Spherical cap from x containing the directions to polygon poly[:n]: cap = (direction (3),
    cos, sin of its angular radius). A radius of 90 degrees or more (or x on the polygon) is
    stored as cos = -2: such a cap culls nothing, because only caps under a hemisphere are convex."""
    m0, m1, m2 = _mean_vertex(poly, n)
    d0, d1, d2 = m0 - x[0], m1 - x[1], m2 - x[2]
    dn = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    cap[3] = -2.0
    if dn == 0.0:
        return
    d0, d1, d2 = d0 / dn, d1 / dn, d2 / dn
    c = 1.0
    for v in range(n):
        e0, e1, e2 = poly[v, 0] - x[0], poly[v, 1] - x[1], poly[v, 2] - x[2]
        en = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        if en == 0.0:
            return
        c = min(c, (e0 * d0 + e1 * d1 + e2 * d2) / en)
    if c <= _CAP_COS_MIN:
        return
    cap[0], cap[1], cap[2] = d0, d1, d2
    cap[3] = c
    cap[4] = math.sqrt(max(0.0, 1.0 - c * c))


@njit(cache=True, inline="always")
def _caps_meet(a, b):
    """False only if the caps a and b (see :func:`_cap`) are disjoint by a clear margin."""
    if a[3] < -1.0 or b[3] < -1.0:
        return True
    bound = a[3] * b[3] - a[4] * b[4]  # cos(ra + rb)
    if a[4] * b[3] + a[3] * b[4] < 0.0:  # ra + rb beyond 180 degrees
        return True
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] >= bound - _CAP_PAD


@njit(cache=True)
def _classify_hull(vi, vj, polys, normal, center, inward, olo, ohi, node_lo, node_hi, node_left, node_right,
                   node_start, node_count, order, pad, tol, out_occ, stack, lo, hi, si, sj, outside, valid, gi, gj,
                   caps, stamp, stamp_id, src_cap):
    """Walk the BVH for receiver hull vi (a point, or a cluster's box) and source vj.

    Returns (status, number of MAYBE occluders): FREE (0) / FULL (1) / MAYBE (2); the MAYBE
    occluders are written to out_occ (as many as fit; pass an empty array to count only).

    For a point receiver (``stamp_id >= 0``), an occluder whose cap seen from the point misses
    the source's cap ``src_cap`` cannot block it and is skipped; the point's occluder caps are
    computed on first use (``caps[k]`` is valid where ``stamp[k] == stamp_id``).
    """
    for c in range(3):
        lo[c] = 1e300
        hi[c] = -1e300
        for v in range(vi.shape[0]):
            lo[c] = min(lo[c], vi[v, c])
            hi[c] = max(hi[c], vi[v, c])
        for v in range(vj.shape[0]):
            lo[c] = min(lo[c], vj[v, c])
            hi[c] = max(hi[c], vj[v, c])
    n_maybe = 0
    top, pos, end = 0, 0, 0
    stack[0] = 0
    while True:
        top, pos, end, kk = _next_occluder(stack, top, pos, end, lo, hi, olo, ohi, node_lo, node_hi, node_left,
                                           node_right, node_start, node_count, order, pad, caps[:0, :4], 0)
        if kk < 0:
            break
        if stamp_id >= 0:
            if stamp[kk] != stamp_id:
                _cap(vi[0], polys[kk], polys.shape[1], caps[kk])
                stamp[kk] = stamp_id
            if not _caps_meet(caps[kk], src_cap):
                continue
        state = _classify_one(vi, vj, polys, normal, center, inward, kk, tol, si, sj, outside, valid, gi, gj)
        if state == 1:
            return 1, 0
        if state == 2:
            if n_maybe < out_occ.shape[0]:
                out_occ[n_maybe] = kk
            n_maybe += 1
    return (2 if n_maybe else 0), n_maybe


# Caps wider than this (cos of the radius) cull nothing; a margin on the caps' separation.
_CAP_COS_MIN = 1e-3
_CAP_PAD = 1e-9

# A visible part below this fraction of a source's factor is round-off of a fully hidden one.
_SEEN_FLOOR = 1e-12

# Clusters of receiver points per parallel task (scratch is allocated per task).
_CLUSTER_BLOCK = 4
# Occluder entries kept per point for the exact shadows: this many per lit source, at least _POOL_MIN.
_POOL_PER_SOURCE = 8
_POOL_MIN = 4096


@njit(cache=True)
def _cluster_block(c0, c1, x, nx, members, cstart, quads, normals, centroid, radiosity, lit, polys, onormal, center,
                   inward, olo, ohi, node_lo, node_hi, node_left, node_right, node_start, node_count, order, pad,
                   tol, rtol, max_union, out, ok, n_exact, reuse):
    """Clusters c0..c1-1 of :func:`sensor_irradiance`.

    Each (cluster, source) pair is classified first, from the cluster's box: a free or fully
    blocked box is free or fully blocked for every point in it (up to the plane tolerance).
    Only the partly occluded boxes are classified again point by point, so a point's value is
    the one it would have on its own.
    """
    n_lit = lit.shape[0]
    n_occ = polys.shape[0]
    nv = polys.shape[1]
    ns = quads.shape[1]
    # scratch of the classification
    stack = np.empty(2 * node_lo.shape[0] + 2, np.int64)
    occ = np.empty(max(n_occ, 1), np.int64)
    lo = np.empty(3)
    hi = np.empty(3)
    si = np.empty(8)
    sj = np.empty(8)
    outside = np.zeros(nv, np.bool_)
    valid = np.zeros(nv, np.bool_)
    gi = np.empty((8, nv))
    gj = np.empty((8, nv))
    box = np.empty((8, 3))
    blo = np.empty(3)
    bhi = np.empty(3)
    status = np.zeros(n_lit, np.int8)
    none = np.empty(0, np.int64)
    caps = np.empty((max(n_occ, 1), 5))
    stamp = np.full(max(n_occ, 1), -1, np.int64)
    src_cap = np.empty(5)
    # scratch of the exact shadows
    a, b, s1, s2, hp, hn, levels, lcount, nxt, sa, sb = union_scratch(ns, nv, max_union)
    # the partly occluded sources of one point
    cand = np.empty(n_lit, np.int64)
    cand_f = np.empty(n_lit)
    key = np.empty(n_lit)
    rest = np.empty((n_lit + 1, 3))
    h = np.zeros(3)
    # the partly occluding occluders of each candidate, kept from its classification
    pool = np.empty(max(_POOL_MIN, _POOL_PER_SOURCE * n_lit), np.int64)
    cand_at = np.empty(n_lit, np.int64)
    cand_count = np.empty(n_lit, np.int64)
    for cl in range(c0, c1):
        if n_occ:
            for c in range(3):
                blo[c] = 1e300
                bhi[c] = -1e300
            for q in range(cstart[cl], cstart[cl + 1]):
                for c in range(3):
                    blo[c] = min(blo[c], x[members[q], c])
                    bhi[c] = max(bhi[c], x[members[q], c])
            n_box = 0
            for v in range(8):
                if (v & 1 and bhi[0] == blo[0]) or (v & 2 and bhi[1] == blo[1]) or (v & 4 and bhi[2] == blo[2]):
                    continue  # a flat box: that corner repeats another
                box[n_box, 0] = bhi[0] if v & 1 else blo[0]
                box[n_box, 1] = bhi[1] if v & 2 else blo[1]
                box[n_box, 2] = bhi[2] if v & 4 else blo[2]
                n_box += 1
            for t in range(n_lit):
                j = lit[t]
                facing = False
                for v in range(n_box):
                    if ((box[v, 0] - centroid[j, 0]) * normals[j, 0] + (box[v, 1] - centroid[j, 1]) * normals[j, 1]
                            + (box[v, 2] - centroid[j, 2]) * normals[j, 2]) > 0.0:
                        facing = True
                if not facing:
                    status[t] = 1  # faces away from every point of the box: contributes nothing
                    continue
                status[t], _ = _classify_hull(box[:n_box], quads[j], polys, onormal, center, inward, olo, ohi,
                                              node_lo, node_hi, node_left, node_right, node_start, node_count, order,
                                              pad, tol, none, stack, lo, hi, si, sj, outside, valid, gi, gj, caps,
                                              stamp, -1, src_cap)
        for q in range(cstart[cl], cstart[cl + 1]):
            p = members[q]
            _point_value(p, x, nx, quads, normals, centroid, radiosity, lit, status, polys, onormal, center, inward,
                         olo, ohi, node_lo, node_hi, node_left, node_right, node_start, node_count, order, pad, tol,
                         rtol, max_union, out, ok, n_exact, stack, occ, lo, hi, si, sj, outside, valid, gi, gj, caps,
                         stamp, src_cap, a, b, s1, s2, hp, hn, levels, lcount, nxt, sa, sb, cand, cand_f, key, rest, h,
                         pool, cand_at, cand_count, reuse)


@njit(cache=True)
def _point_value(p, x, nx, quads, normals, centroid, radiosity, lit, status, polys, onormal, center, inward, olo,
                 ohi, node_lo, node_hi, node_left, node_right, node_start, node_count, order, pad, tol, rtol,
                 max_union, out, ok, n_exact, stack, occ, lo, hi, si, sj, outside, valid, gi, gj, caps, stamp, src_cap,
                 a, b, s1, s2, hp, hn, levels, lcount, nxt, sa, sb, cand, cand_f, key, rest, h, pool, cand_at,
                 cand_count, reuse):
    """Irradiance at point p, given the status of its cluster against each lit source.

    A partly occluded source's occluders are written to ``pool`` by the classification that
    finds it partly occluded, and its exact shadow reads them from there: the same walk gives
    the same list, so the walk is not repeated (it is when the pool is full).
    """
    n_lit = lit.shape[0]
    ns = quads.shape[1]
    xp = x[p]
    np_ = nx[p]
    vi = x[p:p + 1]  # the point as a one-vertex receiver
    h[:] = 0.0
    unoccluded = np.zeros(3)
    n_cand = 0
    used = 0
    for t in range(n_lit):
        if status[t] == 1:
            continue
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
        for c in range(3):
            unoccluded[c] += f * radiosity[j, c]
        st = status[t]
        n_maybe = 0
        if st == 2:
            _cap(xp, quads[j], ns, src_cap)
            st, n_maybe = _classify_hull(vi, quads[j], polys, onormal, center, inward, olo, ohi, node_lo, node_hi,
                                         node_left, node_right, node_start, node_count, order, pad, tol,
                                         pool[used:], stack, lo, hi, si, sj, outside, valid, gi, gj, caps, stamp, p,
                                         src_cap)
        if st == 0:
            for c in range(3):
                h[c] += f * radiosity[j, c]
        elif st == 2:
            if reuse and used + n_maybe <= pool.shape[0]:
                cand_at[n_cand] = used
                cand_count[n_cand] = n_maybe
                used += n_maybe
            else:
                cand_at[n_cand] = -1  # the pool is full: walk again for its exact shadow
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
            at = cand_at[srt[q]]
            if at >= 0:
                hidden, good = _point_hidden(xp, np_, quads[j], normals[j], pool, at, at + cand_count[srt[q]], polys,
                                             onormal, tol, max_union, a, b, s1, s2, hp, hn, levels, lcount, nxt, sa,
                                             sb)
            else:
                _cap(xp, quads[j], ns, src_cap)
                _, n_maybe = _classify_hull(vi, quads[j], polys, onormal, center, inward, olo, ohi, node_lo,
                                            node_hi, node_left, node_right, node_start, node_count, order, pad,
                                            tol, occ, stack, lo, hi, si, sj, outside, valid, gi, gj, caps, stamp, p,
                                            src_cap)
                hidden, good = _point_hidden(xp, np_, quads[j], normals[j], occ, 0, n_maybe, polys, onormal, tol,
                                             max_union, a, b, s1, s2, hp, hn, levels, lcount, nxt, sa, sb)
            n_exact[p] += 1
            if not good:
                ok[p] = False
                continue
            seen = f - min(hidden, f)
            if seen <= _SEEN_FLOOR * f:
                seen = 0.0  # round-off of a source hidden whole (a point under a block on the floor)
            for c in range(3):
                h[c] += seen * radiosity[j, c]
    for c in range(3):
        # round-off of light hidden whole (a point inside a solid) is 0
        out[p, c] = h[c] if h[c] > _SEEN_FLOOR * unoccluded[c] else 0.0


@njit(cache=True, parallel=True)
def sensor_irradiance(x, nx, members, cstart, quads, normals, centroid, radiosity, lit, polys, onormal, center,
                      inward, olo, ohi, node_lo, node_hi, node_left, node_right, node_start, node_count, order, pad,
                      tol, rtol, max_union, block_order, reuse):
    """Irradiance (m, 3) at points x with unit normals nx from the lit patches ``lit``.

    The points are grouped in clusters: cluster c holds points ``members[cstart[c]:cstart[c + 1]]``.
    Blocks of ``_CLUSTER_BLOCK`` clusters are taken in the order ``block_order`` (a permutation
    of the blocks): the parallel loop gives each thread one contiguous run of it, and a shuffled
    order spreads the costly points (penumbrae) evenly over the threads, where runs of
    neighbouring clusters left one thread with most of them. A point's value does not depend
    on the order. ``reuse``: keep each partly occluded source's occluders from its classification
    for its exact shadow (False walks the BVH again, as before; the same values either way).

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
    n_clusters = cstart.shape[0] - 1
    n_blocks = (n_clusters + _CLUSTER_BLOCK - 1) // _CLUSTER_BLOCK
    for i in prange(n_blocks):
        blk = block_order[i]
        _cluster_block(blk * _CLUSTER_BLOCK, min(n_clusters, (blk + 1) * _CLUSTER_BLOCK), x, nx, members, cstart,
                       quads, normals, centroid, radiosity, lit, polys, onormal, center, inward, olo, ohi, node_lo,
                       node_hi, node_left, node_right, node_start, node_count, order, pad, tol, rtol, max_union, out,
                       ok, n_exact, reuse)
    return out, ok, n_exact

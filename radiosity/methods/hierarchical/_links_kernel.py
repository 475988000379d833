"""numba kernels of the element links: G's part for the links that gather from their source's
children (see :class:`._hierarchy._Children`), applied link by link from each link's value and
its four shares instead of four entries of a sparse matrix each; the near bound of new links; the
copy of the links' occluder lists."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ...formfactors._quadrature import _distance


@njit(cache=True)
def gather_children(r, first, value, shares, x, y):
    """y[r[k]] += value[k] * sum_c shares[k, c] * x[first[k] + c] for every link k (serial:
    links of one receiver add into the same entry)."""
    for k in range(len(r)):
        f = first[k]
        y[r[k]] += value[k] * (shares[k, 0] * x[f] + shares[k, 1] * x[f + 1]
                               + shares[k, 2] * x[f + 2] + shares[k, 3] * x[f + 3])


@njit(cache=True)
def collect_children(r, first, value, shares, y, x):
    """x[first[k] + c] += value[k] * shares[k, c] * y[r[k]] for every link k and child c
    (the transpose of :func:`gather_children`)."""
    for k in range(len(r)):
        taken = value[k] * y[r[k]]
        f = first[k]
        for c in range(4):
            x[f + c] += taken * shares[k, c]


@njit(cache=True, parallel=True)
def gather_deviations(indptr, column, codes, scale, x, out):
    """out[q, i] += codes[k, i] * scale[k] * x[column[k]] for the links k of receiver q
    (``indptr[q]:indptr[q + 1]``): :class:`._variation.Variation`'s part of G @ x. Receivers
    are rows of their own, so they run in parallel."""
    for q in prange(len(indptr) - 1):
        for k in range(indptr[q], indptr[q + 1]):
            v = scale[k] * x[column[k]]
            if v != 0.0:
                for i in range(codes.shape[1]):
                    out[q, i] += codes[k, i] * v


@njit(cache=True)
def collect_deviations(indptr, column, codes, scale, y, x):
    """x[column[k]] += scale[k] * sum_i codes[k, i] * y[q, i] (the transpose of
    :func:`gather_deviations`; serial: links of one source add into the same entry)."""
    for q in range(len(indptr) - 1):
        for k in range(indptr[q], indptr[q + 1]):
            t = 0.0
            for i in range(codes.shape[1]):
                t += codes[k, i] * y[q, i]
            x[column[k]] += scale[k] * t


@njit(cache=True)
def copy_masked_lists(occ, count, mask, out, at):
    """Copy the lists of the links where ``mask`` is set (``occ``: link after link, ``count[k]``
    entries for link k) into ``out`` from ``at`` on, in order; returns where they end. One pass:
    a boolean mask over the entries (``np.repeat(mask, count)``) cost a tenth of a furnished
    room's solve."""
    src = 0
    for k in range(len(count)):
        c = count[k]
        if mask[k]:
            for e in range(src, src + c):
                out[at] = occ[e]
                at += 1
        src += c
    return at


@njit(cache=True, parallel=True)
def near_bounds(quads, centroid, normal, area, splittable, r, s, near_only, near_smaller, near_gap, near_relative,
                touching_bound, out):
    """out[k]: the bound of :func:`._hierarchy._near_bound` for link k (r[k] gathers from s[k]),
    the numpy expressions written out per link (their temporaries were 7% of a furnished room's
    solve)."""
    for k in prange(len(r)):
        a, b = r[k], s[k]
        radius_r, radius_s = 0.0, 0.0
        for v in range(4):
            radius_r = max(radius_r, _distance(quads[a, v], centroid[a]))
            radius_s = max(radius_s, _distance(quads[b, v], centroid[b]))
        w0, w1, w2 = centroid[b, 0] - centroid[a, 0], centroid[b, 1] - centroid[a, 1], centroid[b, 2] - centroid[a, 2]
        dist = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
        d = max(abs(w0 * normal[a, 0] + w1 * normal[a, 1] + w2 * normal[a, 2]), dist - radius_r)
        lo_s, hi_s = _heights(quads[b], centroid[a], normal[a])  # s's vertices over r's plane
        lo_r, hi_r = _heights(quads[a], centroid[b], normal[b])
        # the elements are at least this far apart: their spheres' gap, or the lowest vertex of
        # one above the other's plane (a big wall's sphere holds the cubes in front of it)
        gap = max(dist - radius_r - radius_s, max(lo_s, lo_r))
        apart = gap > 0.0
        g = gap if apart else 1.0
        cos_r, cos_s = min(1.0, max(hi_s, 0.0) / g), min(1.0, max(hi_r, 0.0) / g)
        cone = (radius_s / max(d, radius_s)) ** 2 * min(1.0, 2.0 * cos_r)
        bound = min(cone, area[b] * cos_r * cos_s / (np.pi * g ** 2))
        facing = normal[a, 0] * normal[b, 0] + normal[a, 1] * normal[b, 1] + normal[a, 2] * normal[b, 2] < -0.5
        small = radius_s < near_smaller * radius_r
        # a source as large as the receiver has a peak as wide as the 3x3 points' spacing: they see
        # it, unless it faces r closer than that spacing (a cabinet's back 1 cm from a wall: the
        # points of a triangle of its back all missed the wall's element over its apex, 0.0005 for
        # 0.028); neighbours on a curved surface face the same way, and are left to the points
        use = apart and splittable[a] and (small or (facing and g < near_gap * radius_r))
        if near_only:
            use = use and dist - radius_s < near_relative * radius_r
        if use:
            out[k] = bound
        elif not apart and splittable[a] and small:
            # a small source touching r (a wall element at the foot of a long floor strip) is seen
            # from r's points next to it at up to a half, and the 3x3 points may all be far from
            # it: the strips of a 1 cm gap between a shelf and a wall got 0.006 of the wall for 0.5
            out[k] = touching_bound
        else:
            out[k] = 0.0


@njit(cache=True, inline="always")
def _heights(quad, point, n):
    """(lowest, highest) height of the quad's vertices over the plane through point with unit normal n."""
    lo, hi = np.inf, -np.inf
    for v in range(4):
        h = (quad[v, 0] - point[0]) * n[0] + (quad[v, 1] - point[1]) * n[1] + (quad[v, 2] - point[2]) * n[2]
        lo, hi = min(lo, h), max(hi, h)
    return lo, hi


@njit(cache=True, parallel=True)
def source_weights(rho, root, B, r, s):
    """(m,) max over channels of rho[root[r[k]]] * B[s[k]]: the radiosity link k's error bound
    scales with (the numpy expression's (m, channels) temporaries were 2% of a lit room's solve)."""
    out = np.empty(len(r))
    for k in prange(len(r)):
        a, b = root[r[k]], s[k]
        w = rho[a, 0] * B[b, 0]
        for c in range(1, B.shape[1]):
            w = max(w, rho[a, c] * B[b, c])
        out[k] = w
    return out

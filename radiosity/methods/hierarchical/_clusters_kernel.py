"""numba kernels of the cluster links: their error bounds, their representative patches and how
their receivers share them out (see :mod:`._clusters` for what each computes and why).

Each works one link (or node) at a time over its node's patches, in tree order, without the
(link, pair) and (link, patch) temporaries of the numpy forms they replace: on a 50,000-face
furnace sphere those took 80% of the solve's time (the bounds 19.5%, the estimates 18%, the
facing patches 16%, the shares 26%), and their temporaries were the million-face sphere's peak.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

_HALF_PI = math.pi / 2
# Values per thread below which spread_links runs on one thread (a private copy of y per
# thread costs a pass over it).
PARALLEL_VALUES = 65_536


@njit(cache=True, inline="always")
def _angle(a0, a1, a2, b0, b1, b2):
    """Angle between two unit vectors, radians."""
    return math.acos(min(1.0, max(-1.0, a0 * b0 + a1 * b1 + a2 * b2)))


@njit(cache=True, parallel=True)
def link_bounds(r, s, centre, radius, axis, cone, area, rho, B, out):
    """out[k] = bound of the link r[k] gathers from s[k]: ``max_c(rho_r,c B_s,c)`` times the
    smaller of ``A_s cos_r cos_s / (pi gap^2)`` (1 where the spheres overlap) and the
    orientation bound ``sin^2 w`` (see ClusterTree.bound)."""
    for k in prange(len(r)):
        i, j = r[k], s[k]
        factor = _factor_bound(centre[i], radius[i], axis[i], cone[i], centre[j], radius[j], axis[j], cone[j],
                               area[j])
        power = 0.0
        for c in range(rho.shape[1]):
            power = max(power, rho[i, c] * B[j, c])
        out[k] = power * factor


@njit(cache=True, parallel=True)
def element_bounds(centroid, extent, normal, rho_r, s, centre, radius, axis, cone, area, B, out):
    """out[k] = :func:`link_bounds`' bound of a flat element gathering from node s[k]: a node
    with centre ``centroid[k]``, radius ``extent[k]``, axis ``normal[k]``, no cone and
    reflectance ``rho_r[k]``."""
    for k in prange(len(s)):
        j = s[k]
        factor = _factor_bound(centroid[k], extent[k], normal[k], 0.0, centre[j], radius[j], axis[j], cone[j],
                               area[j])
        power = 0.0
        for c in range(rho_r.shape[1]):
            power = max(power, rho_r[k, c] * B[j, c])
        out[k] = power * factor


@njit(cache=True, parallel=True)
def element_source_bounds(r, centroid, extent, normal, area_s, B_s, centre, radius, axis, cone, rho, out):
    """out[k] = :func:`link_bounds`' bound of node r[k] gathering from a flat element: a node
    with centre ``centroid[k]``, radius ``extent[k]``, axis ``normal[k]``, no cone, area
    ``area_s[k]`` and radiosity ``B_s[k]``."""
    for k in prange(len(r)):
        i = r[k]
        factor = _factor_bound(centre[i], radius[i], axis[i], cone[i], centroid[k], extent[k], normal[k], 0.0,
                               area_s[k])
        power = 0.0
        for c in range(rho.shape[1]):
            power = max(power, rho[i, c] * B_s[k, c])
        out[k] = power * factor


@njit(cache=True, inline="always")
def _factor_bound(ci, ri, ai, cone_i, cj, rj, aj, cone_j, area_j):
    """The factor part of :func:`link_bounds` for receiver sphere (ci, ri, normal cone ai,
    cone_i) and source (cj, rj, aj, cone_j) of area ``area_j``."""
    w0, w1, w2 = cj[0] - ci[0], cj[1] - ci[1], cj[2] - ci[2]
    dist = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    gap = dist - ri - rj
    if dist > 0.0:
        w0, w1, w2 = w0 / dist, w1 / dist, w2 / dist
    factor = 1.0
    if gap > 0.0:
        spread = math.asin(min(1.0, max(0.0, (ri + rj) / dist)))
        tilt_r = _angle(ai[0], ai[1], ai[2], w0, w1, w2)
        tilt_s = _angle(aj[0], aj[1], aj[2], -w0, -w1, -w2)
        cos_r = math.cos(min(_HALF_PI, max(0.0, tilt_r - cone_i - spread)))
        cos_s = math.cos(min(_HALF_PI, max(0.0, tilt_s - cone_j - spread)))
        factor = min(1.0, area_j * cos_r * cos_s / (math.pi * gap * gap))
    w = _angle(ai[0], ai[1], ai[2], aj[0], aj[1], aj[2]) + cone_i + cone_j
    if w < _HALF_PI:
        factor = min(factor, math.sin(w) ** 2)
    return factor


@njit(cache=True, parallel=True)
def facing_patches(lo, hi, order, normals, areas, centre, toward, pick):
    """pick[k] = the patch p of order[lo[k]:hi[k]] with the largest ``A_p n_p . (toward[k] -
    centre[k])`` (the last of equals), where that is positive; pick[k] is left as it is if none is."""
    for k in prange(len(lo)):
        u0, u1, u2 = toward[k, 0] - centre[k, 0], toward[k, 1] - centre[k, 1], toward[k, 2] - centre[k, 2]
        best, arg = -np.inf, -1
        for t in range(lo[k], hi[k]):
            p = order[t]
            score = areas[p] * (normals[p, 0] * u0 + normals[p, 1] * u1 + normals[p, 2] * u2)
            if score >= best:
                best, arg = score, p
        if best > 0.0:
            pick[k] = arg


# A cone this far (radians) from straddling u's plane is on one side of it: far above the
# arccos rounding of the cones and of the tilt.
PROJECTED_MARGIN = 1e-6


@njit(cache=True, inline="always")
def _projected(k, u0, u1, u2, lo, hi, order, normals, areas, axis, cone, area_vector):
    """Sum over node k's patches of ``A_i max(0, n_i . u)``, u unit (or zero: 0).

    Where the normal cone lies wholly on one side of u's plane no term is clipped: the sum is
    the node's area vector dotted with u (or 0). Only nodes whose cone straddles the plane are
    summed patch by patch; on a 50k-face sphere those sums were 29% of the solve's time."""
    tilt = _angle(axis[k, 0], axis[k, 1], axis[k, 2], u0, u1, u2)
    if tilt + cone[k] <= _HALF_PI - PROJECTED_MARGIN:
        return area_vector[k, 0] * u0 + area_vector[k, 1] * u1 + area_vector[k, 2] * u2
    if tilt - cone[k] >= _HALF_PI + PROJECTED_MARGIN:
        return 0.0
    total = 0.0
    for t in range(lo[k], hi[k]):
        p = order[t]
        c = normals[p, 0] * u0 + normals[p, 1] * u1 + normals[p, 2] * u2
        if c > 0.0:
            total += areas[p] * c
    return total


@njit(cache=True, inline="always")
def _below(node, depth, child, patch, out):
    """The nodes ``depth`` levels below ``node`` into out (a patch node is its own child);
    returns how many."""
    out[0] = node
    n = 1
    for _ in range(depth):
        m = n
        for t in range(n - 1, -1, -1):  # a node's first child takes its place, the second goes last
            x = out[t]
            if patch[x] < 0:
                out[m], m = child[x, 1], m + 1
                out[t] = child[x, 0]
        n = m
    return n


@njit(cache=True, inline="always")
def _direction(p, q):
    """(u0, u1, u2, d^2): the unit vector from point p to point q and their squared distance
    (u zero where they coincide)."""
    u0, u1, u2 = q[0] - p[0], q[1] - p[1], q[2] - p[2]
    d2 = u0 * u0 + u1 * u1 + u2 * u2
    if d2 <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    d = math.sqrt(d2)
    return u0 / d, u1 / d, u2 / d, d2


@njit(cache=True, parallel=True)
def link_estimates(r, s, depth, child, patch, lo, hi, order, normals, areas, centre, axis, cone, area,
                   area_vector, out):
    """out[k] = isotropic factor of the link r[k] gathers from s[k], summed over the pairs of
    nodes ``depth`` levels below each end (see ClusterTree.estimates)."""
    for k in prange(len(r)):
        ends_r, ends_s = np.empty(2 ** depth, np.int64), np.empty(2 ** depth, np.int64)
        n_r = _below(r[k], depth, child, patch, ends_r)
        n_s = _below(s[k], depth, child, patch, ends_s)
        total = 0.0
        for i in range(n_r):
            a = ends_r[i]
            for j in range(n_s):
                b = ends_s[j]
                u0, u1, u2, d2 = _direction(centre[a], centre[b])
                if d2 <= 0.0:
                    continue
                power = (_projected(a, u0, u1, u2, lo, hi, order, normals, areas, axis, cone, area_vector)
                         * _projected(b, -u0, -u1, -u2, lo, hi, order, normals, areas, axis, cone, area_vector)
                         / (math.pi * d2))
                total += area[a] * min(power / max(area[a], 1e-300), 1.0)
        out[k] = min(total / max(area[r[k]], 1e-300), 1.0)


@njit(cache=True, parallel=True)
def element_estimates(centroid, normal, s, depth, child, patch, lo, hi, order, centroids, normals, areas, centre,
                      axis, cone, area_vector, out):
    """out[k] = isotropic factor from the point ``centroid[k]`` (facing ``normal[k]``) to node
    s[k], summed over the nodes b ``depth`` levels below s[k], at most 1 (see
    ClusterTree.element_estimates): ``P_b(-u) max(0, n . u) / (pi d^2)`` (``u``, ``d``: from the
    point to b's centre) where b's normal cone lies on one side of u's plane, and patch by patch
    from each patch's own centroid where it straddles it."""
    for k in prange(len(s)):
        ends = np.empty(2 ** depth, np.int64)
        n_s = _below(s[k], depth, child, patch, ends)
        total = 0.0
        for j in range(n_s):
            b = ends[j]
            u0, u1, u2, d2 = _direction(centroid[k], centre[b])
            if d2 <= 0.0:
                continue
            tilt = _angle(axis[b, 0], axis[b, 1], axis[b, 2], -u0, -u1, -u2)
            if tilt + cone[b] <= _HALF_PI - PROJECTED_MARGIN:
                cos = normal[k, 0] * u0 + normal[k, 1] * u1 + normal[k, 2] * u2
                if cos > 0.0:
                    total += cos * -(area_vector[b, 0] * u0 + area_vector[b, 1] * u1
                                     + area_vector[b, 2] * u2) / (math.pi * d2)
            elif tilt - cone[b] < _HALF_PI + PROJECTED_MARGIN:
                total += _point_to_patches(centroid[k], normal[k], lo[b], hi[b], order, centroids, normals, areas)
        out[k] = min(total, 1.0)


@njit(cache=True, inline="always")
def _point_to_patches(point, point_normal, lo, hi, order, centroids, normals, areas):
    """``sum_p A_p max(0, n_p . w) max(0, -n . w) / (pi |w|^4)`` over patches order[lo:hi]
    (``w`` from the point to the patch's centroid): each patch's own direction. A node's centre
    lies inside a curved surface, closer to the point than its patches' planes, so the
    centre's direction tilts every patch toward the point: where the node straddles the
    horizon that took a reverse link of 460 sphere triangles to 1.7x its exact mean, and two
    triangles' rows of K to 1.15."""
    total = 0.0
    for t in range(lo, hi):
        p = order[t]
        w0, w1, w2 = centroids[p, 0] - point[0], centroids[p, 1] - point[1], centroids[p, 2] - point[2]
        cos_s = point_normal[0] * w0 + point_normal[1] * w1 + point_normal[2] * w2
        cos_p = -(normals[p, 0] * w0 + normals[p, 1] * w1 + normals[p, 2] * w2)
        if cos_s > 0.0 and cos_p > 0.0:
            d2 = w0 * w0 + w1 * w1 + w2 * w2
            total += areas[p] * cos_p * cos_s / (math.pi * d2 * d2)
    return total


@njit(cache=True, parallel=True)
def receiver_shares(r, s, depth, child, patch, lo, hi, order, centroids, normals, areas, area, centre, axis,
                    cone, area_vector, scale, start, share):
    """share[start[k] + t] for patch order[lo[r[k]] + t] of link k's receiver: its weight
    ``sum_b P_b(-u) max(0, n . w) / |w|^3`` over the nodes b ``depth`` levels below s[k] (``u``
    from r's centre to b's, ``w`` from the patch's centroid to b's centre), scaled so that the
    area mean over r is 1 (all ones where no patch faces a source; see
    ClusterTree.oriented_shares), times scale[k]."""
    for k in prange(len(r)):
        ends = np.empty(2 ** depth, np.int64)
        power = np.zeros(2 ** depth)
        n_s = _below(s[k], depth, child, patch, ends)
        node = r[k]
        for j in range(n_s):
            b = ends[j]
            u0, u1, u2 = centre[b, 0] - centre[node, 0], centre[b, 1] - centre[node, 1], centre[b, 2] - centre[node, 2]
            d = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
            if d > 0.0:
                power[j] = _projected(b, -u0 / d, -u1 / d, -u2 / d, lo, hi, order, normals, areas, axis, cone,
                                      area_vector)
        total = 0.0
        for t in range(hi[node] - lo[node]):
            p = order[lo[node] + t]
            weight = 0.0
            for j in range(n_s):
                b = ends[j]
                w0, w1, w2 = centre[b, 0] - centroids[p, 0], centre[b, 1] - centroids[p, 1], \
                    centre[b, 2] - centroids[p, 2]
                d2 = w0 * w0 + w1 * w1 + w2 * w2
                if d2 > 0.0:
                    cos = max(normals[p, 0] * w0 + normals[p, 1] * w1 + normals[p, 2] * w2, 0.0) / math.sqrt(d2)
                    weight += power[j] * cos / d2
            share[start[k] + t] = weight
            total += weight * areas[p]
        mean = total / max(area[node], 1e-300)
        for t in range(hi[node] - lo[node]):
            share[start[k] + t] = scale[k] * (share[start[k] + t] / mean if mean > 0.0 else 1.0)


@njit(cache=True, parallel=True)
def point_receiver_shares(r, point, point_normal, lo, hi, order, centroids, normals, areas, area, scale, start,
                          share):
    """share[start[k] + t] for patch order[lo[r[k]] + t] of link k's receiver, from a flat
    source at ``point[k]`` facing ``point_normal[k]``: ``max(0, n . w) max(0, -n_s . w) /
    |w|^4`` (``w`` from the patch's centroid to the point), scaled so that the area mean over r
    is 1 (all ones where no patch faces the source), times scale[k]."""
    for k in prange(len(r)):
        node = r[k]
        total = 0.0
        for t in range(hi[node] - lo[node]):
            p = order[lo[node] + t]
            w0, w1, w2 = point[k, 0] - centroids[p, 0], point[k, 1] - centroids[p, 1], point[k, 2] - centroids[p, 2]
            d2 = w0 * w0 + w1 * w1 + w2 * w2
            weight = 0.0
            if d2 > 0.0:
                cos_r = normals[p, 0] * w0 + normals[p, 1] * w1 + normals[p, 2] * w2
                cos_s = -(point_normal[k, 0] * w0 + point_normal[k, 1] * w1 + point_normal[k, 2] * w2)
                if cos_r > 0.0 and cos_s > 0.0:
                    weight = cos_r * cos_s / (d2 * d2)
            share[start[k] + t] = weight
            total += weight * areas[p]
        mean = total / max(area[node], 1e-300)
        for t in range(hi[node] - lo[node]):
            share[start[k] + t] = scale[k] * (share[start[k] + t] / mean if mean > 0.0 else 1.0)


@njit(cache=True)
def _spread_range(r, column, lo, hi, order, start, value, x, y, first, last):
    for k in range(first, last):
        source = x[column[k]]
        if source == 0.0:
            continue
        node, base = r[k], start[k]
        for t in range(hi[node] - lo[node]):
            y[order[lo[node] + t]] += value[base + t] * source


@njit(cache=True, parallel=True)
def spread_links(r, column, lo, hi, order, start, value, x, y, threads):
    """y[order[lo[r[k]] + t]] += value[start[k] + t] * x[column[k]] for every link k and
    patch t of its receiver (the oriented cluster links' part of G @ x). Links scatter into the
    same patches, so each of ``threads`` threads takes a run of links holding about as many values
    as the others' into its own copy of y (the first thread into y), and the copies are added
    after: 97 -> 58-62 ms on two cores where 200,000 links spread 20 M values. (The element
    links' scatter, gather_children, and the sparse products gained nothing that way: they are
    bound by memory.)"""
    n = len(r)
    parts = max(1, min(threads, len(value) // PARALLEL_VALUES))
    bounds = np.searchsorted(start, np.arange(parts + 1) * len(value) // parts)
    bounds[0], bounds[parts] = 0, n
    extra = np.zeros((parts - 1, len(y)))
    for p in prange(parts):
        if p == 0:
            _spread_range(r, column, lo, hi, order, start, value, x, y, bounds[p], bounds[p + 1])
        else:
            _spread_range(r, column, lo, hi, order, start, value, x, extra[p - 1], bounds[p], bounds[p + 1])
    add_rows(extra, y)


@njit(cache=True, parallel=True)
def add_rows(extra, y):
    """y += the sum of the rows of ``extra``."""
    for i in prange(len(y)):
        for p in range(extra.shape[0]):
            y[i] += extra[p, i]


@njit(cache=True, parallel=True)
def collect_links(r, column, lo, hi, order, start, value, y, out):
    """out[k] = sum_t value[start[k] + t] * y[order[lo[r[k]] + t]]: what link k's column
    takes of G.T @ y (to be added up by column)."""
    for k in prange(len(r)):
        node, base = r[k], start[k]
        total = 0.0
        for t in range(hi[node] - lo[node]):
            total += value[base + t] * y[order[lo[node] + t]]
        out[k] = total

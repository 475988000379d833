"""Closed objects: which occluders a pair can do without.

**The rule.** Let an object's patches form a closed, consistently oriented surface S (every
point off S has an integer winding number w with respect to S). Crossing S against its normal
(from its front side to its back) raises w by one, crossing along it lowers w by one. Take a
segment from a source point y to a receiver point x with w(y) = w(x): its crossings sum to
zero, so if it crosses S at all it crosses some face from front to back, that is, a face whose
plane has y strictly in front. Hence, for a pair (i receives from j) whose two patches have one
and the same winding number with respect to S, every segment that S blocks is blocked by a face
of S with part of the source j in front of its plane: the faces of S whose plane has all of j
behind it (or in it) can be dropped from the pair's occluders without changing any visible set.
(Which end plays y only has to be the same for all of S's faces in one pair, so each pair takes,
per object, the end that drops more faces; the fill shares a pair's list with its mirror, which
is fine for that reason.) Where the windings differ (a patch
inside a closed box, the other outside) every segment crosses S an odd number of times and
nothing is dropped.

A patch of S itself is seen only from its front side, so its winding is taken just in front of
it, like every patch's: at its centroid and its vertices pulled 1% towards the centroid, each
offset ``WINDING_OFFSET_REL`` of the scene size along its normal. A patch whose points disagree
(it crosses S) gets no label and keeps all its occluders; an object with a fractional winding
number at any of these points or at 8 probes in its box (open, or touched by a coincident face)
is not culled. A patch crossing S with
all five points on one side is not detected (interpenetrating geometry).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..geometry import centroids_and_areas
from ._constants import WINDING_BUDGET, WINDING_OFFSET_REL, WINDING_TOL

__all__ = ["winding_labels", "closed_cull"]

NO_LABEL = np.iinfo(np.int16).min


def _triangles(quads: np.ndarray) -> np.ndarray:
    """(2m, 3, 3) non-degenerate triangles of patches (m, 4, 3) (fans 0-1-2, 0-2-3)."""
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    area = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    return tris[area > 0]


def winding_numbers(points: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(p,) winding numbers of points (p, 3) with respect to triangles (t, 3, 3).

    Van Oosterom and Strackee's solid angle per triangle, summed and divided by 4 pi (compiled:
    the numpy version's (p, t) temporaries cost seconds on a room cut into hundreds of patches).
    """
    return _winding_kernel(np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(tris, dtype=np.float64))


@njit(cache=True, parallel=True)
def _winding_kernel(points, tris):
    out = np.zeros(len(points))
    for p in prange(len(points)):
        total = 0.0
        for t in range(len(tris)):
            a0, a1, a2 = tris[t, 0, 0] - points[p, 0], tris[t, 0, 1] - points[p, 1], tris[t, 0, 2] - points[p, 2]
            b0, b1, b2 = tris[t, 1, 0] - points[p, 0], tris[t, 1, 1] - points[p, 1], tris[t, 1, 2] - points[p, 2]
            c0, c1, c2 = tris[t, 2, 0] - points[p, 0], tris[t, 2, 1] - points[p, 1], tris[t, 2, 2] - points[p, 2]
            la = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
            lb = math.sqrt(b0 * b0 + b1 * b1 + b2 * b2)
            lc = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
            det = a0 * (b1 * c2 - b2 * c1) + a1 * (b2 * c0 - b0 * c2) + a2 * (b0 * c1 - b1 * c0)
            den = (la * lb * lc + (a0 * b0 + a1 * b1 + a2 * b2) * lc + (a0 * c0 + a1 * c1 + a2 * c2) * lb
                   + (b0 * c0 + b1 * c1 + b2 * c2) * la)
            total += math.atan2(det, den)
        out[p] = total / (2.0 * math.pi)
    return out


def _sample_points(quads: np.ndarray, normals: np.ndarray, scale: float) -> np.ndarray:
    """(n, 5, 3): each patch's centroid and vertices pulled 1% inwards, just in front of it."""
    centroid, _ = centroids_and_areas(quads)
    pts = np.concatenate([centroid[:, None, :], quads + 0.01 * (centroid[:, None, :] - quads)], axis=1)
    return pts + WINDING_OFFSET_REL * scale * normals[:, None, :]


def _probes(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """8 fixed points of a box (Halton fractions), to tell open surfaces from closed ones."""
    f = np.array([[0.5, 1 / 3, 0.2], [0.25, 2 / 3, 0.4], [0.75, 1 / 9, 0.6], [0.125, 4 / 9, 0.8],
                  [0.625, 7 / 9, 0.04], [0.375, 2 / 9, 0.24], [0.875, 5 / 9, 0.44], [1 / 16, 8 / 9, 0.64]])
    return lo + f * (hi - lo)


def _pierces(a: np.ndarray, b: np.ndarray, poly: np.ndarray, normal: np.ndarray, tol: float) -> np.ndarray:
    """(t,) whether segment a-b (t, 3) crosses the convex polygon (t, 4, 3) strictly inside."""
    da = np.einsum("tc,tc->t", a - poly[:, 0], normal)
    db = np.einsum("tc,tc->t", b - poly[:, 0], normal)
    cross = ((da > tol) & (db < -tol)) | ((da < -tol) & (db > tol))
    x = a + (da / np.where(cross, da - db, 1.0))[:, None] * (b - a)
    edge = np.roll(poly, -1, axis=1) - poly
    side = np.einsum("tkc,tc->tk", np.cross(edge, x[:, None, :] - poly), normal)
    length = np.linalg.norm(edge, axis=2)
    return cross & ((side > tol * length) | (length <= tol)).all(axis=1)


def _crossing(quads: np.ndarray, normals: np.ndarray, faces: np.ndarray, patches: np.ndarray, scale: float
              ) -> np.ndarray:
    """The patches (indices) that cut through one of ``faces`` (transversally, not touching).

    Two convex polygons in different planes meet along a segment whose ends are where an edge of
    one crosses the other, so testing both polygons' edges against the other polygon suffices.
    """
    if not len(patches) or not len(faces):
        return np.zeros(0, np.int64)
    tol = 1e-9 * scale
    lo, hi = quads.min(axis=1), quads.max(axis=1)
    meet = ((lo[patches, None] <= hi[None, faces] + tol) & (hi[patches, None] >= lo[None, faces] - tol)).all(axis=2)
    p, f = np.nonzero(meet)
    p, f = patches[p], faces[f]
    hit = np.zeros(len(p), bool)
    for k in range(4):
        for one, other in ((p, f), (f, p)):  # edge k of one against the other polygon
            a, b = quads[one, k], quads[one, (k + 1) % 4]
            hit |= _pierces(a, b, quads[other], normals[other], tol)
    return np.unique(p[hit])


def winding_labels(quads: np.ndarray, normals: np.ndarray, groups: np.ndarray, scale: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Closed objects and each patch's winding number with respect to each of them.

    Returns
    -------
    column : (n_groups,) int
        Column of each object in ``labels``, -1 where it is not closed (or too costly to tell).
    labels : (n, c) int16
        Winding number of patch n with respect to closed object c, ``NO_LABEL`` where the
        patch's points disagree or lie on the surface.
    """
    groups = np.asarray(groups)
    n_groups = int(groups.max()) + 1 if len(groups) else 0
    column = np.full(n_groups, -1, np.int64)
    labels = []
    # an object of one patch has at most 2 triangles, too few to close (below): skipping those
    # first keeps scenes of single-patch objects (View3D models: one object per surface) from a
    # Python pass over every object (0.2-0.3 s on the blocked plates of bench_fill), and from
    # the sample points when no object has two patches
    sizes = np.bincount(groups, minlength=n_groups) if len(groups) else np.zeros(0, np.int64)
    several = np.flatnonzero(sizes >= 2)
    if len(several):
        pts = _sample_points(quads, normals, scale)
        plo, phi = pts.min(axis=1), pts.max(axis=1)
    for g in several:
        mine = groups == g
        tris = _triangles(quads[mine])
        if len(tris) < 4:
            continue
        lo, hi = tris.reshape(-1, 3).min(axis=0), tris.reshape(-1, 3).max(axis=0)
        near = np.flatnonzero(((plo <= hi) & (phi >= lo)).all(axis=1))  # outside the box: w = 0
        if (len(near) * 5 + 8) * len(tris) > WINDING_BUDGET:
            continue
        w = winding_numbers(np.concatenate([_probes(lo, hi), pts[near].reshape(-1, 3)]), tris)
        r = np.rint(w)
        if np.abs(w - r).max() > WINDING_TOL:
            continue  # an open surface (or a point on it, from a coincident face): no culling
        r = r[8:].reshape(-1, 5)
        label = np.zeros(len(quads), np.int16)
        label[near] = np.where((r == r[:, :1]).all(axis=1), r[:, 0], NO_LABEL).astype(np.int16)
        label[_crossing(quads, normals, np.flatnonzero(mine), near[~mine[near]], scale)] = NO_LABEL
        column[g] = len(labels)
        labels.append(label)
    table = np.stack(labels, axis=1) if labels else np.zeros((len(quads), 0), np.int16)
    return column, table


def closed_cull(quads: np.ndarray, i: np.ndarray, j: np.ndarray, rows: np.ndarray, occ: np.ndarray,
                occluders, column: np.ndarray, labels: np.ndarray, tol: float) -> np.ndarray:
    """(t,) bool: the (pair, occluder) rows to keep (see the module's rule).

    ``rows`` index the pairs ``(i, j)`` (i receives from j), ``occ`` the occluders.
    """
    keep = np.ones(len(rows), bool)
    if not len(rows) or not labels.shape[1]:
        return keep
    col = column[occluders.group[occ]]
    front = occluders.front[occ]
    cand = np.flatnonzero((col >= 0) & (front != 0))
    if not len(cand):
        return keep
    c, pi, pj = col[cand], i[rows[cand]], j[rows[cand]]
    li, lj = labels[pi, c], labels[pj, c]
    same = (li == lj) & (li != NO_LABEL)
    cand, c, pi, pj = cand[same], c[same], pi[same], pj[same]
    # either end may play the source, as long as it is the same one for all of S's faces in the
    # pair: take the one that drops more of them
    by_i, by_j = _behind_kernel(np.ascontiguousarray(quads, dtype=np.float64), pi.astype(np.int64, copy=False),
                                pj.astype(np.int64, copy=False), occ[cand].astype(np.int64, copy=False),
                                np.ascontiguousarray(occluders.center, dtype=np.float64),
                                np.ascontiguousarray(occluders.normal, dtype=np.float64),
                                np.ascontiguousarray(front[cand], dtype=np.float64), float(tol))
    _, group = np.unique(rows[cand] * labels.shape[1] + c, return_inverse=True)
    use_i = np.bincount(group, by_i) > np.bincount(group, by_j)
    keep[cand[np.where(use_i[group], by_i, by_j)]] = False
    return keep


@njit(cache=True, parallel=True)
def _behind_kernel(quads, pi, pj, k, center, normal, front, tol):
    """(t,) bool twice: all of patch pi[t] (pj[t]) behind face k[t]'s plane, or in it; front[t]
    (+1 or -1) says which side of the plane is its front (compiled: the numpy version's (t, 4, 3)
    temporaries took 5 s of a 1,752-patch furnace's 42)."""
    t = len(k)
    by_i = np.empty(t, np.bool_)
    by_j = np.empty(t, np.bool_)
    for r in prange(t):
        by_i[r] = _all_behind(quads[pi[r]], center[k[r]], normal[k[r]], front[r], tol)
        by_j[r] = _all_behind(quads[pj[r]], center[k[r]], normal[k[r]], front[r], tol)
    return by_i, by_j


@njit(cache=True, inline="always")
def _all_behind(quad, center, normal, front, tol):
    for v in range(quad.shape[0]):
        height = ((quad[v, 0] - center[0]) * normal[0] + (quad[v, 1] - center[1]) * normal[1]
                  + (quad[v, 2] - center[2]) * normal[2])
        if front * height > tol:
            return False
    return True

"""Occluder polygons, their bounding-volume hierarchy, and the exact per-pair classification.

Occluder patches of one object that lie in one plane and tile a convex polygon are merged into
that polygon (a cube's face cut into 64 patches is one occluder). Each (pair, occluder) row is
then classified exactly, before any ray:

* free: the pair lies on one side of the occluder's plane (or in it), or the bundle of the
  16 vertex-to-vertex segments crosses the plane outside the polygon (separated by one of its
  edges). The crossing points of all segments between two convex patches lie in the convex hull
  of the crossing points of those 16 segments, because a central projection maps a convex
  patch to the convex hull of its projected vertices.
* full: all 16 crossing points lie inside the convex polygon or on its edges, so every segment
  crosses it (those through an edge are a set of measure zero).
* maybe: anything else (a patch straddles the plane, or the bundle meets an edge).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from ..geometry import centroids_and_areas, vector_areas
from ._constants import BVH_LEAF, CHUNK_TRIPLES, CROSS_MERGE_MAX, MAX_OCCLUDER_VERTICES, MERGE_AREA_REL, PLANE_REL

__all__ = ["Occluders", "build_occluders", "FREE", "FULL", "MAYBE"]

FREE, FULL, MAYBE = 0, 1, 2


@dataclass(frozen=True)
class Occluders:
    """Convex occluder polygons as a struct of arrays, with a BVH over their boxes."""

    polys: np.ndarray  # (k, m, 3) float, padded by repeating the last vertex
    normal: np.ndarray  # (k, 3) unit normals
    center: np.ndarray  # (k, 3) vertex mean (inside the convex polygon)
    inward: np.ndarray  # (k, m, 3) in-plane inward normals of the edges (0 for padding edges)
    lo: np.ndarray  # (k, 3)
    hi: np.ndarray  # (k, 3)
    # BVH: node boxes, children (-1 for leaves), leaf ranges into ``order``
    node_lo: np.ndarray
    node_hi: np.ndarray
    node_left: np.ndarray
    node_right: np.ndarray
    node_start: np.ndarray
    node_count: np.ndarray
    order: np.ndarray
    # the object of each occluder, and +1 / -1 where its patches' front side is along / against
    # ``normal`` (0: a merged polygon whose patches face both ways); for closed-object culling
    group: np.ndarray | None = None
    front: np.ndarray | None = None

    @property
    def n_occluders(self) -> int:
        return len(self.polys)


def _plane_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(normal, u)


def _merge_group(quads: np.ndarray, normal: np.ndarray, area: float) -> np.ndarray | None:
    """Convex polygon (k, 3) tiled by coplanar patches, or None if they do not tile one."""
    u, w = _plane_basis(normal)
    pts = quads.reshape(-1, 3)
    origin = pts.mean(axis=0)
    flat = np.column_stack([(pts - origin) @ u, (pts - origin) @ w])
    try:
        hull = ConvexHull(flat)
    except (QhullError, ValueError):
        return None
    if len(hull.vertices) > MAX_OCCLUDER_VERTICES or abs(hull.volume - area) > MERGE_AREA_REL * area:
        return None
    ring = flat[hull.vertices]  # counter-clockwise in (u, w)
    depth = float(np.mean((pts - origin) @ normal))
    return origin + ring[:, :1] * u + ring[:, 1:] * w + depth * normal


def _merge_across_objects(polys: list[np.ndarray], members_of: list[np.ndarray], planes: np.ndarray, tol: float
                          ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Merge coplanar polygons of different objects, two at a time, wherever two tile a convex one.

    A thermal model's wall is often several surfaces (in View3D's 398-surface hall one wall is
    four: two spans, each cut at a ledge's height). Each alone hid part of what the wall hides,
    so a pair behind the wall was partly occluded by all, fully by none: its adaptive squares
    split to the deepest level along the seams (103 s a pair), and light leaked through them.
    Planes holding more than ``CROSS_MERGE_MAX`` polygons are left as they are (every two are
    tried). The polygons keep the input's order where nothing merges.
    """
    if len(polys) < 2:
        return polys, members_of
    _, plane_of = np.unique(planes, axis=0, return_inverse=True)
    plane_of = plane_of.ravel()
    out = []  # (index of the first polygon, polygon, patches)
    for members in np.split(np.argsort(plane_of, kind="stable"), np.cumsum(np.bincount(plane_of))[:-1]):
        ring = [(int(m), polys[m], members_of[m]) for m in members]
        if 1 < len(ring) <= CROSS_MERGE_MAX:
            ring = _merge_plane(ring, tol)
        out.extend(ring)
    out.sort(key=lambda t: t[0])
    return [p for _, p, _ in out], [m for _, _, m in out]


def _merge_plane(ring: list[tuple[int, np.ndarray, np.ndarray]], tol: float
                 ) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """(first index, polygon, patches) of one plane, merged two at a time while two tile a convex
    polygon; ``tol``: how far apart two polygons' boxes may be and still touch."""
    vector = [0.5 * np.cross(p, np.roll(p, -1, axis=0)).sum(axis=0) for _, p, _ in ring]
    area = [float(np.linalg.norm(v)) for v in vector]
    k = int(np.argmax(area))
    if area[k] == 0.0:
        return ring
    normal = vector[k] / area[k]
    box = [(p.min(axis=0), p.max(axis=0)) for _, p, _ in ring]

    def touch(a, b):  # two polygons that tile a convex one share an edge: their boxes meet
        return bool((box[a][0] <= box[b][1] + tol).all() and (box[b][0] <= box[a][1] + tol).all())

    while True:
        pair = next(((a, b, both) for a in range(len(ring)) for b in range(a + 1, len(ring))
                     if touch(a, b) and (both := _merge_group(np.concatenate([ring[a][1], ring[b][1]]), normal,
                                                              area[a] + area[b])) is not None), None)
        if pair is None:
            return ring
        a, b, both = pair
        ring[a] = (ring[a][0], both, np.concatenate([ring[a][2], ring[b][2]]))
        box[a] = (both.min(axis=0), both.max(axis=0))
        area[a] += area[b]
        del ring[b], area[b], box[b]


def _pad(polys: list[np.ndarray]) -> np.ndarray:
    m = max(len(p) for p in polys)
    out = np.empty((len(polys), m, 3))
    for k, p in enumerate(polys):
        out[k, :len(p)] = p
        out[k, len(p):] = p[-1]
    return out


def _dedupe(quad: np.ndarray) -> np.ndarray:
    keep = np.ones(len(quad), bool)
    keep[1:] = np.any(quad[1:] != quad[:-1], axis=1)
    keep[-1] &= np.any(quad[-1] != quad[0])
    return quad[keep]


def build_occluders(quads: np.ndarray, normals: np.ndarray, groups: np.ndarray, mask: np.ndarray,
                    scale: float) -> Occluders:
    """Merge the masked patches into convex occluder polygons and build their hierarchy."""
    idx = np.flatnonzero(mask & normals.any(axis=1))
    polys: list[np.ndarray] = []
    members_of: list[np.ndarray] = []  # the patches of each polygon
    planes: list[np.ndarray] = []  # the plane key of each polygon
    if len(idx):
        n = normals[idx]
        # one sign per plane, so both faces of a thin wall fall in the same group
        lead = np.take_along_axis(n, np.argmax(np.abs(n), axis=1)[:, None], axis=1)[:, 0]
        n = n * np.sign(lead)[:, None]
        centroid, area = centroids_and_areas(quads[idx])
        d = np.einsum("pc,pc->p", n, centroid)
        key = np.column_stack([groups[idx], np.round(n * 1e7), np.round(d / (1e-7 * scale))])
        _, inverse = np.unique(key, axis=0, return_inverse=True)
        inverse = inverse.ravel()
        # the members of each plane group, in index order (a scan of all patches per group cost
        # n^2: a 581k-triangle terrain, every triangle its own plane, never got past this loop)
        by_group = np.argsort(inverse, kind="stable")
        ends = np.cumsum(np.bincount(inverse))
        for g in range(len(ends)):
            members = by_group[ends[g - 1] if g else 0:ends[g]]
            merged = None
            if len(members) > 1:
                merged = _merge_group(quads[idx[members]], n[members[0]], float(area[members].sum()))
            if merged is not None:
                polys.append(merged)
                members_of.append(idx[members])
            else:
                polys.extend(_dedupe(quads[p]) for p in idx[members])
                members_of.extend(idx[members, None])
            planes.extend([key[members[0], 1:]] * (1 if merged is not None else len(members)))
        polys, members_of = _merge_across_objects(polys, members_of, np.array(planes), PLANE_REL * scale)
    if not polys:
        z = np.zeros((0, 3))
        zi = np.zeros(0, np.int64)
        return Occluders(np.zeros((0, 3, 3)), z, z, np.zeros((0, 3, 3)), z, z, z, z, zi, zi, zi, zi, zi, zi,
                         np.zeros(0, np.int8))
    P = _pad(polys)
    normal = vector_areas(P)  # half the old unscaled sum: the same bits once normalised
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    center = np.stack([p.mean(axis=0) for p in polys])
    edge = np.roll(P, -1, axis=1) - P
    inward = np.cross(normal[:, None, :], edge)
    length = np.linalg.norm(inward, axis=2, keepdims=True)
    ok = length > 1e-12 * scale
    inward = np.where(ok, inward / np.where(ok, length, 1.0), 0.0)
    sign = np.sign(np.einsum("kmc,kmc->km", center[:, None, :] - P, inward))
    inward *= np.where(sign < 0, -1.0, 1.0)[..., None]
    lo, hi = P.min(axis=1), P.max(axis=1)
    group = np.array([groups[m[0]] for m in members_of], np.int64)
    # a polygon of several objects takes no part in closed-object culling (front 0)
    front = np.array([_front_sign(normals[m] @ nk) if (groups[m] == groups[m[0]]).all() else 0
                      for m, nk in zip(members_of, normal)], np.int8)
    return Occluders(P, normal, center, inward, lo, hi, *_build_bvh(lo, hi), group, front)


def _front_sign(cosines: np.ndarray) -> int:
    """+1 / -1 if every patch of a polygon faces along / against its normal, else 0."""
    if (cosines > 0).all():
        return 1
    return -1 if (cosines < 0).all() else 0


def _build_bvh(lo: np.ndarray, hi: np.ndarray):
    """Median-split BVH over boxes; returns node arrays and the leaf order of the boxes."""
    mid = 0.5 * (lo + hi)
    order = np.arange(len(lo))
    nodes_lo, nodes_hi, left, right, start, count = [], [], [], [], [], []
    stack = [(0, len(lo), -1, False)]
    while stack:
        s, e, parent, is_right = stack.pop()
        node = len(nodes_lo)
        sel = order[s:e]
        nodes_lo.append(lo[sel].min(axis=0))
        nodes_hi.append(hi[sel].max(axis=0))
        left.append(-1)
        right.append(-1)
        start.append(s)
        count.append(e - s)
        if parent >= 0:
            (right if is_right else left)[parent] = node
        if e - s > BVH_LEAF:
            axis = int(np.argmax(np.ptp(mid[sel], axis=0)))
            order[s:e] = sel[np.argsort(mid[sel, axis], kind="stable")]
            half = (s + e) // 2
            stack.append((half, e, node, True))
            stack.append((s, half, node, False))
    return (np.array(nodes_lo), np.array(nodes_hi), np.array(left), np.array(right), np.array(start),
            np.array(count), order)


def candidates(occ: Occluders, lo: np.ndarray, hi: np.ndarray, pad: float) -> tuple[np.ndarray, np.ndarray]:
    """(row, occluder) pairs whose boxes meet: rows given by boxes lo, hi (p, 3)."""
    if occ.n_occluders == 0 or len(lo) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    rows = np.arange(len(lo))
    nodes = np.zeros(len(lo), np.int64)
    out_r, out_k = [], []
    while len(rows):
        meet = ((lo[rows] <= occ.node_hi[nodes] + pad) & (hi[rows] >= occ.node_lo[nodes] - pad)).all(axis=1)
        rows, nodes = rows[meet], nodes[meet]
        leaf = occ.node_left[nodes] < 0
        if leaf.any():
            lr, ln = rows[leaf], nodes[leaf]
            cnt = occ.node_count[ln]
            rep_r = np.repeat(lr, cnt)
            offs = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
            k = occ.order[np.repeat(occ.node_start[ln], cnt) + offs]
            hit = ((lo[rep_r] <= occ.hi[k] + pad) & (hi[rep_r] >= occ.lo[k] - pad)).all(axis=1)
            out_r.append(rep_r[hit])
            out_k.append(k[hit])
        rows, nodes = rows[~leaf], nodes[~leaf]
        rows = np.concatenate([rows, rows])
        nodes = np.concatenate([occ.node_left[nodes], occ.node_right[nodes]])
    r = np.concatenate(out_r) if out_r else np.zeros(0, np.int64)
    k = np.concatenate(out_k) if out_k else np.zeros(0, np.int64)
    return r, k


def classify_rows(occ: Occluders, vi: np.ndarray, vj: np.ndarray, k: np.ndarray, scale: float) -> np.ndarray:
    """(t,) FREE / FULL / MAYBE for rows (patch vertices vi, vj (t, 4, 3); occluder k (t,)).

    Runs the compiled kernel; ``_classify_chunk`` is the same test in numpy (the reference).
    """
    from ._exact_kernel import classify_rows as kernel

    if len(k) == 0:
        return np.zeros(0, np.int8)
    return kernel(np.ascontiguousarray(vi, dtype=np.float64), np.ascontiguousarray(vj, dtype=np.float64),
                  occ.polys, occ.normal, occ.center, occ.inward, np.ascontiguousarray(k, dtype=np.int64),
                  PLANE_REL * scale)


def classify_rows_numpy(occ: Occluders, vi: np.ndarray, vj: np.ndarray, k: np.ndarray, scale: float
                        ) -> np.ndarray:
    """Reference implementation of :func:`classify_rows` in numpy (chunked)."""
    out = np.empty(len(k), np.int8)
    for s in range(0, len(k), CHUNK_TRIPLES):
        e = min(len(k), s + CHUNK_TRIPLES)
        out[s:e] = _classify_chunk(occ, vi[s:e], vj[s:e], k[s:e], scale)
    return out


def _classify_chunk(occ, vi, vj, k, scale):
    tol = PLANE_REL * scale
    n, c = occ.normal[k], occ.center[k]
    si = np.einsum("tvc,tc->tv", vi - c[:, None, :], n)
    sj = np.einsum("tvc,tc->tv", vj - c[:, None, :], n)
    on_plane = (np.abs(si).max(axis=1) <= tol) | (np.abs(sj).max(axis=1) <= tol)
    pos_i, neg_i = si.min(axis=1) >= -tol, si.max(axis=1) <= tol
    pos_j, neg_j = sj.min(axis=1) >= -tol, sj.max(axis=1) <= tol
    same = (pos_i & pos_j) | (neg_i & neg_j) | on_plane
    opposite = ~same & ((pos_i & neg_j) | (neg_i & pos_j))
    out = np.full(len(k), MAYBE, np.int8)
    out[same] = FREE
    if opposite.any():
        o = np.flatnonzero(opposite)
        su, sv = si[o][:, :, None], sj[o][:, None, :]
        den = su - sv
        den_ok = (np.abs(den) > tol).all(axis=(1, 2))
        t = su / np.where(np.abs(den) > tol, den, 1.0)
        u, v = vi[o][:, :, None, :], vj[o][:, None, :, :]
        m = (u + t[..., None] * (v - u)).reshape(len(o), 16, 3)
        P, inward = occ.polys[k[o]], occ.inward[k[o]]
        g = np.einsum("tpmc,tmc->tpm", m[:, :, None, :] - P[:, None, :, :], inward)  # (t, 16, m)
        valid = inward.any(axis=2)[:, None, :]
        separated = ((g < tol) & valid).all(axis=1).any(axis=1)  # one edge has all points outside
        inside = ((g > -tol) | ~valid).all(axis=(1, 2)) & den_ok  # on an edge counts as inside
        state = np.full(len(o), MAYBE, np.int8)
        state[separated] = FREE
        state[inside & ~separated] = FULL
        out[o] = state
    one = ~same & ~opposite & ((pos_i | neg_i) != (pos_j | neg_j))  # one of the two straddles the plane
    for t in np.flatnonzero(one):
        cut, whole = (vi[t], vj[t]) if not (pos_i[t] | neg_i[t]) else (vj[t], vi[t])
        out[t] = _straddle_reference(cut, whole, occ.polys[k[t]], occ.inward[k[t]], n[t], c[t], tol)
    return out


def _straddle_reference(cut, whole, poly, inward, normal, centre, tol):
    """FREE or MAYBE of the segments from ``cut`` (straddling the occluder's plane) to ``whole``
    (on one side): the part of ``cut`` beyond the plane, as points, and their crossings."""
    s_cut, s_whole = (cut - centre) @ normal, (whole - centre) @ normal
    side = 1.0 if s_whole.min() >= -tol else -1.0
    beyond = side * s_cut <= 0
    points, s_p = list(cut[beyond]), list(s_cut[beyond])
    for a in range(len(cut)):
        for b in range(a + 1, len(cut)):
            if s_cut[a] * s_cut[b] < 0:  # the plane cuts the segment between them
                points.append(cut[a] + s_cut[a] / (s_cut[a] - s_cut[b]) * (cut[b] - cut[a]))
                s_p.append(0.0)
    points, s_p = np.array(points), np.array(s_p)
    den = s_p[:, None] - s_whole[None, :]
    if (np.abs(den) <= tol).any():
        return MAYBE
    t = s_p[:, None] / den
    crossing = points[:, None, :] + t[..., None] * (whole[None, :, :] - points[:, None, :])
    g = np.einsum("pqec,ec->pqe", crossing[:, :, None, :] - poly[None, None, :, :], inward)
    valid = inward.any(axis=1)
    return FREE if ((g < tol) & valid).all(axis=(0, 1)).any() else MAYBE

"""Visibility between patches: which pairs can be blocked at all, and how much is blocked.

Pairs are classified before any ray is traced (``_occluders``):

1. A face lying on the convex hull of the scene can block only segments inside its own plane,
   so only the other faces ("occluders") matter. Coplanar occluder patches of one object that
   tile a convex polygon are merged into it.
2. A bounding-volume hierarchy over the occluder polygons gives each pair the occluders whose
   boxes meet the pair's joint box.
3. Each (pair, occluder) is then decided exactly from the occluder's plane and the bundle of
   the 16 vertex-to-vertex segments: free, fully blocking, or maybe.

Pairs with a fully blocking occluder are 0; pairs with only free occluders are 1; the others
("partial") get either stratified shadow rays through Embree, adaptive (``samples**4`` rays per
pair, and ``max_samples**4`` where those disagree), or exact shadows (``_exact``): the hidden
part of the source is clipped by the occluders' cones from each receiver quadrature point and
its Lambert form factor subtracted.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from .. import _tol
from ..quadrature import patch_points
from . import _occluders
from ._constants import CHUNK_SHADOWS, PLANE_REL, WEIGHT_FLOOR_REL
from ._exact import hidden_factors, point_factors
from ._occluders import FREE, FULL, MAYBE, build_occluders

__all__ = ["Visibility", "occluder_mask", "FREE", "FULL", "MAYBE"]


def occluder_mask(quads: np.ndarray, scale: float) -> np.ndarray:
    """(n,) bool: patches that can block a segment between two other patches."""
    points = quads.reshape(-1, 3)
    try:
        hull = ConvexHull(points)
    except (QhullError, ValueError):
        return np.zeros(len(quads), dtype=bool)  # flat scene: every pair is coplanar or open
    planes = hull.equations  # (f, 4): n . x + d <= 0 inside
    tol = 1e-7 * scale
    dist = np.einsum("fc,nkc->nkf", planes[:, :3], quads) + planes[None, None, :, 3]
    on_facet_plane = (np.abs(dist) <= tol).all(axis=1).any(axis=1)
    return ~on_facet_plane


def _hash_uniform(key: np.ndarray) -> np.ndarray:
    """Uniform numbers in [0, 1) from uint64 keys (splitmix64): reproducible, order-free."""
    z = key + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return (z >> np.uint64(11)).astype(np.float64) / float(1 << 53)


def stratified_points(quads: np.ndarray, samples: int, key: np.ndarray, salt: int
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Jittered stratified points on patches: one per cell of a samples x samples grid.

    Parameters
    ----------
    quads : (m, 4, 3) float
        Patches (triangles repeat their third vertex: the bilinear map becomes Duffy's).
    samples : int
        Cells per direction.
    key : (m,) uint64
        A key per row (e.g. the pair): the jitter is a hash of key, cell and ``salt``, so it is
        the same however the rows are chunked, and differs between the two ends of a pair.
    salt : int

    Returns
    -------
    points : (m, samples**2, 3) float
    weights : (m, samples**2) float
        Area weights; they sum to each patch's area (up to the jitter's quadrature error).

    Notes
    -----
    Symmetric point sets (Gauss nodes on both patches) aim many rays exactly at an occluder's
    edge when patch and occluder edges line up, and Embree's watertight mode counts those as
    hits: a bias of order 1/samples. Independent jitter removes it.
    """
    with np.errstate(over="ignore"):
        cells = np.uint64(samples * samples)
        base = (key.astype(np.uint64)[:, None] * cells + np.arange(samples * samples, dtype=np.uint64)[None, :])
        base = base * np.uint64(8) + np.uint64(salt * 2)
        ju = _hash_uniform(base)
        jv = _hash_uniform(base + np.uint64(1))
    a = np.repeat(np.arange(samples), samples)[None, :]
    b = np.tile(np.arange(samples), samples)[None, :]
    u = ((a + ju) / samples)[..., None]
    v = ((b + jv) / samples)[..., None]
    p0, p1, p2, p3 = (quads[:, k, None, :] for k in range(4))
    points = (1 - u) * (1 - v) * p0 + u * (1 - v) * p1 + u * v * p2 + (1 - u) * v * p3
    du = (1 - v) * (p1 - p0) + v * (p2 - p3)
    dv = (1 - u) * (p3 - p0) + u * (p2 - p1)
    weights = np.linalg.norm(np.cross(du, dv), axis=-1) / (samples * samples)
    return points, weights


class Visibility:
    """Fractional visibility between patches: exact classification, then rays or exact shadows.

    Parameters
    ----------
    quads : (n, 4, 3) float
        The patches; every one of them blocks light from both sides.
    normals : (n, 3) float
        Unit normals (front sides).
    groups : (n,) int
        The object index of each patch: coplanar occluder patches merge only within an object.
    scale : float
        Scene size, metres: ray ends are pulled off surfaces by a fixed fraction of it.
    samples : int, default: 2
        Sample points per direction on each patch for the first round of rays
        (``samples**4`` rays per partly occluded pair).
    max_samples : int, default: 4
        Points per direction for pairs whose first-round rays disagree.
    cull : bool, default: True
        Classify pairs before tracing. ``False`` treats every patch as an occluder and every
        pair as partly occluded (for robustness tests of the ray path).
    """

    def __init__(self, quads: np.ndarray, normals: np.ndarray, groups: np.ndarray, scale: float, *,
                 samples: int = 2, max_samples: int = 4, cull: bool = True):
        self.quads = quads
        self.normals = normals
        self.scale = scale
        self.samples = samples
        self.max_samples = max(max_samples, samples)
        self.cull = cull
        mask = occluder_mask(quads, scale) if cull else np.ones(len(quads), bool)
        self.n_occluders = int(mask.sum())
        self.occluders = build_occluders(quads, normals, np.asarray(groups), mask, scale)
        self._lo = quads.min(axis=1)
        self._hi = quads.max(axis=1)
        self._tracer = None
        self.n_rays = 0
        self.n_exact_rows = 0

    # ------------------------------------------------------------------ classification
    def classify(self, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Classify pairs (i receives from j) before any ray.

        Returns
        -------
        status : (m,) int8
            ``FREE`` (nothing blocks), ``FULL`` (some occluder blocks every segment) or
            ``MAYBE`` (partly occluded).
        rows, occluder : (t,) int
            For the partly occluded pairs: the pair (index into i, j) and each occluder polygon
            that may block it.
        """
        return self._classify(self.quads[i], self.quads[j],
                              np.minimum(self._lo[i], self._lo[j]), np.maximum(self._hi[i], self._hi[j]))

    def _classify(self, vi, vj, lo, hi):
        m = len(vi)
        status = np.full(m, FREE, np.int8)
        pad = PLANE_REL * self.scale
        rows, occ = _occluders.candidates(self.occluders, lo, hi, pad)
        if self.cull and len(rows):
            state = _occluders.classify_rows(self.occluders, vi[rows], vj[rows], occ, self.scale)
            full = np.zeros(m, bool)
            full[rows[state == FULL]] = True
            maybe = state == MAYBE
            rows, occ = rows[maybe], occ[maybe]
            status[rows] = MAYBE
            status[full] = FULL
            keep = ~full[rows]
            rows, occ = rows[keep], occ[keep]
        elif not self.cull:
            status[:] = MAYBE
        return status, rows, occ

    def needs_rays(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """(m,) bool: pairs that are partly occluded (neither free nor fully blocked)."""
        return self.classify(i, j)[0] == MAYBE

    # ------------------------------------------------------------------ pair fractions
    def fraction(self, i: np.ndarray, j: np.ndarray, *, exact: bool = False, order: int = 2) -> np.ndarray:
        """(m,) visible fraction of each pair (i receives from j), kernel-weighted.

        Parameters
        ----------
        i, j : (m,) int
            Receiver and source patches.
        exact : bool, default: False
            Exact shadows at ``order**2`` Gauss points of the receiver instead of rays.
        order : int, default: 2
            Receiver points per direction for exact shadows.
        """
        status, rows, occ = self.classify(i, j)
        out = np.where(status == FULL, 0.0, 1.0)
        part = np.flatnonzero(status == MAYBE)
        if len(part):
            if exact:
                local = np.full(len(i), -1)
                local[part] = np.arange(len(part))
                out[part] = self.exact_fraction(i[part], j[part], local[rows], occ, order)
            else:
                out[part] = self.ray_fraction(i[part], j[part])
        return out

    def ray_fraction(self, i: np.ndarray, j: np.ndarray, samples: int | None = None,
                     max_samples: int | None = None) -> np.ndarray:
        """(m,) kernel-weighted unblocked fraction by stratified rays, refined where they disagree.

        Each ray from a sample x on i to a sample y on j is weighted by the area weights of both
        samples times the differential form factor cos_i cos_j / r^2, which is zero where y is
        behind i's plane: rays never count the hidden part of a source that straddles the
        receiver's horizon.
        """
        s0 = samples or self.samples
        s1 = max(max_samples or self.max_samples, s0)
        key = i.astype(np.uint64) * np.uint64(len(self.quads)) + j.astype(np.uint64)
        xs, wx = stratified_points(self.quads[i], s0, key, 1)
        frac, agree = self._weighted_fraction(xs, wx, self.normals[i], j, s0, key)
        if s1 > s0 and not agree.all():
            redo = np.flatnonzero(~agree)
            xs, wx = stratified_points(self.quads[i[redo]], s1, key[redo], 3)
            frac[redo] = self._weighted_fraction(xs, wx, self.normals[i[redo]], j[redo], s1, key[redo])[0]
        return frac

    def exact_fraction(self, i: np.ndarray, j: np.ndarray, rows: np.ndarray, occ: np.ndarray, order: int
                       ) -> np.ndarray:
        """(m,) visible fraction by exact shadows at ``order**2`` Gauss points of each receiver.

        ``rows``/``occ`` list the occluder polygons that may block each pair (from
        :meth:`classify`). The fraction is ``1 - sum_q w_q F(x_q -> hidden) / sum_q w_q F(x_q -> j)``.
        """
        pts, w = patch_points(self.quads, order)
        q = pts.shape[1]
        out = np.ones(len(i))
        srt = np.argsort(rows, kind="stable")
        rows, occ = rows[srt], occ[srt]
        per_pair = np.bincount(rows, minlength=len(i))
        ends = np.cumsum(per_pair)
        step_pairs = max(1, CHUNK_SHADOWS // max(1, q * max(1, int(per_pair.max(initial=1)))))
        for s in range(0, len(i), step_pairs):
            e = min(len(i), s + step_pairs)
            a, b = (ends[s - 1] if s else 0), ends[e - 1]
            out[s:e] = self._exact_chunk(i[s:e], j[s:e], rows[a:b] - s, occ[a:b], pts, w)
        return out

    def _exact_chunk(self, i, j, rows, occ, pts, w):
        q = pts.shape[1]
        x = pts[i].reshape(-1, 3)  # (m*q, 3), point p*q + a
        nx = np.repeat(self.normals[i], q, axis=0)
        unocc = point_factors(x, nx, np.repeat(self.quads[j], q, axis=0)).reshape(-1, q)
        # one row per (maybe occluder, receiver point)
        r = np.repeat(rows, q)
        a = np.tile(np.arange(q), len(rows))
        k = np.repeat(occ, q)
        group = r * q + a
        _, group = np.unique(group, return_inverse=True)
        group = group.ravel()
        xr = pts[i[r], a]
        hidden_g = hidden_factors(xr, self.normals[i[r]], group, self.quads[j[r]], self.normals[j[r]],
                                  self.occluders.polys[k], self.occluders.normal[k], PLANE_REL * self.scale)
        self.n_exact_rows += len(r)
        hidden = np.zeros(len(i) * q)
        first = np.unique(group, return_index=True)[1]
        hidden[(r * q + a)[first]] = hidden_g
        hidden = np.minimum(hidden.reshape(-1, q), unocc)
        total = (unocc * w[i]).sum(axis=1)
        lost = (hidden * w[i]).sum(axis=1)
        return np.where(total > 0, 1.0 - lost / np.where(total > 0, total, 1.0), 1.0)

    # ------------------------------------------------------------------ points (final gather)
    def point_fraction(self, points: np.ndarray, normals: np.ndarray, j: np.ndarray, *,
                       exact: bool = False) -> np.ndarray:
        """(m,) visible fraction of patch j seen from each receiver point (kernel-weighted).

        Parameters
        ----------
        points, normals : (m, 3) float
            Receiver points and unit normals.
        j : (m,) int
            Source patches.
        exact : bool, default: False
            Exact shadows instead of rays.
        """
        out = np.ones(len(j))
        if self.occluders.n_occluders == 0 or len(j) == 0:
            return out
        vi = np.repeat(points[:, None, :], 4, axis=1)
        status, rows, occ = self._classify(vi, self.quads[j], np.minimum(points, self._lo[j]),
                                           np.maximum(points, self._hi[j]))
        out[status == FULL] = 0.0
        part = np.flatnonzero(status == MAYBE)
        if not len(part):
            return out
        if exact:
            local = np.full(len(j), -1)
            local[part] = np.arange(len(part))
            x, nx, jj = points[part], normals[part], j[part]
            unocc = point_factors(x, nx, self.quads[jj])
            r = local[rows]
            hidden = np.zeros(len(part))
            _, group = np.unique(r, return_inverse=True)
            first = np.unique(r, return_index=True)[1]
            hidden[r[first]] = hidden_factors(x[r], nx[r], group.ravel(), self.quads[jj[r]], self.normals[jj[r]],
                                              self.occluders.polys[occ], self.occluders.normal[occ],
                                              PLANE_REL * self.scale)
            self.n_exact_rows += len(r)
            out[part] = np.where(unocc > 0, 1.0 - np.minimum(hidden, unocc) / np.where(unocc > 0, unocc, 1.0), 1.0)
        else:
            ones = np.ones((len(part), 1))
            key = np.arange(len(part), dtype=np.uint64)
            frac, _ = self._weighted_fraction(points[part][:, None, :], ones, normals[part], j[part],
                                              self.samples, key)
            out[part] = frac
        return out

    # ------------------------------------------------------------------ rays
    def _occluder(self):
        if self._tracer is None:
            from ._embree import EmbreeOccluder

            tris = np.concatenate([self.quads[:, [0, 1, 2]], self.quads[:, [0, 2, 3]]], axis=0)
            area = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
            self._tracer = EmbreeOccluder(tris[area > 0])
        return self._tracer

    def _weighted_fraction(self, receivers, receiver_weights, receiver_normals, j, samples, key):
        """Weighted unblocked fraction of rays from receivers (p, a, 3) to samples of j.

        Returns the fraction and whether all rays that carry weight agreed.
        """
        out = np.empty(len(j))
        agree = np.empty(len(j), bool)
        per_pair = receivers.shape[1] * samples * samples
        step = max(1, _tol.CHUNK_RAYS // per_pair)
        for s in range(0, len(j), step):
            sl = slice(s, s + step)
            ys, wy = stratified_points(self.quads[j[sl]], samples, key[sl], 2)
            out[sl], agree[sl] = self._fraction_chunk(receivers[sl], receiver_weights[sl], receiver_normals[sl],
                                                      ys, wy, self.normals[j[sl]])
        return out, agree

    def _fraction_chunk(self, xs, wx, nx, ys, wy, ny):
        off = _tol.RAY_OFFSET_REL * self.scale
        x = xs[:, :, None, :] + off * nx[:, None, None, :]
        y = ys[:, None, :, :] + off * ny[:, None, None, :]
        d = ys[:, None, :, :] - xs[:, :, None, :]
        r2 = np.einsum("pabc,pabc->pab", d, d)
        cos_i = np.einsum("pabc,pc->pab", d, nx)
        cos_j = -np.einsum("pabc,pc->pab", d, ny)
        weight = (wx[:, :, None] * wy[:, None, :] * np.clip(cos_i, 0, None) * np.clip(cos_j, 0, None)
                  / np.maximum(r2, 1e-300) ** 2)
        traced = weight > WEIGHT_FLOOR_REL * weight.max(axis=(1, 2), keepdims=True)
        x, y = np.broadcast_arrays(x, y)
        blocked = np.zeros(weight.shape, bool)
        blocked[traced] = self._occluder().occluded(x[traced], y[traced])
        self.n_rays += int(traced.sum())
        total = weight.sum(axis=(1, 2))
        visible = (weight * ~blocked).sum(axis=(1, 2))
        n_traced = traced.sum(axis=(1, 2))
        n_blocked = (blocked & traced).sum(axis=(1, 2))
        agree = (n_blocked == 0) | (n_blocked == n_traced)
        plain = 1.0 - n_blocked / np.maximum(n_traced, 1)
        return np.where(total > 0, visible / np.where(total > 0, total, 1.0), plain), agree

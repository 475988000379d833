"""Visibility between patches: which pairs can be blocked at all, and how much is blocked.

Rays are traced only for pairs that something could block. A face lying on the convex hull of
the scene can block only segments inside its own plane, so only the other faces ("occluders")
matter; a pair whose joint bounding box misses every occluder's box is fully visible.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from ..quadrature import patch_points

__all__ = ["Visibility", "occluder_mask"]


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


def _boxes_of(quads: np.ndarray, groups: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    labels = np.unique(groups)
    lo = np.stack([quads[groups == g].reshape(-1, 3).min(axis=0) for g in labels])
    hi = np.stack([quads[groups == g].reshape(-1, 3).max(axis=0) for g in labels])
    return lo, hi


class Visibility:
    """Fractional visibility between patches, by stratified shadow rays through Embree.

    Parameters
    ----------
    quads : (n, 4, 3) float
        The patches; every one of them blocks light from both sides.
    groups : (n,) int
        A grouping (the object index) used to bound the occluders with few boxes.
    scale : float
        Scene size, metres: ray ends are pulled off surfaces by a fixed fraction of it.
    samples : int
        Sample points per direction on each patch; ``samples**4`` rays per pair.
    """

    def __init__(self, quads: np.ndarray, normals: np.ndarray, groups: np.ndarray, scale: float, *, samples: int = 2):
        self.quads = quads
        self.normals = normals
        self.scale = scale
        self.samples = samples
        mask = occluder_mask(quads, scale)
        self.n_occluders = int(mask.sum())
        self._occ_lo, self._occ_hi = _boxes_of(quads[mask], groups[mask]) if mask.any() else (np.zeros((0, 3)), np.zeros((0, 3)))
        self._lo = quads.min(axis=1)
        self._hi = quads.max(axis=1)
        self._tracer = None
        self.n_rays = 0

    def _occluder(self):
        if self._tracer is None:
            from ._embree import EmbreeOccluder

            tris = np.concatenate([self.quads[:, [0, 1, 2]], self.quads[:, [0, 2, 3]]], axis=0)
            area = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
            self._tracer = EmbreeOccluder(tris[area > 0])
        return self._tracer

    def needs_rays(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """(m,) bool: pairs whose joint bounding box meets some occluder's box."""
        if len(self._occ_lo) == 0:
            return np.zeros(len(i), dtype=bool)
        return self._boxes_meet(np.minimum(self._lo[i], self._lo[j]), np.maximum(self._hi[i], self._hi[j]))

    def fraction(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """(m,) visible fraction of each pair (i receives from j), kernel-weighted.

        Each ray from a sample x on i to a sample y on j is weighted by the differential form
        factor cos_i cos_j / r^2, which is zero where y is behind i's plane: rays never aim at
        the hidden part of a source that straddles the receiver's horizon.
        """
        out = np.ones(len(i))
        trace = self.needs_rays(i, j)
        if trace.any():
            out[trace] = self._traced_fraction(i[trace], j[trace])
        return out

    def point_fraction(self, points: np.ndarray, normals: np.ndarray, j: np.ndarray) -> np.ndarray:
        """(m,) visible fraction of patch j seen from each receiver point (kernel-weighted)."""
        out = np.ones(len(j))
        if len(self._occ_lo) == 0 or len(j) == 0:
            return out
        lo = np.minimum(points, self._lo[j])
        hi = np.maximum(points, self._hi[j])
        trace = self._boxes_meet(lo, hi)
        if trace.any():
            out[trace] = self._weighted_fraction(points[trace][:, None, :], normals[trace], j[trace])
        return out

    def _boxes_meet(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        pad = 1e-6 * self.scale
        meets = np.zeros(len(lo), dtype=bool)
        for olo, ohi in zip(self._occ_lo, self._occ_hi):
            meets |= ((lo <= ohi + pad) & (hi >= olo - pad)).all(axis=1)
        return meets

    def _traced_fraction(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        pts, _ = patch_points(self.quads, self.samples)
        return self._weighted_fraction(pts[i], self.normals[i], j)

    def _weighted_fraction(self, receivers: np.ndarray, receiver_normals: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Kernel-weighted unblocked fraction of rays from receivers (p, a, 3) to samples of j."""
        pts, _ = patch_points(self.quads, self.samples)
        out = np.empty(len(j))
        per_pair = receivers.shape[1] * pts.shape[1]
        step = max(1, 2_000_000 // per_pair)
        for s in range(0, len(j), step):
            out[s:s + step] = self._fraction_chunk(receivers[s:s + step], receiver_normals[s:s + step], pts[j[s:s + step]], self.normals[j[s:s + step]])
        return out

    def _fraction_chunk(self, xs, nx, ys, ny) -> np.ndarray:
        off = 1e-5 * self.scale
        x = xs[:, :, None, :] + off * nx[:, None, None, :]
        y = ys[:, None, :, :] + off * ny[:, None, None, :]
        x, y = np.broadcast_arrays(x, y)
        d = y - x
        r2 = np.einsum("pabc,pabc->pab", d, d)
        cos_i = np.einsum("pabc,pc->pab", d, nx)
        cos_j = -np.einsum("pabc,pc->pab", d, ny)
        weight = np.clip(cos_i, 0, None) * np.clip(cos_j, 0, None) / np.maximum(r2, 1e-300) ** 2
        blocked = self._occluder().occluded(x.reshape(-1, 3), y.reshape(-1, 3)).reshape(weight.shape)
        self.n_rays += blocked.size
        total = weight.sum(axis=(1, 2))
        visible = (weight * ~blocked).sum(axis=(1, 2))
        plain = (~blocked).mean(axis=(1, 2))
        return np.where(total > 0, visible / np.where(total > 0, total, 1.0), plain)

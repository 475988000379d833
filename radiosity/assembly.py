"""The view-factor matrix: candidate pairs, unoccluded form factors, visibility, sparse F.

Row i of F is the receiver: ``F[i, j]`` is F(i -> j), the area average over patch i of the
point-to-polygon form factor to patch j (Lambert's closed form at Gauss points of i), times
the visible fraction of the pair. Pairs facing away from each other are exactly zero and are
never evaluated; pairs that nothing can block get no rays.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from . import _tol
from .formfactors import lambert_pairs
from .quadrature import patch_points

__all__ = ["FillSettings", "FillStats", "candidate_pairs", "unoccluded_factors", "assemble"]


@dataclass(frozen=True)
class FillSettings:
    """Accuracy knobs of the fill (part of the cache key)."""

    near_order: int = 3  # Gauss points per direction on the receiver for near pairs
    far_separation: float = 3.0  # relative separation beyond which one centroid point is used
    visibility_samples: int = 2  # points per direction on each patch for shadow rays


@dataclass
class FillStats:
    n_pairs: int = 0
    n_traced_pairs: int = 0
    n_rays: int = 0
    dropped_mass: float = 0.0
    seconds_formfactors: float = 0.0
    seconds_visibility: float = 0.0


def _circumradius(quads: np.ndarray, centroid: np.ndarray) -> np.ndarray:
    return np.linalg.norm(quads - centroid[:, None, :], axis=2).max(axis=1)


def candidate_pairs(quads: np.ndarray, normals: np.ndarray, centroid: np.ndarray, rows: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i in rows, j) that face each other: some of j is in front of i and vice versa."""
    n = len(quads)
    offset_i = np.einsum("nc,nc->n", normals, centroid)
    # height of every vertex of j above plane i: (rows, n, 4)
    h_ji = np.einsum("rc,nkc->rnk", normals[rows], quads) - offset_i[rows, None, None]
    h_ij = np.einsum("nc,rkc->rnk", normals, quads[rows]) - offset_i[None, :, None]
    scale = _circumradius(quads, centroid)
    tol = 1e-9 * (scale[rows, None] + scale[None, :])
    ok = (h_ji.max(axis=2) > tol) & (h_ij.max(axis=2) > tol)
    ok[np.arange(len(rows)), rows] = False
    r, j = np.nonzero(ok)
    del n
    return rows[r], j


def unoccluded_factors(quads: np.ndarray, normals: np.ndarray, centroid: np.ndarray, area: np.ndarray,
                       i: np.ndarray, j: np.ndarray, settings: FillSettings) -> np.ndarray:
    """F(i -> j) without occlusion, by Gauss quadrature over i of Lambert's formula to j."""
    radius = _circumradius(quads, centroid)
    separation = np.linalg.norm(centroid[i] - centroid[j], axis=1) / (radius[i] + radius[j])
    near = separation < settings.far_separation
    out = np.empty(len(i))
    far = ~near
    out[far] = lambert_pairs(centroid[i[far]], normals[i[far]], quads[j[far]])
    if near.any():
        pts, w = patch_points(quads, settings.near_order)
        q = pts.shape[1]
        ni, nj = i[near], j[near]
        values = lambert_pairs(pts[ni].reshape(-1, 3), np.repeat(normals[ni], q, axis=0),
                               np.repeat(quads[nj], q, axis=0)).reshape(-1, q)
        out[near] = (values * w[ni]).sum(axis=1) / area[ni]
    return out


def assemble(quads, normals, centroid, area, visibility, settings: FillSettings, progress=None
             ) -> tuple[sp.csr_matrix, FillStats]:
    """The sparse view-factor matrix F (n, n) with occlusion, and fill statistics."""
    n = len(quads)
    stats = FillStats()
    rows_per_block = max(1, min(n, 2_000_000 // max(n, 1)))
    parts_i, parts_j, parts_v = [], [], []
    for start in range(0, n, rows_per_block):
        rows = np.arange(start, min(n, start + rows_per_block))
        i, j = candidate_pairs(quads, normals, centroid, rows)
        if len(i):
            t0 = time.perf_counter()
            f = unoccluded_factors(quads, normals, centroid, area, i, j, settings)
            t1 = time.perf_counter()
            stats.seconds_formfactors += t1 - t0
            if visibility is not None:
                nonzero = f > 0
                traced = visibility.needs_rays(i[nonzero], j[nonzero])
                stats.n_traced_pairs += int(traced.sum())
                f[nonzero] *= visibility.fraction(i[nonzero], j[nonzero])
                stats.seconds_visibility += time.perf_counter() - t1
            keep = f > _tol.DROP_FACTOR
            stats.dropped_mass += float((f[~keep] * area[i[~keep]]).sum())
            stats.n_pairs += len(i)
            parts_i.append(i[keep])
            parts_j.append(j[keep])
            parts_v.append(f[keep])
        if progress is not None:
            progress(len(rows))
    if visibility is not None:
        stats.n_rays = visibility.n_rays
    if parts_i:
        i, j, v = (np.concatenate(p) for p in (parts_i, parts_j, parts_v))
    else:
        i = j = np.zeros(0, np.int64)
        v = np.zeros(0)
    return sp.csr_matrix((v, (i, j)), shape=(n, n)), stats

"""First hits of the light-path rays (``_lightpaths``) with boxes around runs of triangles.

The plain kernel tests every triangle for every ray: 2 x 1024 rays x 1.2M triangles for a
581k-triangle OBJ, most of its load time (issue 19). Triangles of a mesh come in runs of
neighbours (a file lists a surface's faces together), so a box around each run of ``CHUNK``
consecutive triangles is small; a ray that misses a run's box, or meets it only beyond the
nearest hit found so far, skips the run's triangles. Those it does not skip are tested exactly
as the plain kernel tests them, in the same order and with the same strict comparison, so the
hits (ties included) are the plain kernel's; the boxes are padded, so round-off in the slab
test cannot skip a triangle the plain test would hit.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["CHUNK", "arrival_side", "chunk_boxes", "first_hits_chunked", "hit_distance"]

CHUNK = 64
# Boxes grow by this fraction of the scene's diagonal (and slab distances by this fraction of
# themselves): far above the round-off of the tests, far below a triangle.
_PAD_REL = 1e-6


@njit(cache=True, inline="always")
def hit_distance(ox, oy, oz, dx, dy, dz, v0, e1, e2, k):
    """Ray parameter t where o + t d meets triangle k (Moller-Trumbore), or -inf if it misses.

    The one ray-triangle test of both first-hit kernels (plain and chunked), so their hits agree
    bit for bit.
    """
    ax, ay, az = e1[k, 0], e1[k, 1], e1[k, 2]
    bx, by, bz = e2[k, 0], e2[k, 1], e2[k, 2]
    px, py, pz = dy * bz - dz * by, dz * bx - dx * bz, dx * by - dy * bx
    det = ax * px + ay * py + az * pz
    if det == 0.0:
        return -np.inf
    inv = 1.0 / det
    sx, sy, sz = ox - v0[k, 0], oy - v0[k, 1], oz - v0[k, 2]
    u = (sx * px + sy * py + sz * pz) * inv
    if u < 0.0 or u > 1.0:
        return -np.inf
    qx, qy, qz = sy * az - sz * ay, sz * ax - sx * az, sx * ay - sy * ax
    v = (dx * qx + dy * qy + dz * qz) * inv
    if v < 0.0 or u + v > 1.0:
        return -np.inf
    return (bx * qx + by * qy + bz * qz) * inv


@njit(cache=True, inline="always")
def arrival_side(dx, dy, dz, e1, e2, k):
    """``dot(d, e1 x e2)`` of triangle k: positive when the ray arrives at its back."""
    ax, ay, az = e1[k, 0], e1[k, 1], e1[k, 2]
    bx, by, bz = e2[k, 0], e2[k, 1], e2[k, 2]
    return dx * (ay * bz - az * by) + dy * (az * bx - ax * bz) + dz * (ax * by - ay * bx)


def first_hits_chunked(origins, directions, v0, e1, e2, offset: float, hit, side, boxes=None) -> None:
    """``_lightpaths._first_hits_kernel`` (same arguments, same results), skipping runs of
    triangles whose box a ray does not reach before its nearest hit so far. ``boxes``:
    :func:`chunk_boxes` of these triangles, if the caller traces them more than once."""
    lo, hi = chunk_boxes(v0, e1, e2) if boxes is None else boxes
    _kernel(origins, directions, v0, e1, e2, offset, lo, hi, CHUNK, hit, side)


def chunk_boxes(v0, e1, e2) -> tuple[np.ndarray, np.ndarray]:
    """Padded (lo, hi) boxes of each run of ``CHUNK`` consecutive triangles."""
    b, c = v0 + e1, v0 + e2
    starts = np.arange(0, len(v0), CHUNK)
    lo = np.minimum.reduceat(np.minimum(np.minimum(v0, b), c), starts, axis=0)
    hi = np.maximum.reduceat(np.maximum(np.maximum(v0, b), c), starts, axis=0)
    pad = _PAD_REL * float(np.linalg.norm(hi.max(axis=0) - lo.min(axis=0))) + 1e-300
    return lo - pad, hi + pad


@njit(cache=True, inline="always")
def _reaches(ox, oy, oz, dx, dy, dz, lo, hi, best_t):
    """Does the ray o + t d, 0 <= t <= best_t (padded), meet the box [lo, hi]?"""
    t0 = 0.0
    t1 = best_t
    for axis in range(3):
        o = ox if axis == 0 else (oy if axis == 1 else oz)
        d = dx if axis == 0 else (dy if axis == 1 else dz)
        if d == 0.0:
            if o < lo[axis] or o > hi[axis]:
                return False
            continue
        a = (lo[axis] - o) / d
        b = (hi[axis] - o) / d
        if a > b:
            a, b = b, a
        t0 = max(t0, a - _PAD_REL * abs(a))
        t1 = min(t1, b + _PAD_REL * abs(b))
        if t0 > t1:
            return False
    return True


@njit(cache=True)
def _kernel(origins, directions, v0, e1, e2, offset, box_lo, box_hi, chunk, hit, side):  # pragma: no cover
    n = len(v0)
    for r in range(len(origins)):  # serial, as the plain kernel
        ox, oy, oz = origins[r, 0], origins[r, 1], origins[r, 2]
        dx, dy, dz = directions[r, 0], directions[r, 1], directions[r, 2]
        best_t = np.inf
        best = -1
        for c in range(len(box_lo)):
            if not _reaches(ox, oy, oz, dx, dy, dz, box_lo[c], box_hi[c], best_t):
                continue
            for k in range(c * chunk, min(n, (c + 1) * chunk)):
                t = hit_distance(ox, oy, oz, dx, dy, dz, v0, e1, e2, k)
                if offset < t < best_t:
                    best_t = t
                    best = k
        hit[r] = best
        if best >= 0:
            side[r] = arrival_side(dx, dy, dz, e1, e2, best)

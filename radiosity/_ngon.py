"""Well-shaped pieces of convex faces with many corners (CAD n-gons: disks, cylinder caps).

Earcut on a 1,000-corner disk gives 998 triangles fanning out from the corners, nearly all of
them slivers (a corner angle of 2 pi / n), and subdivision cuts those again: 1,534 patches,
thin enough that the solve's quadrature crawls. Any exact tiling of such a face needs a patch
edge on every one of its n edges, so about n / 2 patches at least; what can be chosen is their
shape. Here the face is tiled by a Delaunay triangulation of its corners plus graded rings of
points inside (each ring has half the points of the one outside it, spaced and set in by about
the same length), so triangles grow from the edge length at the rim to the face's size inside,
each about as wide as it is long; pairs of triangles are then merged into convex quads. The
tiling is checked by area and the caller falls back to earcut when it fails.
"""

from __future__ import annotations

import numpy as np

__all__ = ["GRADED_MIN_CORNERS", "graded_pieces"]

# Convex faces with at least this many corners are tiled here (fewer: earcut, as before).
GRADED_MIN_CORNERS = 32

# Each ring inside holds 1 / RING_RATIO of the points of the one outside it, set in by about
# RING_DEPTH times its own spacing: 5 and 0.4 give pieces with longest edge² / area below ~4.2 and
# about 0.75 n pieces for n corners (2 and 0.75: 1.6 n).
RING_RATIO = 5
RING_DEPTH = 0.4

# Tilings whose area misses the face's by more than this fraction are rejected.
AREA_REL = 1e-9

# Triangles smaller than this fraction of the face are flat (collinear corners): dropped.
FLAT_REL = 1e-12

# A merged quad keeps each corner turning by at least this (sine of the angle times both edges).
TURN_REL = 1e-6


def _frame(poly: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    origin = poly.mean(axis=0)
    u = poly[0] - origin
    u = u - (u @ normal) * normal
    u = u / np.linalg.norm(u)
    return origin, u, np.cross(normal, u)


def _rings(xy: np.ndarray) -> np.ndarray:
    """Interior points: rings of every 5th, 25th, ... corner pulled towards the centre (the
    origin) by about their spacing, down to a few points, then the centre."""
    radius = np.linalg.norm(xy, axis=1)
    inner = float(radius.min())
    edge = float(np.median(np.linalg.norm(np.roll(xy, -1, axis=0) - xy, axis=1)))
    out = []
    step, depth = 1, 0.0
    while True:
        step *= RING_RATIO
        index = np.arange(0, len(xy), step)
        depth += RING_DEPTH * edge * step
        if len(index) < 6 or depth >= 0.85 * inner:
            break
        out.append(xy[index] * (1.0 - depth / radius[index])[:, None])
    out.append(np.zeros((1, 2)))
    return np.concatenate(out)


def _turns_ok(quad: list[tuple[float, float]]) -> bool:
    """Every corner of a 2-D quad turns left by more than ``TURN_REL`` (Python floats: this
    runs once per candidate pair)."""
    for k in range(4):
        (ax, ay), (bx, by), (cx, cy) = quad[k - 1], quad[k], quad[(k + 1) % 4]
        ex, ey, fx, fy = bx - ax, by - ay, cx - bx, cy - by
        if not ex * fy - ey * fx > TURN_REL * ((ex * ex + ey * ey) * (fx * fx + fy * fy)) ** 0.5:
            return False
    return True


def _merge(points: np.ndarray, tris: np.ndarray) -> list[np.ndarray]:
    """Counter-clockwise triangles merged in pairs into convex quads, longest shared edge first."""
    start = tris.reshape(-1)
    end = np.roll(tris, -1, axis=1).reshape(-1)
    owner = dict(zip(zip(start.tolist(), end.tolist()), np.repeat(np.arange(len(tris)), 3).tolist()))
    lengths = np.hypot(*(points[start] - points[end]).T).tolist()
    shared = []
    for (i, j), t, length in zip(owner, owner.values(), lengths):
        s = owner.get((j, i))
        if s is not None and t < s:
            shared.append((length, i, j, t, s))
    shared.sort(reverse=True)
    xy = [tuple(p) for p in points.tolist()]
    rows = tris.tolist()
    used = [False] * len(tris)
    out = []
    for _, i, j, t, s in shared:
        if used[t] or used[s]:
            continue
        c_t = next(x for x in rows[t] if x not in (i, j))
        c_s = next(x for x in rows[s] if x not in (i, j))
        quad = [i, c_s, j, c_t]  # t holds i -> j, s holds j -> i
        if _turns_ok([xy[q] for q in quad]):
            used[t] = used[s] = True
            out.append(np.array(quad))
    out.extend(tri for tri, u in zip(tris, used) if not u)
    return out


def graded_pieces(poly: np.ndarray, normal: np.ndarray) -> list[np.ndarray] | None:
    """Convex triangles and quads (3-D, wound like ``poly``) tiling a convex planar face.

    Parameters
    ----------
    poly : (n, 3) float
        The face's corners, counter-clockwise around ``normal``, convex, planar.
    normal : (3,) float
        Unit normal.

    Returns
    -------
    list of (3, 3) or (4, 3) arrays, or None when the tiling fails its area check.
    """
    from scipy.spatial import Delaunay

    origin, u, v = _frame(poly, normal)
    rel = poly - origin
    xy = np.column_stack([rel @ u, rel @ v])
    area = 0.5 * float(np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1]))
    if not area > 0:
        return None
    points = np.concatenate([xy, _rings(xy)])
    try:
        tris = Delaunay(points).simplices.astype(np.int64)
    except Exception:  # qhull refuses degenerate input: let earcut have it
        return None
    a, b, c = points[tris[:, 0]], points[tris[:, 1]], points[tris[:, 2]]
    signed = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    if abs(np.abs(signed).sum() - area) > AREA_REL * area:
        return None  # qhull dropped a corner (collinear on the rim) or a point fell outside
    keep = np.abs(signed) > FLAT_REL * area
    tris = np.where((signed < 0)[:, None], tris[:, ::-1], tris)[keep]
    points3 = origin + points[:, :1] * u + points[:, 1:] * v
    points3[: len(poly)] = poly  # the corners exactly as given
    return [points3[piece] for piece in _merge(points, tris)]

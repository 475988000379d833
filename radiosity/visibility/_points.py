"""Irradiance at receiver points (sensors): exact shadows, every face an occluder, bounded error.

For a receiver point x with normal n, H(x) = sum_j B_j F(x -> visible part of j), summed over
the lit patches j that face x. Each pair (x, j) is classified exactly (free, fully blocked,
or partly occluded) against the occluder polygons whose boxes meet the pair's box, as for
patch pairs (``_occluders``). For partly occluded pairs the hidden part of j is clipped
exactly (``_exact``), so no ray noise enters, and the value of a point depends only on that
point.

Which faces can block. Faces on the scene's convex hull can block nothing between two points
of the hull, so the patch-pair fill leaves them out. A sensor outside the hull (under a closed
room's floor, beside a closed cube) is shadowed by exactly those faces, so points outside the
hull (by more than the plane tolerance) are classified against every face.

Error control. Exact shadows cost most where many partly occluded sources each add little.
With ``rtol > 0``, a point's partly occluded sources are taken in decreasing order of their
unoccluded contribution c_j B_j; once half the sum R of those left is at most ``rtol`` times the
irradiance H_known already accumulated (free sources plus the exact ones), those left are
counted half visible. The error is then at most R / 2 <= rtol * H_known <= rtol * H per channel.
``rtol=0`` computes every shadow exactly.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from ._constants import MAX_UNION, PLANE_REL
from ._occluders import Occluders, build_occluders

# A point on two or more surfaces that meet at an angle (a room's floor at a wall's foot, a
# corner) is moved this far (relative to the scene's size) off each of them along its normal
# before the gather: see ``off_inner_edges``.
EDGE_NUDGE_REL = 1e-7

__all__ = ["SensorGather", "block_order", "clusters", "inside_hull"]

# Receiver points per cluster: the cluster's box is classified against each source once, and
# only the partly occluded boxes are classified point by point.
CLUSTER_SIZE = 32
# Keep the occluders a point's classification finds for its exact shadows (bench_sensors turns
# it off to time the kernel as it was).
REUSE_WALKS = True


def clusters(points: np.ndarray, size: int = CLUSTER_SIZE) -> tuple[np.ndarray, np.ndarray]:
    """Runs of ``size`` points along a Morton (Z-order) curve: spatially compact groups.

    Returns (members, starts): cluster c holds points ``members[starts[c]:starts[c + 1]]``.
    """
    lo, hi = points.min(axis=0), points.max(axis=0)
    span = np.where(hi > lo, hi - lo, 1.0)
    cells = np.minimum(((points - lo) / span * 1024).astype(np.int64), 1023)  # 10 bits per axis
    code = np.zeros(len(points), np.int64)
    for bit in range(10):
        for axis in range(3):
            code |= ((cells[:, axis] >> bit) & 1) << (3 * bit + axis)
    members = np.argsort(code, kind="stable").astype(np.int64)
    starts = np.r_[np.arange(0, len(points), size), len(points)].astype(np.int64)
    return members, starts


def block_order(n_clusters: int) -> np.ndarray:
    """A fixed shuffle of the kernel's blocks of clusters (``_points_kernel.sensor_irradiance``):
    each thread then gets costly and cheap regions alike, whatever the scene."""
    from ._points_kernel import _CLUSTER_BLOCK

    n_blocks = -(-n_clusters // _CLUSTER_BLOCK)
    return np.random.default_rng(0).permutation(n_blocks).astype(np.int64)


def patch_trees(quads: np.ndarray) -> tuple[np.ndarray, list]:
    """The patches' centres, and k-d trees over them by size class: (members, tree, largest
    radius) per power of two of the radius, so a point's ball query meets few patches."""
    from scipy.spatial import cKDTree

    centre = quads.mean(axis=1)
    radius = np.linalg.norm(quads - centre[:, None, :], axis=2).max(axis=1)
    size_class = np.floor(np.log2(np.maximum(radius, 1e-300))).astype(np.int64)
    trees = []
    for c in np.unique(size_class):
        members = np.flatnonzero(size_class == c)
        trees.append((members, cKDTree(centre[members]), float(radius[members].max())))
    return centre, trees


def off_inner_edges(points: np.ndarray, quads: np.ndarray, normals: np.ndarray, tol: float, step: float,
                    trees: tuple[np.ndarray, list] | None = None) -> np.ndarray:
    """The points, those on two or more patches in different planes moved ``step`` off each of
    them along its normal.

    A point exactly where a floor meets a wall lies in the wall's plane, so the wall is at
    grazing from it and gives nothing, while from any point of the floor beside it the wall
    fills half the hemisphere: in a furnace room (B = 2 everywhere) a sensor there read 1.0, at
    a room's corner 0.5, at a box's corner on the floor 1.5. Moved off each surface it lies on,
    the point takes the value its neighbours on the surface converge to. A point on one surface
    only is left where it is (the surface is behind its hemisphere either way). ``trees``:
    :func:`patch_trees` of the quads (built here if not given).
    """
    if not len(points) or not len(quads):
        return points
    centre, by_size = patch_trees(quads) if trees is None else trees
    ps, ks = [], []
    for members, tree, reach in by_size:
        found = tree.query_ball_point(points, reach + tol, return_sorted=False)
        count = np.fromiter((len(h) for h in found), np.int64, len(found))
        ps.append(np.repeat(np.arange(len(points)), count))
        ks.append(members[np.fromiter(itertools.chain.from_iterable(found), np.int64, int(count.sum()))])
    p, k = np.concatenate(ps), np.concatenate(ks)
    x = points[p]
    on = (np.abs(np.einsum("tc,tc->t", x - centre[k], normals[k])) <= tol) & normals[k].any(axis=1)  # no degenerate
    edge = np.roll(quads[k], -1, axis=1) - quads[k]
    inward = np.cross(normals[k][:, None, :], edge)  # counter-clockwise about the normal
    length = np.linalg.norm(inward, axis=2)
    side = np.einsum("tec,tec->te", x[:, None, :] - quads[k], inward)
    on &= ((side >= -tol * length) | (length <= tol)).all(axis=1)
    p, k = p[on], k[on]
    if not len(p):
        return points
    # only points on surfaces in two or more planes: the normals of a point's surfaces differ
    first = np.full(len(points), -1)
    first[p[::-1]] = k[::-1]
    differs = np.einsum("tc,tc->t", normals[k], normals[first[p]]) < 1.0 - 1e-9
    moved = np.zeros(len(points), bool)
    moved[p[differs]] = True
    keep = moved[p]
    out = points.copy()
    np.add.at(out, p[keep], step * normals[k[keep]])
    return out


def inside_hull(points: np.ndarray, vertices: np.ndarray, tol: float) -> np.ndarray:
    """(m,) bool: points inside the convex hull of ``vertices`` or within ``tol`` of it.

    A flat (or degenerate) vertex set has no interior; every point counts as inside then,
    because faces that all lie in one plane block no segment ending on one of them.
    """
    try:
        planes = ConvexHull(vertices).equations
    except (QhullError, ValueError):
        return np.ones(len(points), bool)
    out = np.ones(len(points), bool)
    step = max(1, 4_000_000 // max(len(planes), 1))
    for s in range(0, len(points), step):
        d = points[s:s + step] @ planes[:, :3].T + planes[:, 3]
        out[s:s + step] = (d <= tol).all(axis=1)
    return out


class SensorGather:
    """Irradiance at receiver points for one solved scene.

    Parameters
    ----------
    quads : (n, 4, 3) float
        The patches (triangles repeat their third vertex).
    normals : (n, 3) float
        Unit normals.
    groups : (n,) int
        Object index per patch (coplanar occluder patches merge only within an object).
    scale : float
        Scene size, metres (sets the plane tolerance).
    radiosity : (n, 3) float
        Radiosity per patch, W/m^2.
    inner : Occluders, optional
        Occluders without the hull's faces (``Visibility.occluders``), reused for points inside
        the hull; built here if not given.
    """

    def __init__(self, quads: np.ndarray, normals: np.ndarray, groups: np.ndarray, scale: float,
                 radiosity: np.ndarray, inner: Occluders | None = None):
        from ._pairs import occluder_mask

        self.quads = np.ascontiguousarray(quads, dtype=np.float64)
        self.normals = np.ascontiguousarray(normals, dtype=np.float64)
        self.groups = np.asarray(groups)
        self.scale = float(scale)
        self.radiosity = np.ascontiguousarray(radiosity, dtype=np.float64)
        self.centroid = self.quads.mean(axis=1)
        # a degenerate patch (zero normal) emits and receives nothing
        self.lit = np.flatnonzero(self.radiosity.any(axis=1) & self.normals.any(axis=1)).astype(np.int64)
        self.tol = PLANE_REL * self.scale
        if inner is None:
            inner = build_occluders(self.quads, self.normals, self.groups, occluder_mask(self.quads, self.scale),
                                    self.scale)
        self.inner = inner
        self._outer = None
        self._trees = None  # patch_trees, on first use
        self.n_exact = 0

    @property
    def outer(self) -> Occluders:
        """Every face as an occluder (for points outside the hull); built on first use."""
        if self._outer is None:
            every = np.ones(len(self.quads), bool)
            self._outer = build_occluders(self.quads, self.normals, self.groups, every, self.scale)
        return self._outer

    def irradiance(self, points: np.ndarray, normals: np.ndarray, rtol: float = 1e-3) -> np.ndarray:
        """(m, 3) irradiance at points (m, 3) with unit normals (m, 3), W/m^2.

        ``rtol`` bounds each channel's relative error due to shadows taken half visible
        (0: every shadow exact); see the module notes.
        """
        points = np.ascontiguousarray(points, dtype=np.float64)
        normals = np.ascontiguousarray(normals, dtype=np.float64)
        out = np.zeros((len(points), 3))
        if len(points) == 0 or len(self.lit) == 0:
            return out
        if self._trees is None:
            self._trees = patch_trees(self.quads)
        points = off_inner_edges(points, self.quads, self.normals, self.tol, EDGE_NUDGE_REL * self.scale, self._trees)
        inside = inside_hull(points, self.quads.reshape(-1, 3), self.tol)
        for mask, occ in ((inside, self.inner), (~inside, None)):
            idx = np.flatnonzero(mask)
            if len(idx):
                out[idx] = self._gather(points[idx], normals[idx], occ if occ is not None else self.outer, rtol)
        return out

    def _gather(self, x: np.ndarray, nx: np.ndarray, occ: Occluders, rtol: float) -> np.ndarray:
        from ._points_kernel import sensor_irradiance

        members, starts = clusters(x)
        h, ok, n_exact = sensor_irradiance(
            x, nx, members, starts, self.quads, self.normals, self.centroid, self.radiosity, self.lit, occ.polys,
            occ.normal, occ.center, occ.inward, occ.lo, occ.hi, occ.node_lo, occ.node_hi, occ.node_left, occ.node_right,
            occ.node_start, occ.node_count, occ.order, self.tol, self.tol, float(rtol), MAX_UNION,
            block_order(len(starts) - 1), REUSE_WALKS)
        self.n_exact += int(n_exact.sum())
        bad = np.flatnonzero(~ok)
        if len(bad):
            h[bad] = self._gather_united(x[bad], nx[bad], occ)
        return h

    def _gather_united(self, x: np.ndarray, nx: np.ndarray, occ: Occluders) -> np.ndarray:
        """Every shadow exact, unions of many hidden polygons by shapely (the rare points where a
        source has more than ``MAX_UNION`` of them)."""
        from ._exact import hidden_factors, point_factors
        from ._exact_kernel import classify_pairs

        out = np.zeros((len(x), 3))
        for p in range(len(x)):
            j = self.lit[np.einsum("jc,jc->j", x[p] - self.centroid[self.lit], self.normals[self.lit]) > 0]
            xs, ns = np.repeat(x[p][None], len(j), axis=0), np.repeat(nx[p][None], len(j), axis=0)
            f = point_factors(xs, ns, self.quads[j])
            vi = np.repeat(x[p][None, None, :], 4, axis=1)
            status, starts, k = classify_pairs(vi, np.zeros(len(j), np.int64), self.quads, j, occ.polys, occ.normal,
                                               occ.center, occ.inward, occ.lo, occ.hi, occ.node_lo, occ.node_hi,
                                               occ.node_left, occ.node_right, occ.node_start, occ.node_count,
                                               occ.order, self.tol, self.tol, np.zeros((1, 3)), np.zeros((1, 3)), -1.0)
            seen = np.where(status == 1, 0.0, f)
            part = np.flatnonzero(status == 2)
            if len(part):
                count = starts[part + 1] - starts[part]
                group = np.repeat(np.arange(len(part)), count)
                rows = np.concatenate([k[starts[q]:starts[q + 1]] for q in part])
                jj = j[part][group]
                xr, nr = np.repeat(x[p][None], len(rows), axis=0), np.repeat(nx[p][None], len(rows), axis=0)
                hidden = hidden_factors(xr, nr, group, self.quads[jj], self.normals[jj],
                                        occ.polys[rows], occ.normal[rows], self.tol)
                seen[part] = f[part] - np.minimum(hidden, f[part])
            out[p] = seen @ self.radiosity[j]
        return out

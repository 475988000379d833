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
("partial") get either stratified shadow rays, adaptive (``samples**4`` rays per pair, and
``max_samples**4`` where those disagree), or exact shadows (``_exact``): the hidden part of the
source is clipped by the occluders' cones from each receiver quadrature point and its Lambert
form factor subtracted. A shadow ray is tested, in float64, only against the occluder polygons
left undecided for its pair (``_ray_kernel``): no other polygon can block it. Embree casts rays
against every patch only when culling is off (robustness tests).

Classification, rays and exact shadows are compiled (numba) loops over pairs; the numpy
versions (``Visibility._classify``, ``Visibility._trace_numpy``, ``_occluders.classify_rows_numpy``,
``_exact._hidden_factors_shapely``) are the references the tests compare them with.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.spatial import ConvexHull, QhullError, cKDTree

from .. import _tol
from ..geometry import centroids_and_areas, polygon_normals
from ..formfactors import (gauss_legendre_01, pair_factors, patch_points, square_cell_corners, square_cell_points,
                           tip_collapsed)
from . import _occluders
from ._constants import (BLIND_ORDERS, CAPPED_RTOL_STEP, CELL_FALLBACK_ATOL, CELL_RETRY_POINTS, CHUNK_CELL_PAIRS,
                         CHUNK_CLASSIFY, CHUNK_SHADOWS, CHUNK_SQUARE_PAIRS, CHUNK_TRIPLES, GOOD, KINK_BAND,
                         MAX_ROOT_CELLS, MAX_UNION, MAX_UNION_CELLS, OUT_OF_POINTS, PLANE_REL, RAY_LIST_EMBREE,
                         RAY_TFAR_SHORT,
                         RECEIVE_SMALLER_WIDTHS, SATURATED_REL, SHADOW_MAX_DEPTH, WEIGHT_FLOOR_REL)
from ._exact import hidden_factors, point_factors
from ._occluders import FREE, FULL, MAYBE, build_occluders

__all__ = ["Visibility", "occluder_mask", "FREE", "FULL", "MAYBE"]


# Patches x hull facets below which occluder_mask tests every facet instead of the nearest ones.
_ALL_FACETS_BELOW = 65_536


def occluder_mask(quads: np.ndarray, scale: float) -> np.ndarray:
    """(n,) bool: patches that can block a segment between two other patches."""
    points = quads.reshape(-1, 3)
    try:
        hull = ConvexHull(points)
    except (QhullError, ValueError):
        return np.zeros(len(quads), dtype=bool)  # flat scene: every pair is coplanar or open
    planes = hull.equations  # (f, 4): n . x + d <= 0 inside
    tol = 1e-7 * scale
    # A patch lies in a facet's plane only if its own plane is (nearly) that facet's: test each
    # patch against the facets whose (normal, offset) are nearest its own, with either sign,
    # not against every facet (n x facets distances: 30 GB for a 32,000-face sphere). A match
    # missed this way only keeps a patch as an occluder, which costs time, never accuracy.
    from ._exact_kernel import on_facet_planes

    if len(quads) * len(planes) <= _ALL_FACETS_BELOW:
        # few enough to test every facet: no tree to build (half the 8 x 8 open plates' setup)
        candidates = np.broadcast_to(np.arange(len(planes)), (len(quads), len(planes)))
    else:
        candidates = _nearest_planes(quads, planes, scale)  # (n, c) facet indices
    # compiled: the (n, c, 4) distances and their gathers were half the open plates' setup
    return ~on_facet_planes(np.ascontiguousarray(quads, dtype=np.float64), np.ascontiguousarray(planes),
                            np.ascontiguousarray(candidates, dtype=np.int64), tol)


def _on_facet_planes_numpy(quads: np.ndarray, planes: np.ndarray, candidates: np.ndarray, tol: float) -> np.ndarray:
    """Reference for ``_exact_kernel.on_facet_planes`` (the former numpy form)."""
    dist = np.einsum("ncd,nkd->nck", planes[candidates, :3], quads) + planes[candidates, 3][..., None]
    return (np.abs(dist) <= tol).all(axis=2).any(axis=1)


def _nearest_planes(quads: np.ndarray, planes: np.ndarray, scale: float, k: int = 8) -> np.ndarray:
    """(n, 2k) indices of the hull facets whose planes are nearest each patch's plane, either sign."""
    normal = polygon_normals(quads)  # zero for a degenerate patch: it matches no facet, stays an occluder
    offset = -np.einsum("nc,nc->n", normal, quads.mean(axis=1)) / scale
    keys = np.column_stack([normal, offset])
    tree = cKDTree(np.column_stack([planes[:, :3], planes[:, 3] / scale]))
    k = min(k, len(planes))
    found = [tree.query(sign * keys, k=k)[1].reshape(len(quads), k) for sign in (1.0, -1.0)]
    return np.concatenate(found, axis=1)


@functools.lru_cache(maxsize=1)
def _gauss_table():
    """The cells' Gauss-Legendre table, built once (1.6 ms a fill: 3% of the blocked 8 x 8 plates')."""
    from ._cells_kernel import gauss_table

    return gauss_table(8)


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


def _corner_extrapolation(values: np.ndarray, order: int) -> np.ndarray:
    """(c, 4) the polynomial through the four children's Gauss points of each cell (values
    (c, 4, order**2), children and points in :func:`square_cell_points`' order), at the cell's
    corners in :func:`square_cell_corners`' order."""
    nodes = gauss_legendre_01(order)[0]
    grid_nodes = np.concatenate([0.5 * nodes, 0.5 + 0.5 * nodes])  # along u and along v
    n = len(grid_nodes)
    # Lagrange basis at 0 and 1: weights[e, k] = L_k(e)
    weights = np.array([[np.prod([(e - grid_nodes[m]) / (grid_nodes[k] - grid_nodes[m]) for m in range(n) if m != k])
                         for k in range(n)] for e in (0.0, 1.0)])
    grid = np.zeros((len(values), n, n))
    for child, (cu, cv) in enumerate(((0, 0), (1, 0), (0, 1), (1, 1))):
        grid[:, cu * order:(cu + 1) * order, cv * order:(cv + 1) * order] = values[:, child].reshape(-1, order, order)
    corners = ((0, 0), (1, 0), (1, 1), (0, 1))
    return np.stack([np.einsum("cuv,u,v->c", grid, weights[eu], weights[ev]) for eu, ev in corners], axis=1)


def _occluder_lists(rows: np.ndarray, occ: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """(starts (m + 1,), occ sorted by row): pair p's occluders are ``occ[starts[p]:starts[p + 1]]``."""
    srt = np.argsort(rows, kind="stable")
    starts = np.zeros(m + 1, np.int64)
    np.cumsum(np.bincount(rows, minlength=m), out=starts[1:])
    return starts, np.ascontiguousarray(occ[srt], dtype=np.int64)


def _rows_of(rows: np.ndarray, occ: np.ndarray, sel: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """The (pair, occluder) rows of pairs ``sel`` (of m), pairs renumbered 0..len(sel)-1."""
    where = np.full(m, -1)
    where[sel] = np.arange(len(sel))
    keep = where[rows] >= 0
    return where[rows[keep]], occ[keep]


def _owned(lists: tuple[np.ndarray, ...], sel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(starts, occ, owner): the lists of rows ``sel`` (an index or a slice) of ``lists``,
    (starts, occ[, owner]), each row naming the CSR list it reads (``owner``) instead of a copy
    of it: the rays' subsets and chunks copied their lists, 9 times over for the 3x3 points of a
    receiver (7% of a 300-cube room's solve)."""
    starts, occ = lists[0], lists[1]
    owner = lists[2] if len(lists) > 2 else np.arange(len(starts) - 1)
    return starts, occ, owner[sel]


def _subset_lists(starts: np.ndarray, occ: np.ndarray, sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The occluder lists of pairs ``sel`` (in that order)."""
    count = starts[sel + 1] - starts[sel]
    new = np.zeros(len(sel) + 1, np.int64)
    np.cumsum(count, out=new[1:])
    idx = np.repeat(starts[sel] - new[:-1], count) + np.arange(new[-1])
    return new, occ[idx]


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
    closed : bool, default: True
        Drop, for each partly occluded pair, the faces of closed objects that cannot be the
        first to block it (``_closed``: those with the whole source behind their plane, when
        both patches have the same winding number with respect to the object).
    """

    def __init__(self, quads: np.ndarray, normals: np.ndarray, groups: np.ndarray, scale: float, *,
                 samples: int = 2, max_samples: int = 4, cull: bool = True, closed: bool = True):
        # contiguous: a strided view would compile a second copy of each ray and shadow kernel
        quads = self.quads = np.ascontiguousarray(quads, dtype=np.float64)
        normals = self.normals = np.ascontiguousarray(normals, dtype=np.float64)
        self.groups = np.asarray(groups)
        self.closed = closed and cull
        # (column, labels) of winding_labels, on first use; a dict so that shallow copies (the
        # hierarchy's views, one a batch) share it: each copy computed its own, 2% of the
        # 300-cube furnace room's refinement
        self._windings: dict = {}
        self._windings_for = quads
        self.scale = scale
        self.samples = samples
        self.max_samples = max(max_samples, samples)
        self.cull = cull
        mask = occluder_mask(quads, scale) if cull else np.ones(len(quads), bool)
        self.n_occluders = int(mask.sum())
        self._occluder_patches = mask
        self.occluders = build_occluders(quads, normals, np.asarray(groups), mask, scale)
        self._lo = quads.min(axis=1)
        self._hi = quads.max(axis=1)
        # the Embree scene of the occluder patches, on first use: a dict, so that shallow copies
        # (the hierarchy's views of its elements, whose ``quads`` are not the patches) share it
        self._tracers: dict = {}
        self._patch_quads = quads
        self._area = None  # patch areas, on first use (receive_on_source, _settle_capped)
        self.n_rays = 0
        self.n_exact_rows = 0
        self.n_closed_culled = 0  # (pair, occluder) rows left out by closed-object culling
        # leave out occluders behind either patch's plane in the classification (the hierarchy's
        # elements: a cube face's element kept the faces of its cube that touch it)
        self.cull_behind = False
        # test every undecided occluder of a walk against the pair's hull, as classify_listed
        # tests its candidates (the hierarchy's elements: see _exact_kernel._classify_pair)
        self.hull_always = False
        # stop a walk at this many undecided occluders (0: never; the hierarchy's elements: see
        # _exact_kernel._classify_pair and hierarchical._links.LIST_CAP)
        self.list_cap = 0
        # receiver points whose shadow union GEOS could not compute directly (see _exact._unite)
        self.union_fallbacks: dict[str, int] = {}

    def union_note(self) -> str | None:
        """A note counting the receiver points whose shadow union needed a fallback, or None."""
        snapped = self.union_fallbacks.get("snapped", 0)
        lost = self.union_fallbacks.get("lower_bound", 0)
        if not snapped and not lost:
            return None
        note = (f"exact shadows: GEOS failed to unite the hidden polygons at {snapped + lost} receiver "
                f"point(s) (degenerate overlaps); {snapped} were united again with snap-rounding")
        if lost:
            note += f", {lost} use their largest hidden polygon (a lower bound of the shadow)"
        return note

    # ------------------------------------------------------------------ classification
    def classify(self, i: np.ndarray, j: np.ndarray, *, runs: bool = True
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Classify pairs (i receives from j) before any ray.

        ``runs`` False walks each pair alone, where runs of pairs sharing a patch are known to
        be undecided as a whole (the same status either way).

        Returns
        -------
        status : (m,) int8
            ``FREE`` (nothing blocks), ``FULL`` (some occluder blocks every segment) or
            ``MAYBE`` (partly occluded).
        rows, occluder : (t,) int
            For the partly occluded pairs: the pair (index into i, j) and each occluder polygon
            that may block it, sorted by pair.
        """
        if not self.cull:
            return self._classify(self.quads[i], self.quads[j], np.minimum(self._lo[i], self._lo[j]),
                                  np.maximum(self._hi[i], self._hi[j]))
        i, j = np.asarray(i), np.asarray(j)
        normals = self.normals if self.cull_behind else None
        status, rows, occ = self._classify_pairs(self.quads, i, self.quads, j, normals, runs)
        if self.closed and len(rows) and self.quads is self._windings_for:  # not for the hierarchy's elements
            status, rows, occ = self._cull_closed(i, j, status, rows, occ)
        return status, rows, occ

    def classify_listed(self, i: np.ndarray, j: np.ndarray, starts: np.ndarray, candidates: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`classify` against given possible occluders instead of the BVH: pair t
        (i[t] receives from j[t]) against ``candidates[starts[t]:starts[t + 1]]``.

        Only right where those hold every occluder the pair's own walk would find undecided or
        full, as the undecided occluders of a pair whose segments hold the pair's (a link's
        children in the hierarchy). No closed-object culling.
        """
        from ._exact_kernel import classify_listed

        m = len(i)
        occ = self.occluders
        if occ.n_occluders == 0 or m == 0:
            return np.full(m, FREE, np.int8), np.zeros(0, np.int64), np.zeros(0, np.int64)
        normals, behind = self._behind_arguments(self.normals if self.cull_behind else None)
        tol = PLANE_REL * self.scale
        status, out_starts, out = classify_listed(self.quads, np.ascontiguousarray(i, dtype=np.int64), self.quads,
                                                  np.ascontiguousarray(j, dtype=np.int64), normals, normals,
                                                  np.ascontiguousarray(starts, dtype=np.int64),
                                                  np.ascontiguousarray(candidates, dtype=np.int64), occ.polys,
                                                  occ.normal, occ.center, occ.inward, occ.lo, occ.hi, tol, tol, behind)
        return status, np.repeat(np.arange(m), np.diff(out_starts)), out

    def _behind_arguments(self, normals):
        """(normals, behind) for the classification kernels: the patches' unit normals and the
        tolerance of the behind-the-plane test, or a placeholder and -1 (no test) for None."""
        if normals is None:
            return np.zeros((1, 3)), -1.0
        return np.ascontiguousarray(normals, dtype=np.float64), PLANE_REL * self.scale

    def _cull_closed(self, i, j, status, rows, occ):
        """Leave out the closed objects' faces that a partly occluded pair can do without."""
        from ._closed import closed_cull, winding_labels

        if "labels" not in self._windings:
            self._windings["labels"] = winding_labels(self.quads, self.normals, self.groups, self.scale)
        column, labels = self._windings["labels"]
        keep = closed_cull(self.quads, i, j, rows, occ, self.occluders, column, labels, PLANE_REL * self.scale)
        if self.list_cap > 0:
            # a list the walk cut short keeps its length: list_cap entries mark it so for the
            # hierarchy, whose children take it as incomplete (Undecided.cut)
            keep |= (np.bincount(rows, minlength=len(status)) >= self.list_cap)[rows]
        if keep.all():
            return status, rows, occ
        self.n_closed_culled += int((~keep).sum())
        left = np.bincount(rows[keep], minlength=len(status))
        status = status.copy()
        status[(status == MAYBE) & (left == 0)] = FREE  # every maybe occluder was one the pair can do without
        return status, rows[keep], occ[keep]

    def _classify_pairs(self, va, ia, vb, ib, normals=None, runs=True):
        """Compiled classification of pairs (va[ia], vb[ib]): BVH walk and exact test fused.

        With ``normals`` (unit, per row of both va and vb), occluders behind either patch's
        plane are left out (``cull_behind``)."""
        from ._exact_kernel import classify_pairs

        m = len(ia)
        occ = self.occluders
        if occ.n_occluders == 0 or m == 0:
            return np.full(m, FREE, np.int8), np.zeros(0, np.int64), np.zeros(0, np.int64)
        va = np.ascontiguousarray(va, dtype=np.float64)
        vb = np.ascontiguousarray(vb, dtype=np.float64)
        status = np.empty(m, np.int8)
        rows, occs = [], []
        normals, behind = self._behind_arguments(normals)
        for s in range(0, m, CHUNK_CLASSIFY):
            e = min(m, s + CHUNK_CLASSIFY)
            st, starts, k = classify_pairs(va, np.ascontiguousarray(ia[s:e], dtype=np.int64), vb,
                                           np.ascontiguousarray(ib[s:e], dtype=np.int64), occ.polys, occ.normal,
                                           occ.center, occ.inward, occ.lo, occ.hi, occ.node_lo, occ.node_hi,
                                           occ.node_left, occ.node_right, occ.node_start, occ.node_count,
                                           occ.order, PLANE_REL * self.scale, PLANE_REL * self.scale,
                                           normals, normals, behind, runs, self.hull_always, self.list_cap)
            status[s:e] = st
            rows.append(s + np.repeat(np.arange(e - s), np.diff(starts)))
            occs.append(k)
        return status, np.concatenate(rows), np.concatenate(occs)

    def _classify(self, vi, vj, lo, hi):
        """Reference classification in numpy (and the path for ``cull=False``)."""
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
                local = np.full(len(i), -1)
                local[part] = np.arange(len(part))
                out[part] = self.ray_fraction(i[part], j[part], rows=local[rows], occ=occ)
        return out

    def ray_fraction(self, i: np.ndarray, j: np.ndarray, samples: int | None = None,
                     max_samples: int | None = None, *, rows: np.ndarray | None = None,
                     occ: np.ndarray | None = None, blind: bool = True) -> np.ndarray:
        """(m,) kernel-weighted unblocked fraction by stratified rays, refined where they disagree.

        Each ray from a sample x on i to a sample y on j is weighted by the area weights of both
        samples times the differential form factor cos_i cos_j / r^2, which is zero where y is
        behind i's plane: rays never count the hidden part of a source that straddles the
        receiver's horizon.

        With culling on (the default), each ray is intersected only with the occluder polygons
        that the classification left undecided for its pair (``rows``/``occ`` from
        :meth:`classify`, with ``rows`` indexing i and j; classified here if not given), in
        float64. With ``cull=False`` every ray is cast through Embree against every patch.

        Pairs whose rays all carry no weight take exact shadows (:meth:`blind_fraction`), or
        with ``blind=False`` come back NaN, for the caller to resolve once however many rays
        it traces.
        """
        s0 = samples or self.samples
        s1 = max(max_samples or self.max_samples, s0)
        i = np.ascontiguousarray(i, dtype=np.int64)
        j = np.ascontiguousarray(j, dtype=np.int64)
        key = i.astype(np.uint64) * np.uint64(len(self.quads)) + j.astype(np.uint64)
        lists = None
        full = np.zeros(len(i), bool)
        if self.cull:
            if rows is None or occ is None:
                status, rows, occ = self.classify(i, j)
                full = status == FULL
            lists = _occluder_lists(rows, occ, len(i))
        frac, agree = self._patch_rays(i, j, s0, key, 1, lists)
        if s1 > s0 and not agree.all():
            redo = np.flatnonzero(~agree)
            sub = None if lists is None else _owned(lists, redo)
            frac[redo] = self._patch_rays(i[redo], j[redo], s1, key[redo], 3, sub)[0]
        unseen = np.flatnonzero(np.isnan(frac) & ~full)
        if len(unseen) and blind:
            sub = None if lists is None else _subset_lists(*lists, unseen)
            frac[unseen] = self._blind_fraction(i[unseen], j[unseen], sub)
        frac[full] = 0.0
        return frac

    def blind_fraction(self, i: np.ndarray, j: np.ndarray, rows: np.ndarray, occ: np.ndarray,
                       orders: tuple[int, ...] = BLIND_ORDERS) -> np.ndarray:
        """(m,) :meth:`_blind_fraction` of pairs (i, j) whose possible occluders are ``rows``/``occ``
        (as from :meth:`classify`, ``rows`` indexing i and j)."""
        lists = _occluder_lists(rows, occ, len(i))
        return self._blind_fraction(np.asarray(i, np.int64), np.asarray(j, np.int64), lists, orders)

    def _blind_fraction(self, i, j, lists, orders: tuple[int, ...] = BLIND_ORDERS):
        """Visible fraction, by exact shadows at Gauss points, of pairs whose rays all carried no
        weight: each sample on one patch saw the other's samples on or behind its horizon.

        The pair still exchanges light where the patches straddle each other's planes, and
        rays cannot say how much of it is blocked. Counting such a pair as unblocked, as until
        2026-12-06, let a roof piece of View3D's hall see a wall of another room through the
        wall between them (F = 2.5e-6 where 0 is exact: its row summed to 1 + 2.6e-6).
        The points go on i, else (where none of them sees j) on j, which has the same visible
        fraction by reciprocity, then both again at each finer rule of ``orders``; a pair no
        point sees counts as unblocked.
        """
        frac = np.full(len(i), np.nan)
        if lists is None:  # cull=False: the exact classification, not "every patch may block"
            status, rows, occ = self._classify_pairs(self.quads, i, self.quads, j)
            frac[status == FULL] = 0.0
        else:
            starts, occ = lists
            rows = np.repeat(np.arange(len(i)), np.diff(starts))
        for order in orders:
            for recv, src in ((i, j), (j, i)):
                left = np.flatnonzero(np.isnan(frac))
                if len(left):
                    sub_rows, sub_occ = _rows_of(rows, occ, left, len(i))
                    frac[left] = self.exact_fraction(recv[left], src[left], sub_rows, sub_occ, order, blind=np.nan)
        return np.where(np.isnan(frac), 1.0, frac)

    def exact_fraction(self, i: np.ndarray, j: np.ndarray, rows: np.ndarray, occ: np.ndarray, order: int,
                       blind: float = 1.0) -> np.ndarray:
        """(m,) visible fraction by exact shadows at ``order**2`` Gauss points of each receiver.

        ``rows``/``occ`` list the occluder polygons that may block each pair (from
        :meth:`classify`). The fraction is ``1 - sum_q w_q F(x_q -> hidden) / sum_q w_q F(x_q -> j)``,
        or ``blind`` where no point sees any of j (all of it on or behind their horizons).
        """
        i = np.ascontiguousarray(i, dtype=np.int64)
        j = np.ascontiguousarray(j, dtype=np.int64)
        out = np.ones(len(i))
        lists = _occluder_lists(rows, occ, len(i))
        step = max(1, CHUNK_SHADOWS // (order * order))
        for s in range(0, len(i), step):
            e = min(len(i), s + step)
            # the points of this chunk's receivers only: those of every patch, at order 16 for
            # a few pairs, took 19 GB on a terrain of a million triangles
            pts, w = patch_points(self.quads[i[s:e]], order)
            unocc, hidden = self._points_hidden(pts, i[s:e], j[s:e], lists, np.arange(s, e))
            total = (unocc * w).sum(axis=1)
            lost = (hidden * w).sum(axis=1)
            out[s:e] = np.where(total > 0, 1.0 - lost / np.where(total > 0, total, 1.0), blind)
        return out

    def adaptive_hidden(self, i: np.ndarray, j: np.ndarray, rows: np.ndarray, occ: np.ndarray,
                        atol: float | np.ndarray,
                        order: int = 2, max_depth: int = SHADOW_MAX_DEPTH, penumbra_depth: int = 0) -> np.ndarray:
        """(m,) hidden part of partly occluded pairs, by receiver cells refined where the shadow varies.

        The mean over receiver i of F(x -> part of j hidden from x), integrated on cells of i's
        parameter domain, about square ones to start with (:meth:`_root_cells`): a cell is split
        in four while its ``order**2``-point rule and its four children's disagree by more than
        ``atol`` times i's area times the cell's longest side over the patch's, so the cells
        along a shadow's edge, the only ones that do
        not converge fast, sum to about ``atol`` (absolute, in form-factor units) per patch
        length of edge. A fixed rule smears an edge across the patch (a plate with a centred
        blocker erred by 9%; a closed room of boxes had rows 1.7e-3 from 1); the refinement
        spends points only along the edges. ``rows``/``occ`` list each pair's possible
        occluders (:meth:`classify`); ``atol`` is one tolerance or one per pair. The obstructed
        factor is ``unoccluded - hidden``.

        Down to ``penumbra_depth`` levels, a square whose points are all lit (or all in full
        shadow) is split anyway where the shadow may cross it (:meth:`_square_occluders`):
        a penumbra narrower than the points' spacing passes between them unseen (an outer cap
        0.4 m above an inner prism's cap: 3% of the pair's factor). It costs points wherever an
        occluder may reach a square (the Cornell box's default fill took minutes, not seconds),
        so the fill asks for it only at view_factors' tolerances. To the same depth, a cell is
        split where the hidden factor at one of its corners misses the polynomial through its
        children's points (:func:`_corner_extrapolation`): a kink between the outermost points
        and the cell's side. At any depth, a square whose points are all in full shadow and
        that its occluders together hide (:meth:`_squares_covered`) stops there, with its
        whole unoccluded factor from the area kernel (:meth:`_squares_unoccluded`).
        """
        i = np.ascontiguousarray(i, dtype=np.int64)
        j = np.ascontiguousarray(j, dtype=np.int64)
        m = len(i)
        hidden = np.zeros(m)
        if not m:
            return hidden
        atol = np.broadcast_to(np.asarray(atol, dtype=float), (m,))
        starts, occ_sorted = _occluder_lists(rows, occ, m)
        # pairs in chunks of about CHUNK_SQUARE_PAIRS list entries (memory); each pair's squares
        # do not depend on the others', so the chunks give the same factors bit for bit
        weight = np.cumsum(np.diff(starts) + 1)
        edges = np.r_[0, np.flatnonzero(np.diff(weight // CHUNK_SQUARE_PAIRS)) + 1, m]
        for s, e in zip(edges[:-1], edges[1:]):
            lists = _subset_lists(starts, occ_sorted, np.arange(s, e))
            hidden[s:e] = self._adaptive_chunk(i[s:e], j[s:e], lists, atol[s:e], order, max_depth, penumbra_depth)
        return hidden

    def _adaptive_chunk(self, i, j, pair_lists, atol, order, max_depth, penumbra_depth) -> np.ndarray:
        """:meth:`adaptive_hidden` of pairs (i, j) with one occluder list each, ``pair_lists``."""
        m = len(i)
        hidden = np.zeros(m)
        pair, corner, size, share = self._root_cells(i)
        lists, may_cross = self._square_occluders(i, j, _subset_lists(*pair_lists, pair), pair, corner, size)
        coarse, area, state, _ = self._cell_hidden(i, j, lists, pair, corner, size, order)
        patch_area = np.bincount(pair, weights=area, minlength=m)  # the root cells tile the patches
        offsets = np.array([[0.0, 0.0], [0.5, 0.0], [0.0, 0.5], [0.5, 0.5]])
        for depth in range(max_depth):
            pair4 = np.repeat(pair, 4)
            size4 = np.repeat(size / 2, 4, axis=0)
            corner4 = np.repeat(corner, 4, axis=0) + np.tile(offsets, (len(pair), 1)) * np.repeat(size, 4, axis=0)
            child_lists, child_may_cross = self._square_occluders(
                i, j, _subset_lists(*lists, np.repeat(np.arange(len(pair)), 4)), pair4, corner4, size4)
            child, child_area, child_state, child_values = self._cell_hidden(i, j, child_lists, pair4, corner4,
                                                                             size4, order)
            fine = child.reshape(-1, 4).sum(axis=1)
            # the cell's share of the pair's tolerance follows its side, not its area: a cell
            # across a shadow's edge keeps a fixed relative error however small it gets, so an
            # area share split every such cell to max_depth (the Cornell box at fine: 787 s,
            # not 24 s); by side, the cells along an edge of the patch's length sum to about atol
            allowed = atol[pair] * patch_area[pair] * share
            done = np.abs(fine - coarse) <= allowed
            penumbra = depth < min(penumbra_depth, max_depth - 1)
            agree = state & np.bitwise_and.reduce(child_state.reshape(-1, 4), axis=1)
            # a square that its occluders together hide (behind a wall of many surfaces no one
            # of them hides it: a roof piece of View3D's hall behind 65+ took 6 minutes) hides its
            # whole unoccluded factor, which the area kernel gives to any tolerance where its
            # points' rule may not converge (near the source: that piece split half its squares
            # at every level). A square that one occluder hides keeps its points: that test
            # counts crossings on an edge as inside, and a square touching the occluder's plane
            # there (two faces of a box) was found hidden where its points are lit.
            whole = np.zeros(len(pair), bool)
            dark = np.flatnonzero(may_cross & ((agree & 2) != 0))
            if len(dark):
                whole[dark] = self._squares_covered(i, j, lists, dark, pair[dark], corner[dark], size[dark])
            if penumbra:
                # points all lit (or all in shadow) agree whatever passes between them: such a
                # cell is done only if no occluder can shadow part of it
                same = agree != 0
                done &= ~(same & may_cross)
                # a kink of the hidden factor between the outermost points and the cell's side
                # (where a shadow starts, or two overlap) passes unseen too: both rules see one
                # smooth branch (a box's shadow on a cube face: 1.8e-5 of its factor, at every
                # depth). A straight kink that misses every point cuts off a corner (a half plane
                # meeting a square holds one of its corners), where the children's points'
                # polynomial then misses the value
                check = np.flatnonzero(done & ~same)
                if len(check):
                    at = self._corner_hidden(i, j, lists, check, pair[check], corner[check], size[check])
                    miss = np.abs(at - _corner_extrapolation(child_values.reshape(-1, 4, order * order)[check],
                                                             order)).max(axis=1)
                    done[check] = miss * KINK_BAND * area[check] <= allowed[check]
            whole = np.flatnonzero(whole)
            if len(whole):
                fine[whole] = self._squares_unoccluded(i, j, pair[whole], corner[whole], size[whole], fine[whole],
                                                       allowed[whole])
                done[whole] = True
            if depth == max_depth - 1:
                done[:] = True
            np.add.at(hidden, pair[done], fine[done])
            again = np.repeat(~done, 4)
            pair, corner, size, share = pair4[again], corner4[again], size4[again], np.repeat(share / 2, 4)[again]
            lists, may_cross = _subset_lists(*child_lists, np.flatnonzero(again)), child_may_cross[again]
            coarse, area, state = child[again], child_area[again], child_state[again]
            if not len(pair):
                break
        return np.where(patch_area > 0, hidden / np.where(patch_area > 0, patch_area, 1.0), 0.0)

    def _root_cells(self, i: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The first cells of :meth:`adaptive_hidden` on receivers ``i``: each patch cut into
        about square cells, k_u x k_v in its parameter domain (a 0.77 x 4.8 m wall takes 1 x 6).

        On one parameter square per patch, an elongated wall's cells stayed as elongated at every
        level, 6 levels only 1.2 cm across it but 7.5 cm along it: shadows' edges along the wall
        were smeared and a closed 8-sided prism shell's rows stayed 6.7e-6 from 1.

        Returns each cell's pair, (u, v) corner, (u, v) sides and its longest side as a share of
        its patch's longest side (its share of the pair's tolerance).
        """
        q = self._cell_quads[i]
        side = lambda a, b: np.linalg.norm(q[:, b] - q[:, a], axis=1)  # noqa: E731
        lu = np.maximum(side(0, 1), side(3, 2))
        lv = np.maximum(side(0, 3), side(1, 2))
        short = np.maximum(np.minimum(lu, lv), 1e-300)
        ku = np.clip(np.floor(lu / short), 1, MAX_ROOT_CELLS).astype(np.int64)
        kv = np.clip(np.floor(lv / short), 1, MAX_ROOT_CELLS).astype(np.int64)
        count = ku * kv
        pair = np.repeat(np.arange(len(i)), count)
        k = np.arange(len(pair)) - np.repeat(np.cumsum(count) - count, count)  # the cell within its patch
        su, sv = 1.0 / ku[pair], 1.0 / kv[pair]
        corner = np.stack([(k // kv[pair]) * su, (k % kv[pair]) * sv], axis=1)
        longest = np.maximum(lu, lv)[pair]
        share = np.where(longest > 0, np.maximum(su * lu[pair], sv * lv[pair]) / np.where(longest > 0, longest, 1.0),
                         1.0)
        return pair, corner, np.stack([su, sv], axis=1), share

    def receive_on_source(self, i: np.ndarray, j: np.ndarray, rows: np.ndarray, occ: np.ndarray) -> np.ndarray:
        """(m,) bool: where pair (i, j)'s shadow is smoother integrated over j than over i.

        An occluder's penumbra on a receiver r is about w_s d_r / d_s wide (w: patch size, d: the
        patch's distance to the occluder), sharp where r touches it and slow for the squares of
        :meth:`adaptive_hidden` to resolve; relative to r's own size it is widest on the patch
        with the larger d / w. So j receives where its nearest possible occluder is farther, in
        units of its size, than i's. (A floor patch straddling the foot of a box's wall: on its
        own squares F to a face of the next box came out 0.03529 for 0.02771, 27% high; from
        that face, 0.1 m from the wall, 0.0277089.)
        """
        width = np.sqrt(self._areas())
        o = self.occluders

        def nearest(patch):
            """Gap between the boxes of each pair's patch and its nearest possible occluder in
            front of it (one behind its plane, such as a box's next face, shadows nothing there)."""
            p = patch[rows]
            gap = np.linalg.norm(np.maximum(np.maximum(o.lo[occ] - self._hi[p], self._lo[p] - o.hi[occ]), 0.0), axis=1)
            height = np.einsum("rvc,rc->rv", o.polys[occ] - self.quads[p, :1], self.normals[p]).max(axis=1)
            d = np.full(len(patch), np.inf)
            np.minimum.at(d, rows, np.where(height > PLANE_REL * self.scale, gap, np.inf))
            return d

        d_i, d_j = nearest(np.asarray(i)), nearest(np.asarray(j))
        smoother = d_j * width[i] > d_i * width[j]
        # a large receiver sees a small source's shadows as features far smaller than itself,
        # which pass between its points unseen: the smaller patch receives
        w_i, w_j = width[i], width[j]
        lopsided = np.maximum(w_i, w_j) > RECEIVE_SMALLER_WIDTHS * np.minimum(w_i, w_j)
        return np.where(lopsided, w_j < w_i, smoother)

    def _square_occluders(self, i, j, lists, pair, corner, size):
        """Each receiver square's own possible occluders, and whether a shadow may cross it.

        ``lists`` holds one occluder list per square (its pair's, or its parent square's); each
        is classified against the segments from the square (corner, size on receiver i[pair]) to
        source j[pair] (:meth:`classify`'s test): the occluders that miss them are dropped, and
        one that hides all of them stands alone. A shadow may cross the square where some
        occluder hides part of it and none hides all. A square 1/64 of its patch across sits
        behind a few of the 20-60 occluders of a pair in View3D's 398-surface hall, and each of
        its points was clipped against all of them.

        Returns ((starts, occ) one list per square, may_cross (c,) bool).
        """
        starts, occ = lists
        count = np.diff(starts)
        row = np.repeat(np.arange(len(pair)), count)
        state = np.empty(len(row), np.int8)
        step = max(1, CHUNK_TRIPLES // max(1, int(count.max(initial=1))))
        for s in range(0, len(pair), step):
            e = min(len(pair), s + step)
            a, b = starts[s], starts[e]
            if a == b:
                continue
            squares = square_cell_corners(self._cell_quads[i[pair[s:e]]], corner[s:e, 0], corner[s:e, 1], size[s:e])
            state[a:b] = _occluders.classify_rows(self.occluders, squares[row[a:b] - s],
                                                  self.quads[j[pair[row[a:b]]]], occ[a:b], self.scale)
        full = state == FULL
        hidden = np.bincount(row[full], minlength=len(pair)) > 0
        keep = (state == MAYBE) & ~hidden[row]
        first = np.flatnonzero(full)
        first = first[np.r_[True, row[first[1:]] != row[first[:-1]]]] if len(first) else first
        keep[first] = True
        kept = _occluder_lists(row[keep], occ[keep], len(pair))
        return kept, (np.diff(kept[0]) > 0) & ~hidden

    def _cell_hidden(self, i, j, lists, pair, corner, size, order):
        """Integral of F(x -> hidden) over receiver cells (pair, corner, size), their areas, their
        points' state (bit 1 if all of them are lit, bit 2 if all are in full shadow) and the
        hidden factor at each of their points; ``lists``: one occluder list per cell."""
        out = np.zeros(len(pair))
        area = np.zeros(len(pair))
        state = np.zeros(len(pair), np.int8)
        values = np.zeros((len(pair), order * order))
        step = max(1, CHUNK_SHADOWS // (order * order))
        for s in range(0, len(pair), step):
            e = min(len(pair), s + step)
            p = pair[s:e]
            pts, w = square_cell_points(self._cell_quads[i[p]], corner[s:e, 0], corner[s:e, 1], size[s:e], order)
            unocc, values[s:e] = self._points_hidden(pts, i[p], j[p], lists, np.arange(s, e))
            out[s:e] = (values[s:e] * w).sum(axis=1)
            area[s:e] = w.sum(axis=1)
            lit = (values[s:e] <= SATURATED_REL * unocc).all(axis=1)
            dark = (values[s:e] >= (1 - SATURATED_REL) * unocc).all(axis=1)
            state[s:e] = lit.astype(np.int8) | (dark.astype(np.int8) << 1)
        return out, area, state, values

    def _corner_hidden(self, i, j, lists, cells, pair, corner, size) -> np.ndarray:
        """(c, 4) hidden factors at the corners of cells (pair, corner, size), in
        :func:`square_cell_corners`' order; their occluders are rows ``cells`` of ``lists``."""
        out = np.zeros((len(pair), 4))
        step = max(1, CHUNK_SHADOWS // 4)
        for s in range(0, len(pair), step):
            e = min(len(pair), s + step)
            p = pair[s:e]
            pts = square_cell_corners(self._cell_quads[i[p]], corner[s:e, 0], corner[s:e, 1], size[s:e])
            out[s:e] = self._points_hidden(pts, i[p], j[p], lists, cells[s:e])[1]
        return out

    def _squares_covered(self, i, j, lists, cells, pair, corner, size) -> np.ndarray:
        """(c,) bool: cells (pair, corner, size) hidden from their source by the union of their
        occluders (rows ``cells`` of ``lists``), :func:`_exact_kernel.covered_squares`."""
        from ._exact_kernel import covered_squares

        if not len(pair):
            return np.zeros(0, bool)
        starts, cell_occ = _subset_lists(*lists, cells)
        corners = square_cell_corners(self._cell_quads[i[pair]], corner[:, 0], corner[:, 1], size)
        o = self.occluders
        return covered_squares(np.ascontiguousarray(corners), corners.mean(axis=1), self.normals[i[pair]],
                               self.quads[j[pair]], self.normals[j[pair]], starts, cell_occ, o.polys, o.normal,
                               PLANE_REL * self.scale, MAX_UNION)

    def _squares_unoccluded(self, i, j, pair, corner, size, estimate, allowed) -> np.ndarray:
        """(c,) unoccluded factor of cells (pair, corner, size) to their sources, times the
        cells' areas, each within about ``allowed`` of it (``estimate``: a first value of it).

        One call of the area kernel per decade of relative tolerance, from 1e-3 to 1e-9."""
        corners = square_cell_corners(self._cell_quads[i[pair]], corner[:, 0], corner[:, 1], size)
        centroid, area = centroids_and_areas(corners)
        ratio = allowed / np.maximum(np.abs(estimate), np.finfo(float).tiny)
        decade = np.clip(np.floor(np.log10(np.maximum(ratio, 1e-300))), -9, -3)
        out = np.zeros(len(pair))
        for d in np.unique(decade):
            sel = np.flatnonzero(decade == d)
            out[sel] = pair_factors(corners[sel], self.normals[i[pair[sel]]], centroid[sel], area[sel],
                                    np.arange(len(sel)), np.arange(len(sel)), rtol=10.0 ** d,
                                    sources=self.quads[j[pair[sel]]])
        return out * area

    def _points_hidden(self, pts, i, j, lists, p):
        """Unoccluded and hidden factors (c, q) at receiver points ``pts`` (c, q, 3) of pairs
        (i, j), with the possible occluders of rows ``p`` of ``lists``."""
        from ._exact_kernel import exact_pairs

        c, q = pts.shape[:2]
        starts, cell_occ = _subset_lists(*lists, p)
        # the kernel reads receiver points and normals by i and source polygons and normals by j:
        # cell rows 0..c-1 are receivers, c..2c-1 their sources
        normals = np.concatenate([self.normals[i], self.normals[j]])
        sources = np.concatenate([self.quads[j], self.quads[j]])
        o = self.occluders
        unocc, hidden, ok = exact_pairs(np.ascontiguousarray(pts), normals, sources, np.arange(c), np.arange(c, 2 * c),
                                        starts, cell_occ, o.polys, o.normal, PLANE_REL * self.scale, MAX_UNION)
        self.n_exact_rows += len(cell_occ) * q
        if not ok.all():
            hidden[~ok] = self._hidden_at(pts, i, j, starts, cell_occ, ~ok)
        return unocc, np.minimum(hidden, unocc)

    def exact_hidden(self, i: np.ndarray, j: np.ndarray, rows: np.ndarray, occ: np.ndarray, rtol: float,
                     unoccluded: np.ndarray, max_points: int = 4096, penumbra_depth: int = 0,
                     max_depth: int = SHADOW_MAX_DEPTH) -> np.ndarray:
        """(m,) hidden part of partly occluded pairs, integrated over shadow-aligned receiver cells.

        The mean over receiver i (its part in front of j's plane) of F(x -> part of j hidden
        from x): the pair's obstructed factor is ``unoccluded - hidden``. The receiver is cut
        along the lines where the hidden polygon changes shape (``_cells_kernel``), so each
        cell's integrand is smooth and its Gauss rule (picked for ``rtol``, within about
        ``max_points`` receiver points a pair) converges. A pair out of points tries again with
        ``CELL_RETRY_POINTS`` times the budget; one still not integrated tries the cells from
        j's side (mirrored by reciprocity), and then falls back to :meth:`adaptive_hidden`, to
        ``rtol`` times ``unoccluded`` (m,), the pairs' factors (at least ``CELL_FALLBACK_ATOL``),
        with ``penumbra_depth`` and ``max_depth``.
        """
        i = np.ascontiguousarray(i, dtype=np.int64)
        j = np.ascontiguousarray(j, dtype=np.int64)
        hidden = np.zeros(len(i))
        if not len(i):
            return hidden
        starts, occ_sorted = _occluder_lists(rows, occ, len(i))
        status = np.empty(len(i), np.int8)
        capped = np.empty(len(i), bool)
        for s in range(0, len(i), CHUNK_CELL_PAIRS):
            e = min(len(i), s + CHUNK_CELL_PAIRS)
            hidden[s:e], status[s:e], capped[s:e] = self._cell_pairs(
                i[s:e], j[s:e], *_subset_lists(starts, occ_sorted, np.arange(s, e)), rtol, max_points)

        def again(sel, receiver, source):
            """The pairs ``sel`` from ``receiver`` to ``source`` with the larger budget."""
            return self._cell_pairs(receiver[sel], source[sel], *_subset_lists(starts, occ_sorted, sel), rtol,
                                    max_points * CELL_RETRY_POINTS)

        # a pair whose bound asked for more points than the budget (a floor patch crossed by
        # a partition's foot: 3.6e-4 off on squares, which resolve the jump at first order)
        # tries again with a larger one; a pair short of lines or cells would be short again
        short = np.flatnonzero(status == OUT_OF_POINTS)
        if len(short):
            hidden[short], status[short], capped[short] = again(short, i, j)
        bad = np.flatnonzero(status != GOOD)
        if len(bad):
            # then from the source's side, mirrored by reciprocity: a shadow that is a thin strip
            # on the receiver can be a broad one on the source. A ceiling piece beside a light
            # hung 1 mm below it sees the floor's far end hidden from a strip 0.8 mm wide along
            # its edge; its cells split that strip four ways until the budget ran out, and the
            # squares then missed it (F 2.4e-4 high); from the floor, 192 points.
            mirror, mirror_status, _ = again(bad, j, i)
            good = mirror_status == GOOD
            hidden[bad[good]] = mirror[good] * self._mirror_ratio(i[bad[good]], j[bad[good]])
            bad = bad[~good]
        capped = np.flatnonzero((status == GOOD) & capped)
        if len(capped):
            hidden[capped] = self._settle_capped(i[capped], j[capped], *_subset_lists(starts, occ_sorted, capped),
                                                 rtol, max_points, hidden[capped])
        if len(bad):
            local = np.full(len(i), -1)
            local[bad] = np.arange(len(bad))
            keep = local[rows] >= 0
            atol = np.maximum(float(rtol) * np.asarray(unoccluded)[bad], CELL_FALLBACK_ATOL)
            hidden[bad] = self.adaptive_hidden(i[bad], j[bad], local[rows[keep]], occ[keep], atol,
                                               penumbra_depth=penumbra_depth, max_depth=max_depth)
        return hidden

    def _settle_capped(self, i, j, starts, occ, rtol, max_points, first) -> np.ndarray:
        """Hidden factors of cell pairs whose grading was capped (``first``, at ``rtol``).

        A cap means a piece's bound still failed at the deepest grading, which is harmless where
        the bound is merely pessimistic (a piece in full shadow along an occluder's edge) and not
        where the hidden factor turns about a point: an occluder's edge ending on the receiver.
        An L-shaped room's ceiling piece, whose corner is the top of the inner corner's edge, saw
        the end wall 4.5e-4 low (8.5e-7 absolute) at rtol 1e-8 and 3.7e-5 low at 1e-12; from the
        end wall, 1e-13 off. So each side is integrated at ``rtol`` and ``CAPPED_RTOL_STEP``
        times it, and the side whose two results agree better gives the tighter one, mirrored
        by reciprocity from j's side (F_ij^hidden = A_j F_ji^hidden / A_i). Agreement of the two
        sides at ``rtol`` is no shortcut: both may be singular (the ceiling's east piece and the
        floor's north piece each touch an end of that edge; at formfactor_rtol 1e-10 they agreed
        with each other and were both 6.9e-9 off).
        """
        budget = max_points * CELL_RETRY_POINTS
        own, own_status, _ = self._cell_pairs(i, j, starts, occ, rtol * CAPPED_RTOL_STEP, budget)
        coarse, coarse_status, _ = self._cell_pairs(j, i, starts, occ, rtol, budget)
        fine, fine_status, _ = self._cell_pairs(j, i, starts, occ, rtol * CAPPED_RTOL_STEP, budget)
        own_ok, coarse_ok, fine_ok = own_status == GOOD, coarse_status == GOOD, fine_status == GOOD
        ratio = self._mirror_ratio(i, j)
        own_drift = np.where(own_ok, np.abs(own - first), np.inf)
        mirror_drift = np.where(coarse_ok & fine_ok, np.abs(fine - coarse) * ratio, np.inf)
        settled = np.where(own_ok, own, first)
        return np.where(mirror_drift < own_drift, fine * ratio, settled)

    def _cell_pairs(self, i, j, starts, occ, rtol, max_points):
        """``_cells_kernel.cell_pairs`` on pairs (i, j) with occluder lists (starts, occ): the
        hidden factors, their status (``GOOD``, ``OUT_OF_POINTS``, ``OUT_OF_ROOM``) and where
        their grading was capped."""
        from ._cells_kernel import cell_pairs

        gn, gw = _gauss_table()
        o = self.occluders
        hidden, status, n_points, capped = cell_pairs(self.quads, self.normals, i, j, starts, occ, o.polys,
                                                      o.normal, o.center, o.inward, PLANE_REL * self.scale,
                                                      MAX_UNION_CELLS, float(rtol), int(max_points), gn, gw)
        self.n_exact_rows += int(n_points.sum())
        return hidden, status, capped

    def _mirror_ratio(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """A_j / A_i: a hidden factor integrated from j's side times this is i's (reciprocity);
        a receiver of zero area takes A_j, against 0 hidden."""
        area = self._areas()
        return area[j] / np.where(area[i] > 0, area[i], 1.0)

    @functools.cached_property
    def _cell_quads(self) -> np.ndarray:
        """(n, 4, 3) the receivers as :meth:`adaptive_hidden`'s cells map them: needles collapsed
        at their tips (:func:`tip_collapsed`); on first use, since fills that never reach the
        squares (rays, the shadow cells alone) need no copy of the patches."""
        return tip_collapsed(self.quads)

    def _areas(self) -> np.ndarray:
        """(n,) patch areas."""
        if self._area is None:
            self._area = centroids_and_areas(self.quads)[1]
        return self._area

    def _hidden_at(self, pts, i, j, starts, occ, where):
        """Hidden form factors at the receiver points where the kernel left them (shapely unions).

        ``pts`` (m, q, 3): the receiver points of each pair (row p belongs to pair i[p], j[p]).
        """
        p, a = np.nonzero(where)
        count = np.diff(starts)[p]
        r = np.repeat(np.arange(len(p)), count)
        k = occ[np.repeat(starts[p], count) + np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)]
        return hidden_factors(pts[p[r], a[r]], self.normals[i[p[r]]], r, self.quads[j[p[r]]],
                              self.normals[j[p[r]]], self.occluders.polys[k], self.occluders.normal[k],
                              PLANE_REL * self.scale, self.union_fallbacks)

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
        if self.cull:
            status, rows, occ = self._classify_pairs(vi, np.arange(len(j)), self.quads, np.asarray(j))
        else:
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
                                              PLANE_REL * self.scale, self.union_fallbacks)
            self.n_exact_rows += len(r)
            out[part] = np.where(unocc > 0, 1.0 - np.minimum(hidden, unocc) / np.where(unocc > 0, unocc, 1.0), 1.0)
        else:
            key = np.arange(len(part), dtype=np.uint64)
            local = np.full(len(j), -1)
            local[part] = np.arange(len(part))
            lists = _occluder_lists(local[rows], occ, len(part)) if self.cull else None
            out[part] = self.points_ray_fraction(points[part][:, None, :], normals[part], j[part], lists, key)[:, 0]
        return out

    def points_ray_fraction(self, points: np.ndarray, normals: np.ndarray, j: np.ndarray,
                            lists: tuple[np.ndarray, np.ndarray] | None, key: np.ndarray) -> np.ndarray:
        """(m, q) kernel-weighted fraction of patch j[p] that rays from each point points[p, a] see.

        ``lists`` (starts, occ): pair p's possible occluders (CSR over the m pairs, e.g. from the
        classification of the patch that holds the points: a point's segments are a subset of its
        patch's); None: Embree against the occluder patches. Each point traces ``samples**2``
        rays to the same stratified samples of j (``key``). A point wholly behind j's horizon (no
        ray carries weight) counts as seeing it: its factor to j is 0.
        """
        m, q = points.shape[:2]
        if m == 0:
            return np.ones((m, q))
        per_point = None if lists is None else _owned(lists, np.repeat(np.arange(m), q))
        frac, _ = self._weighted_fraction(points.reshape(m * q, 1, 3), np.ones((m * q, 1)), np.repeat(normals, q, axis=0),
                                          np.repeat(j, q), self.samples, np.repeat(key, q), per_point)
        return np.where(np.isnan(frac), 1.0, frac).reshape(m, q)

    # ------------------------------------------------------------------ rays
    def _occluder(self):
        """The Embree scene of the occluder patches (every patch with ``cull=False``).

        Faces on the convex hull can block only segments in their own plane, and ray ends are
        pulled off their surfaces into the hull, so leaving those faces out changes no answer
        (the classification already ignores them) and makes each ray cheaper.
        """
        if "scene" not in self._tracers:
            from ._embree import EmbreeOccluder

            quads = self._patch_quads[self._occluder_patches]
            tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]], axis=0)
            area = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
            self._tracers["scene"] = EmbreeOccluder(tris[area > 0])
        return self._tracers["scene"]

    def _patch_rays(self, i, j, samples, key, salt, lists=None):
        """Fractions by rays between stratified samples of patches i (``salt``) and j, chunked.

        ``lists``: (starts, occ[, owner]), pair p's undecided occluders
        ``occ[starts[q]:starts[q + 1]]``, q = ``owner[p]`` (default p), for segment tests; None:
        Embree against the occluder patches (all patches with ``cull=False``).
        """
        from ._ray_kernel import stratified_points as points

        out = np.empty(len(j))
        agree = np.empty(len(j), bool)
        step = max(1, _tol.CHUNK_RAYS // samples**4)
        for s in range(0, len(j), step):
            e = min(len(j), s + step)
            xs, wx = points(self.quads, i[s:e], samples, key[s:e], salt)
            sub = None if lists is None else _owned(lists, slice(s, e))
            out[s:e], agree[s:e] = self._trace(xs, wx, self.normals[i[s:e]], j[s:e], samples, key[s:e], sub)
        return out, agree

    def _weighted_fraction(self, receivers, receiver_weights, receiver_normals, j, samples, key, lists=None):
        """Weighted unblocked fraction of rays from receivers (p, a, 3) to samples of j.

        Returns the fraction and whether all rays that carry weight agreed.
        """
        out = np.empty(len(j))
        agree = np.empty(len(j), bool)
        per_pair = receivers.shape[1] * samples * samples
        step = max(1, _tol.CHUNK_RAYS // per_pair)
        j = np.ascontiguousarray(j, dtype=np.int64)
        for s in range(0, len(j), step):
            e = min(len(j), s + step)
            sub = None if lists is None else _owned(lists, slice(s, e))
            out[s:e], agree[s:e] = self._trace(np.ascontiguousarray(receivers[s:e], dtype=np.float64),
                                               np.ascontiguousarray(receiver_weights[s:e], dtype=np.float64),
                                               np.ascontiguousarray(receiver_normals[s:e], dtype=np.float64),
                                               j[s:e], samples, key[s:e], sub)
        return out, agree

    def _trace(self, xs, wx, nx, j, samples, key, lists=None):
        """Fraction and agreement of one chunk of pairs (compiled; see :meth:`_patch_rays`).

        With ``lists``, each segment is tested against its pair's undecided occluders in a
        compiled loop, except for pairs with more than ``RAY_LIST_EMBREE`` of them, whose rays
        go through Embree against every occluder patch: the same answers (a segment that crosses
        any occluder is blocked), and a BVH instead of a loop over hundreds of triangles of a
        tessellated sphere (842 a pair: 2.5 s against 0.28 s for 4,096 pairs).
        """
        from ._ray_kernel import ray_fractions, segment_fractions, shadow_rays

        if lists is not None:
            o = self.occluders
            starts, occ, owner = _owned(lists, slice(None))
            long = starts[owner + 1] - starts[owner] > RAY_LIST_EMBREE
            if long.any():  # Embree for these, the occluder loops for the rest
                frac, agree = np.empty(len(j)), np.empty(len(j), bool)
                frac[long], agree[long] = self._trace(xs[long], wx[long], nx[long], j[long], samples, key[long])
                short = ~long
                if short.any():
                    frac[short], agree[short] = self._trace(xs[short], wx[short], nx[short], j[short], samples,
                                                            key[short], (starts, occ, owner[short]))
                return frac, agree
            frac, agree, n_traced = segment_fractions(
                xs, wx, nx, self.quads, self.normals, j, samples, key, 2, WEIGHT_FLOOR_REL,
                _tol.RAY_OFFSET_REL * self.scale, 1.0 - RAY_TFAR_SHORT, starts, occ, owner, o.polys, o.normal,
                o.center, o.inward, PLANE_REL * self.scale)
            self.n_rays += int(n_traced.sum())
            return frac, agree
        weight, starts, traced, origins, ends = shadow_rays(xs, wx, nx, self.quads, self.normals, j, samples, key,
                                                            2, WEIGHT_FLOOR_REL, _tol.RAY_OFFSET_REL * self.scale)
        blocked = self._occluder().occluded(origins, ends)
        self.n_rays += len(origins)
        return ray_fractions(weight, traced, starts, blocked)

    def _trace_numpy(self, xs, wx, nx, j, samples, key):
        """Reference for :meth:`_trace` in numpy (same rays, same weights)."""
        ys, wy = stratified_points(self.quads[j], samples, key, 2)
        ny = self.normals[j]
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
        total = weight.sum(axis=(1, 2))
        visible = (weight * ~blocked).sum(axis=(1, 2))
        n_traced = traced.sum(axis=(1, 2))
        n_blocked = (blocked & traced).sum(axis=(1, 2))
        agree = (total > 0) & ((n_blocked == 0) | (n_blocked == n_traced))
        return np.where(total > 0, visible / np.where(total > 0, total, 1.0), np.nan), agree

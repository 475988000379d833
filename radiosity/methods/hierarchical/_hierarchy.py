"""Links between elements, refined where their error bound exceeds the tolerance; the solve.

Refinement (Hanrahan, Salzman & Aupperle 1991, "BF refinement" with visibility in the bound):
a link (r <- s) carries the power ``rho_r B_s F_rs V_rs A_r`` to r, that is the radiosity
``rho_r B_s F_rs V_rs`` on each point of r. Its error bound, in radiosity units, is

    err = max_c(rho_r,c B_s,c) (spread_rs V_rs + F_rs [partly visible])

(times ``A_r`` it bounds the power the link gets wrong), where ``spread`` is the range of the
point-to-polygon factor over r's Gauss points (how far one constant per receiver is from the
truth) and the last term counts the whole power of a partly visible link as uncertain. A link
whose bound exceeds ``eps = link_tolerance * B_ref`` (``B_ref``: the scene's mean emitted
exitance, emitted power over active area, largest channel) is replaced by links to the four
children of the larger of its two elements (the other, if the larger is at the minimum size).
Fully hidden links are dropped; fully visible ones refine only for their spread. Links that
exceed ``eps`` with both ends at the minimum size stay, with their factor recomputed by the
uniform fill's adaptive quadrature and, if partly visible, their visibility by exact shadow
clipping.

Each link meeting eps alone does not bound what a receiver's links push onto its leaves
together (a corner element sees less of every far region than its mean). Each link's point
deviations of ``F V`` (a partly visible link's visibility measured at each point) reach the
leaves below its receiver as the quadratic fitting them (:mod:`._variation`), and after each
pass an element whose links' deviations, summed with their weights, stray from that quadratic
by more than ``FIT_LEAF_SHARE * leaf_tolerance * B_ref`` at one of its Gauss points (or from
their mean by ``FIT_LEAF_DEVIATION`` times that) moves all its links to its children
(:meth:`Hierarchy._varying_receivers`).

The bound is per unit area on purpose: a bound on the power itself (times ``A_r``) lets small
receivers keep links whose factor is wrong by 100% (their power is small), and a closed box
where every surface emits then misses ``B = E / (1 - rho)`` by 10% on its small elements.

The radiosity is solved on the leaves: B = E + rho K B with K = P G R, where R pulls (area
mean of the leaves below each element), G gathers over the links and P pushes (each leaf
receives what every ancestor gathered).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ... import _memory, _tol
from ...formfactors import patch_points
from ...visibility import Visibility
from ._clusters import CLUSTER_MIN_ROOTS, ClusterTree
from ._clusters import _ranges as _cluster_ranges
from ._clusters_kernel import collect_links, spread_links
from ._elements import Elements
from ._links import RECEIVER_ORDER, ElementVisibility, adaptive_factors, link_factors, source_shares
from ._links_kernel import collect_children, copy_masked_lists, gather_children, near_bounds, source_weights
from ._variation import Variation, fit_residuals, variation_part

__all__ = ["Hierarchy", "LinkOperator", "Links", "HierarchyStats"]

# Bytes per stored link (ends, factor, spread, visibility, flags, point deviations, G's CSR entry,
# and, above the leaves, its deviations in G's variation part): what the peak rates below are
# measured against.
LINK_BYTES = 8 + 8 + 8 + 8 + 8 + 2 + 9 + 4 + 12 + 40 + 17
# What a link costs at the peak of a solve, with the refinement's batches (and, for cluster
# links, the estimates' node pairs), per link the check counts (the kept links and the new
# candidates): on the Cornell box at fine, 3.5 mm, link_tolerance 5e-4, 2.32 GB above the RSS
# before the solve for at least 23.2 M links counted, about 100 bytes a link; element links
# take twice that. Per final link, bench_growth measured 230-360 bytes on the Cornell box and
# 360-645 on the cluster-heavy furnace spheres (645 at 100k faces, 4.9 M of its 5.0 M links
# cluster links) and 970 in the room of 1,000 floating cubes (7.7 GB for 7.95 M links, 5.13 M
# of them cluster links), so cluster links took 1,536. With the small-source budget and the
# oriented shares (2026-12-05) the same room peaked at 10.5 GB for 6.81 M links (2,048 a cluster
# link then); the peak was the numpy test of every (link, occluder) row for occluders behind
# either element's plane, which the classification kernel now makes: 4.4 GB, 647 bytes a link,
# so cluster links took 1,024. The stored size (LINK_BYTES) is 107 (94 before the point deviations).
# Session 28 took the cluster links' estimates, shares and visibility out of whole-array numpy
# passes. Peaks above the RSS before the solve: the 1,000-cube room 2.76 GB (11.3 M links, 5.07 M
# cluster links; 4.8 GB before), the furnace spheres 1.18 GB at 300k faces and 3.26 GB at 1M
# (5.4 M and 6.2 M cluster links; 6.5 and 16.8 GB before), which now grow with the elements:
# about 60 bytes a cluster link and 2.7 kB an element (the scene, its occluders, the tree, the
# operator's P, R and shares). The rates keep the room 1.4x and the spheres 2.3-4x above their
# peaks; the old element term (816 bytes, the stored size twice) fell short of the spheres'.
LINK_PEAK_BYTES = 200
CLUSTER_LINK_PEAK_BYTES = 512
ELEMENT_PEAK_BYTES = 4096
# A link whose source has children gathers from them, each by its share of the link's factor
# (_links.source_shares), not from the source's area mean: where the source's radiosity varies,
# the part the receiver sees best weighs most. Without it every surface of the bundled box came
# out dark at draft, the ceiling by 1.7-1.9% (it sees the walls' upper parts best, brighter than
# their means; on the 2.4 cm leaves the free links' error was all this covariance and none the
# factors'), and refining further made it worse. With it: 3.5 mm at draft, worst object 1.92% ->
# 0.71% for 13% more time (such a link is a value and four shares in G, class _Children).
SOURCE_SHARES = True
CHUNK_LINKS = 100_000  # links evaluated at once (bounds the temporaries of their visibility)
# Inherited candidates classified at once, and the bytes each takes meanwhile: the index into
# the parent's list and the int64 copy (Undecided.of), the kernel's found list and its output,
# the output's pair of each row (ElementVisibility.fractions_undecided), 8 bytes each, and 2 more
CHUNK_CANDIDATES = 8_000_000
CANDIDATE_BYTES = 42
# Cluster links scale their isotropic estimate by the visibility of one representative pair of
# patches (since 2026-12-05 the two facing each other most, ClusterTree.facing_patch; the middle
# patches in tree order, until then, were often turned away from each other and so "free": the
# 100-cube room's worst leaf +4.9% -> +2.3%); their bound needs none, but without it
# occluded far transfer is counted whole on every link and adds up: the room with 300 cubes
# came out +5.1% bright on average (+17% worst leaf). With it, the 100-cube room went from
# +0.46% to -0.34% mean (+8.0% to +5.2% worst) at 3.6x the time; a sphere (nothing occludes)
# pays nothing.
CLUSTER_VISIBILITY = True
# Cluster links whose representative pair is partly visible meet this share of eps: the
# 100-cube furnace room's worst leaf went from -4.7%/+5.1% to -3.3%/+3.1% (0.3 on every cluster
# link: -3.2%/+2.3%, but twice the links on an unoccluded sphere).
CLUSTER_EPS_SHARE = 0.3
# A cluster receiving a link shares its estimate out over its patches by how each faces the
# source (ClusterTree.oriented_shares) when its normal cone is wider than this (radians); a
# flatter one spreads it evenly. The 100-cube furnace room (with the small-source budget below):
# worst leaf -2.0%/+1.7% at pi/4, -0.7%/+0.5% at 0.2 (a cube's two adjacent faces have a cone of
# exactly pi/4, and spread evenly the one turned to a wall 2 cm away got 0.036 of light it
# cannot see); the 2,880-face furnace sphere, whose clusters are about flat, is unchanged
# (147,746 shares for 373,389 cluster links).
ORIENT_CONE = 0.2
# A receiver's links to sources whose longest edge is under this share of its own meet eps in
# sum, not each (Hierarchy._over). 0.5 cost the bundled box's default solve 33% more links for
# nothing; at 0.25 it has the same links within 0.2%, and the 100-cube room the same accuracy.
SMALL_SOURCE = 0.25
# Receiver points per direction of the exact shadows of partly visible links at the minimum size
# (see Hierarchy._settle).
SETTLE_ORDER = 3
# Settle partly visible links by exact shadows even when the preset's visibility is "rays".
SETTLE_EXACT_ALWAYS = True
# How a link's spread is bounded near its source (see _near_bound): "off" (the 3x3 points'
# range only), "near" (the sphere bound where the source is closer than the receiver's radius),
# "always".
NEAR_BOUND = "near"
NEAR_SMALLER = 0.5  # ... and the source's radius is below this share of r's
NEAR_RELATIVE = 2.0  # "near": the source's sphere comes closer to r's centroid than this many r radii
NEAR_GAP = 0.25  # ... or, whatever its size, the source faces r closer than this many r radii
TOUCHING_BOUND = 1.0  # the point factor bound of a small source touching r (0: leave it to the points)
SETTLE_LATER = True
# Links whose receiver cannot split but whose source is near enough for the receiver's 3x3
# points to miss its peak (where _near_bound would bound a splittable receiver) take the
# adaptive quadrature's factor instead of the points' mean (Hierarchy._exact_near_leaves).
EXACT_NEAR_LEAVES = True
# Children of a partly visible link are classified against its undecided occluders (kept with
# the link while it may split, across passes) instead of walking the occluders' BVH again.
# Until session 31 they were kept within a pass only: in the 100-cube furnace room (draft)
# 931k children of links split in later passes walked the BVH, 18 of the 26 s.
INHERIT_OCCLUDERS = True
# Share of an undecided link's factor left in doubt when all its rays agree (see _visibility_doubt).
UNANIMOUS_DOUBT = 1.0
# Partly visible links whose receiver can split measure their visibility at each of the
# receiver's Gauss points too (rays from each point), and the receiver's variation test
# (_varying_receivers) sums F V at each point, not F alone times the link's mean V.
RECEIVER_VISIBILITY = True
# New links that will split if partly visible, whatever their fraction, take no rays or exact
# shadows (Hierarchy._split_if_partial).
SKIP_DOOMED = True
# An input patch at least as large as a cluster it gathers from, over eps, splits its quadtree
# under a mixed link (element <- cluster) instead of taking a link from each patch of the
# cluster (Sillion 1995): a room with a 5,120-triangle sphere on its floor had 2.1 M element
# links from room elements to single triangles at draft (Hierarchy._refine_mixed).
MIXED_LINKS = True
# ... only to clusters of at least this many patches, all of one object other than the
# element's (ClusterTree.refine): below, a link to each patch costs little, and with mixed links
# to any cluster the 100-cube furnace room's floor leaves at the walls' feet went from 1.2% to
# 2.3% off (the estimates of clusters of wall patches wrapping round them all lean one way).
# Requiring the two spheres to lie apart instead kept the room right but lost the sphere rooms'
# gain: their links are near ones.
MIXED_MIN_PATCHES = 32
MIXED_VARY_ROUNDS = 6  # rounds of Hierarchy._varying_mixed a pass
# ... and the other way round: a cluster of one object gathering from an input patch at least as
# large as itself, over eps, splits the patch's quadtree under a reverse mixed link (cluster <-
# element) instead of splitting down to a link per patch of the cluster (Hierarchy._refine_reverse):
# a 20,480-triangle sphere in a closed room had 790,062 element links from its triangles to
# room elements, 39 a triangle, each with its own visibility.
REVERSE_MIXED = True
# ... only to clusters whose patches are all smaller than this share of the minimum element size
# (their spheres' diameters): a cluster's bound takes the widest cosine over its normal cone,
# where each triangle's own is tighter, so reverse links split room elements further than the
# triangles' links do. In a 2 m furnace room at draft (minimum 6.9 cm), a 0.4 m sphere of 12,
# 6 or 3 cm triangles had 6-12% more links with them (3 cm: 13.3 against 15.1 s, beside another
# solve), one of 1.5 cm 10% fewer in half the time (23.6 against 43.5 s).
REVERSE_PATCH_SHARE = 0.5
# A reverse mixed link's cluster shares what it gathers by each patch's own visibility of the
# element (a segment from its centroid to the element's centroid, Hierarchy._reverse_patch_seen)
# instead of the visible fraction of the one patch that faces the element most: in the 26,678-
# face furnished room a sphere's triangle that sees 0.093 of a wall got 0.142 from links whose
# facing patch saw the wall whole.
REVERSE_PATCH_VISIBILITY = True
# Each element link's variation across its receiver reaches the leaves below it as the
# quadratic fitting its Gauss points' deviations (:mod:`._variation`), not as the receiver's
# mean alone: an empty 6 x 5 x 3 m furnace room's leaves went from -2.0% / +2.4% to within
# 0.02% at draft, the room of primitives' from -3.44% / +3.08% to -1.40% / +1.47% (with the
# old split test; with FIT_LEAF_TEST below, 0.14% and -1.19% / +1.64% in fewer links).
QUADRATIC_PUSH = True
# With it, the leaf tolerance splits a receiver where what the quadratic leaves out at one of
# its points passes FIT_LEAF_SHARE of leaf_eps (the 9 points see less of the fit's error than
# the leaves between them), or where the deviations themselves pass FIT_LEAF_DEVIATION times
# leaf_eps (a peak at the element's edge, beside an object standing on it, is no quadratic,
# and the fit extrapolates there): :meth:`Hierarchy._unfitted_receivers`. The 2,120-face
# furnished furnace room at draft: worst leaf -3.47% / +3.27% with the deviations alone
# (before, each at leaf_eps), -4.18% / +4.59% with the residuals alone (a table top), -3.08%
# / +2.83% with both; the room of primitives: 3.90 M links with the residuals alone, 6.58 M
# with the deviations.
FIT_LEAF_TEST = True
FIT_LEAF_SHARE = 0.1
FIT_LEAF_DEVIATION = 2.0
CHUNK_SEEN = 1 << 21  # segments a chunk of Hierarchy._reverse_patch_seen traces


@dataclass
class Links:
    """Links (r gathers from s) with their estimates; all arrays of one length."""

    r: np.ndarray
    s: np.ndarray
    factor: np.ndarray
    spread: np.ndarray
    visible: np.ndarray
    doubt: np.ndarray
    partial: np.ndarray
    settled: np.ndarray
    # the point values over r's Gauss points less their mean, as int8 codes of ``shape_scale``
    # (the largest |deviation|) / 127: what the receiver's variation test sums (9 bytes a link)
    shape: np.ndarray
    shape_scale: np.ndarray
    # the undecided occluders of each link while it may split (none for free links)
    occluders: Undecided = field(default_factory=lambda: Undecided.empty(0))

    @classmethod
    def empty(cls) -> "Links":
        z = np.zeros(0)
        i = np.zeros(0, np.int64)
        b = np.zeros(0, bool)
        q = RECEIVER_ORDER ** 2
        return cls(i, i.copy(), z, z.copy(), z.copy(), z.copy(), b, b.copy(), np.zeros((0, q), np.int8),
                   np.zeros(0, np.float32))

    def __len__(self) -> int:
        return len(self.r)

    def take(self, mask: np.ndarray) -> "Links":
        """The links where the boolean ``mask`` is set."""
        return Links.gather([(self, mask)])

    @staticmethod
    def concat(parts: list["Links"]) -> "Links":
        """All links of ``parts``, in order, in new arrays."""
        return Links.gather([(p, None) for p in parts])

    @staticmethod
    def gather(parts: list[tuple["Links", np.ndarray | None]]) -> "Links":
        """``concat`` of ``links.take(mask)`` over (links, mask) in ``parts`` (None: all of
        them), copied once and by index: a pass joined its millions of kept links after
        copying them out by mask, and the copies were 13% of a furnished room's solve."""
        parts = [(p, m) for p, m in parts if len(p)]
        if not parts:
            return Links.empty()
        rows = [None if m is None else np.flatnonzero(m) for _, m in parts]
        fields = [_gathered([getattr(p, f) for p, _ in parts], rows) for f in _LINK_ARRAYS]
        lists = [p.occluders for p, _ in parts]
        counts, cut = (_gathered([getattr(u, f) for u in lists], rows) for f in ("count", "cut"))
        return Links(*fields, occluders=Undecided(counts, _gathered_lists(lists, [m for _, m in parts]), cut))


@dataclass
class Undecided:
    """The undecided occluders of each link of a :class:`Links` (none for links found free),
    kept while its links may split: their children are classified against them only."""

    count: np.ndarray  # (n_links,) int32
    occ: np.ndarray  # (count.sum(),) int16 or int32, link after link
    # (n_links,) bool: the list is not all of the link's occluders (a walk stopped at
    # ``_links.LIST_CAP``, or the link descends from one that did): its children are classified
    # against it for occluders that hide them wholly, and trace their rays through Embree
    cut: np.ndarray | None = None

    def __post_init__(self):
        # the smallest type that holds them: the lists of a cluttered room's links run to tens
        # of millions of entries (the 2,120-face furnished room peaked at 3.24 GB without the
        # lists, 4.85 GB with them as int32, 4.09 GB as int16)
        small = self.occ.dtype == np.int16 or self.occ.size == 0 or self.occ.max() < np.iinfo(np.int16).max
        self.occ = self.occ.astype(np.int16 if small else np.int32, copy=False)
        self.count = self.count.astype(np.int32, copy=False)
        self.cut = np.zeros(len(self.count), bool) if self.cut is None else self.cut.astype(bool, copy=False)

    @staticmethod
    def empty(n: int) -> "Undecided":
        return Undecided(np.zeros(n, np.int32), np.zeros(0, np.int16))

    def take(self, mask: np.ndarray) -> "Undecided":
        """The lists of the links where the boolean ``mask`` is set."""
        return Undecided(self.count[mask], self.masked(mask), self.cut[mask])

    def only(self, mask: np.ndarray) -> "Undecided":
        """The same links, with the lists of those where ``mask`` is not set emptied."""
        return Undecided(np.where(mask, self.count, 0), self.masked(mask), self.cut & mask)

    def masked(self, mask: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """The lists of the links where ``mask`` is set, joined (into ``out`` if given)."""
        if out is None:
            out = np.empty(int(self.count[mask].sum(dtype=np.int64)), self.occ.dtype)
        copy_masked_lists(self.occ, self.count, np.asarray(mask, bool), out, 0)
        return out

    def of(self, parent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(starts, occluders), CSR over ``parent``: each entry's link's undecided occluders."""
        first = np.concatenate([[0], np.cumsum(self.count)])[parent]
        count = self.count[parent]
        starts = np.concatenate([[0], np.cumsum(count)])
        at = np.repeat(first - starts[:-1], count) + np.arange(starts[-1])
        return starts, self.occ[at].astype(np.int64)


_LINK_ARRAYS = tuple(f for f in Links.__dataclass_fields__ if f != "occluders")


def _gathered(arrays: list[np.ndarray], rows: list[np.ndarray | None]) -> np.ndarray:
    """The ``rows`` of each of ``arrays`` (None: all), joined into one new array. ``np.take``
    into the output: a boolean mask cost twice as long, and six times on the (m, 9) codes."""
    dtype = np.result_type(*(a.dtype for a in arrays))
    sizes = [len(a) if at is None else len(at) for a, at in zip(arrays, rows)]
    out = np.empty((sum(sizes),) + arrays[0].shape[1:], dtype)
    start = 0
    for a, at, n in zip(arrays, rows, sizes):
        if at is None:
            out[start:start + n] = a
        elif a.dtype == dtype:
            np.take(a, at, axis=0, out=out[start:start + n], mode="clip")  # "raise" copies through a buffer
        else:
            out[start:start + n] = a[at]
        start += n
    return out


def _in_pair_order(occ: np.ndarray, parts: list[np.ndarray], count: np.ndarray) -> np.ndarray:
    """``occ``, the lists of the pairs of ``parts`` one part after the other (``count[p]``
    entries for pair p), reordered so that the pairs come in increasing order."""
    pairs = np.concatenate(parts)
    order = np.argsort(pairs, kind="stable")
    counts = count[pairs]
    first = np.cumsum(counts) - counts  # where each pair's list starts in occ
    size = counts[order]
    return occ[np.repeat(first[order] - (np.cumsum(size) - size), size) + np.arange(len(occ))]


def _gathered_lists(lists: list[Undecided], masks: list[np.ndarray | None]) -> np.ndarray:
    """The occluder lists of the links where each of ``masks`` is set (None: all), joined into
    one new array, a part at a time and link by link (:meth:`Undecided.masked`): the lists run to
    hundreds of millions of entries, and int64 indices of all of them at once (8 bytes an entry,
    against 2 or 4 for the entry) took a 29,536-face room from 4.8 to 12.9 GB in half a minute."""
    dtype = np.result_type(*(u.occ.dtype for u in lists))
    sizes = [len(u.occ) if m is None else int(u.count[m].sum(dtype=np.int64)) for u, m in zip(lists, masks)]
    out = np.empty(sum(sizes), dtype)
    start = 0
    for u, m, n in zip(lists, masks, sizes):
        if m is None:
            out[start:start + n] = u.occ
        else:
            u.masked(m, out[start:start + n])
        start += n
    return out


class LinkOperator(spla.LinearOperator):
    """K = P G R on leaf radiosities: what ``Solution.F`` is for the hierarchical method.

    ``K @ B`` is the irradiance each leaf receives; ``K.T @ A`` is, per leaf, the area of
    fronts its light reaches (as for a view-factor matrix). ``nnz`` counts the links.
    ``row_scale`` (optional, (n_leaves,)) scales each leaf's row: the rows of P G R that sum
    past 1 are brought down to 1 (:meth:`Hierarchy.operator`).
    """

    def __init__(self, push: sp.csr_matrix, gather: sp.csr_matrix, pull: sp.csr_matrix, links: int | None = None,
                 row_scale: np.ndarray | None = None):
        self.push, self.gather, self.pull = push, gather, pull
        self.nnz = int(gather.nnz if links is None else links)  # G drops links hidden by their rays
        self.row_scale = row_scale
        super().__init__(dtype=np.float64, shape=(push.shape[0], pull.shape[1]))

    def _scaled(self, y):
        if self.row_scale is None:
            return y
        return self.row_scale * y if y.ndim == 1 else self.row_scale[:, None] * y

    def _matvec(self, x):
        return self._scaled(self.push @ (self.gather @ (self.pull @ x)))

    def _matmat(self, x):
        return self._scaled(self.push @ (self.gather @ (self.pull @ x)))

    def _rmatvec(self, y):
        return self.pull.T @ (self.gather.T @ (self.push.T @ self._scaled(y)))

    def _rmatmat(self, y):
        return self.pull.T @ (self.gather.T @ (self.push.T @ self._scaled(y)))


@dataclass
class _Spread:
    """Oriented cluster links as G holds them: link k takes ``x[column[k]]`` to the patches of
    its receiving node r[k] (``tree.order[lo:hi]``; input patch i is root element i, so that is
    also its row of G), each by its ``value`` (the link's factor
    times the patch's share, :meth:`ClusterTree.receiver_shares`), link after link. 8 bytes a
    value, where a sparse matrix's entry took 12, and 28 while it was built (the 1M-face
    sphere's peak)."""

    r: np.ndarray
    column: np.ndarray
    start: np.ndarray  # where link k's values begin
    value: np.ndarray
    tree: ClusterTree

    @property
    def nbytes(self) -> int:
        return self.value.nbytes + 3 * 8 * len(self.r)

    def add_gathered(self, x: np.ndarray, y: np.ndarray) -> None:
        """y += (these links of G) @ x, for one vector."""
        t = self.tree
        spread_links(self.r, self.column, t.lo, t.hi, t.order, self.start, self.value, x, y, numba.get_num_threads())

    def add_collected(self, y: np.ndarray, x: np.ndarray) -> None:
        """x += (these links of G).T @ y, for one vector."""
        t = self.tree
        taken = np.empty(len(self.r))
        collect_links(self.r, self.column, t.lo, t.hi, t.order, self.start, self.value, y, taken)
        x += np.bincount(self.column, taken, minlength=len(x))


@dataclass
class _Children:
    """Element links whose source has children, as G holds them: link k adds ``value[k]``
    times the ``shares[k]``-weighted radiosities of the four children ``first[k] + 0..3`` to
    row r[k] (:meth:`Hierarchy._gather_entries`). 32 bytes a link, where four entries of a
    sparse matrix took 48, and 112 while it was built (the bundled box at fine, 3.5 mm, peaked
    2 GB higher that way)."""

    r: np.ndarray
    first: np.ndarray
    value: np.ndarray
    shares: np.ndarray

    @property
    def nbytes(self) -> int:
        return self.r.nbytes + self.first.nbytes + self.value.nbytes + self.shares.nbytes

    def add_gathered(self, x: np.ndarray, y: np.ndarray) -> None:
        """y += (these links of G) @ x, for one vector."""
        gather_children(self.r, self.first, self.value, self.shares, x, y)

    def add_collected(self, y: np.ndarray, x: np.ndarray) -> None:
        """x += (these links of G).T @ y, for one vector."""
        collect_children(self.r, self.first, self.value, self.shares, y, x)


class Gather(spla.LinearOperator):
    """G: a sparse matrix (element links whose source is a leaf, cluster links spread evenly)
    plus parts applied link by link (:class:`_Children`, :class:`_Spread`), and optionally the
    links' point deviations gathered per receiver point (:class:`._variation.Variation`, rows
    after the matrix's)."""

    def __init__(self, matrix: sp.csr_matrix, parts: list, variation: Variation | None = None):
        self.matrix, self.parts, self.variation = matrix, parts, variation
        extra = 0 if variation is None else variation.n_out
        super().__init__(dtype=np.float64, shape=(matrix.shape[0] + extra, matrix.shape[1]))

    @property
    def nbytes(self) -> int:
        extra = 0 if self.variation is None else self.variation.nbytes
        return matrix_bytes(self.matrix) + sum(p.nbytes for p in self.parts) + extra

    def _matvec(self, x):
        x = np.ascontiguousarray(np.ravel(x), dtype=float)
        y = self.matrix @ x
        for part in self.parts:
            part.add_gathered(x, y)
        if self.variation is not None:
            y = np.concatenate([y, self.variation.gathered(x)])
        return y

    def _rmatvec(self, y):
        y = np.ascontiguousarray(np.ravel(y), dtype=float)
        n = self.matrix.shape[0]
        x = self.matrix.T @ y[:n]
        for part in self.parts:
            part.add_collected(y[:n], x)
        if self.variation is not None:
            self.variation.add_collected(y[n:], x)
        return x


def matrix_bytes(m) -> int:
    """Bytes held by a CSR matrix or a Gather."""
    if hasattr(m, "indptr"):
        return m.data.nbytes + m.indices.nbytes + m.indptr.nbytes
    return m.nbytes


@dataclass
class SolveReport:
    """The leaf solve, in the fields ``Solution.summary`` reads."""

    method: str = "gmres (leaves, K = P G R)"
    iterations: list = field(default_factory=list)
    residual: list = field(default_factory=list)
    fallback: list = field(default_factory=list)


@dataclass
class HierarchyStats:
    """What the refinement built and cost (``summary.json``'s ``hierarchy``)."""

    rounds: int = 0
    converged: bool = False
    links: int = 0
    partly_visible_links: int = 0
    links_evaluated: int = 0
    pairs_traced: int = 0
    exact_links: int = 0
    exact_near_links: int = 0  # leaf links near their source given adaptive factors (_exact_near_leaves)
    elements: int = 0
    leaves: int = 0
    max_level: int = 0
    roots: int = 0
    initial_links: int = 0
    clusters: int = 0
    cluster_links: int = 0
    mixed_links: int = 0  # element <- cluster links (Hierarchy._refine_mixed)
    reverse_mixed_links: int = 0  # cluster <- element links (Hierarchy._refine_reverse)
    min_element_size: float = 0.0
    eps: float = 0.0
    memory_bytes: int = 0
    split_per_round: list = field(default_factory=list)
    n_rays: int = 0
    seconds_refine: float = 0.0
    rows_over_one: int = 0  # leaf rows of K summing past 1 in the last solve
    max_row_sum: float = 0.0  # the largest row sum of K in the last solve
    seconds_solve: float = 0.0

    # the fields the uniform method's fill stats share (Solution.summary reads them)
    @property
    def n_pairs(self) -> int:
        return self.links

    @property
    def n_traced_pairs(self) -> int:
        return self.pairs_traced

    def summary(self) -> dict:
        keys = ("rounds", "converged", "links", "partly_visible_links", "links_evaluated", "pairs_traced",
                "exact_links", "exact_near_links", "elements", "leaves", "max_level", "roots", "initial_links",
                "clusters", "cluster_links", "mixed_links", "reverse_mixed_links", "min_element_size",
                "eps", "memory_bytes", "split_per_round", "rows_over_one",
                "max_row_sum")
        return {k: getattr(self, k) for k in keys}


class Hierarchy:
    """Element quadtrees, their links and the leaf solve of one scene.

    Parameters
    ----------
    quads, normals : (n, 4, 3), (n, 3) float
        The input patches (roots).
    reflectance, emission : (n, 3) float
        Per input patch.
    active : (n,) bool
        Patches that exchange light (obstructions and hidden patches do not: no links).
    visibility : Visibility
        Over the input patches (the occluders).
    min_size : float
        Minimum element size, metres.
    tolerance : float
        Link error bound (W/m^2) as a fraction of the mean emitted exitance (largest channel).
    leaf_tolerance : float
        Bound on what an element's links together push onto the leaves below it, in the same
        units (:meth:`Hierarchy._varying_receivers`); 0: none.
    formfactor_rtol : float
        Accuracy of the adaptive factors of links at the minimum size.
    exact : bool
        Exact shadows for partly visible links at the minimum size.
    clusters : bool or None
        Start from a volume hierarchy over the patches (:mod:`._clusters`) instead of all facing
        pairs; None: when there are at least ``CLUSTER_MIN_ROOTS`` active patches.
    """

    def __init__(self, quads, normals, reflectance, emission, active, visibility: Visibility, *, min_size: float,
                 tolerance: float, leaf_tolerance: float = 0.0, formfactor_rtol: float = 1e-4, exact: bool = True,
                 clusters: bool | None = None):
        self.el = Elements(quads, normals, min_size)
        self.rho = np.asarray(reflectance, float)
        self.emission = np.asarray(emission, float)
        self.active = np.asarray(active, bool)
        self.vis = ElementVisibility(visibility)
        self.formfactor_rtol = formfactor_rtol
        self.exact = exact
        area = self.el.area[self.active]
        power = (area[:, None] * self.emission[self.active]).sum(axis=0).max() if self.active.any() else 0.0
        self.reference = power / area.sum() if power > 0 else 0.0
        self.eps = tolerance * self.reference if power > 0 else np.inf
        self.leaf_eps = leaf_tolerance * self.reference if power > 0 and leaf_tolerance > 0 else np.inf
        self.B = self.emission.copy()  # per element; children start with their parent's value
        self.links = Links.empty()
        self.stats = HierarchyStats(roots=len(quads), min_element_size=float(min_size), eps=float(self.eps))
        self._started = False
        self._planned = (0, 0)  # what the last memory check counted beyond self.links
        self.progress = lambda n: None  # called with the number of links evaluated (a progress bar)
        n_active = int(self.active.sum())
        if clusters is None:
            clusters = n_active >= CLUSTER_MIN_ROOTS
        self.tree = None
        self.cluster_r = self.cluster_s = self.cluster_factor = np.zeros(0, np.int64)
        # mixed links: element mixed_r gathers from cluster node mixed_s
        self.mixed_r = self.mixed_s = np.zeros(0, np.int64)
        self.mixed_factor = np.zeros(0)
        self.mixed_shape = np.zeros((0, RECEIVER_ORDER ** 2), np.float32)
        # reverse mixed links: cluster node reverse_r gathers from element reverse_s
        self.reverse_r = self.reverse_s = np.zeros(0, np.int64)
        self.reverse_factor = self.reverse_estimate = np.zeros(0)  # with and without visibility
        self._reverse_seen: dict[int, np.ndarray] = {}  # (r << 32 | s): each patch of r sees s's centroid
        self._reverse_below = REVERSE_PATCH_SHARE * min_size if REVERSE_MIXED else 0.0
        if clusters and n_active:
            self.tree = ClusterTree(np.flatnonzero(self.active), self.el.quads, self.el.normal, self.el.area, self.rho,
                                    visibility.groups)
            self.stats.clusters = len(self.tree.internal)

    # ------------------------------------------------------------------ refinement
    def initial_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """Root pairs (r, s), r != s, both active, each with a vertex in front of the other's plane."""
        el = self.el
        idx = np.flatnonzero(self.active)
        quads, centroid, normal = el.quads[idx], el.centroid[idx], el.normal[idx]
        tol = 1e-9 * max(float(np.ptp(el.quads.reshape(-1, 3), axis=0).max()), 1e-300)
        # front[a, b]: some vertex of b lies in front of a's plane
        height = np.einsum("bkc,ac->abk", quads, normal) - np.einsum("ac,ac->a", centroid, normal)[:, None, None]
        front = (height > tol).any(axis=2)
        ok = front & front.T
        np.fill_diagonal(ok, False)
        a, b = np.nonzero(ok)
        _memory.check(f"the {len(a):,} initial links of {len(idx):,} input patches",
                      int(len(a) * LINK_PEAK_BYTES), "cut the scene into fewer input faces")
        return idx[a], idx[b]

    def error(self, links: Links) -> np.ndarray:
        """(m,) error bound of each link, W/m^2 of the receiver (see the module notes)."""
        return self._weights(links.r, links.s) * (links.spread * links.visible + links.doubt)

    def _weights(self, r: np.ndarray, s: np.ndarray) -> np.ndarray:
        """(m,) the largest over channels of rho(r) B(s): what a link's bound is in units of."""
        return source_weights(self.rho, self.el.root, self.B, r, s)

    def _over(self, links: Links) -> np.ndarray:
        """(m,) links to refine: their bound exceeds eps, or they are among a receiver's links
        to sources under ``SMALL_SOURCE`` of its size whose bounds sum past eps.

        Each link meeting eps alone let their sum grow without bound: a 1 m wall of the
        100-cube furnace room kept about 400 links to cubes at its root, each under eps, and its
        corner leaf got 25% too little from them (the room's worst leaf -3.3%). The sum is taken
        over links to small sources only: over all links the bundled box's draft solve took 14x
        as long, over partly visible links its default solve 10x (4.5 M links, for 0.64% against
        0.77%), where a tighter tolerance buys more.
        """
        err = self.error(links)
        over = err > self.eps
        small = np.flatnonzero(self.el.edge[links.s] < SMALL_SOURCE * self.el.edge[links.r])
        over[small] |= _past_budget(links.r[small], err[small], self.eps)
        return over

    def _evaluate(self, r: np.ndarray, s: np.ndarray,
                  parents: tuple[Links, np.ndarray] | None = None) -> Links:
        """Estimates of new links, those that cannot carry anything dropped, with their undecided
        occluders.

        ``parents`` (optional): (links, the index of each pair's parent among them) when the
        pairs are children of split links. A child's segments are a subset of its parent's, so a
        child of a free link is free without a test, and a child of a partly visible one is
        classified against its parent's undecided occluders only.

        Dropped: pairs that do not face each other, and pairs an occluder blocks entirely. A
        pair the classification leaves undecided keeps its whole factor as doubt if its rays
        disagree (one ray's share of it if they all agree), and a pair where one element
        crosses the other's plane its largest point value (its Gauss points do not resolve
        where the plane cuts): such links refine until their doubt meets ``eps``.
        """
        parts = []
        for a in range(0, len(r), CHUNK_LINKS):
            rr, ss = r[a:a + CHUNK_LINKS], s[a:a + CHUNK_LINKS]
            self.stats.links_evaluated += len(rr)
            self.progress(len(rr))
            facing, crossing = _facing(self.el, rr, ss)
            rr, ss, crossing = rr[facing], ss[facing], crossing[facing]
            factor, spread, peak, deviation = link_factors(self.el, rr, ss, shape=True)
            self._exact_near_leaves(rr, ss, factor)
            # a pair no receiver point sees, and that crosses neither plane, carries nothing: it
            # is dropped before its visibility is paid for
            useful = (factor > 0) | crossing
            rr, ss, crossing, factor, spread, peak, deviation = (
                x[useful] for x in (rr, ss, crossing, factor, spread, peak, deviation))
            if NEAR_BOUND != "off":
                spread = np.maximum(spread, _near_bound(self.el, rr, ss, NEAR_BOUND == "near") - (peak - spread))
            ours = None if parents is None else (parents[0], parents[1][a:a + CHUNK_LINKS][facing][useful])
            doomed = self._split_if_partial(rr, ss, factor)
            visible, partial, count, occ, cut = self._visibility(rr, ss, ours, doomed)
            undecided = Undecided(count, occ, cut)
            deviation = self._visible_deviation(rr, ss, factor, deviation, visible, partial, undecided,
                                                None if doomed is None else partial & doomed)
            keep = visible >= 0.0  # FULL pairs come back as -1
            # A crossing pair is as uncertain as its largest point value (the points do not
            # resolve where the plane cuts), or as its crude bound if every point missed.
            unseen = np.where(peak > 0, peak, _factor_bound(self.el, rr, ss))
            doubt = factor * _visibility_doubt(visible, partial, self.vis.patches.samples) + unseen * crossing
            n = int(keep.sum())
            codes, scale = _shape_codes(deviation[keep])
            parts.append(Links(rr[keep], ss[keep], factor[keep], spread[keep], np.clip(visible[keep], 0, 1),
                               doubt[keep], partial[keep], np.zeros(n, bool), codes, scale,
                               occluders=undecided.take(keep)))
            if parents is not None:  # twice: Links.concat copies them
                self._check_memory(*self._planned, grown_bytes=2 * sum(p.occluders.occ.nbytes for p in parts))
        return Links.concat(parts)

    def _exact_near_leaves(self, r: np.ndarray, s: np.ndarray, factor: np.ndarray) -> None:
        """Replace in ``factor`` the 3x3-point means of links whose receiver cannot split and
        whose source is near enough for those points to miss its peak (where
        :func:`_near_bound` would bound a splittable receiver) by the adaptive quadrature's.

        A receiver that can split takes the near bound and splits; a leaf keeps its mean, which
        its points may miss by a factor of four: the floor leaf under a cylinder standing 1 cm
        above it got 0.0034 from one of the base's wedges for 0.0133, and 0.90 of the base in
        all for 1.00 (the room's worst leaf, -4.8% in the furnace).
        """
        if not EXACT_NEAR_LEAVES or not len(r):
            return
        leaf = np.flatnonzero(~self.el.splittable[r])
        if not len(leaf):
            return
        near = leaf[_near_bound(self.el, r[leaf], s[leaf], NEAR_BOUND == "near", as_if_splittable=True) > 0]
        if len(near):
            factor[near] = adaptive_factors(self.el, r[near], s[near], self.formfactor_rtol)
            self.stats.exact_near_links += len(near)

    def _visible_deviation(self, r: np.ndarray, s: np.ndarray, factor: np.ndarray, deviation: np.ndarray,
                           visible: np.ndarray, partial: np.ndarray, undecided: Undecided,
                           doomed: np.ndarray | None = None) -> np.ndarray:
        """(m, q) the visible factor F V at each of r's Gauss points less its mean: what
        :meth:`_varying_receivers` sums.

        Free links take the factor's deviation. A partly visible link whose receiver can split
        takes its points' own visibility (rays from each point to the source, against the pair's
        undecided occluders), since the leaves below get the visibility of r as a whole: a cube
        face in a room of floating cubes gathered a far wall's light through its links' mean
        visibility, 0.6 where its half behind a neighbouring cube sees 0.17, and each link met
        eps alone; that leaf's row summed to 0.945 (``RECEIVER_VISIBILITY``).
        """
        out = deviation * np.clip(visible, 0.0, 1.0)[:, None]
        ask = partial & self.el.splittable[r]
        if doomed is not None:  # links about to split (:meth:`_split_if_partial`): no rays
            ask &= ~doomed
        ask = np.flatnonzero(ask) if RECEIVER_VISIBILITY else np.zeros(0, np.int64)
        if not len(ask):
            return out
        points, weights = patch_points(self.el.quads[r[ask]], RECEIVER_ORDER)
        seen = np.empty(points.shape[:2])
        cut = undecided.cut[ask]
        for sel in (~cut, cut):  # a list cut short would miss occluders: Embree for those
            if sel.any():
                seen[sel] = self.vis.at_points(self.el, r[ask[sel]], s[ask[sel]], points[sel],
                                               None if sel is cut else undecided.of(ask[sel]))
        values = (deviation[ask] + factor[ask, None]) * seen
        mean = (values * weights).sum(axis=1) / np.maximum(weights.sum(axis=1), 1e-300)
        out[ask] = values - mean[:, None]
        return out

    def _split_if_partial(self, r: np.ndarray, s: np.ndarray, factor: np.ndarray) -> np.ndarray | None:
        """(m,) new links that :meth:`_descend` splits if they are partly visible, whatever
        their visible fraction: one end can split, and the whole factor, the doubt a partly
        visible link keeps (``UNANIMOUS_DOUBT``), is over eps at the current radiosities. Their
        rays and exact shadows would be thrown away with them. (In a first pass only the
        emitters' links qualify: the others' sources have no radiosity yet.)"""
        if not SKIP_DOOMED or UNANIMOUS_DOUBT < 1.0:
            return None
        can = self.el.splittable
        return (can[r] | can[s]) & (self._weights(r, s) * factor > self.eps)

    def _visibility(self, r: np.ndarray, s: np.ndarray, parents: tuple[Links, np.ndarray] | None,
                    split_if_partial: np.ndarray | None = None):
        """(visible, partial, count, occluders, cut) of pairs (see
        :meth:`ElementVisibility.fractions_undecided`); with ``parents`` (as :meth:`_evaluate`'s,
        the index of each of these pairs' parent), children of free links are free, children of
        partly visible ones take their parent's undecided occluders as candidates. Where the
        parent's list is cut short (``Undecided.cut``) the children are classified against it
        as an incomplete list (:meth:`ElementVisibility._cut_short`)."""
        if parents is None:
            return self.vis.fractions_undecided(self.el, r, s, split_if_partial=split_if_partial)
        links, parent = parents
        m = len(r)
        visible, partial, count, cut = np.ones(m), np.zeros(m, bool), np.zeros(m, np.int64), np.zeros(m, bool)
        ask = np.flatnonzero(links.partial[parent])
        short = links.occluders.cut[parent[ask]]
        batches = [(part, False) for part in self._candidate_batches(links, parent, ask[~short])]
        batches += [(part, True) for part in self._candidate_batches(links, parent, ask[short])]
        lists = [np.zeros(0, np.int32)]
        for part, incomplete in batches:
            candidates = links.occluders.of(parent[part]) if INHERIT_OCCLUDERS else None
            visible[part], partial[part], count[part], occ, cut[part] = self.vis.fractions_undecided(
                self.el, r[part], s[part], children=True, candidates=candidates, incomplete=incomplete,
                split_if_partial=None if split_if_partial is None else split_if_partial[part])
            lists.append(occ.astype(np.int32))  # kept: 4 bytes, not the kernel's 8
            del candidates, occ
        occ = np.concatenate(lists)
        if short.any() and not short.all():  # the lists in the pairs' order, as Undecided keeps them
            occ = _in_pair_order(occ, [part for part, _ in batches], count)
        return visible, partial, count, occ, cut

    def _candidate_batches(self, links: Links, parent: np.ndarray, ask: np.ndarray) -> list[np.ndarray]:
        """The children ``ask`` of partly visible links (``parent``: each child's parent in
        ``links``), in runs of at most ``CHUNK_CANDIDATES`` inherited candidates (at least one
        child a run), in order.

        Each candidate entry costs about ``CANDIDATE_BYTES`` while its child is classified; in a
        room of tessellated primitives (29,536 faces), 100,000 children of links behind
        thousands of undecided triangles each asked for more than the machine has, and the
        kernel's OOM killer ended the solve at 24 GB.
        """
        if not INHERIT_OCCLUDERS or not len(ask):
            return [ask] if len(ask) else []
        ends = np.cumsum(links.occluders.count[parent[ask]].astype(np.int64))
        cuts = np.searchsorted(ends, np.arange(CHUNK_CANDIDATES, ends[-1], CHUNK_CANDIDATES), side="right")
        return [part for part in np.split(ask, np.unique(np.maximum(cuts, 1))) if len(part)]

    def _expand(self, links: Links, receiver: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The child links replacing ``links`` (the larger end, if it can split, is split four
        ways; with ``receiver``, the receiver), and the index of each child's parent in ``links``."""
        el = self.el
        can = el.splittable
        split_r = can[links.r] & ((el.area[links.r] >= el.area[links.s]) | ~can[links.s] | receiver)
        first_r = self._split_elements(links.r[split_r])
        first_s = self._split_elements(links.s[~split_r])
        four = np.arange(4)
        r_new = np.concatenate([(first_r[:, None] + four).ravel(), np.repeat(links.r[~split_r], 4)])
        s_new = np.concatenate([np.repeat(links.s[split_r], 4), (first_s[:, None] + four).ravel()])
        parent = np.concatenate([np.repeat(np.flatnonzero(split_r), 4), np.repeat(np.flatnonzero(~split_r), 4)])
        return r_new, s_new, parent

    def _settle(self, links: Links) -> Links:
        """Links at the minimum size that still exceed eps: adaptive factors, exact shadows."""
        if not len(links):
            return links
        links.factor = adaptive_factors(self.el, links.r, links.s, self.formfactor_rtol)
        links.spread = np.zeros(len(links))
        links.doubt = np.zeros(len(links))
        links.shape_scale = np.zeros(len(links), np.float32)
        if (self.exact or SETTLE_EXACT_ALWAYS) and links.partial.any():
            p = np.flatnonzero(links.partial)
            links.visible[p] = self.vis.exact(self.el, links.r[p], links.s[p], order=SETTLE_ORDER)
            self.stats.exact_links += len(p)
        links.settled = np.ones(len(links), bool)
        return links.take((links.factor > 0) & (links.visible > 0))

    def _check_memory(self, extra_links: int, extra_bytes: int = 0, grown_bytes: int = 0) -> None:
        """Refuse the refinement before it outgrows the budget, with the estimate.

        ``extra_links`` and ``extra_bytes``: the links about to be evaluated and those the
        pass keeps beside ``self.links``, and their occluder lists. They are remembered, so
        that :meth:`_evaluate` can check again as the new links' own lists grow
        (``grown_bytes``; the lists of a link's children were not counted until the next level).
        """
        if not grown_bytes:
            self._planned = (extra_links, extra_bytes)
        node_links = len(self.cluster_r) + len(self.mixed_r) + len(self.reverse_r)
        links = len(self.links) + node_links + extra_links
        # the kept links' occluder lists, and their copy when the pass's links are joined; and
        # the classification's temporaries (_candidate_batches): a run holds at most
        # CHUNK_CANDIDATES, and at most four children's copies of every list (entries of 2 bytes
        # or more), so a scene with few lists is not charged the whole run
        entries = self.links.occluders.occ.size + (extra_bytes + grown_bytes) // 2
        estimate = ((len(self.links) + extra_links) * LINK_PEAK_BYTES + 2 * self.links.occluders.occ.nbytes
                    + node_links * CLUSTER_LINK_PEAK_BYTES
                    + len(self.el) * ELEMENT_PEAK_BYTES + extra_bytes + grown_bytes
                    + min(CHUNK_CANDIDATES, 4 * entries) * CANDIDATE_BYTES)
        _memory.check(f"a hierarchy of {links:,} links and {len(self.el):,} elements", int(estimate),
                      "raise link_tolerance or min_element_size (or use a coarser preset)")

    def _refine_clusters(self, r: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """Refine the cluster links (r, s) with the current radiosities; keep those meeting eps.

        Returns the pairs of input patches they came down to (to become element links) and
        how many cluster links were split.
        """
        tree = self.tree
        B = tree.values(self.B[:tree.n_roots])
        over = (tree.bound(r, s, B) > self.eps) | (r == s)
        factor = self.cluster_factor[~over] if len(self.cluster_factor) == len(r) else np.zeros(0)
        to_elements = (self.el.splittable[:tree.n_roots] & self.active[:tree.n_roots]) if MIXED_LINKS else None
        cr, cs, pr, ps, mr, ms, vr, vs, n_split = tree.refine(r[over], s[over], B, self.eps, to_elements,
                                                              MIXED_MIN_PATCHES, self._reverse_below)
        visible, partial = self._cluster_visibility(cr, cs)
        if CLUSTER_EPS_SHARE < 1.0 and len(cr):
            # a link whose representative pair is partly visible meets a share of eps: its
            # visibility is a guess, and the guesses of many links add up on one leaf
            tight = partial & (tree.bound(cr, cs, B) > CLUSTER_EPS_SHARE * self.eps)
            if tight.any():
                tr, ts, tpr, tps, tmr, tms, tvr, tvs, t_split = tree.refine(cr[tight], cs[tight], B,
                                                                            CLUSTER_EPS_SHARE * self.eps, to_elements,
                                                                            MIXED_MIN_PATCHES, self._reverse_below)
                t_visible, _ = self._cluster_visibility(tr, ts)
                cr, cs = np.concatenate([cr[~tight], tr]), np.concatenate([cs[~tight], ts])
                visible = np.concatenate([visible[~tight], t_visible])
                pr, ps, n_split = np.concatenate([pr, tpr]), np.concatenate([ps, tps]), n_split + t_split
                mr, ms = np.concatenate([mr, tmr]), np.concatenate([ms, tms])
                vr, vs = np.concatenate([vr, tvr]), np.concatenate([vs, tvs])
        # links that stay keep their estimate; only the new ones are estimated
        self.cluster_r, self.cluster_s = np.concatenate([r[~over], cr]), np.concatenate([s[~over], cs])
        estimate = tree.estimates(cr, cs)
        if CLUSTER_VISIBILITY:
            estimate = estimate * visible
        self.cluster_factor = np.concatenate([factor, estimate])
        self.stats.cluster_links = len(self.cluster_r)
        er, es, m_split = self._refine_mixed(mr, ms, B)
        vr, vs, v_split = self._refine_reverse(vr, vs)
        self._check_memory(len(pr) + len(er) + len(vr))
        return np.concatenate([pr, er, vr]), np.concatenate([ps, es, vs]), n_split + m_split + v_split

    def _refine_reverse(self, r: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """Refine the reverse mixed links (cluster node r gathers from element s): those kept
        from the last pass that still meet eps, and the new ones (r, s) the cluster refinement
        stopped at, down to eps (partly visible ones to ``CLUSTER_EPS_SHARE`` of it, as cluster
        links).

        A link over eps splits its element when that can split and is at least as large as
        the cluster (by bounding spheres), else the cluster; a cluster's patch children become
        element links. Kept links take the isotropic estimate of the element's Gauss points
        toward the cluster, by reciprocity per unit of the cluster's area, times the visibility
        of the element and the cluster's patch that faces it most.

        Returns the element pairs (patch, s) to evaluate and how many links were split.
        """
        if len(self.reverse_r):
            still = self._reverse_bound(self.reverse_r, self.reverse_s) <= self.eps
            r, s = np.concatenate([self.reverse_r[~still], r]), np.concatenate([self.reverse_s[~still], s])
            kept = [(self.reverse_r[still], self.reverse_s[still], self.reverse_factor[still],
                     self.reverse_estimate[still])]
        else:
            kept = []
        nr, ns, visible, pr, ps, n_split = self._split_to_eps(r, s, self._split_reverse, self._reverse_visibility,
                                                              self._reverse_bound)
        estimate = self._reverse_estimates(nr, ns)
        kept.append((nr, ns, estimate * visible, estimate))
        self.reverse_r, self.reverse_s, self.reverse_factor, self.reverse_estimate = (
            np.concatenate([k[i] for k in kept]) for i in range(4))
        self.stats.reverse_mixed_links = len(self.reverse_r)
        return pr, ps, n_split

    def _reverse_bound(self, r: np.ndarray, s: np.ndarray, extent: np.ndarray | None = None) -> np.ndarray:
        """(m,) :meth:`ClusterTree.bound` of reverse mixed links (node r gathers from element
        s); ``extent``: s's :meth:`_extent`, if known."""
        el = self.el
        extent = self._extent(s) if extent is None else extent
        return self.tree.element_source_bound(r, el.centroid[s], extent, el.normal[s], el.area[s], self.B[s])

    def _split_reverse(self, r: np.ndarray, s: np.ndarray, eps: float):
        """:meth:`_split_mixed` of reverse mixed links (node r gathers from element s): (kept_r,
        kept_s, patch_r, patch_s, n_split), the element pairs as (r input patch, s element)."""
        s, r, ps, pr, n_split = self._split_element_node(s, r, lambda e, n, x: self._reverse_bound(n, e, x), eps)
        return r, s, pr, ps, n_split

    def _reverse_visibility(self, r: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(visible, partial) of reverse mixed links: rays between the cluster's patch that
        faces the element's centroid most and the element."""
        if not (CLUSTER_VISIBILITY or CLUSTER_EPS_SHARE < 1.0) or not len(r):
            return np.ones(len(r)), np.zeros(len(r), bool)
        return self._rays_between(self.tree.facing_patch(r, self.el.centroid[s]), s)

    def _reverse_estimates(self, r: np.ndarray, s: np.ndarray) -> np.ndarray:
        """(m,) isotropic factor of reverse mixed links per unit of the cluster's area:
        ``A_s F_sr / A_r``, F_sr the estimate from the element's Gauss points to the cluster
        (:meth:`_mixed_estimates` of the element gathering from the cluster)."""
        if not len(r):
            return np.zeros(0)
        mean, _ = self._mixed_estimates(s, r)
        return self.el.area[s] * mean / np.maximum(self.tree.area[r], 1e-300)

    def _refine_mixed(self, r: np.ndarray, s: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """Refine the mixed links (element r gathers from cluster node s): the kept ones and the
        new pairs (r, s) the cluster refinement stopped at, under the node radiosities ``B``.

        A link over eps splits its element when that can split and is at least as large as the
        cluster (by bounding spheres), else the cluster; a cluster's patch children become
        element links. Kept links take the isotropic estimate at the element's Gauss points
        (:meth:`ClusterTree.element_estimates`) times the visibility of the element and the
        cluster's patch that faces it most; partly visible ones meet ``CLUSTER_EPS_SHARE`` of
        eps, as cluster links do. An element whose mixed links together vary across it past
        ``leaf_eps`` at one of its points hands them to its children, as element links do
        (:meth:`_varying_receivers`; the two sums are apart).

        Returns the element pairs (r, patch) to evaluate and how many links were split.
        """
        if len(self.mixed_r):
            still = self._mixed_bound(self.mixed_r, self.mixed_s, B) <= self.eps
            r, s = np.concatenate([self.mixed_r[~still], r]), np.concatenate([self.mixed_s[~still], s])
            kept = [(self.mixed_r[still], self.mixed_s[still], self.mixed_factor[still], self.mixed_shape[still])]
        else:
            kept = []
        mr, ms, mf, md, pr, ps, n_split = self._keep_mixed(r, s, B)
        kept.append((mr, ms, mf, md))
        cat = lambda k: np.concatenate([part[k] for part in kept])  # noqa: E731
        mr, ms, mf, md = cat(0), cat(1), cat(2), cat(3)
        pairs = [(pr, ps)]
        for _ in range(MIXED_VARY_ROUNDS if np.isfinite(self.leaf_eps) else 0):
            vary = self._varying_mixed(mr, ms, md, B)
            if not vary.any():
                break
            first = self._split_elements(mr[vary])
            nr, ns, nf, nd, pr, ps, n = self._keep_mixed((first[:, None] + np.arange(4)).ravel(),
                                                         np.repeat(ms[vary], 4), B)
            mr, ms = np.concatenate([mr[~vary], nr]), np.concatenate([ms[~vary], ns])
            mf, md = np.concatenate([mf[~vary], nf]), np.concatenate([md[~vary], nd])
            pairs.append((pr, ps))
            n_split += n + int(vary.sum())
        self.mixed_r, self.mixed_s, self.mixed_factor, self.mixed_shape = mr, ms, mf, md
        self.stats.mixed_links = len(mr)
        return np.concatenate([p for p, _ in pairs]), np.concatenate([q for _, q in pairs]), n_split

    def _keep_mixed(self, r: np.ndarray, s: np.ndarray, B: np.ndarray):
        """Split the mixed links (r, s) down to eps (:meth:`_split_mixed`, partly visible ones to
        ``CLUSTER_EPS_SHARE`` of it) and estimate those kept.

        Returns (r, s, factor, shape, patch_r, patch_s, n_split): the kept links, their
        factors and deviations at the receiver's Gauss points (:meth:`_mixed_estimates`), and the
        element pairs split off.
        """
        nr, ns, visible, pr, ps, n_split = self._split_to_eps(
            r, s, lambda a, b, eps: self._split_mixed(a, b, B, eps), self._mixed_visibility,
            lambda a, b: self._mixed_bound(a, b, B))
        factor, shape = self._mixed_estimates(nr, ns)
        return nr, ns, factor * visible, (shape * visible[:, None]).astype(np.float32), pr, ps, n_split

    def _split_to_eps(self, r: np.ndarray, s: np.ndarray, split, visibility, bound):
        """Mixed links (either way round) split down to eps by ``split(r, s, eps)``, with the
        ``visibility(r, s)`` of those kept; the partly visible ones whose ``bound(r, s)`` is over
        ``CLUSTER_EPS_SHARE`` of eps are split again down to that share, as cluster links are.

        Returns (r, s, visible, patch_r, patch_s, n_split): the kept links, their visible
        fractions (ones without ``CLUSTER_VISIBILITY``) and the element pairs split off.
        """
        nr, ns, pr, ps, n_split = split(r, s, self.eps)
        visible, partial = visibility(nr, ns)
        if CLUSTER_EPS_SHARE < 1.0 and len(nr):
            tight = partial & (bound(nr, ns) > CLUSTER_EPS_SHARE * self.eps)
            if tight.any():
                tr, ts, tpr, tps, t_split = split(nr[tight], ns[tight], CLUSTER_EPS_SHARE * self.eps)
                t_visible, _ = visibility(tr, ts)
                nr, ns = np.concatenate([nr[~tight], tr]), np.concatenate([ns[~tight], ts])
                visible = np.concatenate([visible[~tight], t_visible])
                pr, ps, n_split = np.concatenate([pr, tpr]), np.concatenate([ps, tps]), n_split + t_split
        if not CLUSTER_VISIBILITY:
            visible = np.ones(len(nr))
        return nr, ns, visible, pr, ps, n_split

    def _mixed_estimates(self, r: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(m,) isotropic factor of mixed links, the mean over the receiver's ``RECEIVER_ORDER``
        Gauss points, and (m, q) its value at each point less that mean."""
        points, weights = patch_points(self.el.quads[r], RECEIVER_ORDER)
        q = points.shape[1]
        values = self.tree.element_estimates(points.reshape(-1, 3), np.repeat(self.el.normal[r], q, axis=0),
                                             np.repeat(s, q)).reshape(-1, q)
        mean = (values * weights).sum(axis=1) / np.maximum(weights.sum(axis=1), 1e-300)
        return mean, values - mean[:, None]

    def _varying_mixed(self, r: np.ndarray, s: np.ndarray, shape: np.ndarray, B: np.ndarray) -> np.ndarray:
        """(m,) mixed links whose receiver can split and whose mixed links' deviations, summed
        at one of its Gauss points, stray past ``leaf_eps`` (see :meth:`_varying_receivers`)."""
        can = self.el.splittable[r]
        if not can.any():
            return can
        weight = (self.rho[self.el.root[r]] * B[s]).max(axis=1)
        if QUADRATIC_PUSH and FIT_LEAF_TEST:
            return can & self._unfitted_receivers(r, weight, shape)[r]
        worst = np.zeros(len(self.el))
        for k in range(shape.shape[1]):
            np.maximum(worst, np.abs(np.bincount(r, weights=weight * shape[:, k], minlength=len(self.el))), out=worst)
        return can & (worst > self.leaf_eps)[r]

    def _mixed_bound(self, r: np.ndarray, s: np.ndarray, B: np.ndarray, extent: np.ndarray | None = None) -> np.ndarray:
        """(m,) :meth:`ClusterTree.bound` of mixed links (element r gathers from node s);
        ``extent``: r's :meth:`_extent`, if known."""
        el = self.el
        extent = self._extent(r) if extent is None else extent
        return self.tree.element_bound(el.centroid[r], extent, el.normal[r], self.rho[el.root[r]], s, B)

    def _extent(self, r: np.ndarray) -> np.ndarray:
        """(m,) radius of each element's sphere about its centroid."""
        return np.linalg.norm(self.el.quads[r] - self.el.centroid[r][:, None], axis=2).max(axis=1)

    def _split_mixed(self, r: np.ndarray, s: np.ndarray, B: np.ndarray, eps: float):
        """Split mixed links over ``eps`` until each meets it or becomes element links.

        Returns (kept_r, kept_s, patch_r, patch_s, n_split): the mixed links meeting eps and
        the element pairs (r element, s input patch) split off the clusters.
        """
        return self._split_element_node(r, s, lambda e, n, x: self._mixed_bound(e, n, B, x), eps)

    def _split_element_node(self, element: np.ndarray, node: np.ndarray, bound, eps: float):
        """Split links between elements and cluster nodes (either way round) whose ``bound``
        (element, node, the element's extent) exceeds ``eps``: the element where it can split
        and is at least as large as the node (by bounding spheres), else the node; a node's
        patch children become element pairs.

        Returns (kept_element, kept_node, pair_element, pair_patch, n_split).
        """
        tree, el = self.tree, self.el
        kept, pairs, n_split = [], [], 0
        four = np.arange(4)
        while len(element):
            extent = self._extent(element)
            over = bound(element, node, extent) > eps
            kept.append((element[~over], node[~over]))
            element, node, extent = element[over], node[over], extent[over]
            n_split += len(element)
            split = el.splittable[element] & (extent >= tree.radius[node])
            first = self._split_elements(element[split])
            new_element, new_node = [(first[:, None] + four).ravel()], [np.repeat(node[split], 4)]
            ee, nn = element[~split], node[~split]
            for k in range(2):
                c = tree.child[nn, k]
                patch = tree.patch[c]
                pairs.append((ee[patch >= 0], patch[patch >= 0]))
                new_element.append(ee[patch < 0])
                new_node.append(c[patch < 0])
            element, node = np.concatenate(new_element), np.concatenate(new_node)
        cat = lambda parts, i: np.concatenate([p[i] for p in parts]) if parts else np.zeros(0, np.int64)  # noqa: E731
        return cat(kept, 0), cat(kept, 1), cat(pairs, 0), cat(pairs, 1), n_split

    def _mixed_visibility(self, r: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(visible, partial) of mixed links: rays between the element and the cluster's patch
        that faces its centroid most, as :meth:`_cluster_visibility` does for two clusters."""
        if not (CLUSTER_VISIBILITY or CLUSTER_EPS_SHARE < 1.0) or not len(r):
            return np.ones(len(r)), np.zeros(len(r), bool)
        return self._rays_between(r, self.tree.facing_patch(s, self.el.centroid[r]))

    def _split_elements(self, which: np.ndarray) -> np.ndarray:
        """:meth:`Elements.split`, the new children starting with their parent's radiosity."""
        n_before = len(self.el)
        first = self.el.split(which)
        if len(self.el) > n_before:
            self.B = np.concatenate([self.B, self.B[self.el.parent[n_before:]]])
        return first

    def _cluster_visibility(self, r: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(visible, partial) of cluster links: those of the pair of patches, one in each node,
        that face each other most (:meth:`ClusterTree.facing_patch`), by rays alone
        (:meth:`ElementVisibility.by_rays`): partly visible where they disagree or all are
        blocked."""
        if not (CLUSTER_VISIBILITY or CLUSTER_EPS_SHARE < 1.0) or not len(r):
            return np.ones(len(r)), np.zeros(len(r), bool)
        tree = self.tree
        return self._rays_between(tree.facing_patch(r, tree.centre[s]), tree.facing_patch(s, tree.centre[r]))

    def _rays_between(self, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(visible, partial) of the element pairs (a, b) by rays alone
        (:meth:`ElementVisibility.by_rays`), in chunks as element links are: the 5 M cluster
        links of the 1,000-cube room at once gave the closed-room cull a (link, occluder) row
        per candidate of each, its 4.8 GB peak."""
        visible, partial = np.empty(len(a)), np.empty(len(a), bool)
        for start in range(0, len(a), CHUNK_LINKS):
            part = slice(start, start + CHUNK_LINKS)
            visible[part], partial[part] = self.vis.by_rays(self.el, a[part], b[part])
        return np.clip(visible, 0.0, 1.0), partial

    def refine(self) -> int:
        """One refinement pass with the current radiosities; returns how many links were split."""
        n_cluster_split = 0
        if not self._started:
            self._started = True
            if self.tree is None:
                r, s = self.initial_pairs()
            else:
                r, s, n_cluster_split = self._refine_clusters(np.zeros(1, np.int64), np.zeros(1, np.int64))
            self.stats.initial_links = len(r) + len(self.cluster_r)
            work = self._evaluate(r, s)
            kept = []
            n_first = 0
        else:
            over = self._over(self.links)
            can = self.el.splittable
            split = over & (can[self.links.r] | can[self.links.s])
            # links that now exceed eps (the radiosities grew) but cannot split are settled, as
            # in the first pass: left as they were, a wall's 0.25 m leaves kept the 16-ray
            # visibility of links carrying 2% of their light (the cube room, issue 14)
            stuck = over & ~split & ~self.links.settled
            # (links, mask) parts, taken when they are joined: the links that stay are most of
            # them, and copying them out first cost a second copy
            kept = [(self.links, ~split & ~stuck)]
            if SETTLE_LATER and stuck.any():
                kept.append((self._settle(self.links.take(stuck)), None))
            else:
                kept.append((self.links, stuck))
            work = self.links.take(split)
            n_first = int(split.sum())
            r, s, parent = self._expand(work)
            self._check_memory(len(r))
            work = self._evaluate(r, s, (work, parent))
            if self.tree is not None:
                r, s, n_cluster_split = self._refine_clusters(self.cluster_r, self.cluster_s)
                work = Links.concat([work, self._evaluate(r, s)])
        n_split = n_first + n_cluster_split + self._descend(work, kept)
        links = Links.gather(kept)
        del kept, work  # their arrays are in links now
        if np.isfinite(self.leaf_eps):
            links, n_moved = self._move_varying_receivers(links)
            n_split += n_moved
        # a link neither of whose ends can split has no children to classify: its list goes
        can = self.el.splittable
        links.occluders = links.occluders.only(can[links.r] | can[links.s])
        self.links = links
        self.stats.split_per_round.append(n_split)
        return n_split

    def _descend(self, work: Links, kept: list) -> int:
        """Split the links of ``work`` over eps until every link meets it or is settled; the
        links that stay go to ``kept`` (as (links, None) parts of :meth:`Links.gather`).
        Returns how many were split."""
        n_split = 0
        while len(work):
            over = self._over(work)
            can = self.el.splittable
            split = over & (can[work.r] | can[work.s])
            stuck = over & ~split & ~work.settled
            # taken now, not at the join: ``work`` is dropped at the next level
            kept.append((work.take(~over | work.settled), None))
            kept.append((self._settle(work.take(stuck)), None))
            n_split += int(split.sum())
            todo = work.take(split)
            if not len(todo):
                break
            r, s, parent = self._expand(todo)
            # with the occluder lists the pass has kept so far (a room of tessellated primitives
            # outgrew the estimate by its lists and was killed at 24 GB)
            new = [p for p, _ in kept if p is not self.links]
            self._check_memory(len(r) + sum(len(p) for p in new), sum(p.occluders.occ.nbytes for p in new))
            work = self._evaluate(r, s, (todo, parent))
        return n_split

    def _move_varying_receivers(self, links: Links) -> tuple[Links, int]:
        """Move all links of each receiver whose gathered radiosity varies across it past
        ``leaf_eps`` (:meth:`_varying_receivers`; each of its links meets eps alone) down to
        its children, until none does. Returns the links and how many were split.

        After the first round only the receivers that gained links are tested again (the test
        is per receiver, and the others' links did not change), and the links that move are
        marked dead in their part rather than the millions that stay copied out round after
        round (9% of the 594-face furnished room's solve, with up to 6 rounds a pass). The
        links come back in the order of moving them one round at a time, as they did.
        """
        parts, alive = [links], [np.ones(len(links), bool)]
        tested, chosen = links, None  # chosen: per part, the mask of its links under test
        n_split = 0
        while True:
            moved = self._varying_receivers(tested)
            if not moved.any():
                break
            todo = tested.take(moved)
            if chosen is None:
                alive[0] &= ~moved
            else:
                start = 0
                for live, pick in zip(alive, chosen):
                    at = np.flatnonzero(pick)
                    live[at[moved[start:start + len(at)]]] = False
                    start += len(at)
            n_split += len(todo)
            r, s, parent = self._expand(todo, receiver=True)
            self._check_memory(len(r) + sum(int(a.sum()) for a in alive),
                               sum(part.occluders.occ.nbytes for part in parts[1:]))
            new = []
            n_split += self._descend(self._evaluate(r, s, (todo, parent)), new)
            parts.append(Links.gather(new))
            alive.append(np.ones(len(parts[-1]), bool))
            gained = np.zeros(len(self.el), bool)
            gained[parts[-1].r] = True
            chosen = [live & gained[part.r] for part, live in zip(parts, alive)]
            tested = Links.gather(list(zip(parts, chosen)))
        if len(parts) == 1:
            return links, n_split
        return Links.gather(list(zip(parts, alive))), n_split

    def _varying_receivers(self, links: Links) -> np.ndarray:
        """(m,) links whose receiver can split and whose gathered radiosity, summed over its
        links at its Gauss points, strays from its mean by more than ``leaf_eps`` at one of them
        (with ``QUADRATIC_PUSH``: from the quadratic that carries it to the leaves, by more
        than ``FIT_LEAF_SHARE`` of that, or from its mean by ``FIT_LEAF_DEVIATION`` times it;
        :meth:`_unfitted_receivers`).

        Each link's spread meets eps alone, but a receiver's links can all lean the same way: a
        floor element in a room's corner sees less of every far wall region than its mean, and
        its corner leaf gathered 1.15 of its row in a furnace (issue 14); the bundled box's
        floor elements see more of every element of the lamp on one side. The leaves below get
        the mean, so that sum is the error this level pushes onto them. Signed sums keep the
        leanings that cancel (more of the near walls, less of the far ones) from refining. The
        deviations are of ``F V`` (:meth:`_visible_deviation`): where shadows fall across the
        receiver, its points see the sources differently.
        """
        can = self.el.splittable[links.r]
        if not can.any():
            return can
        idx = np.flatnonzero(can & (links.shape_scale > 0))
        if not len(idx):
            return np.zeros(len(links), bool)
        r, s = links.r[idx], links.s[idx]
        weight = self._weights(r, s) * links.shape_scale[idx] / 127
        if QUADRATIC_PUSH and FIT_LEAF_TEST:
            return can & self._unfitted_receivers(r, weight, links.shape[idx])[links.r]
        # per element, not per distinct receiver: a bincount over all elements needs no sort of
        # the links (np.unique's; the box at draft, 3.5 mm: 0.150 -> 0.119 s a call)
        worst = np.zeros(len(self.el))
        for k in range(links.shape.shape[1]):
            np.maximum(worst, np.abs(np.bincount(r, weights=weight * links.shape[idx, k], minlength=len(self.el))),
                       out=worst)
        return can & (worst > self.leaf_eps)[links.r]

    def _unfitted_receivers(self, r: np.ndarray, weight: np.ndarray, codes: np.ndarray) -> np.ndarray:
        """(n_elements,) bool: receivers whose links' weighted point deviations, summed, stray
        past ``FIT_LEAF_SHARE * leaf_eps`` from the quadratic that carries them to the leaves
        (:mod:`._variation`) at one of their points (what that push leaves out), or past
        ``FIT_LEAF_DEVIATION * leaf_eps`` from their mean."""
        receivers, at = np.unique(r, return_inverse=True)
        summed = np.zeros((len(receivers), codes.shape[1]))
        for k in range(codes.shape[1]):
            summed[:, k] = np.bincount(at, weights=weight * codes[:, k], minlength=len(receivers))
        out = np.zeros(len(self.el), bool)
        out[receivers] = ((np.abs(fit_residuals(self.el, receivers, summed)).max(axis=1) > FIT_LEAF_SHARE * self.leaf_eps)
                          | (np.abs(summed).max(axis=1) > FIT_LEAF_DEVIATION * self.leaf_eps))
        return out

    # ------------------------------------------------------------------ solve
    def operator(self, clamp: bool = False) -> tuple[LinkOperator, np.ndarray]:
        """(K, leaves): the leaf operator K = P G R and the leaf elements it acts on; with
        ``clamp``, leaf rows summing past 1 are scaled down to 1."""
        el = self.el
        leaves = el.leaves()
        rows, elements = el.ancestry(leaves)
        ne, nl = len(el), len(leaves)
        push = sp.csr_matrix((np.ones(len(rows)), (rows, elements)), shape=(nl, ne))
        share = el.area[leaves][rows] / np.where(el.area[elements] > 0, el.area[elements], 1.0)
        pull = sp.csr_matrix((share, (elements, rows)), shape=(ne, nl))
        links = len(self.links)
        if self.tree is None:
            (r, s, value), children = self._gather_entries()
            gather = Gather(sp.csr_matrix((value, (r, s)), shape=(ne, ne)), [children])
        else:
            push, gather, pull = self._with_clusters(push, pull, leaves)
            links += len(self.cluster_r) + len(self.mixed_r) + len(self.reverse_r)
        if QUADRATIC_PUSH:
            push, gather = self._with_variation(push, gather, leaves)
        K = LinkOperator(push, gather, pull, links)
        total = K @ np.ones(nl)
        over = total > 1.0
        self.stats.rows_over_one = int(over.sum())
        self.stats.max_row_sum = float(total.max(initial=0.0))
        if clamp and over.any():
            K.row_scale = np.where(over, 1.0 / np.where(over, total, 1.0), 1.0)
        return K, leaves

    def _with_variation(self, push: sp.csr_matrix, gather: Gather, leaves: np.ndarray) -> tuple[sp.csr_matrix, Gather]:
        """P and G with the element links' and mixed links' variation across their receivers
        (:mod:`._variation`): G gathers each receiver's point deviations, P pushes the
        quadratic fitting them onto the leaves below."""
        links = self.links
        r, s, codes, scale = links.r, links.s, links.shape, links.shape_scale
        if self.tree is not None and len(self.mixed_r):  # element <- cluster: the cluster's column
            mixed_codes, mixed_scale = _shape_codes(self.mixed_shape)
            r, s = np.concatenate([r, self.mixed_r]), np.concatenate([s, self._node_columns()[self.mixed_s]])
            codes, scale = np.concatenate([codes, mixed_codes]), np.concatenate([scale, mixed_scale])
        found = variation_part(self.el, r, s, codes, scale, leaves)
        if found is None:
            return push, gather
        part, columns = found
        return sp.hstack([push, columns], format="csr"), Gather(gather.matrix, gather.parts, part)

    def _node_columns(self) -> np.ndarray:
        """(n_nodes,) each cluster node's column of G: a patch node's input patch (its root
        element), an internal node's row after the elements'."""
        tree = self.tree
        return np.where(tree.patch >= 0, tree.patch, len(self.el) + tree.column)

    def _gather_entries(self) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], _Children]:
        """G's element links: (rows, columns, values) of those whose source is a leaf, and
        the others as a :class:`_Children`.

        A link whose source has children gathers from them, each by its share of the link's
        factor (:func:`._links.source_shares`; four Lambert factors a link, each time an
        operator is made: kept with the links, their 16 bytes a link went through every copy
        refinement makes), instead of from the source's area mean (see ``SOURCE_SHARES``).
        """
        links, el = self.links, self.el
        value = links.factor * links.visible
        split = el.first_child[links.s] >= 0 if SOURCE_SHARES else np.zeros(len(links), bool)
        at = np.flatnonzero(split)
        shares = np.empty((len(at), 4), np.float32)
        for a in range(0, len(at), CHUNK_LINKS):
            part = at[a:a + CHUNK_LINKS]
            shares[a:a + CHUNK_LINKS] = source_shares(el, links.r[part], links.s[part])
        index = np.int32 if len(el) < np.iinfo(np.int32).max else np.int64
        children = _Children(links.r[at].astype(index), el.first_child[links.s[at]].astype(index), value[at], shares)
        whole = ~split
        return (links.r[whole], links.s[whole], value[whole]), children

    def _with_clusters(self, push, pull, leaves):
        """P, G, R extended by the cluster nodes (columns/rows after the elements).

        A cluster pulls the area mean of its patches. What a link to a cluster gathers (per unit
        of its area) goes to its patches by their shares (:meth:`ClusterTree.oriented_shares`),
        or to every leaf below it alike where the cluster is about flat (``ORIENT_CONE``).
        """
        tree, ne = self.tree, len(self.el)
        share = tree.membership(tree.n_roots)  # (c, n_roots): roots are elements 0..n_roots-1
        pull_c = share @ pull[:tree.n_roots]
        inside = (share > 0).astype(float).tocsc()[:, self.el.root[leaves]]
        push = sp.hstack([push, inside.T.tocsr()], format="csr")
        pull = sp.vstack([pull, pull_c], format="csr")
        del share, pull_c, inside
        column = self._node_columns()
        oriented = (tree.patch[self.cluster_r] < 0) & (tree.cone[self.cluster_r] > ORIENT_CONE)
        even = ~oriented
        r, s, factor = self.cluster_r[oriented], self.cluster_s[oriented], self.cluster_factor[oriented]
        (lr, ls, lvalue), children = self._gather_entries()
        gather = _Triplets(len(lr) + int(even.sum()) + len(self.mixed_r), ne + len(tree.internal))
        gather.add(lr, ls, lvalue)
        del lr, ls, lvalue
        gather.add(column[self.cluster_r[even]], column[self.cluster_s[even]], self.cluster_factor[even])
        gather.add(self.mixed_r, column[self.mixed_s], self.mixed_factor)
        # an oriented link has one value per patch of its receiver (tens of millions for a
        # 300k-face sphere): kept link by link, without row and column indices
        spread = _Spread(r, column[s], *tree.receiver_shares(r, s, factor), tree)
        # reverse mixed links: the element's radiosity to the cluster's patches, by how each
        # faces it and whether it sees it (the element's column is its own index)
        el, vr, vs = self.el, self.reverse_r, self.reverse_s
        if REVERSE_PATCH_VISIBILITY:
            start, share = tree.point_shares(vr, el.centroid[vs], el.normal[vs], self.reverse_estimate)
            self._apply_patch_seen(vr, vs, start, share)
        else:
            start, share = tree.point_shares(vr, el.centroid[vs], el.normal[vs], self.reverse_factor)
        spread_back = _Spread(vr, vs, start, share, tree)
        return push, Gather(gather.tocsr(), [children, spread, spread_back]), pull

    def _apply_patch_seen(self, r: np.ndarray, s: np.ndarray, start: np.ndarray, share: np.ndarray) -> None:
        """Zero in ``share`` (:meth:`ClusterTree.point_shares` of the reverse mixed links (r, s))
        the patches that do not see their link's element (:meth:`_reverse_patch_seen`), link by
        link: one float array of every share's visibility held 0.8 GB more at the 103k room's peak."""
        seen = self._reverse_patch_seen(r, s)
        for k, mask in enumerate(seen):
            share[start[k]:start[k] + len(mask)] *= mask

    def _reverse_patch_seen(self, r: np.ndarray, s: np.ndarray) -> list[np.ndarray]:
        """For each reverse mixed link (r, s), whether each patch of its cluster (in
        :meth:`point_shares`' order) sees the element: a segment from the patch's centroid to the
        element's centroid. Traced once a link (``_reverse_seen``), when an operator first holds
        it; links no longer held are forgotten."""
        tree, el = self.tree, self.el
        keys = (r.astype(np.int64) << 32) | s.astype(np.int64)
        cache = self._reverse_seen
        new = np.flatnonzero([k not in cache for k in keys.tolist()])
        off = _tol.RAY_OFFSET_REL * self.vis.patches.scale
        members = tree.hi[r[new]] - tree.lo[r[new]]
        ends = np.cumsum(members)
        a = 0
        while a < len(new):  # about CHUNK_SEEN segments at a time: 64 bytes each while traced
            b = max(a + 1, int(np.searchsorted(ends, ends[a] - members[a] + CHUNK_SEEN, side="right")))
            links = new[a:b]
            seg, pos = _cluster_ranges(tree.lo[r[links]], tree.hi[r[links]])
            patch, source = tree.order[pos], s[links][seg]
            traced = _facing_or_all(tree.centroids[patch], tree.normals[patch], el.centroid[source],
                                    el.normal[source], seg, len(links))
            seen = np.zeros(len(patch), bool)
            seen[traced] = ~self.vis.patches._occluder().occluded(
                tree.centroids[patch[traced]] + off * tree.normals[patch[traced]],
                el.centroid[source[traced]] + off * el.normal[source[traced]])
            self.vis.n_rays += len(traced)
            bounds = np.concatenate([[0], np.cumsum(members[a:b])])
            for i, k in enumerate(keys[links].tolist()):
                cache[k] = seen[bounds[i]:bounds[i + 1]].copy()  # not a view: a chunk outlives its links
            a = b
        held = [cache[k] for k in keys.tolist()]
        self._reverse_seen = dict(zip(keys.tolist(), held))
        return held

    def solve(self, rtol: float, clamp: bool = False) -> tuple[np.ndarray, LinkOperator, np.ndarray, SolveReport]:
        """Leaf radiosities (l, 3) of B = E + rho K B; element radiosities are pulled from them.

        ``clamp``: scale leaf rows of K past 1 down to 1 (for the solves that steer refinement;
        see :func:`radiosity.methods.hierarchical._alternate`).
        """
        K, leaves = self.operator(clamp)
        root = self.el.root[leaves]
        rho, emission = self.rho[root], self.emission[root]
        B = self.B[leaves].copy()
        report = SolveReport()
        for c in range(3):
            same = next((k for k in range(c) if np.array_equal(rho[:, k], rho[:, c])
                         and np.array_equal(emission[:, k], emission[:, c])), None)
            if same is not None:  # a grey channel: the same system as one solved already
                B[:, c] = B[:, same]
                iterations, residual, fallback = 0, report.residual[same], report.fallback[same]
            else:
                B[:, c], iterations, residual, fallback = _solve_channel(K, rho[:, c], emission[:, c], B[:, c], rtol)
            report.iterations.append(iterations)
            report.residual.append(residual)
            report.fallback.append(fallback)
        self.B = (K.pull @ B)[:len(self.el)]
        return B, K, leaves, report


def _facing_or_all(centroid: np.ndarray, normal: np.ndarray, point: np.ndarray, point_normal: np.ndarray,
                   seg: np.ndarray, n_links: int) -> np.ndarray:
    """Indices of the patches (one row each, of link ``seg``) whose visibility of their link's
    element matters: those that face it and that it faces, as :func:`point_receiver_shares`
    weighs them (the others take no share), or every patch of a link none of whose patches
    does (they then share alike). Most of a cluster faces away from a reverse link's element:
    tracing only the rest saved most of 157 M segments in the 103k room."""
    w = point - centroid
    facing = (np.einsum("ij,ij->i", normal, w) > 0.0) & (np.einsum("ij,ij->i", point_normal, w) < 0.0)
    none = np.bincount(seg[facing], minlength=n_links) == 0
    return np.flatnonzero(facing | none[seg])


class _Triplets:
    """A square sparse matrix's (row, column, value) entries, filled in place block by block.

    One allocation of 16 bytes an entry (int32 indices, which scipy then keeps without a
    copy): the lists of int64 blocks this replaces, concatenated and converted, took about 60
    bytes an entry at their peak, 1.7 GB of a 300k-face sphere's 6.7 GB (session 27).
    """

    def __init__(self, size: int, n: int):
        index = np.int32 if n < np.iinfo(np.int32).max else np.int64
        self.rows, self.cols, self.values = np.empty(size, index), np.empty(size, index), np.empty(size)
        self.n, self.end = n, 0

    def add(self, rows: np.ndarray, cols: np.ndarray, values: np.ndarray) -> None:
        stop = self.end + len(values)
        self.rows[self.end:stop], self.cols[self.end:stop], self.values[self.end:stop] = rows, cols, values
        self.end = stop

    def tocsr(self) -> sp.csr_matrix:
        """The matrix, duplicates summed; the triplets are released."""
        assert self.end == len(self.values), "every entry counted is filled"
        out = sp.csr_matrix((self.values, (self.rows, self.cols)), shape=(self.n, self.n))
        self.rows = self.cols = self.values = None
        return out


def _past_budget(r: np.ndarray, err: np.ndarray, budget: float) -> np.ndarray:
    """(m,) links past their receiver's budget: each receiver ``r`` keeps its smallest bounds
    while they sum to at most ``budget``; the rest are past it."""
    if not len(r):
        return np.zeros(0, bool)
    order = np.lexsort((err, r))
    receiver, sorted_err = r[order], err[order]
    total = np.cumsum(sorted_err)
    first = np.flatnonzero(np.r_[True, receiver[1:] != receiver[:-1]])
    before = np.repeat(total[first] - sorted_err[first], np.diff(np.r_[first, len(r)]))
    out = np.zeros(len(r), bool)
    out[order] = total - before > budget
    return out


def _shape_codes(deviation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(codes, scale): int8 codes of each row of ``deviation`` in units of its largest |value| / 127."""
    scale = np.abs(deviation).max(axis=1)
    safe = np.where(scale > 0, scale, 1.0)
    codes = np.rint(deviation / safe[:, None] * 127.0).astype(np.int8)
    return codes, scale.astype(np.float32)


def _facing(el: Elements, r: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(facing, crossing): each end has a vertex in front of the other's plane; an end
    has vertices on both sides of the other's plane."""
    tol = 1e-9 * np.maximum(el.edge[r], el.edge[s])
    h_s = np.einsum("mkc,mc->mk", el.quads[s] - el.centroid[r][:, None, :], el.normal[r])
    h_r = np.einsum("mkc,mc->mk", el.quads[r] - el.centroid[s][:, None, :], el.normal[s])
    front_s, front_r = (h_s > tol[:, None]).any(axis=1), (h_r > tol[:, None]).any(axis=1)
    back_s, back_r = (h_s < -tol[:, None]).any(axis=1), (h_r < -tol[:, None]).any(axis=1)
    return front_s & front_r, (front_s & back_s) | (front_r & back_r)


def _near_bound(el: Elements, r: np.ndarray, s: np.ndarray, near_only: bool, *,
                as_if_splittable: bool = False) -> np.ndarray:
    """(m,) upper bound of the point-to-polygon factor F(x -> s) over the points x of r.

    s lies in the sphere of radius ``R_s`` about its centroid, at least ``d`` from any point
    of r (the distance of that centre to r's plane, or to r's centroid less r's radius), and
    the elements are at least ``g`` apart (their spheres' gap, or the height of one's lowest
    vertex over the other's plane). From x, s fits in a cone of half-angle
    ``asin(R_s / d)``, whose projected solid angle is at most ``(R_s / d)^2``; every direction
    to s rises at most ``H_s / g`` above r's plane (``H_s``: the height of s's highest vertex
    over it), so its cosine is at most that, and the cone's plain solid angle is at most
    ``2 pi (R_s / d)^2``. Likewise ``F <= A_s cos_r cos_s / (pi g^2)``. Where the elements are
    not apart (touching neighbours), the bound is ``TOUCHING_BOUND`` for a source under
    ``NEAR_SMALLER`` of r's radius and 0 (unused: the 3x3 points' range and the crossing test
    stay in charge) for a larger one. It is 0 where r cannot split (a leaf's mean is what it
    stores, so its links make no push error), unless ``as_if_splittable``; ``near_only``: only
    where s comes within ``NEAR_RELATIVE`` radii of r.

    The receiver's 3x3 points miss the peak of a source closer to r than r's size (a small
    cube 10 cm from a 1 m wall: the wall's links saw 0.0012 where its leaf nearest the cube
    sees 0.0073), so this bound replaces their range there.
    """
    out = np.empty(len(r))
    splittable = np.ones(len(el), bool) if as_if_splittable else el.splittable
    near_bounds(el.quads, el.centroid, el.normal, el.area, splittable, np.asarray(r, np.int64),
                np.asarray(s, np.int64), near_only, NEAR_SMALLER, NEAR_GAP, NEAR_RELATIVE, TOUCHING_BOUND, out)
    return out


def _visibility_doubt(visible: np.ndarray, partial: np.ndarray, samples: int) -> np.ndarray:
    """(m,) share of a link's factor its visibility leaves in doubt.

    0 for pairs the classification decided. For undecided pairs: 1 where the rays disagree
    (some blocked, some not: the shadow crosses the pair), and one ray's share where they all
    agree: ``UNANIMOUS_DOUBT``. A heuristic, not a bound: with one ray's share (1/16), links
    whose rays all missed a thin shadow (or all hit a wide one) stayed coarse and the bundled
    box's floor and red wall, beside the blocks, reached 1% too few patches.
    """
    mixed = (visible > 0.0) & (visible < 1.0)
    return np.where(partial, np.where(mixed, 1.0, UNANIMOUS_DOUBT), 0.0)


def _factor_bound(el: Elements, r: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(m,) a crude upper bound of F(r -> s): A_s / (pi d^2) at the centroids' distance, at most 1."""
    d2 = np.einsum("mc,mc->m", el.centroid[r] - el.centroid[s], el.centroid[r] - el.centroid[s])
    return np.minimum(1.0, el.area[s] / (np.pi * np.maximum(d2, 1e-300)))


def _solve_channel(K: LinkOperator, rho: np.ndarray, emission: np.ndarray, x0: np.ndarray, rtol: float):
    """One channel of (I - rho K) b = E: GMRES, then fixed-point sweeps if it stalls."""
    n = len(rho)
    A = spla.LinearOperator((n, n), matvec=lambda x: x - rho * (K @ x), dtype=np.float64)
    norm_e = float(np.linalg.norm(emission))
    if norm_e == 0.0:
        return np.zeros(n), 0, 0.0, ""
    count = [0]

    def callback(_):
        count[0] += 1

    b, _ = spla.gmres(A, emission, x0=x0, rtol=rtol, atol=0.0, restart=40, maxiter=50, callback=callback,
                      callback_type="pr_norm")
    residual = float(np.linalg.norm(A @ b - emission)) / norm_e
    fallback = ""
    if not np.isfinite(residual) or residual > max(rtol, 1e-12) * 10:
        fallback = "fixed point"
        b = x0.copy() if np.isfinite(x0).all() else emission.copy()
        for _ in range(5000):
            new = emission + rho * (K @ b)
            step = float(np.linalg.norm(new - b))
            b = new
            count[0] += 1
            if step <= rtol * max(float(np.linalg.norm(b)), 1e-300):
                break
        residual = float(np.linalg.norm(A @ b - emission)) / norm_e
    return b, count[0], residual, fallback

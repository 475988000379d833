"""What one link carries: its form factor (Lambert at receiver points) and its visibility.

A link (r, s) lets element r gather from element s: H_r += F_rs V_rs B_s. Its estimates:

- ``F_rs``: the mean over Gauss points x_q of r of Lambert's exact point-to-polygon factor
  F(x_q -> s), zero where x_q is behind s (sources are one-sided). The spread of the point
  values, ``max - min``, says how far one constant per receiver is from the truth.
- ``V_rs``: the exact classification of :class:`radiosity.visibility.Visibility` first (the
  input patches are the occluders: an element lies in its patch's plane, so its own patch never
  counts); only pairs it leaves undecided trace stratified rays (kernel-weighted). Such a link
  is *partly visible*: its whole power is uncertain, whatever its rays say.
"""

from __future__ import annotations

import copy

import numpy as np

from ...formfactors import lambert_indexed
from ...formfactors import pair_factors, patch_points
from ...visibility import FREE, FULL, MAYBE, Visibility
from ...visibility._pairs import _rows_of
from ._elements import Elements

__all__ = ["link_factors", "source_shares", "ElementVisibility", "adaptive_factors"]

RECEIVER_ORDER = 3  # Gauss points per direction on the receiver: 9 Lambert evaluations per link
SETTLE_RAY_SAMPLES = 5  # the many-occluder pairs of ElementVisibility.exact trace this**4 rays at least
CULL_BEHIND = True  # leave out occluders behind either end's plane (ElementVisibility._over)
MAX_EXACT_OCCLUDERS = 10  # visibility.MAX_UNION: more possible occluders a pair trace rays (ElementVisibility.exact)
# Undecided pairs whose first samples**4 rays would all agree (all blocked or all passing)
# trace max_samples**4 rays, as those that disagree do: every undecided pair traces those.
# In the room of 300 floating cubes (draft) a fifth of the partly visible links were
# unanimous, and their first rays counted as hidden what gaps between cubes let through
# (exact 0.044 where all 16 rays said 0) more than they counted as free what small cubes hid
# (0.961 where all said 1): the links' power came out 0.6% short.
RETRACE_UNANIMOUS = True
# Pairs whose rays all carry no weight take exact shadows once (not again after the retrace),
# at 4x4 receiver points only: in the 100-cube room (draft) 34,455 such pairs, most of them
# cluster links' proxy pairs, took 3.8 of the 29.5 s, 3.4 s of it the 16x16 second try, which
# found a point seeing the source for 4 of 54,284 pairs (the rest count as unblocked).
BLIND_ORDERS = (4,)
# Blind pairs (rays all without weight) behind more possible occluders than this take no exact
# shadows in the refinement (ElementVisibility.fractions_undecided): visible 0.5, whole factor in doubt.
MAX_BLIND_OCCLUDERS = 64
# A pair's walk of the occluders' BVH stops at this many undecided occluders (Visibility.list_cap).
# Past RAY_LIST_EMBREE and MAX_BLIND_OCCLUDERS the list's content is used only by the children's
# classification (Hierarchy._visibility), which takes it as incomplete (Undecided.cut,
# ElementVisibility._cut_short); its rays go through Embree and a blind pair is marked 0.5 either
# way. Without a cap the room elements of a 103k-face furnished room (five 20,480-triangle
# spheres) collected thousands of sphere triangles a pair, twice (count, then fill): one
# classification call ran for more than ten minutes, and the CLI solve was still refining after
# 37 minutes at 15 GB.
LIST_CAP = 256


def link_factors(el: Elements, r: np.ndarray, s: np.ndarray, order: int = RECEIVER_ORDER, *, shape: bool = False
                 ) -> tuple[np.ndarray, ...]:
    """Mean and spread of the point-to-polygon factor over receiver points of each link.

    Parameters
    ----------
    el : Elements
    r, s : (m,) int
        Receiver and source elements.
    order : int
        Gauss points per direction on the receiver.

    Returns
    -------
    mean : (m,) float
        Estimate of F(r -> s), unoccluded.
    spread : (m,) float
        Largest minus smallest point value.
    top : (m,) float
        With ``shape=True``: the largest point value.
    deviation : (m, order**2) float
        With ``shape=True``: each point value less the mean.
    """
    m = len(r)
    if m == 0:
        empty = np.zeros(0)
        return (empty, empty, empty, np.zeros((0, order * order))) if shape else (empty, empty)
    points, weights = patch_points(el.quads[r], order)
    q = points.shape[1]
    flat = points.reshape(-1, 3)
    normals = np.repeat(el.normal[r], q, axis=0)
    sources = np.repeat(s, q)
    values = lambert_indexed(flat, normals, el.quads, np.arange(m * q), sources).reshape(m, q)
    # One-sided sources: a receiver point behind the source's plane sees its back.
    height = np.einsum("mqc,mc->mq", points - el.centroid[s][:, None, :], el.normal[s])
    values = np.where(height > 0, np.clip(values, 0.0, None), 0.0)
    total = weights.sum(axis=1)
    mean = (values * weights).sum(axis=1) / np.where(total > 0, total, 1.0)
    top = values.max(axis=1)
    spread = top - values.min(axis=1)
    return (mean, spread, top, values - mean[:, None]) if shape else (mean, spread)


def source_shares(el: Elements, r: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(m, 4) float: the share of each child of source ``s`` in the factor F(r -> s) (rows sum to 1).

    The link gathers from the children by these shares instead of from the source's area mean
    (see ``_hierarchy.SOURCE_SHARES``). Each share is Lambert's factor from r's centroid to the
    child over their sum (3x3 Gauss points gave the bundled box's objects within 0.07 points of
    the centroid's answer, at 9 times the cost); where the centroid misses the source (behind
    its plane, or in it), the children's areas.
    """
    children = el.first_child[s][:, None] + np.arange(4)
    factor = lambert_indexed(el.centroid, el.normal, el.quads, np.repeat(r, 4), children.ravel())
    # one-sided sources (the children lie in their parent's plane)
    front = np.einsum("mc,mc->m", el.centroid[r] - el.centroid[s], el.normal[s]) > 0
    factor = np.where(front[:, None], np.clip(factor.reshape(-1, 4), 0.0, None), 0.0)
    total = factor.sum(axis=1, keepdims=True)
    area = el.area[children]
    area_total = area.sum(axis=1, keepdims=True)
    by_area = np.where(area_total > 0, area / np.where(area_total > 0, area_total, 1.0), 0.25)
    return np.where(total > 0, factor / np.where(total > 0, total, 1.0), by_area)


def adaptive_factors(el: Elements, r: np.ndarray, s: np.ndarray, rtol: float) -> np.ndarray:
    """F(r -> s) to ``rtol`` by the uniform fill's adaptive quadrature (near and touching pairs)."""
    if len(r) == 0:
        return np.zeros(0)
    return pair_factors(el.quads, el.normal, el.centroid, el.area, r, s, rtol=rtol)


class ElementVisibility:
    """Visibility between elements, with the input patches as occluders.

    Parameters
    ----------
    patches : Visibility
        Built over the input patches (its occluders, classification and ray settings are used).
    """

    def __init__(self, patches: Visibility):
        self.patches = patches
        self.n_rays = 0
        self.n_classified = 0
        self.n_traced = 0
        self.n_exact = 0

    def _over(self, el: Elements) -> Visibility:
        """The patches' Visibility looking at the elements' geometry instead (same occluders),
        leaving out occluders behind either element's plane."""
        view = copy.copy(self.patches)
        view.quads = el.quads
        view.normals = el.normal
        view._lo, view._hi = el.lo, el.hi
        view.n_rays = 0
        view.n_exact_rows = 0
        # An occluder with no vertex in front of r's plane (or of s's) cannot cut a segment from
        # a point of r to a point of s in front of it. Without that test a cube face kept the
        # faces of its own cube that touch it as possible occluders, and every link of it was
        # "partly visible" (issue 14). Done in numpy on the classification's output, the test
        # took half the refinement of a furnished room; the kernel now makes it.
        view.cull_behind = CULL_BEHIND
        # the children of a link, classified against its undecided occluders, then get what
        # their own walk would (classify_listed tests every candidate against the pair's hull)
        view.hull_always = True
        view.list_cap = self.list_cap
        return view

    @property
    def list_cap(self) -> int:
        """Undecided occluders at which a walk stops (``LIST_CAP``): a list this long may be
        cut short, and its link's children take it as incomplete (:meth:`_cut_short`)."""
        return LIST_CAP

    def fractions(self, el: Elements, r: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Visible fraction and "partly visible" flag of each link (r receives from s).

        Returns
        -------
        visible : (m,) float
            1 for pairs nothing can block, -1 for pairs an occluder blocks entirely, else the
            kernel-weighted fraction of stratified rays that pass.
        partial : (m,) bool
            The classification left the pair undecided (partly visible, whatever the rays say).
        """
        visible, partial, _, _, _ = self.fractions_undecided(el, r, s)
        return visible, partial

    def by_rays(self, el: Elements, r: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`fractions` by the first ``samples**4`` stratified rays alone, cast through
        Embree against every occluder with no classification; "partly visible" where they
        disagree or all are blocked. Pairs whose rays carry no weight take :meth:`fractions`.

        For the cluster links' representative pairs (:meth:`Hierarchy._cluster_visibility`),
        whose visibility is a guess for two whole clusters: their walks through the occluders'
        BVH (9 us a pair, for small patches whose box spans the room) were a fifth of the
        300-cube furnace room's solve.
        """
        m = len(r)
        if m == 0:
            return np.ones(0), np.zeros(0, bool)
        view = self._over(el)
        visible, agree = self._embree_rays(view, el, r, s, view.samples)
        self.n_rays += view.n_rays
        self.n_traced += m
        # all rays blocked counts as partly visible too: the walk would have found most such
        # pairs undecided, not wholly hidden, and their links meet a share of eps
        partial = ~agree | (visible <= 0.0)
        blind = np.flatnonzero(np.isnan(visible))
        if len(blind):
            visible[blind], partial[blind] = self.fractions(el, r[blind], s[blind])
        return visible, partial

    def _embree_rays(self, view: Visibility, el: Elements, r: np.ndarray, s: np.ndarray, samples: int
                     ) -> tuple[np.ndarray, np.ndarray]:
        """(fraction, agree) of pairs (r, s) by ``samples**4`` stratified rays cast through
        Embree against every occluder (:meth:`Visibility._patch_rays` with no lists)."""
        self.patches._occluder()  # one Embree scene, which the views share
        key = r.astype(np.uint64) * np.uint64(len(el)) + s.astype(np.uint64)
        return view._patch_rays(np.asarray(r, np.int64), np.asarray(s, np.int64), samples, key, 1)

    def fractions_undecided(self, el: Elements, r: np.ndarray, s: np.ndarray, *, children: bool = False,
                            candidates: tuple[np.ndarray, np.ndarray] | None = None,
                            incomplete: bool = False, split_if_partial: np.ndarray | None = None
                            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`fractions`, and the undecided occluders of each pair (what its children may
        be classified against).

        Parameters
        ----------
        children : bool
            The links are children of partly visible links, four by four: the classification
            walks each alone (four children span their parent, whose walk was undecided).
        candidates : (starts, occluders), optional
            Possible occluders of each pair, CSR over the pairs: the undecided occluders of
            its parent link, whose segments hold its own. The pairs are classified against
            those only, not by a walk of the occluders' BVH.
        incomplete : bool
            The candidates are not all of the pairs' occluders (the parent's walk stopped at
            :attr:`list_cap`; see :meth:`_cut_short`).
        split_if_partial : (m,) bool, optional
            Pairs that the caller splits if they are partly visible, whatever the fraction:
            those the classification leaves undecided are only marked partly visible (visible
            0.5), without rays or exact shadows.

        Returns
        -------
        visible, partial : (m,)
            As :meth:`fractions`.
        count : (m,) int
            Undecided occluders of each pair (0 unless partly visible).
        occluders : (count.sum(),) int
            Those occluders, pair after pair.
        cut : (m,) bool
            The pair's list is not all of its undecided occluders (its walk stopped at
            :attr:`list_cap`, or it was classified against an incomplete list): its rays went
            through Embree, and its children are to be classified with ``incomplete``.
        """
        m = len(r)
        visible = np.ones(m)
        partial = np.zeros(m, bool)
        if m == 0:
            return visible, partial, np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, bool)
        view = self._over(el)
        cut = np.zeros(m, bool)
        if candidates is None:
            status, rows, occ = view.classify(r, s, runs=not children)
        else:
            status, rows, occ = view.classify_listed(r, s, *candidates)
            if incomplete:
                status, rows, occ, cut = self._cut_short(view, r, s, status, rows, occ)
        self.n_classified += m
        count = np.bincount(rows, minlength=m)
        if view.list_cap > 0:
            cut |= count >= view.list_cap
        visible[status == FULL] = -1.0
        part = np.flatnonzero(status == MAYBE)
        if split_if_partial is not None and len(part):
            doomed = part[split_if_partial[part]]
            visible[doomed], partial[doomed] = 0.5, True
            part = part[~split_if_partial[part]]
        if len(part):
            # every undecided pair ends with max_samples**4 rays: those whose first rays agree
            # are traced again with them (RETRACE_UNANIMOUS), the others refined with them, so
            # they are traced once, with no first round (a sixth of the rays)
            n = max(view.samples, view.max_samples) if RETRACE_UNANIMOUS else None
            whole, listed = part[cut[part]], part[~cut[part]]
            if len(whole):  # a list cut short misses occluders: Embree against all of them
                visible[whole] = self._embree_rays(view, el, r[whole], s[whole], n or view.max_samples)[0]
                # every ray blocked (or none carrying weight): an occluder off the list may hide
                # the pair wholly, which the walk finds (as the children of such links did before,
                # and dropped them)
                dark = whole[~(visible[whole] > 0.0)]
                if len(dark):
                    hidden = dark[view.classify(r[dark], s[dark], runs=False)[0] == FULL]
                    visible[hidden] = -1.0
                    part = np.setdiff1d(part, hidden, assume_unique=True)
            if len(listed):
                sub_rows, sub_occ = _rows_of(rows, occ, listed, m)
                visible[listed] = view.ray_fraction(r[listed], s[listed], n, n, rows=sub_rows, occ=sub_occ,
                                                    blind=False)
            partial[part] = True
            blind = part[np.isnan(visible[part])]
            if len(blind):
                # behind many possible occluders (or a list cut short) a blind pair is only marked
                # uncertain (its whole factor stays in doubt: refinement splits it where that
                # matters): their exact shadows unite hundreds of triangles at a point with
                # shapely, 62% of the first pass in a room of tessellated primitives (29,536 faces)
                many = (count[blind] > MAX_BLIND_OCCLUDERS) | cut[blind]
                visible[blind[many]] = 0.5
                blind = blind[~many]
            if len(blind):
                visible[blind] = view.blind_fraction(r[blind], s[blind], *_rows_of(rows, occ, blind, m),
                                                     orders=BLIND_ORDERS)
            self.n_traced += len(part)
        self.n_rays += view.n_rays
        return visible, partial, count, occ, cut

    @staticmethod
    def _cut_short(view: Visibility, r: np.ndarray, s: np.ndarray, status: np.ndarray, rows: np.ndarray,
                   occ: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(status, rows, occ, cut) of pairs classified against lists that are not all of their
        occluders (as :meth:`Visibility.classify_listed` gave them): an occluder of the list
        that hides a pair wholly or leaves it undecided does so whatever else is there, so
        those pairs stand (the undecided ones ``cut``: their lists miss occluders); a pair the
        list leaves free has none of its occluders near it and walks the occluders' BVH.

        Walking them all, as until session 37, took 200 us a pair in a furnished room of
        3,083 faces, 45 times an inherited classification, and 99.9% of the walks found the
        pair undecided or hidden anyway.
        """
        cut = status == MAYBE
        lone = np.flatnonzero(status == FREE)
        if len(lone):
            status = status.copy()
            status[lone], lone_rows, lone_occ = view.classify(r[lone], s[lone], runs=False)
            rows, occ = np.concatenate([rows, lone[lone_rows]]), np.concatenate([occ, lone_occ])
            order = np.argsort(rows, kind="stable")  # the lists pair after pair
            rows, occ = rows[order], occ[order]
        return status, rows, occ, cut

    def at_points(self, el: Elements, r: np.ndarray, s: np.ndarray, points: np.ndarray,
                  lists: tuple[np.ndarray, np.ndarray] | None) -> np.ndarray:
        """(m, q) visible fraction of s from each point ``points[p]`` on r[p], by rays against
        the pair's undecided occluders (``lists``: (starts, occluders), CSR over the pairs;
        None: through Embree against every occluder)."""
        view = self._over(el)
        key = r.astype(np.uint64) * np.uint64(len(el)) + s.astype(np.uint64)
        out = view.points_ray_fraction(points, el.normal[r], s, lists, key)
        self.n_rays += view.n_rays
        return out

    def exact(self, el: Elements, r: np.ndarray, s: np.ndarray, order: int = 2) -> np.ndarray:
        """(m,) visible fraction by exact shadow clipping at ``order**2`` receiver points.

        Pairs behind more than ``MAX_EXACT_OCCLUDERS`` possible occluders trace the Visibility's
        ``max_samples**4`` stratified rays instead: the exact shadows unite more than
        ``visibility.MAX_UNION`` hidden polygons at a point with shapely, which took 62 of the
        83 s of a 30-cube furnace room (issue 14).
        """
        m = len(r)
        out = np.ones(m)
        if m == 0:
            return out
        view = self._over(el)
        status, rows, occ = view.classify(r, s)
        out[status == FULL] = 0.0
        part = np.flatnonzero(status == MAYBE)
        if len(part):
            count = np.bincount(rows, minlength=m)[part]
            few = count <= MAX_EXACT_OCCLUDERS
            for sel, exact in ((part[few], True), (part[~few], False)):
                if not len(sel):
                    continue
                sub_rows, sub_occ = _rows_of(rows, occ, sel, m)
                if exact:
                    out[sel] = view.exact_fraction(r[sel], s[sel], sub_rows, sub_occ, order)
                else:
                    n = max(view.max_samples, SETTLE_RAY_SAMPLES)
                    out[sel] = view.ray_fraction(r[sel], s[sel], n, n, rows=sub_rows, occ=sub_occ)
            self.n_rays += view.n_rays
        self.n_exact += len(part)
        return np.clip(out, 0.0, 1.0)

"""A volume hierarchy over the input patches and the cluster links above the quadtrees.

Clustering (Smits, Arvo & Greenberg 1994; Sillion 1995): a binary tree of the active input
patches (median splits of their centroids along the longest axis), each node a bounding
sphere. Refinement starts from the root's link to itself, so a scene of n patches does not
start with n^2 links. A link (r gathers from s) between nodes, one of them a cluster, is

- bounded: any point of r sees at most ``A_s cos_r cos_s / (pi d^2)`` of s, with ``d`` the gap
  between the two spheres and the cosines bounded over the normal cones (1 if they overlap),
  and at most ``sin^2`` of the angle the two cones leave between them (the band of directions
  both can face, :meth:`ClusterTree.bound`): ``err = max_c(rho_r,c B_s,c) * that``;
- estimated isotropically when kept: the power r gets is ``B_s P_r(u) P_s(-u) / (pi d^2)``,
  with ``P(u) = sum A_i max(0, n_i . u)`` the projected area of a node's faces toward the
  other's centre ``u`` (faces are one-sided), shared out over r's patches by how each faces s
  (:meth:`ClusterTree.oriented_shares`; evenly where r is about flat), times the visibility of
  the pair of patches that face each other most (:meth:`ClusterTree.facing_patch`).

A link over ``eps`` is split at its larger cluster (both children); a cluster's link to itself
always splits (into its children's links to themselves and to each other). Links between two
nodes of one convex object (a sphere, a box: :func:`radiosity.geometry.convex_groups`) are
dropped: no patch of such an object sees another. A pair of two input patches becomes an
element link (:mod:`._hierarchy`), with its facing test, visibility and quadtrees. A cluster's
radiosity is the area mean of its patches' (isotropic shooting).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ...geometry import convex_groups
from ._clusters_kernel import (element_bounds, element_estimates, element_source_bounds, facing_patches,
                               link_bounds, link_estimates, point_receiver_shares, receiver_shares)

__all__ = ["ClusterTree", "CLUSTER_MIN_ROOTS"]

# Below this many active input patches the hierarchy starts from all facing pairs (n^2 is cheap
# there and its links carry visibility from the start).
CLUSTER_MIN_ROOTS = 400
# Drop the links inside a convex object (ClusterTree._exchanging): they carry nothing.
DROP_CONVEX = True
ESTIMATE_DEPTH = 2  # levels of children a cluster link's estimate sums over (see ClusterTree.estimates)


def _ranges(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(segment, position) of every position in the ranges [lo, hi)."""
    sizes = hi - lo
    seg = np.repeat(np.arange(len(lo)), sizes)
    starts = np.cumsum(sizes) - sizes
    return seg, np.repeat(lo, sizes) + np.arange(int(sizes.sum())) - starts[seg]


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(m,) angle between unit vectors, radians."""
    return np.arccos(np.clip(np.einsum("mc,mc->m", a, b), -1.0, 1.0))


class ClusterTree:
    """Binary volume hierarchy over active input patches.

    Parameters
    ----------
    patches : (m,) int
        The active input patches to cluster (m >= 1).
    quads, normals, areas, reflectance
        Per input patch: (n, 4, 3), (n, 3), (n,), (n, 3).

    Attributes
    ----------
    order : (m,) int
        Patches in tree order; node k holds ``order[lo[k]:hi[k]]``.
    child : (k, 2) int
        Children of each node, -1 for a patch node.
    patch : (k,) int
        The input patch of a one-patch node, else -1.
    centre, radius, area, rho : per node
        Bounding sphere, total area, largest reflectance per channel.
    """

    def __init__(self, patches, quads, normals, areas, reflectance, groups=None):
        self.n_roots = len(quads)
        self.normals, self.areas = np.asarray(normals, float), np.asarray(areas, float)
        order = np.asarray(patches, np.int64).copy()
        centroids = quads.mean(axis=1)
        self.centroids = centroids
        lo, hi, child, level = [0], [len(order)], [[-1, -1]], [0]
        frontier = np.array([0]) if len(order) > 1 else np.zeros(0, np.int64)
        depth = 0
        while len(frontier):
            depth += 1
            L, H = np.array(lo)[frontier], np.array(hi)[frontier]
            seg, pos = _ranges(L, H)
            c = centroids[order[pos]]
            starts = np.cumsum(H - L) - (H - L)
            span = np.maximum.reduceat(c, starts) - np.minimum.reduceat(c, starts)
            axis = span.argmax(axis=1)
            key = c[np.arange(len(c)), axis[seg]]
            order[pos] = order[pos][np.lexsort((key, seg))]
            mid = (L + H) // 2
            first = len(lo)
            for a, b in ((L, mid), (mid, H)):
                lo.extend(a.tolist())
                hi.extend(b.tolist())
            child.extend([[-1, -1]] * (2 * len(frontier)))
            level.extend([depth] * (2 * len(frontier)))
            kids = first + np.arange(2 * len(frontier))
            child = np.asarray(child)
            child[frontier, 0] = kids[:len(frontier)]
            child[frontier, 1] = kids[len(frontier):]
            child = child.tolist()
            sizes = np.array(hi)[kids] - np.array(lo)[kids]
            frontier = kids[sizes > 1]
        self.order, self.lo, self.hi = order, np.array(lo), np.array(hi)
        self.child, self.level = np.array(child, np.int64).reshape(-1, 2), np.array(level)
        single = self.hi - self.lo == 1
        self.patch = np.where(single, order[np.minimum(self.lo, len(order) - 1)], -1)
        self._bounds(quads, np.asarray(reflectance, float))
        self.group = self._groups(np.zeros(self.n_roots, np.int64) if groups is None else np.asarray(groups))
        # groups (objects) that see nothing of themselves: links inside one are dropped
        self.convex = np.zeros(max(int(self.group.max()), 0) + 1, bool)
        if groups is not None and DROP_CONVEX:
            self.convex = convex_groups(quads[order], self.normals[order], np.asarray(groups)[order])
        internal = np.flatnonzero(~single)
        self.internal = internal  # the cluster nodes (two or more patches)
        self.column = np.full(len(self.lo), -1)
        self.column[internal] = np.arange(len(internal))

    def __len__(self) -> int:
        return len(self.lo)

    def _groups(self, groups: np.ndarray) -> np.ndarray:
        """(k,) the group (object) of each node's patches where they share one, else -1."""
        out = np.full(len(self.lo), -1, np.int64)
        leaf = np.flatnonzero(self.patch >= 0)
        out[leaf] = groups[self.patch[leaf]]
        for depth in range(int(self.level.max()), -1, -1):
            nodes = np.flatnonzero((self.level == depth) & (self.patch < 0))
            a, b = out[self.child[nodes, 0]], out[self.child[nodes, 1]]
            out[nodes] = np.where(a == b, a, -1)
        return out

    def _bounds(self, quads: np.ndarray, rho: np.ndarray) -> None:
        """Spheres, areas and reflectance bounds, from the patches up (children follow parents)."""
        k = len(self.lo)
        self.centre, self.radius = np.zeros((k, 3)), np.zeros(k)
        self.area, self.rho = np.zeros(k), np.zeros((k, 3))
        self._box = np.zeros((k, 2, 3))
        self.axis, self.cone = np.zeros((k, 3)), np.zeros(k)  # normal cone: axis, half-angle (rad)
        leaf = np.flatnonzero(self.patch >= 0)
        q = quads[self.patch[leaf]]
        self._box[leaf, 0], self._box[leaf, 1] = q.min(axis=1), q.max(axis=1)
        self.centre[leaf] = self._box[leaf].mean(axis=1)
        self.radius[leaf] = np.linalg.norm(q - self.centre[leaf][:, None], axis=2).max(axis=1)
        self.area[leaf], self.rho[leaf] = self.areas[self.patch[leaf]], rho[self.patch[leaf]]
        self.axis[leaf] = self.normals[self.patch[leaf]]
        self.area_vector = np.zeros((k, 3))  # sum of A_i n_i over the node's patches
        self.area_vector[leaf] = self.area[leaf, None] * self.axis[leaf]
        self.largest = self.radius.copy()  # the largest patch sphere's radius in each node
        for depth in range(int(self.level.max()), -1, -1):
            nodes = np.flatnonzero((self.level == depth) & (self.patch < 0))
            if not len(nodes):
                continue
            a, b = self.child[nodes, 0], self.child[nodes, 1]
            self._box[nodes, 0] = np.minimum(self._box[a, 0], self._box[b, 0])
            self._box[nodes, 1] = np.maximum(self._box[a, 1], self._box[b, 1])
            c = self._box[nodes].mean(axis=1)
            self.centre[nodes] = c
            # the exact sphere about the box centre (children's spheres would inflate per level)
            seg, pos = _ranges(self.lo[nodes], self.hi[nodes])
            far = np.linalg.norm(quads[self.order[pos]] - c[seg][:, None], axis=2).max(axis=1)
            self.radius[nodes] = np.maximum.reduceat(far, np.cumsum(self.hi[nodes] - self.lo[nodes])
                                                     - (self.hi[nodes] - self.lo[nodes]))
            self.area[nodes] = self.area[a] + self.area[b]
            self.largest[nodes] = np.maximum(self.largest[a], self.largest[b])
            self.area_vector[nodes] = self.area_vector[a] + self.area_vector[b]
            self.rho[nodes] = np.maximum(self.rho[a], self.rho[b])
            mean = self.area[a, None] * self.axis[a] + self.area[b, None] * self.axis[b]
            norm = np.linalg.norm(mean, axis=1)
            axis = np.where(norm[:, None] > 1e-12, mean / np.maximum(norm, 1e-300)[:, None], self.axis[a])
            self.axis[nodes] = axis
            self.cone[nodes] = np.minimum(np.pi, np.maximum(_angle(axis, self.axis[a]) + self.cone[a],
                                                            _angle(axis, self.axis[b]) + self.cone[b]))

    def values(self, per_patch: np.ndarray) -> np.ndarray:
        """(k, 3) area mean of per-patch values over each node (a cluster's isotropic radiosity)."""
        out = np.zeros((len(self.lo), per_patch.shape[1]))
        leaf = np.flatnonzero(self.patch >= 0)
        out[leaf] = per_patch[self.patch[leaf]]
        for depth in range(int(self.level.max()), -1, -1):
            nodes = np.flatnonzero((self.level == depth) & (self.patch < 0))
            a, b = self.child[nodes, 0], self.child[nodes, 1]
            area = np.where(self.area[nodes] > 0, self.area[nodes], 1.0)[:, None]
            out[nodes] = (self.area[a, None] * out[a] + self.area[b, None] * out[b]) / area
        return out

    # ------------------------------------------------------------------ links
    def bound(self, r: np.ndarray, s: np.ndarray, B: np.ndarray) -> np.ndarray:
        """(m,) error bound of node links (r gathers from s), radiosity units:
        ``max_c(rho_r,c B_s,c)`` times the smaller of two bounds on the factor from any point of
        r to s (numba: :func:`._clusters_kernel.link_bounds`).

        - ``A_s cos_r cos_s / (pi gap^2)`` with each cosine bounded over the node's normal cone
          and the cone of directions between the two spheres (1 where the spheres overlap).
        - From the normal cones alone, for spheres that overlap as well: ``sin^2 w``,
          ``w = angle(axis_r, axis_s) + cone_r + cone_s`` (1 from pi/2 on). s sends light only
          along directions u with n_s . u < 0 for some n_s in its cone, all within pi/2 + cone_s
          of -axis_s, so at least pi/2 - w from any receiver normal n_r in r's cone; the
          cosine-weighted share of that band of the hemisphere is sin^2 w. Without it two
          touching patches of a terrain (or of one wall) always split down to their leaves.
        """
        out = np.empty(len(r))
        link_bounds(np.asarray(r, np.int64), np.asarray(s, np.int64), self.centre, self.radius, self.axis,
                    self.cone, self.area, self.rho, np.ascontiguousarray(B, dtype=float), out)
        return out

    def refine(self, r: np.ndarray, s: np.ndarray, B: np.ndarray, eps: float, to_elements: np.ndarray | None = None,
               min_patches: int = 2, reverse_below: float = 0.0):
        """Split node links over ``eps`` down to where they meet it or join two patches.

        ``to_elements`` (optional, (n_roots,) bool): input patches that may gather from a
        cluster as elements. A link over ``eps`` from a cluster to such a patch at least as
        large as the cluster stops here, as a mixed link, for the patch's quadtree to split
        (:meth:`Hierarchy._refine_mixed`): splitting the cluster instead took a wall patch
        down to one link per triangle of a tessellated sphere beside it. Only to clusters of
        at least ``min_patches`` patches of one group (object) other than the patch's: the
        estimate from one point of the element leans one way where a cluster wraps round it
        (a floor patch and the walls beside it, one object, in the 100-cube furnace room).
        The same holds the other way round for clusters whose patches are all smaller than
        ``reverse_below`` across (0: none): a cluster gathering from such a patch at least as
        large as itself stops as a reverse mixed link (cluster <- element,
        :meth:`Hierarchy._refine_reverse`), instead of splitting down to one link per patch of
        the cluster (a tessellated sphere's triangles each gathered from every wall patch).

        Returns
        -------
        kept_r, kept_s : (k,) int
            Cluster links meeting ``eps`` (at least one end a cluster).
        patch_r, patch_s : (p,) int
            Pairs of distinct input patches (to become element links).
        mixed_r, mixed_s : (q,) int
            Input patches (element indices) and the cluster nodes they gather from.
        reverse_r, reverse_s : (v,) int
            Cluster nodes and the input patches (element indices) they gather from.
        n_split : int
        """
        kept, pairs, mixed, back, n_split = [], [], [], [], 0
        is_patch = self.patch >= 0
        while len(r):
            r, s = self._exchanging(r, s)
            both = is_patch[r] & is_patch[s]
            pairs.append((self.patch[r[both & (r != s)]], self.patch[s[both & (r != s)]]))
            r, s = r[~both], s[~both]
            over = (self.bound(r, s, B) > eps) | (r == s)
            kept.append((r[~over], s[~over]))
            r, s = r[over], s[over]
            if to_elements is not None:
                # (a cluster of the patch's own object, which may hold the patch itself, splits on)
                stop = self._stops(r, s, min_patches)
                stop[stop] = to_elements[self.patch[r[stop]]]
                mixed.append((self.patch[r[stop]], s[stop]))
                r, s = r[~stop], s[~stop]
                if reverse_below > 0.0:
                    stop = self._stops(s, r, min_patches) & (2.0 * self.largest[r] < reverse_below)
                    stop[stop] = to_elements[self.patch[s[stop]]]
                    back.append((r[stop], self.patch[s[stop]]))
                    r, s = r[~stop], s[~stop]
            n_split += len(r)
            same = r == s
            cr, cs = self.child[r[same]], self.child[s[same]]
            new_r = [cr[:, 0], cr[:, 0], cr[:, 1], cr[:, 1]]
            new_s = [cs[:, 0], cs[:, 1], cs[:, 0], cs[:, 1]]
            r, s = r[~same], s[~same]
            split_r = ~is_patch[r] & ((self.radius[r] >= self.radius[s]) | is_patch[s])
            for k in range(2):
                new_r += [self.child[r[split_r], k], r[~split_r]]
                new_s += [s[split_r], self.child[s[~split_r], k]]
            r, s = np.concatenate(new_r), np.concatenate(new_s)
        cat = lambda parts, i: np.concatenate([p[i] for p in parts]) if parts else np.zeros(0, np.int64)  # noqa: E731
        return (cat(kept, 0), cat(kept, 1), cat(pairs, 0), cat(pairs, 1), cat(mixed, 0), cat(mixed, 1),
                cat(back, 0), cat(back, 1), n_split)

    def _stops(self, patch: np.ndarray, node: np.ndarray, min_patches: int) -> np.ndarray:
        """(m,) links of :meth:`refine` between ``patch`` (a patch node) and a cluster ``node``
        that may stop as mixed links: the patch at least as large as the cluster, the cluster of
        at least ``min_patches`` patches of one group other than the patch's."""
        return ((self.patch[patch] >= 0) & (self.radius[patch] >= self.radius[node])
                & (self.hi[node] - self.lo[node] >= min_patches) & (self.group[node] >= 0)
                & (self.group[node] != self.group[patch]))

    def _exchanging(self, r: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The node links (r, s) less those inside one convex group (:func:`convex_groups`),
        which carry nothing: a 20,480-triangle sphere kept 1.2 M cluster links to itself, each
        meeting eps only with the rays of its representative pair."""
        same = (self.group[r] == self.group[s]) & (self.group[r] >= 0)
        same[same] = self.convex[self.group[r[same]]]
        return (r[~same], s[~same]) if same.any() else (r, s)

    def element_bound(self, centroid: np.ndarray, extent: np.ndarray, normal: np.ndarray, rho: np.ndarray,
                      s: np.ndarray, B: np.ndarray) -> np.ndarray:
        """(m,) :meth:`bound` of flat elements (centroid, circumradius ``extent``, normal,
        reflectance, per link) gathering from nodes s."""
        out = np.empty(len(s))
        element_bounds(np.ascontiguousarray(centroid, dtype=float), np.ascontiguousarray(extent, dtype=float),
                       np.ascontiguousarray(normal, dtype=float), np.ascontiguousarray(rho, dtype=float),
                       np.asarray(s, np.int64), self.centre, self.radius, self.axis, self.cone, self.area,
                       np.ascontiguousarray(B, dtype=float), out)
        return out

    def element_source_bound(self, r: np.ndarray, centroid: np.ndarray, extent: np.ndarray, normal: np.ndarray,
                             area: np.ndarray, B: np.ndarray) -> np.ndarray:
        """(m,) :meth:`bound` of nodes r gathering from flat elements (centroid, circumradius
        ``extent``, normal, area and radiosity ``B``, per link)."""
        out = np.empty(len(r))
        element_source_bounds(np.asarray(r, np.int64), np.ascontiguousarray(centroid, dtype=float),
                              np.ascontiguousarray(extent, dtype=float), np.ascontiguousarray(normal, dtype=float),
                              np.ascontiguousarray(area, dtype=float), np.ascontiguousarray(B, dtype=float),
                              self.centre, self.radius, self.axis, self.cone, self.rho, out)
        return out

    def element_estimates(self, centroid: np.ndarray, normal: np.ndarray, s: np.ndarray,
                          depth: int = ESTIMATE_DEPTH) -> np.ndarray:
        """(m,) isotropic factor from each element (its centroid and normal) to node s, per unit
        of its area: ``sum_b P_b(-u) max(0, n . u) / (pi d^2)`` over the nodes b ``depth``
        levels below s, as :meth:`estimates` takes a flat receiver; a node b whose normal cone
        straddles the horizon of u is summed patch by patch, each from its own centroid (its
        centre's direction biased such links high, up to 1.7x at a sphere's rim)."""
        out = np.empty(len(s))
        child, patch, lo, hi, order, normals, areas, centre, axis, cone = self._kernel_tree()
        element_estimates(np.ascontiguousarray(centroid, dtype=float), np.ascontiguousarray(normal, dtype=float),
                          np.asarray(s, np.int64), depth, child, patch, lo, hi, order, self.centroids, normals,
                          areas, centre, axis, cone, self.area_vector, out)
        return out

    def estimates(self, r: np.ndarray, s: np.ndarray) -> np.ndarray:
        """(m,) isotropic factor of each cluster link: H_r = F_rs B_s per unit area of r.

        Summed over the pairs of the two nodes' descendants ``ESTIMATE_DEPTH`` levels down (a
        patch node is its own child): ``F_rs = sum_ab A_a F_ab / A_r``. One centre-to-centre
        estimate per link was biased high by about the link tolerance on a furnace sphere
        (curved clusters' centres lie inside it, closer than their faces); each level down
        roughly halves that bias for about the same cost again.
        """
        out = np.empty(len(r))
        link_estimates(np.asarray(r, np.int64), np.asarray(s, np.int64), ESTIMATE_DEPTH, *self._kernel_tree(),
                       self.area, self.area_vector, out)
        return out

    def _kernel_tree(self) -> tuple:
        """The arrays the numba kernels walk the tree and project nodes with."""
        return (self.child, self.patch, self.lo, self.hi, self.order, self.normals, self.areas, self.centre,
                self.axis, self.cone)

    def facing_patch(self, nodes: np.ndarray, toward: np.ndarray) -> np.ndarray:
        """(m,) the patch of each node that faces the point ``toward`` (m, 3) most: the largest
        ``A_i n_i . u``, ``u`` from the node's centre (its middle patch if none faces it).

        A cluster link's visibility comes from one pair of patches. The middle patches in tree
        order were often faces turned away from each other, which a cube's own plane culls to
        "free": links of a cube face to a source behind other cubes counted 1 for a true 0.1,
        and the 100-cube furnace room's brightest leaf was 4.9% over.
        """
        pick = self.order[(self.lo[nodes] + self.hi[nodes]) // 2]
        facing_patches(self.lo[nodes], self.hi[nodes], self.order, self.normals, self.areas, self.centre[nodes],
                       np.ascontiguousarray(toward, dtype=float), pick)
        return pick

    def oriented_shares(self, r: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """How cluster links (r gathers from s) share their estimate out over r's patches.

        Patch i of r weighs ``sum_b P_b(-u) max(0, n_i . u_ib) / d_ib^2`` over the nodes b
        ``ESTIMATE_DEPTH`` levels below s (``u``: from r's centre to b's; ``u_ib``, ``d_ib``:
        from i's centroid), scaled so that the area mean over r is 1 (the estimate keeps its
        power; all ones where no patch faces s). Spread evenly, a cube face turned to a wall
        2 cm away got a share of the far room it cannot see (Sillion 1995's oriented clusters).

        Returns (link, patch, share): one row per link and patch of its r.
        """
        _, share = self.receiver_shares(r, s, np.ones(len(r)))
        return (np.repeat(np.arange(len(r)), self.hi[r] - self.lo[r]), self.order[_ranges(self.lo[r], self.hi[r])[1]],
                share)

    def receiver_shares(self, r: np.ndarray, s: np.ndarray, scale: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(start, share): the shares of :meth:`oriented_shares` times ``scale`` (one per link),
        link after link, each receiver's patches in tree order (``order[lo[r]:hi[r]]``); link k's
        begin at ``start[k]``."""
        members = self.hi[r] - self.lo[r]
        start = np.cumsum(members) - members
        share = np.empty(int(members.sum()))
        child, patch, lo, hi, order, normals, areas, centre, axis, cone = self._kernel_tree()
        receiver_shares(np.asarray(r, np.int64), np.asarray(s, np.int64), ESTIMATE_DEPTH, child, patch, lo, hi, order,
                        self.centroids, normals, areas, self.area, centre, axis, cone, self.area_vector,
                        np.asarray(scale, float), start, share)
        return start, share

    def point_shares(self, r: np.ndarray, point: np.ndarray, normal: np.ndarray,
                     scale: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(start, share) as :meth:`receiver_shares` gives them, for nodes r gathering from flat
        sources at ``point`` facing ``normal`` (reverse mixed links): each patch by how it and
        the source face each other over the squared distance."""
        members = self.hi[r] - self.lo[r]
        start = np.cumsum(members) - members
        share = np.empty(int(members.sum()))
        point_receiver_shares(np.asarray(r, np.int64), np.ascontiguousarray(point, dtype=float),
                              np.ascontiguousarray(normal, dtype=float), self.lo, self.hi, self.order,
                              self.centroids, self.normals, self.areas, self.area, np.asarray(scale, float),
                              start, share)
        return start, share

    # ------------------------------------------------------------------ push-pull
    def membership(self, n_roots: int) -> sp.csr_matrix:
        """(c, n_roots) area share of each patch in each cluster node (rows: ``internal``)."""
        nodes = self.internal
        seg, pos = _ranges(self.lo[nodes], self.hi[nodes])
        p = self.order[pos]
        share = self.areas[p] / np.maximum(self.area[nodes][seg], 1e-300)
        return sp.csr_matrix((share, (seg, p)), shape=(len(nodes), n_roots))

"""Element quadtrees over the input patches: quads and triangles split four ways.

Every input patch is the root of a quadtree. Elements are stored in flat arrays that grow as
refinement splits them; the four children of an element are consecutive, so an element's
subtree is found by following ``first_child``. The geometry of an element is a quad (4, 3)
like the scene's patches: a triangle repeats its third vertex, and splits into four triangles
at its edge midpoints (the middle one keeps the parent's winding).
"""

from __future__ import annotations

import numpy as np

from ...geometry import centroids_and_areas

__all__ = ["Elements", "split_quads"]


def _is_triangle(quads: np.ndarray) -> np.ndarray:
    return (quads[:, 3] == quads[:, 2]).all(axis=1)


def split_quads(quads: np.ndarray) -> np.ndarray:
    """(m, 4, 4, 3): the four children of each quad or triangle, in the parent's winding.

    A quad is cut at its edge midpoints and its bilinear centre; a triangle at its edge
    midpoints (three corner triangles and the middle one). The children tile the parent
    exactly for planar quads and for all triangles, so their areas sum to the parent's.
    """
    p0, p1, p2, p3 = (quads[:, k] for k in range(4))
    m01, m12, m23, m30 = 0.5 * (p0 + p1), 0.5 * (p1 + p2), 0.5 * (p2 + p3), 0.5 * (p3 + p0)
    centre = 0.25 * (p0 + p1 + p2 + p3)
    quad_children = np.stack([np.stack([p0, m01, centre, m30], 1), np.stack([m01, p1, m12, centre], 1),
                              np.stack([centre, m12, p2, m23], 1), np.stack([m30, centre, m23, p3], 1)], 1)
    m20 = 0.5 * (p2 + p0)
    tri_children = np.stack([np.stack([p0, m01, m20, m20], 1), np.stack([m01, p1, m12, m12], 1),
                             np.stack([m20, m12, p2, p2], 1), np.stack([m01, m12, m20, m20], 1)], 1)
    return np.where(_is_triangle(quads)[:, None, None, None], tri_children, quad_children)


def longest_edge(quads: np.ndarray) -> np.ndarray:
    """(m,) longest edge of each element, metres (a triangle's repeated vertex adds no edge)."""
    edges = np.roll(quads, -1, axis=1) - quads
    return np.linalg.norm(edges, axis=2).max(axis=1)


class Elements:
    """The element quadtrees of all input patches, growing as they are split.

    Parameters
    ----------
    quads : (n, 4, 3) float
        The input patches (the roots), metres.
    normals : (n, 3) float
        Their unit normals; children keep their root's normal (they lie in its plane).
    min_size : float
        An element is split only while its children's longest edge stays at least this, metres.

    Attributes
    ----------
    quads : (m, 4, 3) float
    root : (m,) int
        The input patch each element belongs to.
    parent, first_child : (m,) int
        -1 for none; the children of ``e`` are ``first_child[e] + 0..3``.
    level : (m,) int
        0 for roots.
    """

    def __init__(self, quads: np.ndarray, normals: np.ndarray, min_size: float):
        n = len(quads)
        self.min_size = float(min_size)
        self._normals_of_roots = np.asarray(normals, dtype=float)
        self._quads = [np.asarray(quads, dtype=float)]
        self._root = [np.arange(n)]
        self._parent = [np.full(n, -1)]
        self._level = [np.zeros(n, np.int64)]
        self.first_child = np.full(n, -1, np.int64)
        self._pack()

    def _pack(self) -> None:
        self.quads = np.concatenate(self._quads) if len(self._quads) > 1 else self._quads[0]
        self.root = np.concatenate(self._root) if len(self._root) > 1 else self._root[0]
        self.parent = np.concatenate(self._parent) if len(self._parent) > 1 else self._parent[0]
        self.level = np.concatenate(self._level) if len(self._level) > 1 else self._level[0]
        self._quads, self._root, self._parent, self._level = [self.quads], [self.root], [self.parent], [self.level]
        self.centroid, self.area = centroids_and_areas(self.quads)
        self.normal = self._normals_of_roots[self.root]
        self.edge = longest_edge(self.quads)
        # each element's bounding box, for the visibility's views (which asked for it per batch)
        self.lo, self.hi = self.quads.min(axis=1), self.quads.max(axis=1)

    def __len__(self) -> int:
        return len(self.quads)

    @property
    def splittable(self) -> np.ndarray:
        """(m,) bool: elements whose children would still be at least ``min_size`` across."""
        return (0.5 * self.edge >= self.min_size) & (self.area > 0)

    @property
    def is_leaf(self) -> np.ndarray:
        return self.first_child < 0

    def split(self, which: np.ndarray) -> np.ndarray:
        """Split the elements ``which`` (those not split yet); returns the first child of each.

        Parameters
        ----------
        which : (k,) int
            Elements to split; repeats and already split elements are allowed.

        Returns
        -------
        (k,) int
            ``first_child`` of each element in ``which``.
        """
        which = np.asarray(which, dtype=np.int64)
        new = np.unique(which[self.first_child[which] < 0])
        if len(new):
            start = len(self.quads)
            children = split_quads(self.quads[new]).reshape(-1, 4, 3)
            self.first_child[new] = start + 4 * np.arange(len(new))
            self._quads.append(children)
            self._root.append(np.repeat(self.root[new], 4))
            self._parent.append(np.repeat(new, 4))
            self._level.append(np.repeat(self.level[new] + 1, 4))
            self.first_child = np.concatenate([self.first_child, np.full(len(children), -1, np.int64)])
            self._pack()
        return self.first_child[which]

    def leaves(self) -> np.ndarray:
        """(l,) int: the leaf elements, in element order (roots' subtrees interleaved by level)."""
        return np.flatnonzero(self.is_leaf)

    def ancestry(self, leaves: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(leaf row, element) pairs for every leaf and each of its ancestors, itself included.

        Returns
        -------
        rows : (t,) int
            Index into ``leaves``.
        elements : (t,) int
        """
        rows, elements = [], []
        current = np.asarray(leaves, dtype=np.int64)
        index = np.arange(len(current))
        while len(current):
            rows.append(index)
            elements.append(current)
            up = self.parent[current]
            keep = up >= 0
            current, index = up[keep], index[keep]
        return np.concatenate(rows), np.concatenate(elements)

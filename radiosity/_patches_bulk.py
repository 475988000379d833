"""The common faces of ``subdivide_faces`` decided at once: triangles and convex planar quads
that stay one patch, and faces of zero area.

A scanned or exported mesh is hundreds of thousands of small triangles, each one patch; the
per-face path (``patches._face_cells``) costs some 50 us a face in numpy calls. Here the same
tests run on arrays, with a margin: a face whose test is closer to its threshold than round-off
could explain (``_MARGIN``) is left to the per-face path, so every face is decided as that path
decides it, and a patch made here is the one it would make, bit for bit.
"""

from __future__ import annotations

import numpy as np

from . import _tol
from .geometry import flat_faces, vector_areas

__all__ = ["whole_faces"]

# Relative distance from a threshold below which a face goes to the per-face path: far above
# the round-off of these few products and sums (about 1e-15), far below any real margin.
_MARGIN = 1e-7
WHOLE, DEGENERATE, PER_FACE = 0, 1, 2


def whole_faces(vertices: np.ndarray, faces: list[np.ndarray], max_size: float | None
                ) -> tuple[np.ndarray, np.ndarray]:
    """(n,) verdict per face (WHOLE, DEGENERATE or PER_FACE) and (n, 4, 3) the patch of each
    WHOLE face (other rows are unset)."""
    n = len(faces)
    verdict = np.full(n, PER_FACE, np.int8)
    cells = np.empty((n, 4, 3))
    if not n:
        return verdict, cells
    flat, sizes = flat_faces(faces)
    offsets = np.cumsum(sizes) - sizes
    for k in (3, 4):
        rows = np.flatnonzero(sizes == k)
        if len(rows):
            poly = vertices[flat[offsets[rows, None] + np.arange(k)]]
            verdict[rows], cell = _decide(poly, max_size)
            cells[rows] = cell
    return verdict, cells


def _decide(poly: np.ndarray, max_size: float | None) -> tuple[np.ndarray, np.ndarray]:
    k = poly.shape[1]
    if k == 3:
        return _decide_triangles(poly, max_size)
    size = (poly.max(axis=1) - poly.min(axis=1)).max(axis=1)  # np.ptp(poly, axis=0).max()
    normal = vector_areas(poly)
    area = np.sqrt((normal * normal).sum(axis=1))
    floor = _tol.DEGENERATE_REL * 1e2 * size**2  # as in subdivide_faces
    verdict = np.full(len(poly), PER_FACE, np.int8)
    verdict[area < floor * (1 - _MARGIN)] = DEGENERATE
    whole = area > floor * (1 + _MARGIN)
    if k == 3:
        cell = np.concatenate([poly, poly[:, 2:3]], axis=1)
        edges = [np.linalg.norm(poly[:, (i + 1) % 3] - poly[:, i], axis=1) for i in range(3)]
    else:
        with np.errstate(invalid="ignore", divide="ignore"):
            unit = normal / area[:, None]
        deviation = np.abs(np.einsum("fvc,fc->fv", poly - poly.mean(axis=1, keepdims=True), unit)).max(axis=1)
        whole &= deviation < _tol.PLANAR_REL * size * (1 - _MARGIN)  # planar_parts keeps it whole
        whole &= _convex(poly, unit)
        cell = _bilinear_corners(poly)
        a, b, c, d = (poly[:, i] for i in range(4))
        edges = [np.maximum(np.linalg.norm(b - a, axis=1), np.linalg.norm(c - d, axis=1)),
                 np.maximum(np.linalg.norm(d - a, axis=1), np.linalg.norm(c - b, axis=1))]
    if max_size is not None:  # uncut: every (paired) edge needs one cut only, by a clear margin
        for length in edges:
            whole &= length / max_size - 1e-9 < 1.0 - _MARGIN
    verdict[whole] = WHOLE
    return verdict, cell


def _decide_triangles(poly: np.ndarray, max_size: float | None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_decide` for (m, 3, 3) triangles, bit for bit, on (m,) columns: numpy's reductions
    over an axis of 3 (``max``, ``mean``, ``sum``, ``norm``) cost most of a 581k-face load, and
    they run in this same order (first corner first), so the sums below give the same bits."""
    a, b, c = (np.ascontiguousarray(poly[:, i].T) for i in range(3))  # (3, m) each: x, y, z rows
    size = np.maximum(np.maximum(a, b), c) - np.minimum(np.minimum(a, b), c)
    size = np.maximum(np.maximum(size[0], size[1]), size[2])
    mean = (a + b + c) / 3
    a, b, c = a - mean, b - mean, c - mean
    normal = 0.5 * (_cross(a, b) + _cross(b, c) + _cross(c, a))  # geometry.vector_areas
    area = np.sqrt(normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2])
    floor = _tol.DEGENERATE_REL * 1e2 * size**2
    verdict = np.full(len(poly), PER_FACE, np.int8)
    verdict[area < floor * (1 - _MARGIN)] = DEGENERATE
    whole = area > floor * (1 + _MARGIN)
    if max_size is not None:
        for i in range(3):
            d = poly[:, (i + 1) % 3] - poly[:, i]
            length = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])  # np.linalg.norm
            whole &= length / max_size - 1e-9 < 1.0 - _MARGIN
    verdict[whole] = WHOLE
    return verdict, np.concatenate([poly, poly[:, 2:3]], axis=1)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of (3, m) columns: the same products and differences."""
    return np.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _convex(poly: np.ndarray, unit: np.ndarray) -> np.ndarray:
    """``patches._is_convex`` by a clear margin (each turn well above zero)."""
    edges = np.roll(poly, -1, axis=1) - poly
    after = np.roll(edges, -1, axis=1)
    turns = np.einsum("fvc,fc->fv", np.cross(edges, after), unit)
    scale = np.linalg.norm(edges, axis=2) * np.linalg.norm(after, axis=2)
    return (turns > _MARGIN * scale).all(axis=1)


def _bilinear_corners(quad: np.ndarray) -> np.ndarray:
    """``patches._split_quad(quad, 1, 1)`` for (m, 4, 3) quads: the same sums, bit for bit."""
    a, b, c, d = (quad[:, i] for i in range(4))

    def at(u: float, v: float) -> np.ndarray:
        return (1 - u) * (1 - v) * a + u * (1 - v) * b + u * v * c + (1 - u) * v * d

    return np.stack([at(0.0, 0.0), at(1.0, 0.0), at(1.0, 1.0), at(0.0, 1.0)], axis=1)

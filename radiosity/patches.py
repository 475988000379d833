"""Patches: faces cut into planar convex triangles and quads no longer than a given size.

A patch is stored as four vertices, ``(n, 4, 3)``; a triangle repeats its third vertex, so the
kernels handle both shapes without masks. ``patch_face`` maps every patch to the face it was cut
from (trimesh's ``return_index`` idea), which in turn maps to its object and material.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import _tol
from .quadrature import centroids_and_areas, triangulate

__all__ = ["Patches", "subdivide_faces"]


@dataclass(frozen=True)
class Patches:
    """Struct of arrays for n patches."""

    quads: np.ndarray  # (n, 4, 3) float, triangles repeat the third vertex
    patch_face: np.ndarray  # (n,) int, index of the source face

    @property
    def n_patches(self) -> int:
        return len(self.quads)


@dataclass
class FaceReport:
    """What subdivision did to faces that were not usable as they stand."""

    degenerate: list[int]  # face indices dropped for zero area
    nonplanar: list[tuple[int, float]]  # (face index, deviation in metres), split into triangles


def _newell(poly: np.ndarray) -> np.ndarray:
    centred = poly - poly.mean(axis=0)
    return 0.5 * np.cross(centred, np.roll(centred, -1, axis=0)).sum(axis=0)


def _is_convex(poly: np.ndarray, normal: np.ndarray) -> bool:
    edges = np.roll(poly, -1, axis=0) - poly
    turns = np.cross(edges, np.roll(edges, -1, axis=0)) @ normal
    return bool((turns > 0).all())


def _split_triangle(tri: np.ndarray, k: int) -> np.ndarray:
    """k*k similar triangles of one triangle, same winding."""
    a, b, c = tri
    i, j = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
    grid = a + (i[..., None] / k) * (b - a) + (j[..., None] / k) * (c - a)
    up_i, up_j = np.nonzero(i[:k, :k] + j[:k, :k] <= k - 1)
    down_i, down_j = np.nonzero(i[:k, :k] + j[:k, :k] <= k - 2)
    up = np.stack([grid[up_i, up_j], grid[up_i + 1, up_j], grid[up_i, up_j + 1]], axis=1)
    down = np.stack([grid[down_i + 1, down_j], grid[down_i + 1, down_j + 1], grid[down_i, down_j + 1]], axis=1)
    tris = np.concatenate([up, down], axis=0)
    return np.concatenate([tris, tris[:, 2:3]], axis=1)


def _split_quad(quad: np.ndarray, ku: int, kv: int) -> np.ndarray:
    """ku*kv bilinear cells of a planar convex quad, same winding."""
    a, b, c, d = quad
    u = np.linspace(0, 1, ku + 1)[:, None, None]
    v = np.linspace(0, 1, kv + 1)[None, :, None]
    grid = (1 - u) * (1 - v) * a + u * (1 - v) * b + u * v * c + (1 - u) * v * d
    cells = np.stack([grid[:-1, :-1], grid[1:, :-1], grid[1:, 1:], grid[:-1, 1:]], axis=2)
    return cells.reshape(-1, 4, 3)


def _cuts(length: float, max_size: float | None) -> int:
    if max_size is None:
        return 1
    return max(1, math.ceil(length / max_size - 1e-9))


def _pieces(poly: np.ndarray, size: float) -> tuple[list[np.ndarray], float]:
    """Planar convex pieces (triangles or one quad) of a face, and its non-planarity."""
    normal = _newell(poly)
    unit = normal / np.linalg.norm(normal)
    deviation = float(np.abs((poly - poly.mean(axis=0)) @ unit).max())
    if len(poly) == 3:
        return [poly], 0.0
    if deviation > _tol.PLANAR_REL * size:
        # Non-planar: a documented, deterministic split, a fan from the first vertex.
        return [np.stack([poly[0], poly[i], poly[i + 1]]) for i in range(1, len(poly) - 1)], deviation
    if len(poly) == 4 and _is_convex(poly, unit):
        return [poly], 0.0
    return list(triangulate(poly)), 0.0


def subdivide_faces(vertices: np.ndarray, faces: list[np.ndarray], max_patch_size: float | None
                    ) -> tuple[Patches, FaceReport]:
    """Cut every face into patches whose longest edge is at most ``max_patch_size``.

    Parameters
    ----------
    vertices : (v, 3) float
    faces : list of (k,) int
        Vertex indices of each face, counter-clockwise seen from the front.
    max_patch_size : float or None
        Longest patch edge in metres; None keeps each face whole (non-planar or non-convex
        faces are still split into triangles).

    Returns
    -------
    Patches, FaceReport
    """
    out: list[np.ndarray] = []
    owner: list[int] = []
    report = FaceReport([], [])
    for index, face in enumerate(faces):
        poly = vertices[face]
        size = float(np.ptp(poly, axis=0).max())
        area = float(np.linalg.norm(_newell(poly)))
        if not area > _tol.DEGENERATE_REL * 1e2 * size**2:
            report.degenerate.append(index)
            continue
        pieces, deviation = _pieces(poly, size)
        if deviation:
            report.nonplanar.append((index, deviation))
        for piece in pieces:
            if len(piece) == 4:
                a, b, c, d = piece
                ku = _cuts(max(np.linalg.norm(b - a), np.linalg.norm(c - d)), max_patch_size)
                kv = _cuts(max(np.linalg.norm(d - a), np.linalg.norm(c - b)), max_patch_size)
                cells = _split_quad(piece, ku, kv)
            else:
                longest = max(np.linalg.norm(piece[1] - piece[0]), np.linalg.norm(piece[2] - piece[1]),
                              np.linalg.norm(piece[0] - piece[2]))
                cells = _split_triangle(piece, _cuts(longest, max_patch_size))
            out.append(cells)
            owner.extend([index] * len(cells))
    quads = np.concatenate(out, axis=0) if out else np.zeros((0, 4, 3))
    _, area = centroids_and_areas(quads)
    keep = area > 0
    return Patches(quads[keep], np.asarray(owner, dtype=np.int64)[keep]), report

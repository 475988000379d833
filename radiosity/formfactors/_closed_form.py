"""Unoccluded form factors: Lambert's closed form from points to polygons, and its integrals.

The kernel is Lambert's formula (seeds 000 and 001; Stark 2000, eq. 3)::

    F(x -> P) = 1/(2 pi) | sum_e  theta_e  (a_e x b_e)/|a_e x b_e| . n |

over the edges ``e = (v_i, v_{i+1})`` of the polygon ``P`` clipped to the receiver's upper
half-space, with ``a_e = v_i - x``, ``b_e = v_{i+1} - x`` and the edge angle
``theta_e = atan2(|a_e x b_e|, a_e . b_e)`` (atan2 stays accurate for tiny and for nearly
opposite angles, where acos loses half its digits).
"""

from __future__ import annotations

import numpy as np

from .. import _memory, _tol
from ._lambert import _lambert_indexed_kernel, _lambert_matrix_kernel, _lambert_rows_kernel
from .._validate import as_points, as_polygon, as_unit_vectors
from ..geometry import clip_slots, polygon_normals

__all__ = ["point_to_polygon", "point_to_polygons", "lambert_pairs", "lambert_indexed"]

_TWO_PI = 2.0 * np.pi


def point_to_polygon(points, normals, polygon) -> np.ndarray:
    """Unoccluded form factor from differential receivers to one planar polygon.

    Parameters
    ----------
    points : (m, 3) float
        Receiver positions, metres.
    normals : (m, 3) float
        Unit normals of the receivers (their front sides).
    polygon : (k, 3) float
        Vertices of a planar, simple polygon, k >= 3, in either winding.

    Returns
    -------
    (m,) float
        Form factor from each differential receiver to the polygon, in [0, 1]. Only the part
        of the polygon above each receiver's tangent plane counts. Degenerate input gives 0.

    Examples
    --------
    A point under the corner of a unit square at height 1 (Howell's catalogue):

    >>> import numpy as np, radiosity
    >>> square = [[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    >>> f = radiosity.point_to_polygon([[0, 0, 0]], [[0, 0, 1]], square)
    >>> round(float(f[0]), 10)
    0.138531606
    """
    polygon = as_polygon(polygon, "polygon")
    return point_to_polygons(points, normals, polygon[None])[:, 0]


def point_to_polygons(points, normals, polygons) -> np.ndarray:
    """Unoccluded form factors from differential receivers to many planar polygons.

    The matrix form of :func:`point_to_polygon`, e.g. a sensor grid against every patch of a
    scene: the kernel runs on blocks of receivers against one polygon at a time, in SIMD lanes
    and on all cores.

    Parameters
    ----------
    points : (m, 3) float
        Receiver positions, metres.
    normals : (m, 3) float
        Unit normals of the receivers (their front sides).
    polygons : (n, k, 3) float, or a sequence of (k_i, 3) arrays
        Planar, simple polygons, k >= 3, in either winding. Polygons with fewer vertices than
        the longest are padded by repeating their last vertex (which adds nothing).

    Returns
    -------
    (m, n) float
        ``F[p, q]``: form factor from receiver p to polygon q, in [0, 1]. Only the part of a
        polygon above a receiver's tangent plane counts. Degenerate input gives 0.

    Examples
    --------
    Two receivers under a unit square at height 1 and a triangle beside it:

    >>> import radiosity
    >>> square = [[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    >>> triangle = [[2, 0, 1], [3, 0, 1], [2, 1, 1]]
    >>> f = radiosity.point_to_polygons([[0, 0, 0], [0.5, 0.5, 0]], [[0, 0, 1]] * 2, [square, triangle])
    >>> f.shape, round(float(f[0, 0]), 10)
    ((2, 2), 0.138531606)
    """
    points = as_points(points, "points")
    normals = as_unit_vectors(normals, "normals")
    if len(points) != len(normals):
        msg = f"points and normals must have the same length, got {len(points)} and {len(normals)}"
        raise ValueError(msg)
    polys = _as_polygons(polygons)
    points, polys = _power_of_two_scaled(points, polys)
    m, n = len(points), len(polys)
    _memory.check(f"the {m:,} x {n:,} form-factor matrix", 8 * m * n, "pass fewer receivers or polygons per call")
    out = np.empty((n, m))
    if m and n:
        _lambert_matrix_kernel(points, normals, polys, _MODES["auto"], out)
    return out.T


def _power_of_two_scaled(points: np.ndarray, polys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points and polygons scaled by a power of two (exactly, so no digit changes) when their
    coordinates are so small or large that the kernel's squared areas would under- or
    overflow; form factors do not depend on scale."""
    big = max(float(np.abs(points).max(initial=0.0)), float(np.abs(polys).max(initial=0.0)))
    if big == 0.0 or 1e-30 < big < 1e30:
        return points, polys
    k = int(np.clip(-np.round(np.log2(big)), -1000, 1000))
    return np.ldexp(points, k), np.ldexp(polys, k)


def _as_polygons(polygons) -> np.ndarray:
    """(n, k, 3) float64 polygons from an array or a ragged sequence (padded by repetition)."""
    if isinstance(polygons, np.ndarray) and polygons.ndim == 3 and polygons.shape[1:2] >= (3,) \
            and polygons.shape[2] == 3:
        polys = np.ascontiguousarray(polygons, dtype=float)
        if np.isfinite(polys).all():
            return polys  # the common case, validated without a Python loop
    polys = [as_polygon(p, f"polygons[{q}]") for q, p in enumerate(polygons)]
    if not polys:
        return np.zeros((0, 3, 3))
    k = max(len(p) for p in polys)
    return np.ascontiguousarray(np.stack([np.concatenate([p, np.repeat(p[-1:], k - len(p), axis=0)])
                                          for p in polys]))


def lambert_pairs(points: np.ndarray, normals: np.ndarray, polys: np.ndarray, *,
                  backend: str = "auto", mode: str = "auto") -> np.ndarray:
    """Form factor of each (receiver point, polygon) row; the private, trusting kernel.

    Parameters
    ----------
    points, normals : (m, 3) float
        Receivers and their unit normals.
    polys : (m, k, 3) float
        One polygon per receiver (repeated vertices allowed, e.g. triangles padded to k = 4).
    backend : {"auto", "numba", "numpy"}, default: "auto"
        ``"numba"`` is the parallel compiled kernel (``"auto"`` picks it when numba imports);
        ``"numpy"`` is the plain vectorised reference (raw Lambert sum only).
    mode : {"auto", "raw"}, default: "auto"
        ``"raw"`` forces Lambert's raw edge sum everywhere (it cancels catastrophically for far
        sources; kept for comparisons). ``"auto"`` switches to the cancellation-free far branch.

    Returns
    -------
    (m,) float
    """
    if backend == "auto":
        backend = "numba"
    if backend == "numba":
        points, normals, polys = (np.ascontiguousarray(a, dtype=float) for a in (points, normals, polys))
        out = np.empty(len(points))
        if len(points):
            _lambert_rows_kernel(points, normals, polys, _MODES[mode], out)
        return out
    return _lambert_numpy(points, normals, polys)


# Kernel modes. "auto": every form where it is the accurate one (far, horizon, near-plane, raw);
# "raw": Lambert's raw sum only (for comparisons); "fill": "auto" without the grazing forms, so
# grazing lanes stay in the SIMD loops (the fill, where their raw-sum error, ~1e-16 absolute, is
# far below what a patch pair's rtol asks; the grazing forms cost a third of the fill's time).
_MODES = {"auto": 0, "raw": 1, "fill": 2}


def lambert_indexed(points: np.ndarray, normals: np.ndarray, polys: np.ndarray, pi: np.ndarray,
                    qi: np.ndarray, *, mode: str = "auto") -> np.ndarray:
    """F(points[pi[t]] -> polys[qi[t]]) for index arrays, without materialising the pairs.

    Parameters
    ----------
    points, normals : (u, 3) float
        Receivers and their unit normals.
    polys : (n, k, 3) float
        Source polygons (triangles padded by repeating a vertex).
    pi, qi : (m,) int
        Receiver and source index of each pair.
    mode : {"auto", "raw"}, default: "auto"
        As in :func:`lambert_pairs`.

    Returns
    -------
    (m,) float
    """
    points, normals, polys = (np.ascontiguousarray(a, dtype=float) for a in (points, normals, polys))
    pi = np.ascontiguousarray(pi, dtype=np.int64)
    qi = np.ascontiguousarray(qi, dtype=np.int64)
    out = np.empty(len(pi))
    if not len(pi):
        return out
    _lambert_indexed_kernel(points, normals, polys, pi, qi, _MODES[mode], out)
    return out


def _lambert_numpy(points: np.ndarray, normals: np.ndarray, polys: np.ndarray) -> np.ndarray:
    """Plain-numpy Lambert (raw edge sum), chunked: the reference and the fallback."""
    m = len(points)
    out = np.zeros(m)
    for start in range(0, m, _tol.CHUNK_PAIRS):
        stop = min(m, start + _tol.CHUNK_PAIRS)
        out[start:stop] = _lambert_chunk(points[start:stop], normals[start:stop], polys[start:stop])
    return out


def _lambert_chunk(x: np.ndarray, n: np.ndarray, polys: np.ndarray) -> np.ndarray:
    rel = polys - x[:, None, :]
    height = np.einsum("mkc,mc->mk", rel, n)
    size2 = np.einsum("mkc,mkc->mk", rel, rel)
    normal = polygon_normals(polys)
    # A receiver in the source's own plane sees it edge-on: exactly 0 (also covers receivers
    # on an edge or a vertex, where Lambert's terms are 0/0).
    off_plane = np.abs(np.einsum("mkc,mc->mk", rel, normal).mean(axis=1)) / np.sqrt(np.maximum(size2.max(axis=1), np.finfo(float).tiny))
    out = np.zeros(len(x))
    above = (height.max(axis=1) > 0.0) & (off_plane > _tol.IN_PLANE_REL) & normal.any(axis=1)
    straddles = above & (height.min(axis=1) < 0.0)
    plain = above & ~straddles
    if plain.any():
        out[plain] = _edge_sum(rel[plain], n[plain])
    if straddles.any():
        verts = _clip_to_upper(rel[straddles], height[straddles])
        out[straddles] = _edge_sum(verts, n[straddles])
    return np.clip(out, 0.0, 1.0)


def _edge_sum(rel: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Lambert's edge sum for polygons given relative to the receiver (rows, k, 3)."""
    nxt = np.roll(rel, -1, axis=1)
    c = np.cross(rel, nxt)
    s = np.sqrt(np.einsum("mkc,mkc->mk", c, c))
    dot = np.einsum("mkc,mkc->mk", rel, nxt)
    theta = np.arctan2(s, dot)
    cn = np.einsum("mkc,mc->mk", c, n)
    la = np.einsum("mkc,mkc->mk", rel, rel)
    lb = np.einsum("mkc,mkc->mk", nxt, nxt)
    edge_ok = s > _tol.DEGENERATE_REL * np.sqrt(la * lb)
    term = np.where(edge_ok, theta * cn / np.where(edge_ok, s, 1.0), 0.0)
    return np.abs(term.sum(axis=1)) / _TWO_PI


def _clip_to_upper(rel: np.ndarray, height: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman clip of each polygon to height >= 0, padded to 2k vertices.

    Slots that the clip removes repeat the previous kept vertex, so they add zero-length edges
    and the edge sum needs no masks.
    """
    rows, k, _ = rel.shape
    slots, valid = clip_slots(rel, height)
    # Rotate each row so that slot 0 is valid, then forward-fill the invalid slots.
    first = valid.argmax(axis=1)
    order = (first[:, None] + np.arange(2 * k)[None, :]) % (2 * k)
    slots = np.take_along_axis(slots, order[..., None], axis=1)
    valid = np.take_along_axis(valid, order, axis=1)
    for s in range(1, 2 * k):
        slots[:, s] = np.where(valid[:, s, None], slots[:, s], slots[:, s - 1])
    return slots

"""Hemicube and Nusselt-disk form-factor estimators with exact per-texel delta form factors.

A measured alternative to Lambert's closed form (``formfactors.point_to_polygon``): the
hemisphere over a receiver point is cut into texels (five faces of a cube, or a square grid over
the unit disk that the hemisphere projects to orthographically), each texel carries the exact
cosine-weighted solid angle it covers (its *delta form factor*, from a closed-form
antiderivative evaluated like a summed-area table, as seed 004 does for plain solid angles), and
each texel is given to the polygon seen through its centre (nearest one with the z-buffer).

Delta form factors (``(1/pi) * integral of cos(theta) d omega`` over a texel):

- hemicube top face ``z = 1``, texel ``[x0, x1] x [y0, y1]``:
  ``T(x1, y1) - T(x0, y1) - T(x1, y0) + T(x0, y0)`` with
  ``T(x, y) = (1/2pi) [x/sqrt(1+x^2) atan(y/sqrt(1+x^2)) + y/sqrt(1+y^2) atan(x/sqrt(1+y^2))]``
  (``(1/pi) dx dy / (1+x^2+y^2)^2`` integrated; ``T(1, 1)`` is Howell's 0.1385316060);
- hemicube side face at distance 1, texel ``[s0, s1] x [z0, z1]`` (z up):
  ``H(s, z) = (1/2pi) [atan(s) - atan(s/sqrt(1+z^2)) / sqrt(1+z^2)]``
  (``(1/pi) z ds dz / (1+s^2+z^2)^2`` integrated);
- Nusselt disk (orthographic projection to z = 0): the delta form factor of a texel is its area
  inside the unit disk over pi (Nusselt's analogue), with the summed-area table of
  ``Q(x, y)`` = area of ``[0, x] x [0, y]`` inside the disk.

Seed 004's plain solid angles (``atan(xy/sqrt(1+x^2+y^2))`` per cube face) are
:func:`texel_solid_angles`.
"""

from __future__ import annotations

import numpy as np

from .._validate import as_points, as_unit_vectors

__all__ = ["hemicube_factors", "delta_form_factors", "texel_solid_angles"]

# Texel-polygon tests per chunk (texels x polygons x vertices): bounds temporary memory to a few
# tens of MB whatever the resolution.
_CHUNK_TESTS = 2_000_000

_METHODS = ("hemicube", "nusselt")


# ---------------------------------------------------------------------------------------------
# Exact delta form factors
# ---------------------------------------------------------------------------------------------

def _top_corner(x, y):
    """T(x, y): form factor of [0, x] x [0, y] on the plane one unit above (odd in x and y)."""
    ax = np.sqrt(1.0 + x * x)
    ay = np.sqrt(1.0 + y * y)
    return (x / ax * np.arctan(y / ax) + y / ay * np.arctan(x / ay)) / (2.0 * np.pi)


def _side_corner(s, z):
    """H(s, z): form factor of [0, s] x [0, z] on a wall one unit away (z up)."""
    a = np.sqrt(1.0 + z * z)
    return (np.arctan(s) - np.arctan(s / a) / a) / (2.0 * np.pi)


def _disk_quadrant(x, y):
    """Q(x, y): area of [0, x] x [0, y] inside the unit disk, odd in x and y, |x|, |y| <= 1."""
    sx, sy = np.sign(x), np.sign(y)
    x, y = np.minimum(np.abs(x), 1.0), np.minimum(np.abs(y), 1.0)
    a0 = np.sqrt(np.maximum(1.0 - y * y, 0.0))  # where the circle reaches height y

    def prim(a):  # integral of sqrt(1 - t^2) from 0 to a
        return 0.5 * (a * np.sqrt(np.maximum(1.0 - a * a, 0.0)) + np.arcsin(a))

    inside = x <= a0
    q = np.where(inside, x * y, a0 * y + prim(x) - prim(np.minimum(a0, x)))
    return sx * sy * q


def _summed(corner, u_edges, v_edges):
    """Texel integrals from a corner antiderivative: C(u1,v1) - C(u0,v1) - C(u1,v0) + C(u0,v0)."""
    c = corner(u_edges[None, :], v_edges[:, None])  # (len(v), len(u))
    return c[1:, 1:] - c[1:, :-1] - c[:-1, 1:] + c[:-1, :-1]


def _check_resolution(resolution, method):
    if method not in _METHODS:
        msg = f"method must be one of {', '.join(map(repr, _METHODS))}, got {method!r}"
        raise ValueError(msg)
    res = int(resolution)
    if res != resolution or res < 2 or (method == "hemicube" and res % 2):
        msg = f"resolution must be an integer >= 2 (even for the hemicube), got {resolution!r}"
        raise ValueError(msg)
    return res


def delta_form_factors(resolution: int, *, method: str = "hemicube") -> list[np.ndarray]:
    """Exact delta form factor of every texel.

    Parameters
    ----------
    resolution : int
        Texels along a side of the top face (hemicube; side faces have ``resolution / 2`` rows)
        or of the square around the unit disk (Nusselt).
    method : {"hemicube", "nusselt"}, default: "hemicube"
        Hemicube faces, or the orthographic projection onto the unit disk.

    Returns
    -------
    list of 2-D float arrays
        Hemicube: ``[top (r, r), side (r/2, r)]``; the side array serves all four sides (rows
        are z from 0 up, columns s from -1 to 1). Nusselt: ``[disk (r, r)]`` (rows y, columns x).
        The texels of the whole hemisphere sum to 1 (up to rounding).

    Examples
    --------
    >>> import numpy as np
    >>> from radiosity.alternatives.hemicube import delta_form_factors
    >>> top, side = delta_form_factors(64)
    >>> bool(abs(top.sum() + 4 * side.sum() - 1.0) < 1e-14)
    True
    """
    res = _check_resolution(resolution, method)
    edges = np.linspace(-1.0, 1.0, res + 1)
    if method == "nusselt":
        area = _summed(_disk_quadrant, edges, edges)
        # Texels wholly outside the disk get exactly 0 (the summed-area differences leave
        # rounding of either sign there).
        near = np.where(edges[:-1] * edges[1:] <= 0.0, 0.0,
                        np.minimum(np.abs(edges[:-1]), np.abs(edges[1:])))
        outside = near[None, :] ** 2 + near[:, None] ** 2 >= 1.0
        return [np.where(outside, 0.0, np.maximum(area, 0.0)) / np.pi]
    z_edges = np.linspace(0.0, 1.0, res // 2 + 1)
    return [_summed(_top_corner, edges, edges), _summed(_side_corner, edges, z_edges)]


def texel_solid_angles(resolution: int) -> list[np.ndarray]:
    """Solid angle of every hemicube texel from seed 004's ``atan(x y / sqrt(1 + x^2 + y^2))``.

    Parameters
    ----------
    resolution : int
        Texels along a side of the top face (even).

    Returns
    -------
    list of 2-D float arrays
        ``[top (r, r), side (r/2, r)]``, steradians; they sum to ``2 pi`` over the hemicube.

    Examples
    --------
    >>> import numpy as np
    >>> from radiosity.alternatives.hemicube import texel_solid_angles
    >>> top, side = texel_solid_angles(8)
    >>> bool(abs(top.sum() + 4 * side.sum() - 2 * np.pi) < 1e-13)
    True
    """
    res = _check_resolution(resolution, "hemicube")
    edges = np.linspace(-1.0, 1.0, res + 1)
    z_edges = np.linspace(0.0, 1.0, res // 2 + 1)

    def corner(x, y):
        return np.arctan(x * y / np.sqrt(1.0 + x * x + y * y))

    return [_summed(corner, edges, edges), _summed(corner, edges, z_edges)]


# ---------------------------------------------------------------------------------------------
# Texel directions and ray casting
# ---------------------------------------------------------------------------------------------

def _texel_directions(res: int, method: str) -> tuple[np.ndarray, np.ndarray]:
    """Unit-free directions through texel centres in the receiver frame, and their weights."""
    centres = (np.arange(res) + 0.5) / res * 2.0 - 1.0
    if method == "nusselt":
        (w,) = delta_form_factors(res, method="nusselt")
        x, y = np.meshgrid(centres, centres)
        r2 = x * x + y * y
        # Rim texels whose centre lies outside the disk look along the horizon at their angle.
        scale = np.where(r2 > 1.0, 1.0 / np.sqrt(np.maximum(r2, 1.0)), 1.0)
        x, y = x * scale, y * scale
        z = np.sqrt(np.maximum(1.0 - x * x - y * y, 0.0))
        dirs = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
        keep = w.ravel() > 0.0
        return dirs[keep], w.ravel()[keep]
    top, side = delta_form_factors(res, method="hemicube")
    x, y = np.meshgrid(centres, centres)
    dirs = [np.stack([x.ravel(), y.ravel(), np.ones(x.size)], axis=1)]
    weights = [top.ravel()]
    zc = (np.arange(res // 2) + 0.5) / (res // 2)
    s, z = np.meshgrid(centres, zc)
    s, z = s.ravel(), z.ravel()
    one = np.ones_like(s)
    for d in (np.stack([one, s, z], 1), np.stack([-one, s, z], 1),
              np.stack([s, one, z], 1), np.stack([s, -one, z], 1)):
        dirs.append(d)
        weights.append(side.ravel())
    return np.concatenate(dirs), np.concatenate(weights)


def _pad_polygons(polygons) -> np.ndarray:
    """List of (k_i, 3) polygons -> (n, kmax, 3), padded by repeating the last vertex."""
    if isinstance(polygons, np.ndarray) and polygons.ndim == 3:
        arr = np.asarray(polygons, dtype=float)
    else:
        polys = [np.asarray(p, dtype=float) for p in polygons]
        for i, p in enumerate(polys):
            if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 3:
                msg = f"polygons[{i}] must have shape (k, 3) with k >= 3, got {p.shape}"
                raise ValueError(msg)
        kmax = max((len(p) for p in polys), default=3)
        arr = np.empty((len(polys), kmax, 3))
        for i, p in enumerate(polys):
            arr[i, :len(p)] = p
            arr[i, len(p):] = p[-1]
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.shape[1] < 3:
        msg = f"polygons must have shape (n, k, 3) with k >= 3, got {arr.shape}"
        raise ValueError(msg)
    if not np.isfinite(arr).all():
        msg = "polygons must be finite"
        raise ValueError(msg)
    return arr


def _hits(dirs: np.ndarray, rel: np.ndarray) -> np.ndarray:
    """Ray parameter t of each (direction, polygon) hit, +inf where the ray misses.

    ``dirs`` (T, 3) from the receiver at the origin, ``rel`` (n, k, 3) polygons relative to it.
    """
    n_vec = np.cross(rel - rel[:, :1], np.roll(rel, -1, axis=1) - rel[:, :1]).sum(axis=1)  # (n, 3)
    height = np.einsum("nc,nc->n", n_vec, rel[:, 0])
    denom = dirs @ n_vec.T  # (T, n)
    ok = (denom != 0.0) & (np.abs(height) > 0.0)
    t = np.where(ok, height[None, :] / np.where(ok, denom, 1.0), np.inf)
    t = np.where(t > 0.0, t, np.inf)
    # 2-D crossing-number test in the polygon's plane, dropping its dominant axis.
    drop = np.abs(n_vec).argmax(axis=1)
    keep_axes = np.array([[1, 2], [0, 2], [0, 1]])[drop]  # (n, 2)
    poly2 = np.take_along_axis(rel, np.broadcast_to(keep_axes[:, None, :], rel.shape[:2] + (2,)), axis=2)
    hit = dirs[:, None, :] * np.where(np.isfinite(t), t, 0.0)[..., None]  # (T, n, 3)
    hit2 = np.take_along_axis(hit, np.broadcast_to(keep_axes[None], hit.shape[:2] + (2,)), axis=2)
    a = poly2[None]  # (1, n, k, 2)
    b = np.roll(poly2, -1, axis=1)[None]
    px = hit2[..., 0][..., None]
    py = hit2[..., 1][..., None]
    straddle = (a[..., 1] > py) != (b[..., 1] > py)
    dy = b[..., 1] - a[..., 1]
    xcross = a[..., 0] + (py - a[..., 1]) * (b[..., 0] - a[..., 0]) / np.where(straddle, dy, 1.0)
    inside = (straddle & (px < xcross)).sum(axis=-1) % 2 == 1
    return np.where(inside, t, np.inf)


def hemicube_factors(point, normal, polygons, resolution: int, *, method: str = "hemicube",
                     occlusion: bool = True) -> np.ndarray:
    """Form factors from a differential receiver to polygons, estimated on a hemicube or disk.

    Parameters
    ----------
    point : (3,) float
        Receiver position, metres.
    normal : (3,) float
        Receiver normal (normalised here).
    polygons : sequence of (k_i, 3) float, or (n, k, 3) float
        Planar source polygons, any winding.
    resolution : int
        Texels along the top face (hemicube, even) or across the disk (Nusselt).
    method : {"hemicube", "nusselt"}, default: "hemicube"
        Five cube faces with the closed-form delta form factors, or a square grid over the unit
        disk with exact texel areas inside the disk.
    occlusion : bool, default: True
        With the z-buffer, each texel counts only for the nearest polygon seen through its
        centre; without it, every polygon seen through the centre gets the texel.

    Returns
    -------
    (n,) float
        Estimated form factor to each polygon. Only parts above the receiver plane count.

    Raises
    ------
    ValueError
        If the method or resolution is invalid, or a polygon has the wrong shape.

    Notes
    -----
    Each texel is tested once, through its centre, so polygon edges cost an error of the order
    of the delta form factor of the texels they cross: O(1/resolution) relative (docs/stark.md
    has the measured curve). The delta form factors themselves are exact (module docstring).

    Examples
    --------
    Howell's point under the corner of a unit square at height 1 (F = 0.1385316060):

    >>> import numpy as np
    >>> from radiosity.alternatives.hemicube import hemicube_factors
    >>> square = [[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    >>> f = hemicube_factors([0, 0, 0], [0, 0, 1], [square], 64)
    >>> round(float(f[0]), 10)
    0.138531606
    """
    res = _check_resolution(resolution, method)
    p = as_points(point, "point")[0]
    n = as_unit_vectors(normal, "normal")[0]
    polys = _pad_polygons(polygons)
    out = np.zeros(len(polys))
    if not len(polys):
        return out
    # Receiver frame (same construction as _stark.receiver_frame).
    sign = 1.0 if n[2] >= 0.0 else -1.0
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    u = np.array([1.0 + sign * n[0] ** 2 * a, sign * b, -sign * n[0]])
    w = np.array([b, sign + n[1] ** 2 * a, -n[1]])
    rel = (polys - p) @ np.stack([u, w, n], axis=1)
    dirs, weights = _texel_directions(res, method)
    step = max(1, _CHUNK_TESTS // (len(polys) * polys.shape[1]))
    for start in range(0, len(dirs), step):
        d = dirs[start:start + step]
        wt = weights[start:start + step]
        t = _hits(d, rel)  # (T, n)
        if occlusion:
            nearest = t.argmin(axis=1)
            seen = np.isfinite(t[np.arange(len(t)), nearest])
            out += np.bincount(nearest[seen], weights=wt[seen], minlength=len(polys))
        else:
            out += (np.isfinite(t) * wt[:, None]).sum(axis=0)
    return out

"""Exact shadows: the part of a source polygon that occluders hide from a receiver point.

For a receiver point x, a source patch S (convex) and a convex occluder polygon K, the hidden
part of S is S clipped by the cone from x over K', where K' is K clipped to the slab between
S's plane and the parallel plane through x (only that part of K lies between x and S). The
cone is the intersection of the half-spaces bounded by the planes through x and each edge of
K', so the clip is a sequence of Sutherland-Hodgman steps on convex polygons, all in 3-D: no
projection to infinity, no image plane to bound (seed 002 §2 clips in the image plane; clipping
by the cone's planes is the same operation without the division). The hidden part's form factor
is Lambert's closed form of that convex polygon (which also clips it to x's horizon), and the
visible form factor is ``F(x -> S) - F(x -> hidden)`` by additivity.

When several occluders hide parts of S from one point, their hidden polygons may overlap.
Their union's form factor is found by inclusion-exclusion: the hidden polygons and all their
intersections are convex polygons in S's plane, so F(A u B) = F(A) + F(B) - F(A n B) needs only
more clipping (compiled, ``_exact_kernel``). Past ``MAX_UNION`` polygons at one point they are
united with shapely instead, and the union's form factor is the sum over its rings (exterior
rings add, holes subtract).
"""

from __future__ import annotations

import numpy as np

from ..geometry import clip_slots
from ._constants import MAX_UNION, SNAP_REL

__all__ = ["clip_convex", "hidden_factors", "point_factors", "union_factors"]


def clip_convex(poly: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Clip convex polygons (r, k, 3) to ``h >= 0`` (values at the vertices, (r, k)).

    Returns (r, k + 1, 3): the clipped polygon, padded by repeating its first vertex (which adds
    zero-length edges only). An empty result repeats one point, so it has zero area.
    """
    r, k, _ = poly.shape
    scale = np.abs(h).max(axis=1, keepdims=True)
    h = np.where(np.abs(h) <= 1e-13 * scale, 0.0, h)  # vertices on the line: no spurious crossings
    slots, valid = clip_slots(poly, h)
    order = np.argsort(~valid, axis=1, kind="stable")[:, :k + 1]
    out = np.take_along_axis(slots, order[..., None], axis=1)
    count = valid.sum(axis=1)
    pad = np.arange(k + 1)[None, :] >= count[:, None]
    first = np.where(count[:, None] > 0, out[:, 0], poly[:, 0])
    return np.where(pad[..., None], first[:, None, :], out)


def union_factors(x: np.ndarray, nx: np.ndarray, group: np.ndarray, polys: np.ndarray,
                  source_normal: np.ndarray, fallbacks: dict | None = None) -> np.ndarray:
    """Form factor from x to the union of the polygons that share a group (all in one plane).

    Parameters
    ----------
    x, nx : (r, 3) float
        Receiver point and normal of each row (equal within a group).
    group : (r,) int
        Rows with the same group are united; groups are numbered 0..g-1.
    polys : (r, k, 3) float
        Convex polygons in the plane of the group's source.
    source_normal : (r, 3) float
    fallbacks : dict, optional
        Counts groups whose union needed snap-rounding (``"snapped"``) or fell back to their
        largest polygon (``"lower_bound"``); see :func:`_unite`.

    Returns
    -------
    (g,) float
    """
    import shapely

    n_groups = int(group.max()) + 1 if len(group) else 0
    out = np.zeros(n_groups)
    if n_groups == 0:
        return out
    first = np.unique(group, return_index=True)[1]
    origin = polys.mean(axis=1)[first][group]
    normal = source_normal[first][group]
    helper = np.where(np.abs(normal[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.cross(normal, u)
    rel = polys - origin[:, None, :]
    flat = np.stack([np.einsum("rkc,rc->rk", rel, u), np.einsum("rkc,rc->rk", rel, w)], axis=2)
    geoms = shapely.polygons(flat)
    geoms = shapely.make_valid(geoms)
    order = np.argsort(group, kind="stable")
    count = np.bincount(group, minlength=n_groups)
    slot = np.arange(len(group)) - np.repeat(np.cumsum(count) - count, count)
    table = np.full((n_groups, count.max()), None, dtype=object)
    table[group[order], slot] = geoms[order]
    extent = float(np.abs(flat).max()) if flat.size else 1.0
    unions, rescued, lost = _unite(table, SNAP_REL * max(extent, np.finfo(float).tiny))
    if fallbacks is not None:
        fallbacks["snapped"] = fallbacks.get("snapped", 0) + int(rescued.sum())
        fallbacks["lower_bound"] = fallbacks.get("lower_bound", 0) + int(lost.sum())
    parts, part_group = shapely.get_parts(unions, return_index=True)
    is_poly = shapely.get_type_id(parts) == 3
    parts, part_group = parts[is_poly], part_group[is_poly]
    if len(parts) == 0:
        return out
    rings, ring_part = shapely.get_rings(parts, return_index=True)
    starts = np.r_[0, np.flatnonzero(np.diff(ring_part)) + 1]
    exterior = np.zeros(len(rings), bool)
    exterior[starts] = True
    coords, ring_of = shapely.get_coordinates(rings, return_index=True)
    counts = np.bincount(ring_of, minlength=len(rings))
    kmax = counts.max()
    pos = np.arange(len(coords)) - np.repeat(np.cumsum(counts) - counts, counts)
    flat_rings = np.repeat(coords[np.cumsum(counts) - 1][:, None, :], kmax, axis=1)  # pad: last vertex
    flat_rings[ring_of, pos] = coords
    g_of_ring = part_group[ring_part]
    row = first[g_of_ring]
    ring3 = origin[row][:, None, :] + flat_rings[..., :1] * u[row][:, None, :] + flat_rings[..., 1:] * w[row][:, None, :]
    f = point_factors(x[row], nx[row], ring3)
    np.add.at(out, g_of_ring, np.where(exterior, f, -f))
    return np.clip(out, 0.0, None)


def _unite(table: np.ndarray, grid: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Union of each row of a (g, c) table of polygons, however degenerate they are.

    GEOS's floating overlay can fail on nearly coincident edges ("TopologyException: side
    location conflict"). A row where it does is repaired (``make_valid``, else ``buffer(0)``)
    and united again with snap-rounding on a grid of ``grid`` (OverlayNG with a fixed
    precision, which is robust; the grid is far below any length that matters); if even that
    fails, the largest polygon stands for the union (its factor is a lower bound of the
    hidden one). Returns the unions and, per row, whether it was
    snapped and whether it fell back to the largest polygon.
    """
    import shapely
    from shapely.errors import GEOSException

    snapped = np.zeros(len(table), bool)
    lost = np.zeros(len(table), bool)
    try:
        return shapely.union_all(table, axis=1), snapped, lost
    except GEOSException:
        pass
    out = np.empty(len(table), dtype=object)
    for g, row in enumerate(table):
        try:
            out[g] = shapely.union_all(row)
            continue
        except GEOSException:
            snapped[g] = True
        polys = row[row != None]  # noqa: E711
        for repair in (shapely.make_valid, lambda p: shapely.buffer(p, 0.0)):
            try:
                out[g] = shapely.union_all(repair(polys), grid_size=grid)
                break
            except GEOSException:
                continue
        else:
            lost[g] = True
            out[g] = polys[int(np.argmax(shapely.area(polys)))] if len(polys) else shapely.Polygon()
    return out, snapped & ~lost, lost


def hidden_factors(x: np.ndarray, nx: np.ndarray, group: np.ndarray, source: np.ndarray,
                   source_normal: np.ndarray, occluder: np.ndarray, occluder_normal: np.ndarray,
                   tol: float, fallbacks: dict | None = None) -> np.ndarray:
    """Form factor of the hidden part of each group's source (rows: one occluder each).

    Rows of a group share x, nx and source; the result is indexed by group (0..g-1). The
    compiled kernel clips every row and unites a group's hidden polygons by inclusion-exclusion
    over their (convex) intersections; groups where more than ``MAX_UNION`` occluders hide
    something are united with shapely instead (``fallbacks``: see :func:`union_factors`).
    """
    from ._exact_kernel import hidden_groups

    n_groups = int(group.max()) + 1 if len(group) else 0
    out = np.zeros(n_groups)
    if n_groups == 0:
        return out
    order = np.argsort(group, kind="stable")
    starts = np.r_[0, np.cumsum(np.bincount(group, minlength=n_groups))]
    args = [np.ascontiguousarray(a[order], dtype=np.float64) for a in (x, nx, source, source_normal)]
    polys = np.ascontiguousarray(occluder[order], dtype=np.float64)
    normals = np.ascontiguousarray(occluder_normal[order], dtype=np.float64)
    out[:], ok = hidden_groups(*args, np.arange(len(order)), starts, polys, normals, float(tol), MAX_UNION)
    if not ok.all():
        bad = np.flatnonzero(~ok)
        rows = order[np.concatenate([np.arange(starts[g], starts[g + 1]) for g in bad])]
        _, local = np.unique(group[rows], return_inverse=True)
        out[bad] = _hidden_factors_shapely(x[rows], nx[rows], local.ravel(), source[rows], source_normal[rows],
                                           occluder[rows], occluder_normal[rows], tol, fallbacks)
    return out


def _hidden_factors_shapely(x, nx, group, source, source_normal, occluder, occluder_normal, tol, fallbacks=None):
    """:func:`hidden_factors` with every group of two or more hidden polygons united by shapely."""
    from ._exact_kernel import hidden_rows

    n_groups = int(group.max()) + 1 if len(group) else 0
    out = np.zeros(n_groups)
    if n_groups == 0:
        return out
    args = [np.ascontiguousarray(a, dtype=np.float64) for a in (x, nx, source, source_normal, occluder,
                                                                occluder_normal)]
    f, _, _ = hidden_rows(*args, float(tol), False)
    lit = f > 0
    count = np.bincount(group[lit], minlength=n_groups)
    single = lit & (count[group] == 1)
    np.add.at(out, group[single], f[single])
    multi = lit & (count[group] > 1)
    if multi.any():
        rows = np.flatnonzero(multi)
        _, polys, _ = hidden_rows(*(a[rows] for a in args), float(tol), True)
        groups, local = np.unique(group[rows], return_inverse=True)
        out[groups] = union_factors(x[rows], nx[rows], local.ravel(), polys, source_normal[rows], fallbacks)
    return out


def point_factors(x: np.ndarray, nx: np.ndarray, polys: np.ndarray) -> np.ndarray:
    """Lambert form factor from points (r, 3) with normals to polygons (r, k, 3) (compiled)."""
    from ._exact_kernel import point_factors as kernel

    counts = np.full(len(x), polys.shape[1], np.int64)
    return kernel(np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(nx, dtype=np.float64),
                  np.ascontiguousarray(polys, dtype=np.float64), counts)

"""Stark's vertex-based formulations of the point-to-polygon form factor (seed 002).

M. Stark, "Vertex-Based Formulations of Irradiance from Polygonal Sources", Utah tech report
UUCS-00-012 (2000), ``shared/seeds/002_*.txt``. Every formula here is a sum over the *vertices*
of the source polygon of a term that depends only on the vertex and the directions of its two
incident edges, so it can be evaluated in any order (useful when a clipped or occluded source is
built vertex by vertex). All of them equal Lambert's edge sum (``formfactors.lambert_pairs``);
``docs/stark.md`` reports how they compare in accuracy and speed.

Functions (all vectorised over rows ``(points[i], normals[i], polys[i])`` like
``formfactors.lambert_pairs``; form factors, i.e. irradiance for emission M = 1):

- :func:`image_plane` -- eq. 8-10 (slopes) or eq. 44-45 (projective directions): the polygon is
  projected through the receiver onto the plane one unit above it. Valid only for polygons
  strictly above the receiver plane; other rows return 0 with ``valid`` False.
- :func:`image_plane_clipped` -- the same after clipping the source to the frustum over the
  square ``|x|, |y| <= R`` of the image plane; with :func:`clip_error_bound` (Lemma 1) the result
  is low by at most ``1/(1 + R^2)``. Works for sources touching or crossing the receiver plane.
- :func:`vertex_lambert` -- eq. 12-13, Lambert's formula rearranged over vertices with the edge
  vectors as angle references; sources are clipped to the receiver's upper half-space.
- :func:`homogeneous` -- Fig. 11 with eq. 44-46: the image-plane formula in homogeneous
  coordinates, where source vertices on the receiver plane are vertices at infinity and source
  edges on the receiver plane are edges at infinity. Exact for sources touching the receiver
  plane; crossing sources are clipped to it first (the cut points are put exactly on it).

Conventions shared by all functions: the polygon's winding is ignored (``|sum|``), receivers in
the source's own plane give 0 (as ``lambert_pairs``), padded polygons (repeated vertices) are
fine, and no function returns NaN.
"""

from __future__ import annotations

import numpy as np

from .. import _tol
from ..geometry import clip_slots, vector_areas

__all__ = ["receiver_frame", "image_plane", "image_plane_clipped", "clip_error_bound",
           "radius_for_error", "vertex_lambert", "homogeneous"]

_TWO_PI = 2.0 * np.pi
_HALF_PI = 0.5 * np.pi


# ---------------------------------------------------------------------------------------------
# Shared pieces
# ---------------------------------------------------------------------------------------------

def receiver_frame(points: np.ndarray, normals: np.ndarray, polys: np.ndarray) -> np.ndarray:
    """Source vertices in each receiver's frame: x, y along the tangent plane, z along the normal.

    Parameters
    ----------
    points : (m, 3) float
        Receiver positions, metres.
    normals : (m, 3) float
        Unit receiver normals.
    polys : (m, k, 3) float
        One polygon per receiver.

    Returns
    -------
    (m, k, 3) float
        ``(v - r) . (u, w, n)`` with the orthonormal tangent basis ``u, w`` of Duff et al. (2017,
        "Building an orthonormal basis, revisited"), continuous except at ``n_z = 0`` sign flips.
    """
    n = normals
    sign = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    u = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    w = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    rel = polys - points[:, None, :]
    return np.stack([np.einsum("mkc,mc->mk", rel, u), np.einsum("mkc,mc->mk", rel, w),
                     np.einsum("mkc,mc->mk", rel, n)], axis=2)


def _in_source_plane(rel: np.ndarray) -> np.ndarray:
    """Rows whose receiver lies in the source's plane (or whose source is degenerate).

    ``rel`` is (m, k, 3), the source relative to the receiver in any orthonormal frame. The test
    is the one of ``formfactors._lambert_chunk``: mean distance of the source's plane from the
    receiver, relative to the source's distance, below ``_tol.IN_PLANE_REL``.
    """
    centred = rel - rel.mean(axis=1, keepdims=True)
    area_vec = vector_areas(rel)
    length = np.linalg.norm(area_vec, axis=1)
    scale = (np.linalg.norm(centred, axis=2).max(axis=1)) ** 2
    ok = length > _tol.DEGENERATE_REL * np.maximum(scale, np.finfo(float).tiny)
    unit = area_vec / np.where(ok, length, 1.0)[:, None]
    size2 = np.einsum("mkc,mkc->mk", rel, rel).max(axis=1)
    off = np.abs(np.einsum("mkc,mc->mk", rel, unit).mean(axis=1))
    off = off / np.sqrt(np.maximum(size2, np.finfo(float).tiny))
    return ~ok | (off <= _tol.IN_PLANE_REL)


def _clip(verts: np.ndarray, dist: np.ndarray, *, flatten: int | None = None) -> np.ndarray:
    """Sutherland-Hodgman clip of padded polygons to ``dist >= 0``.

    Parameters
    ----------
    verts : (m, k, 3) float
        Polygons (repeated vertices allowed).
    dist : (m, k) float
        Signed distance of each vertex from the clipping plane (any positive scale).
    flatten : int or None, default: None
        If given, the cut points get coordinate ``flatten`` set to exactly 0 (used to put the
        cuts of the receiver plane, z = 0, exactly on it).

    Returns
    -------
    (m, k', 3) float
        Clipped polygons, padded by repeating the previous kept vertex (zero-length edges).
        Rows clipped away entirely repeat one vertex (callers treat them as empty).
    """
    rows = verts.shape[0]
    slots, valid = clip_slots(verts, dist)
    if flatten is not None:
        slots[:, 1::2, flatten] = 0.0  # the odd slots are the cut points
    # Compact: valid slots first (stable), then pad with the last valid slot of the row.
    count = valid.sum(axis=1)
    width = max(int(count.max(initial=0)), 1)
    order = np.argsort(~valid, axis=1, kind="stable")[:, :width]
    slots = np.take_along_axis(slots, order[..., None], axis=1)
    last = np.maximum(count - 1, 0)
    pad = np.arange(width)[None, :] >= count[:, None]
    fill = slots[np.arange(rows), np.minimum(last, width - 1)]
    return np.where(pad[..., None], fill[:, None, :], slots)


def _empty_rows(verts: np.ndarray) -> np.ndarray:
    """Rows whose (clipped) polygon has all vertices equal: nothing left."""
    return (verts == verts[:, :1]).all(axis=(1, 2))


# ---------------------------------------------------------------------------------------------
# Image-plane formula (Section 2, eq. 8-10; Section 6.1, eq. 44-45)
# ---------------------------------------------------------------------------------------------

def _stark_F(x, y, m):
    """Eq. 9-10: F(x, y, m) = A x atan(A y) + C (y - m x) atan(C (x + m y))."""
    A = 1.0 / np.sqrt(1.0 + x * x)
    b = y - m * x
    C = 1.0 / np.sqrt(1.0 + m * m + b * b)
    return A * x * np.arctan(A * y) + C * b * np.arctan(C * (x + m * y))


def _stark_G(x, y, a, b):
    """Fig. 11 'edge' term: G(x, y, a, b) = C (a y - b x) atan(C (a x + b y)); 0 if a = b = 0.

    (Eq. 45 as printed swaps the two factors; Fig. 10/11 and the derivation from eq. 9 with
    m = b/a give this form, which is what agrees with Lambert.)
    """
    cross = a * y - b * x
    d2 = a * a + b * b + cross * cross
    ok = (a != 0.0) | (b != 0.0)
    C = 1.0 / np.sqrt(np.where(ok, d2, 1.0))
    return np.where(ok, C * cross * np.arctan(C * (a * x + b * y)), 0.0)


def _image_sum_slopes(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Eq. 8: sum over vertices of F(x_i, y_i, m_{i-1}) - F(x_i, y_i, m_i); vertical edges omitted."""
    dx = np.roll(x, -1, axis=1) - x
    dy = np.roll(y, -1, axis=1) - y
    vertical = dx == 0.0  # also zero-length edges: their (undefined) terms are omitted
    m = dy / np.where(vertical, 1.0, dx)
    m_in = np.roll(m, 1, axis=1)
    vert_in = np.roll(vertical, 1, axis=1)
    f_in = np.where(vert_in, 0.0, _stark_F(x, y, np.where(vert_in, 0.0, m_in)))
    f_out = np.where(vertical, 0.0, _stark_F(x, y, np.where(vertical, 0.0, m)))
    return (f_in - f_out).sum(axis=1)


def _image_sum_projective(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Eq. 44: sum over vertices of G(v_i, d_{i-1}) - G(v_i, d_i), d_i = v_{i+1} - v_i."""
    a = np.roll(x, -1, axis=1) - x
    b = np.roll(y, -1, axis=1) - y
    a_in = np.roll(a, 1, axis=1)
    b_in = np.roll(b, 1, axis=1)
    return (_stark_G(x, y, a_in, b_in) - _stark_G(x, y, a, b)).sum(axis=1)


def image_plane(points: np.ndarray, normals: np.ndarray, polys: np.ndarray, *,
                form: str = "slope") -> tuple[np.ndarray, np.ndarray]:
    """Stark's image-plane formula: vertex sum on the source projected to the plane z = 1.

    Parameters
    ----------
    points : (m, 3) float
        Receiver positions, metres.
    normals : (m, 3) float
        Unit receiver normals.
    polys : (m, k, 3) float
        Source polygons, one per row; repeated vertices allowed.
    form : {"slope", "projective"}, default: "slope"
        ``"slope"`` is eq. 8-10 with edge slopes ``m`` (vertical edges omitted, so the first term
        of F does not cancel at their ends); ``"projective"`` is eq. 44 with the projective
        direction ``(a, b)`` of each edge (Fig. 11 'edge' row), which needs no vertical case.

    Returns
    -------
    F : (m,) float
        Form factor, 0 where not ``valid``.
    valid : (m,) bool
        True where every vertex lies strictly above the receiver plane (z > 0 in the receiver
        frame), the condition of Section 2.2, and the receiver is not in the source's plane.

    Notes
    -----
    With image coordinates ``(x, y) = (X/Z, Y/Z)``, the form factor is
    ``|sum_i F(x_i, y_i, m_{i-1}) - F(x_i, y_i, m_i)| / 2 pi`` (eq. 8), from Green's theorem on
    ``(1/pi) iint dx dy / (1 + x^2 + y^2)^2`` (eq. 6).
    """
    if form not in ("slope", "projective"):
        msg = f"form must be 'slope' or 'projective', got {form!r}"
        raise ValueError(msg)
    rel = receiver_frame(points, normals, polys)
    z = rel[..., 2]
    valid = (z > 0.0).all(axis=1) & ~_in_source_plane(rel)
    zs = np.where(valid[:, None], z, 1.0)
    x = rel[..., 0] / zs
    y = rel[..., 1] / zs
    s = _image_sum_slopes(x, y) if form == "slope" else _image_sum_projective(x, y)
    out = np.where(valid, np.abs(s) / _TWO_PI, 0.0)
    return np.clip(out, 0.0, 1.0), valid


def clip_error_bound(radius) -> np.ndarray:
    """Lemma 1: the form factor of everything outside the disc (or square) of radius R, at most.

    Parameters
    ----------
    radius : float or array
        Half-side R of the clipping square on the image plane (z = 1), or radius of the disc.

    Returns
    -------
    float or array
        ``1 / (1 + R^2)``: the form factor (irradiance for M = 1) of the whole exterior of the
        disc of radius R, ``(1/pi) int_R^inf int_0^2pi r dtheta dr / (1 + r^2)^2``. The square of
        half-side R contains that disc, so clipping to it errs by no more.
    """
    r = np.asarray(radius, dtype=float)
    return 1.0 / (1.0 + r * r)


def radius_for_error(atol) -> np.ndarray:
    """Smallest clipping radius R whose Lemma 1 bound ``1/(1 + R^2)`` is at most ``atol``.

    Parameters
    ----------
    atol : float or array
        Absolute error allowed on the form factor, in (0, 1].

    Returns
    -------
    float or array
        ``sqrt(1/atol - 1)``.
    """
    a = np.asarray(atol, dtype=float)
    return np.sqrt(np.maximum(1.0 / a - 1.0, 0.0))


def image_plane_clipped(points: np.ndarray, normals: np.ndarray, polys: np.ndarray,
                        radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Image-plane formula after clipping the source to the frustum over ``|x|, |y| <= R``.

    Parameters
    ----------
    points : (m, 3) float
        Receiver positions, metres.
    normals : (m, 3) float
        Unit receiver normals.
    polys : (m, k, 3) float
        Source polygons; they may touch or cross the receiver plane.
    radius : float
        Half-side R of the square on the image plane; the frustum is
        ``|X| <= R Z, |Y| <= R Z`` in the receiver frame, which implies ``Z >= 0``.

    Returns
    -------
    F : (m,) float
        Form factor of the clipped source (projective form, eq. 44). The true form factor lies
        in ``[F, F + bound]`` (up to rounding).
    bound : (m,) float
        ``clip_error_bound(radius)`` where the clip removed something, else 0.

    Notes
    -----
    The clipped source lies strictly above the receiver plane unless it passes through the
    receiver itself (the apex of the frustum), i.e. unless the receiver is in the source's plane,
    where the form factor is 0 anyway.
    """
    R = float(radius)
    rel = receiver_frame(points, normals, polys)
    inplane = _in_source_plane(rel)
    clipped = rel
    for axis, sgn in ((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0)):
        clipped = _clip(clipped, R * clipped[..., 2] - sgn * clipped[..., axis])
    z = clipped[..., 2]
    ok = ~inplane & ~_empty_rows(clipped) & (z > 0.0).all(axis=1)
    zs = np.where(ok[:, None], z, 1.0)
    s = _image_sum_projective(clipped[..., 0] / zs, clipped[..., 1] / zs)
    out = np.clip(np.where(ok, np.abs(s) / _TWO_PI, 0.0), 0.0, 1.0)
    inside = ((np.abs(rel[..., 0]) <= R * rel[..., 2]) & (np.abs(rel[..., 1]) <= R * rel[..., 2])).all(axis=1)
    bound = np.where(inside | inplane, 0.0, float(clip_error_bound(R)))
    return out, bound


# ---------------------------------------------------------------------------------------------
# Vertex-based Lambert (Section 3, eq. 12-13)
# ---------------------------------------------------------------------------------------------

def vertex_lambert(points: np.ndarray, normals: np.ndarray, polys: np.ndarray, *,
                   angle: str = "atan2") -> np.ndarray:
    """Lambert's formula as a vertex sum with edge vectors as angle references (eq. 12-13).

    Parameters
    ----------
    points : (m, 3) float
        Receiver positions, metres.
    normals : (m, 3) float
        Unit receiver normals.
    polys : (m, k, 3) float
        Source polygons; parts below the receiver plane are clipped away first.
    angle : {"atan2", "arccos"}, default: "atan2"
        How the angle between a vertex vector and an edge vector is formed: ``"arccos"`` is the
        paper's ``arccos(v^.e^)``, ``"atan2"`` the same angle as ``atan2(|v x e|, v . e)``.

    Returns
    -------
    (m,) float
        Form factor in [0, 1].

    Notes
    -----
    ``2 pi F = |sum_i arccos(v^_i . e^_{i-1}) N . n^_{i-1} - arccos(v^_i . e^_i) N . n^_i|`` with
    ``v_i = v_i - r``, ``e_i = v_{i+1} - v_i`` and ``n_{i-1} = v_i x e_{i-1}``, ``n_i = v_i x e_i``
    formed at the vertex itself (eq. 13; its prefactor M/pi is a misprint for M/2pi, eq. 12).
    Edges whose plane through the receiver is undefined (receiver on the edge's line, or zero
    length) contribute 0, as in Lambert's sum.
    """
    if angle not in ("atan2", "arccos"):
        msg = f"angle must be 'atan2' or 'arccos', got {angle!r}"
        raise ValueError(msg)
    rel = polys - points[:, None, :]
    height = np.einsum("mkc,mc->mk", rel, normals)
    out = np.zeros(len(points))
    rows = (height.max(axis=1, initial=-1.0) > 0.0) & ~_in_source_plane(rel)
    if not rows.any():
        return out
    v = rel[rows]
    h = height[rows]
    n = normals[rows]
    if (h < 0.0).any():
        v = _clip(v, h)
    e_out = np.roll(v, -1, axis=1) - v
    e_in = v - np.roll(v, 1, axis=1)

    def term(e):
        c = np.cross(v, e)
        s = np.sqrt(np.einsum("mkc,mkc->mk", c, c))
        d = np.einsum("mkc,mkc->mk", v, e)
        lv = np.sqrt(np.einsum("mkc,mkc->mk", v, v))
        le = np.sqrt(np.einsum("mkc,mkc->mk", e, e))
        ok = s > _tol.DEGENERATE_REL * lv * le
        if angle == "atan2":
            th = np.arctan2(s, d)
        else:
            th = np.arccos(np.clip(d / np.where(ok, lv * le, 1.0), -1.0, 1.0))
        cn = np.einsum("mkc,mc->mk", c, n)
        return np.where(ok, th * cn / np.where(ok, s, 1.0), 0.0)

    total = (term(e_in) - term(e_out)).sum(axis=1)
    out[rows] = np.abs(total) / _TWO_PI
    return np.clip(out, 0.0, 1.0)


# ---------------------------------------------------------------------------------------------
# Homogeneous coordinates (Section 6, eq. 44-46, Fig. 11)
# ---------------------------------------------------------------------------------------------

def _inf_vertex_term(x, y, px, py):
    """Fig. 11 'vertex at infinity' magnitude: (pi/2) C (x p_y - y p_x), C from (x, y) and p."""
    cross = x * py - y * px
    d2 = x * x + y * y + cross * cross
    ok = d2 > 0.0
    return np.where(ok, _HALF_PI * cross / np.sqrt(np.where(ok, d2, 1.0)), 0.0)


def _inf_edge_term(x, y, a, b):
    """Edge at infinity (eq. 46), signed: atan((a x + b y) / (a y - b x)); 0 on the edge's line.

    Fig. 11 prints ``atan((a x + b y)/|b x - a y|)``, which assumes the clockwise image-plane
    winding of a front-facing source; the sign of ``a y - b x`` (the same at both ends of the
    edge) makes the term right for either winding.
    """
    w = a * y - b * x
    ok = w != 0.0
    return np.where(ok, np.arctan((a * x + b * y) / np.where(ok, w, 1.0)), 0.0)


def homogeneous(points: np.ndarray, normals: np.ndarray, polys: np.ndarray) -> np.ndarray:
    """Image-plane vertex sum in homogeneous coordinates (Fig. 11): sources may touch the plane.

    Parameters
    ----------
    points : (m, 3) float
        Receiver positions, metres.
    normals : (m, 3) float
        Unit receiver normals.
    polys : (m, k, 3) float
        Source polygons. Vertices with z = 0 in the receiver frame (exactly on the receiver
        plane) are vertices at infinity; sources crossing the plane are clipped to z >= 0 first,
        with the cut points put exactly on it.

    Returns
    -------
    (m,) float
        Form factor in [0, 1].

    Notes
    -----
    A finite vertex is ``(X/Z, Y/Z, 1)``, a vertex at infinity ``(X, Y, 0)``. Edge directions:
    finite to finite and infinite to infinite, the difference of the two points; finite to
    infinite, the vertex at infinity; infinite to finite, its negative. The terms of a vertex
    (incoming minus outgoing edge) are those of Fig. 11: the 'edge' term ``G`` at a finite
    vertex, ``(pi/2) C (x y_in - y x_in)`` at a vertex at infinity reached from a finite vertex,
    and ``atan`` of eq. 46 along an edge at infinity. The form factor is ``|sum| / 2 pi``.
    The receiver itself must not be a vertex or lie on a source edge (it is then in the source's
    plane and the result is 0).
    """
    rel = receiver_frame(points, normals, polys)
    z = rel[..., 2]
    out = np.zeros(len(points))
    rows = (z.max(axis=1, initial=-1.0) > 0.0) & ~_in_source_plane(rel)
    if not rows.any():
        return out
    v = rel[rows]
    if (v[..., 2] < 0.0).any():
        v = _clip(v, v[..., 2], flatten=2)
    X, Y, Z = v[..., 0], v[..., 1], v[..., 2]
    inf = Z == 0.0
    zs = np.where(inf, 1.0, Z)
    x = np.where(inf, X, X / zs)  # (x, y) is the finite point or the direction at infinity
    y = np.where(inf, Y, Y / zs)
    xn, yn, inf_n = (np.roll(q, -1, axis=1) for q in (x, y, inf))
    xp, yp, inf_p = (np.roll(q, 1, axis=1) for q in (x, y, inf))
    # Outgoing edge direction of each vertex (and thus incoming direction of the next one).
    a = np.where(inf & ~inf_n, -x, np.where(~inf & inf_n, xn, xn - x))
    b = np.where(inf & ~inf_n, -y, np.where(~inf & inf_n, yn, yn - y))
    a_in = np.roll(a, 1, axis=1)
    b_in = np.roll(b, 1, axis=1)
    fin = ~inf
    t_in = np.where(fin, _stark_G(x, y, a_in, b_in),
                    np.where(inf_p, _inf_edge_term(x, y, a_in, b_in), _inf_vertex_term(x, y, xp, yp)))
    t_out = np.where(fin, _stark_G(x, y, a, b),
                     np.where(inf_n, _inf_edge_term(x, y, a, b), _inf_vertex_term(x, y, xn, yn)))
    total = (t_in - t_out).sum(axis=1)
    out[rows] = np.where(_empty_rows(v), 0.0, np.abs(total) / _TWO_PI)
    return np.clip(out, 0.0, 1.0)

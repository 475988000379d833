"""Numpy references of the compiled loops in ``_quadrature`` (the tests compare the two).

Lambert's sum has its numpy form in ``_closed_form._lambert_numpy`` (also ``lambert_pairs``'
``backend="numpy"``); these are the per-pair setup loops and the quadrature point map.
"""

from __future__ import annotations

import numpy as np

from ._quadrature import _ADAPT_LAYER, _APRIORI_C, _TINY, _TOUCH_REL, _map_frame, _map_square, _receiver_heights


def _rect_points_numpy(quads, rects, nodes, w, frames=None):
    """:func:`rect_points` in numpy (the reference for the loop)."""
    order = len(nodes)
    u = rects[:, 0:1] + rects[:, 2:3] * np.repeat(nodes, order)[None, :]
    v = rects[:, 1:2] + rects[:, 3:4] * np.tile(nodes, order)[None, :]
    scale = rects[:, 2:3] * rects[:, 3:4] * np.outer(w, w).ravel()[None, :]
    if frames is not None:
        u, v, frame_jac = _map_frame(frames, u, v)
        scale = scale * frame_jac
    points, jac = _map_square(quads, u, v)
    return points, jac * scale


def _pair_setup_numpy(quads, normals, centroid, r_rec, s_cen, s_nrm, r_src, i, j, orders, limit,
                      crossing, order):
    """:func:`_pair_setup` in numpy (the reference for the loop)."""
    tiny = _TINY
    dist = np.linalg.norm(centroid[i] - s_cen[j], axis=1)
    rho = (dist - r_src[j]) / np.maximum(r_rec[i], tiny)
    u = (s_cen[j] - centroid[i]) / np.maximum(dist, tiny)[:, None]
    rho = rho * np.minimum(np.abs(np.einsum("mc,mc->m", normals[i], u)), np.abs(np.einsum("mc,mc->m", s_nrm[j], u)))
    h = _receiver_heights(quads, s_cen, s_nrm, i, j)
    tol_h = 1e-12 * (r_rec[i] + r_src[j])
    crossing[:] = (h.max(axis=1) > tol_h) & (h.min(axis=1) < -tol_h)
    ok_rho = (rho > 1.5) & ~crossing
    order[:] = 0
    for p in orders[::-1]:
        order[ok_rho & (_APRIORI_C * np.where(ok_rho, rho, 1.0) ** (-2.0 * p) <= limit)] = p


def _near_flags_numpy(quads, sources, i, j, height, size, lifted, touching, collapsed):
    """:func:`_near_flags` in numpy (the reference for the loop)."""
    lifted[:] = ((height > 0) & (height < 2 * size[:, None] / _ADAPT_LAYER)).any(axis=1)
    centre = quads[i].mean(axis=1)
    radius = np.linalg.norm(quads[i] - centre[:, None, :], axis=2).max(axis=1)
    near = np.linalg.norm(sources[j] - centre[:, None, :], axis=2) < 2 * radius[:, None]
    touching[:] = ((height == 0) & near).any(axis=1)
    corner = quads[i, 3]
    collapsed[:] = (np.linalg.norm(quads[i, 2] - corner, axis=1) <= _TOUCH_REL * size) & (
        (height == 0) & (np.linalg.norm(sources[j] - corner[:, None, :], axis=2) <= _TOUCH_REL * size[:, None])).any(axis=1)

"""Tests of radiosity.formfactors._quadrature: Gauss rules on patches and the adaptive pair_factors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from radiosity.formfactors._quadrature import pair_factors, patch_points, split_patch_points
from radiosity.geometry import centroids_and_areas


def closed_cube(nd):
    """Unit cube, each face cut into nd x nd patches, normals pointing inwards."""
    t = np.linspace(0, 1, nd + 1)
    quads, normals = [], []
    for axis in range(3):
        other = [k for k in range(3) if k != axis]
        for side in (0, 1):
            nrm = np.zeros(3)
            nrm[axis] = 1 if side == 0 else -1
            for a in range(nd):
                for b in range(nd):
                    q = np.array([[t[a], t[b]], [t[a + 1], t[b]], [t[a + 1], t[b + 1]], [t[a], t[b + 1]]])
                    P = np.zeros((4, 3))
                    P[:, other[0]], P[:, other[1]], P[:, axis] = q[:, 0], q[:, 1], side
                    if np.cross(P[1] - P[0], P[2] - P[0]) @ nrm < 0:
                        P = P[::-1]
                    quads.append(P)
                    normals.append(nrm)
    return np.array(quads), np.array(normals)


@pytest.mark.parametrize("order,splits", [(1, 1), (3, 1), (4, 2), (8, 3)])
def test_weights_sum_to_area(order, splits):
    quads = np.array([[[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]],
                      [[0, 0, 0], [1, 0, 0], [0, 1, 1], [0, 1, 1]]], float)
    _, area = centroids_and_areas(quads)
    if splits == 1:
        _, w = patch_points(quads, order)
    else:
        _, w = split_patch_points(quads, order, splits)
    np.testing.assert_allclose(w.sum(axis=1), area, rtol=1e-14)


@pytest.mark.parametrize("rtol", [1e-4, 1e-6, 1e-8])
def test_closed_cube_rows_sum_to_one(rtol):
    quads, normals = closed_cube(4)
    c, a = centroids_and_areas(quads)
    n = len(quads)
    I, J = (x.ravel() for x in np.meshgrid(np.arange(n), np.arange(n), indexing="ij"))
    keep = np.einsum("nc,nc->n", normals[I], normals[J]) < 0.5  # drop coplanar pairs
    I, J = I[keep], J[keep]
    f, info = pair_factors(quads, normals, c, a, I, J, rtol=rtol, return_info=True)
    assert info["converged"].all() and np.isfinite(f).all() and (f >= 0).all()
    rows = np.bincount(I, f, minlength=n)
    assert np.abs(rows - 1).max() < 10 * rtol
    F = np.zeros((n, n))
    F[I, J] = f
    np.testing.assert_allclose(a[:, None] * F, (a[:, None] * F).T, atol=10 * rtol * a.max())


def test_far_pairs_use_few_points_and_stay_accurate():
    quads = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
                      [[0, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0]]], float)
    quads[1, :, 2] = 5e3
    normals = np.array([[0, 0, 1.0], [0, 0, -1.0]])
    c, a = centroids_and_areas(quads)
    f, info = pair_factors(quads, normals, c, a, np.array([0]), np.array([1]), rtol=1e-6, return_info=True)
    assert info["points"][0] <= 4
    exact = 1 / (np.pi * 5e3**2)  # small-plate limit; relative correction ~ 1/d^2
    assert f[0] == pytest.approx(exact, rel=1e-6)


def test_pair_factors_rejects_bad_rtol():
    quads, normals = closed_cube(1)
    c, a = centroids_and_areas(quads)
    with pytest.raises(ValueError, match="rtol"):
        pair_factors(quads, normals, c, a, np.array([0]), np.array([1]), rtol=2.0)


def test_receiver_straddling_the_source_plane():
    """The fill is one-sided: the half of a floor behind a wall's plane sees the wall's back,
    which sends nothing (pair_factors clips it away). polygon_to_polygon ignores the source's
    winding, as point_to_polygon does: each half sees one face of the wall, and both count."""
    from radiosity import polygon_to_polygon

    wall = np.array([[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]], float)  # x = 0, facing +x
    half = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    full = np.array([[-1, 0, 0], [1, 0, 0], [1, 1, 0], [-1, 1, 0]], float)
    f_half = polygon_to_polygon(half, wall, rtol=1e-9)
    np.testing.assert_allclose(f_half, 0.2000437761, rtol=1e-8)
    np.testing.assert_allclose(polygon_to_polygon(full, wall, rtol=1e-9), f_half, rtol=1e-8)
    quads = np.array([full, wall])
    normals = np.array([[0, 0, 1.0], [1.0, 0, 0]])
    c, a = centroids_and_areas(quads)
    one_sided = pair_factors(quads, normals, c, a, np.array([0]), np.array([1]), rtol=1e-9)[0]
    np.testing.assert_allclose(one_sided, 0.5 * f_half, rtol=1e-8)


@settings(max_examples=60, deadline=None)
@given(corners=arrays(np.float64, (3, 3), elements=st.floats(-10, 10)), repeat=st.integers(0, 3))
def test_tip_collapsed_keeps_each_triangle_and_repeats_its_sharpest_corner(corners, repeat):
    """``tip_collapsed`` (the adaptive squares' receiver map) moves a triangle's repeated corner to
    the one opposite its shortest edge, whichever slot the repeat was in; the triangle, its
    winding and every quadrilateral stay as they were."""
    from radiosity.formfactors import tip_collapsed
    from radiosity.geometry import vector_areas

    assume(len({tuple(c) for c in corners}) == 3)  # two equal corners: a segment, left alone
    quad = np.insert(corners, repeat, corners[repeat - 1] if repeat else corners[0], axis=0)
    square = np.array([[0.0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]])
    out = tip_collapsed(np.stack([quad, square]))
    assert np.array_equal(out[1], square)
    tri = out[0]
    assert np.array_equal(tri[2], tri[3])
    assert sorted(map(tuple, tri[:3])) == sorted(map(tuple, corners))
    np.testing.assert_allclose(vector_areas(tri[None])[0], vector_areas(quad[None])[0], atol=1e-9)
    edges = np.linalg.norm(tri[[1, 2, 0]] - tri[[0, 1, 2]], axis=1)  # ab, b-tip, tip-a
    assert edges[0] <= edges[1:].min() * (1 + 1e-12)

"""Subdivision of faces into planar convex patches (radiosity/patches.py)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from radiosity.geometry import polygon_normals
from radiosity.patches import Patches, planar_parts, subdivide_faces
from radiosity.geometry import centroids_and_areas

from helpers import polygon_area


def _longest_edge(quads: np.ndarray) -> float:
    return float(np.linalg.norm(np.roll(quads, -1, axis=1) - quads, axis=2).max())


def _check(poly: np.ndarray, size: float | None) -> Patches:
    patches, report = subdivide_faces(poly, [np.arange(len(poly))], size)
    assert not report.degenerate and not report.nonplanar
    _, areas = centroids_and_areas(patches.quads)
    assert areas.sum() == pytest.approx(polygon_area(poly), rel=1e-12)
    assert (areas > 0).all()
    if size is not None:
        assert _longest_edge(patches.quads) <= size * (1 + 1e-9)
    normal = np.cross(poly[1] - poly[0], poly[2] - poly[0])
    normal /= np.linalg.norm(normal)
    assert np.allclose(polygon_normals(patches.quads), normal, atol=1e-9)  # winding kept
    assert len(patches.patch_hidden) == patches.n_patches and not patches.patch_hidden.any()
    return patches


def test_none_keeps_faces_whole():
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    patches = _check(square, None)
    assert patches.n_patches == 1
    assert np.array_equal(patches.quads[0], square)


def test_a_repeated_vertex_leaves_no_zero_area_patch():
    """A piece with a vertex repeated to round-off (one imprinting left on a table top of the generated
    furnished room, by a rotated box standing on it) is cut into patches that all have area:
    one cell came out at 1.1e-17 m^2 with no normal, a leaf the hierarchy could never light
    (B = E: "-50%" in the furnace). The area is kept."""
    v = np.array([[3.4168703556706066, 0.75, 1.2962192908078538], [3.42688, 0.75, 1.3726289999999999],
                  [3.42688, 0.75, 1.372629], [3.525672825030446, 0.75, 1.3596873979344268]])  # 2e-16 apart
    patches, _ = subdivide_faces(v, [np.arange(4)], None)
    area = centroids_and_areas(patches.quads)[1]
    extent = np.ptp(patches.quads, axis=1).max(axis=1)
    assert (area > 1e-9 * extent ** 2).all()
    assert area.sum() == pytest.approx(polygon_area(v[[0, 1, 3]]), rel=1e-9)
    assert np.isfinite(polygon_normals(patches.quads)).all()


def test_square_grid():
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    assert _check(square, 0.25).n_patches == 16
    assert _check(square, 0.3).n_patches == 16


@pytest.mark.parametrize("apex", [(0.3, 0.8), (0.5, 0.15)])
def test_triangle_cells_are_quads_or_exact_triangles(apex):
    tri = np.array([[0, 0, 0], [1, 0, 0], [apex[0], apex[1], 0]], float)
    quads = _check(tri, 0.2).quads
    is_tri = (quads[:, 3] == quads[:, 2]).all(axis=1)
    # a triangle repeats its third corner bit for bit; every other cell has four distinct corners
    proper = quads[~is_tri]
    assert (np.linalg.norm(np.roll(proper, -1, axis=1) - proper, axis=2) > 0).all()
    tris = quads[is_tri]
    assert (np.linalg.norm(np.roll(tris[:, :3], -1, axis=1) - tris[:, :3], axis=2) > 0).all()


def test_sliver_triangle_is_one_strip():
    sliver = np.array([[0, 0, 0], [1, 0, 0], [0.5, 0.01, 0]], float)
    patches = _check(sliver, 0.1)
    # about length / size cells, not (length / size)**2 smaller slivers
    assert patches.n_patches <= 12


def test_right_triangle_not_worse_than_similar_split():
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    k = int(np.ceil(np.sqrt(2) / 0.1))
    assert _check(tri, 0.1).n_patches < k * k


def test_nonplanar_quad_split_by_fan_from_first_vertex():
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0.05], [0, 1, 0]], float)
    parts, deviation = planar_parts(quad, 1.0)
    assert deviation > 0.01
    assert len(parts) == 2
    assert np.array_equal(parts[0], quad[[0, 1, 2]]) and np.array_equal(parts[1], quad[[0, 2, 3]])
    patches, report = subdivide_faces(quad, [np.arange(4)], 0.3)
    assert report.nonplanar and report.nonplanar[0][0] == 0
    _, areas = centroids_and_areas(patches.quads)
    assert areas.sum() == pytest.approx(polygon_area(quad[[0, 1, 2]]) + polygon_area(quad[[0, 2, 3]]), rel=1e-12)
    assert _longest_edge(patches.quads) <= 0.3 * (1 + 1e-9)


@pytest.mark.parametrize("size", [0.3, 0.1, 0.07])
def test_nonplanar_quad_cells_meet_vertex_to_vertex_across_the_fold(size):
    """No T-junctions along the fold: every patch corner lying on the fold segment is a corner
    of patches on both sides (a T-junction shows as a crease in per-vertex shading)."""
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0.05], [0, 1, 0]], float)
    patches, _ = subdivide_faces(quad, [np.arange(4)], size)
    quads = patches.quads
    _, areas = centroids_and_areas(quads)
    assert areas.sum() == pytest.approx(polygon_area(quad[[0, 1, 2]]) + polygon_area(quad[[0, 2, 3]]), rel=1e-12)
    assert _longest_edge(quads) <= size * (1 + 1e-9)
    for q in quads:  # each patch is planar
        assert planar_parts(q if not (q[3] == q[2]).all() else q[:3], 1.0)[1] == 0.0
    fold = quad[2] - quad[0]
    corners = quads.reshape(-1, 3)
    t = (corners - quad[0]) @ fold / (fold @ fold)
    on_fold = np.linalg.norm(quad[0] + t[:, None] * fold - corners, axis=1) < 1e-12
    side = quad[1] - quad[0] - ((quad[1] - quad[0]) @ fold) / (fold @ fold) * fold  # towards v1's half
    centroid_side = np.sign((quads.mean(axis=1) - quad[0]) @ side)
    keys = {tuple(np.round(c, 12)) for c in corners[on_fold]}
    for key in keys:
        touching = np.any(np.linalg.norm(quads - np.array(key), axis=2) < 1e-12, axis=1)
        assert set(centroid_side[touching]) == {-1.0, 1.0}, key


def test_degenerate_face_reported_and_dropped():
    line = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], float)
    square = np.array([[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
    vertices = np.concatenate([line, square])
    patches, report = subdivide_faces(vertices, [np.arange(3), np.arange(3, 7)], None)
    assert report.degenerate == [0]
    assert (patches.patch_face == 1).all()


def test_nonconvex_face_triangulated():
    ell = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]], float)
    _check(ell, 0.4)
    _check(ell, None)


@given(st.lists(st.floats(-1, 1), min_size=6, max_size=6), st.floats(0.05, 0.7))
def test_random_triangles(coords, size):
    tri = np.array([[coords[0], coords[1], 0.0], [coords[2], coords[3], 0.0], [coords[4], coords[5], 0.0]])
    if polygon_area(tri) < 1e-3:
        return
    if np.cross(tri[1] - tri[0], tri[2] - tri[0])[2] < 0:
        tri = tri[::-1].copy()
    _check(tri, size)


@given(st.floats(0.1, 3), st.floats(0.1, 3), st.floats(-0.9, 0.9), st.floats(0.03, 0.8))
def test_random_convex_quads(width, height, shear, size):
    top = width * (1 - abs(shear) / 2)
    quad = np.array([[0, 0, 0], [width, 0, 0], [shear + top, height, 0], [shear, height, 0]])
    _check(quad, size)

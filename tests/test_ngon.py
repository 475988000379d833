"""Convex faces with many corners are tiled into well-shaped pieces (radiosity/_ngon.py)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import radiosity
from radiosity._ngon import GRADED_MIN_CORNERS, graded_pieces
from radiosity.patches import subdivide_faces
from radiosity.geometry import centroids_and_areas

from helpers import COAXIAL_DISKS, regular_polygon, write_obj


def _polygon_area(n: int, radius: float = 1.0) -> float:
    return 0.5 * n * radius**2 * np.sin(2 * np.pi / n)


def _shape(quads: np.ndarray) -> np.ndarray:
    """Longest edge squared over area, per patch (an equilateral triangle: 2.3)."""
    _, area = centroids_and_areas(quads)
    longest = np.linalg.norm(np.roll(quads, -1, axis=1) - quads, axis=2).max(axis=1)
    return longest**2 / area


@pytest.mark.parametrize("n", [GRADED_MIN_CORNERS, 200, 1000, 5000])
def test_disk_tiles_exactly_with_well_shaped_patches(n):
    disk = regular_polygon(1.0, n)
    patches, report = subdivide_faces(disk, [np.arange(n)], None)
    _, area = centroids_and_areas(patches.quads)
    assert area.sum() == pytest.approx(_polygon_area(n), rel=1e-12)
    assert area.sum() == pytest.approx(np.pi, rel=2 * (2 * np.pi / n) ** 2 / 6)
    assert not report.nonplanar and not report.degenerate
    assert _shape(patches.quads).max() < 8.0  # earcut's fan: ~n / pi
    assert patches.n_patches <= n  # at least n / 2 are needed for n edges
    normals = np.cross(patches.quads[:, 1] - patches.quads[:, 0], patches.quads[:, 2] - patches.quads[:, 0])
    assert (normals[:, 2] > 0).all()  # wound like the disk


@settings(max_examples=15, deadline=None)
@given(n=st.integers(GRADED_MIN_CORNERS, 400), sx=st.floats(0.05, 20), sy=st.floats(0.05, 20),
       turn=st.floats(0, 2 * np.pi), seed=st.integers(0, 2**31))
def test_convex_ngons_tile_exactly(n, sx, sy, turn, seed):
    """Ellipses (stretched, rotated, tilted, uneven corner spacing): area kept to round-off,
    every piece convex and wound like the face, or None (earcut then)."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0, 2 * np.pi, n))
    if np.diff(np.append(t, t[0] + 2 * np.pi)).min() < 1e-4:
        return
    xy = np.column_stack([sx * np.cos(t), sy * np.sin(t)])
    c, s = np.cos(turn), np.sin(turn)
    rotation = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, 0.6, -0.8], [0, 0.8, 0.6]])
    poly = np.column_stack([xy, np.zeros(n)]) @ rotation.T
    normal = rotation[:, 2]
    pieces = graded_pieces(poly, normal)
    area = 0.5 * abs(np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1]))
    if pieces is None:
        return
    total = 0.0
    for piece in pieces:
        edges = np.roll(piece, -1, axis=0) - piece
        turns = np.cross(edges, np.roll(edges, -1, axis=0)) @ normal
        assert (turns > 0).all()
        total += 0.5 * float(np.cross(piece - piece[0], np.roll(piece, -1, axis=0) - piece[0]).sum(axis=0) @ normal)
    assert total == pytest.approx(area, rel=1e-9)
    assert np.allclose((np.concatenate(pieces) - poly[0]) @ normal, 0, atol=1e-12 * max(sx, sy))


def test_disk_light_over_parallel_disk(tmp_path):
    """Radius = distance: F = (3 - sqrt 5) / 2 (coaxial disks), with 2,000-corner disks at the
    draft preset; loading and the factors stay well-shaped and few."""
    n = 2000
    path = write_obj(tmp_path / "disks.obj",
                     {"low": [regular_polygon(1.0, n)], "high": [regular_polygon(1.0, n, 1.0, facing_down=True)]})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", radiosity.RadiosityWarning)
        scene = radiosity.load_scene(path)
        vf = radiosity.compute_view_factors(scene, preset="draft", cache=False)
    assert scene.patch_area[scene.patch_object == 0].sum() == pytest.approx(_polygon_area(n), rel=1e-12)
    assert vf.scene.n_patches < 2 * n
    polygon_correction = 1.0 + 4 * (2 * np.pi / n) ** 2 / 6  # the 2000-gon is smaller than the disk
    assert vf.grouped("object").F[0, 1] == pytest.approx(COAXIAL_DISKS, rel=2e-3 + polygon_correction - 1)

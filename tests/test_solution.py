"""Solution: per-object means, per-vertex values, irradiance at sensor points."""

from __future__ import annotations

import numpy as np
import pytest

import radiosity
from helpers import corner_point_factor, write_obj

LAMP = np.array([[0, 0, 1], [0, 1, 1], [1, 1, 1], [1, 0, 1]], float)  # faces down
FLOOR = np.array([[-1, -1, 0], [2, -1, 0], [2, 2, 0], [-1, 2, 0]], float)  # faces up


def lamp_scene(tmp_path, *, blocker=None):
    objects = {"lamp": [LAMP], "floor": [FLOOR]}
    if blocker is not None:
        objects["blocker"] = [blocker]
    materials = {"lamp": ((0.0, 0.0, 0.0), (1.0, 2.0, 3.0)), "black": ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))}
    path = write_obj(tmp_path / "lamp.obj", objects, materials,
                     {"lamp": "lamp", "floor": "black", "blocker": "black"})
    return radiosity.solve(radiosity.load_scene(path), preset="draft", cache=False)


def test_irradiance_under_a_lamp_corner_is_exact(tmp_path):
    sol = lamp_scene(tmp_path)
    h = sol.irradiance([[0, 0, 0], [0, 0, 0.5]], [[0, 0, 1], [0, 0, 1]])
    exitance = np.pi * np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(h[0], exitance * corner_point_factor(1, 1, 1), rtol=1e-12)
    np.testing.assert_allclose(h[1], exitance * corner_point_factor(1, 1, 0.5), rtol=1e-12)


def test_irradiance_respects_receiver_side_and_blockers(tmp_path):
    blocker = np.array([[-0.5, -0.5, 0.5], [1.5, -0.5, 0.5], [1.5, 1.5, 0.5], [-0.5, 1.5, 0.5]], float)
    sol = lamp_scene(tmp_path, blocker=blocker)
    h = sol.irradiance([[0.5, 0.5, 0.2], [0.5, 0.5, 0.8], [0.5, 0.5, 0.8]],
                       [[0, 0, 1], [0, 0, 1], [0, 0, -1]])
    assert np.all(h[0] == 0)  # under the blocker: fully shadowed
    assert np.all(h[1] > 0)  # above it: lit
    assert np.all(h[2] == 0)  # facing away from the lamp


def test_irradiance_at_centroids_matches_patch_irradiance():
    scene = radiosity.load_scene(radiosity.bundled_scene("unit_cube"), max_patch_size=0.5)
    sol = radiosity.solve(scene, preset="draft", cache=False)
    s = sol.scene
    h = sol.irradiance(s.patch_centroid + 1e-9 * s.patch_normal, s.patch_normal)
    np.testing.assert_allclose(h, sol.patch_irradiance, rtol=0.05)


def test_irradiance_input_is_validated(tmp_path):
    sol = lamp_scene(tmp_path)
    with pytest.raises(ValueError, match="points must have shape"):
        sol.irradiance([[0, 0]], [[0, 0, 1]])
    with pytest.raises(ValueError, match="same length"):
        sol.irradiance([[0, 0, 0]], [[0, 0, 1], [0, 0, 1]])
    with pytest.raises(ValueError, match="non-zero"):
        sol.irradiance([[0, 0, 0]], [[0, 0, 0]])


def test_object_radiosity_is_area_weighted_mean():
    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    sol = radiosity.solve(scene, preset="draft", cache=False)
    means = sol.object_radiosity()
    s = sol.scene
    k = s.objects.index("floor")
    mask = s.patch_object == k
    expected = (s.patch_area[mask, None] * sol.radiosity[mask]).sum(0) / s.patch_area[mask].sum()
    np.testing.assert_allclose(means["floor"], expected)
    np.testing.assert_allclose(means["light"][0], np.pi * 17 + 0.78 * sol.patch_irradiance[s.patch_object == s.objects.index("light"), 0].mean(), rtol=1e-3)


def test_vertex_values_lie_within_patch_values():
    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    sol = radiosity.solve(scene, preset="draft", cache=False)
    vertices, faces, vertex_b = sol.vertex_mesh
    assert len(faces) == sol.scene.n_patches
    assert np.isfinite(vertex_b).all()
    assert vertex_b.min() >= sol.radiosity.min() - 1e-12
    assert vertex_b.max() <= sol.radiosity.max() + 1e-12


def test_patches_grouped_by_label_from_one_sort():
    """The per-face and per-object groups of the vertex mesh and the object means: the indices
    of each label in ascending order, as a mask per label gave them, for labels with gaps."""
    from radiosity.solution import patch_groups

    labels = np.random.default_rng(3).choice([0, 2, 3, 7, 40], size=1000)
    groups = patch_groups(labels)
    assert sorted(groups) == [0, 2, 3, 7, 40]
    for label, members in groups.items():
        np.testing.assert_array_equal(members, np.flatnonzero(labels == label))
    assert patch_groups(np.zeros(0, np.int64)) == {}


def test_vertex_mesh_has_no_t_junctions_and_ignores_hidden_patches():
    """Within each OBJ face no vertex lies inside another patch's edge (imprinted cells are
    cut differently on either side of an outline), and vertices on the rim of a hidden region
    (under a block) take only the visible patches' values."""
    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    sol = radiosity.solve(scene, preset="draft", cache=False)
    vertices, faces, vertex_b = sol.vertex_mesh
    s = sol.scene
    tol = 1e-7 * s.scale
    for face in np.unique(s.patch_face):
        members = np.flatnonzero(s.patch_face == face)
        points = vertices[np.unique(np.concatenate([faces[i] for i in members]))]
        for i in members:
            ring = vertices[faces[i]]
            for a, b in zip(ring, np.roll(ring, -1, axis=0)):
                d = b - a
                t = (points - a) @ d / (d @ d)
                off = np.linalg.norm(points - a - t[:, None] * d, axis=1)
                assert not ((t > 1e-6) & (t < 1 - 1e-6) & (off < tol)).any()
    hidden = s.patch_hidden
    assert hidden.any()
    sums, weights = np.zeros((len(vertices), 3)), np.zeros(len(vertices))
    rim = np.zeros(len(vertices), bool)
    for i, ring in enumerate(faces):
        if hidden[i]:
            rim[ring] = True
        else:
            sums[ring] += s.patch_area[i] * sol.radiosity[i]
            weights[ring] += s.patch_area[i]
    rim &= weights > 0
    assert rim.sum() > 10
    np.testing.assert_allclose(vertex_b[rim], sums[rim] / weights[rim, None], rtol=1e-6)

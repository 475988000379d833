"""Whole-pipeline tests: load -> patches -> form factors -> visibility -> solve."""

from __future__ import annotations

import numpy as np
import pytest

import radiosity
from helpers import write_obj


@pytest.fixture(scope="module")
def cornell_draft():
    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    return radiosity.solve(scene, preset="draft", cache=False)


def test_cornell_loader_keeps_objects_and_materials():
    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    assert scene.objects == ["floor", "ceiling", "back_wall", "red_wall", "green_wall",
                             "short_block", "tall_block", "light"]
    by_object = {name: scene.patch_object == k for k, name in enumerate(scene.objects)}
    np.testing.assert_allclose(scene.reflectance[by_object["red_wall"]][0], [0.63, 0.065, 0.05])
    np.testing.assert_allclose(scene.reflectance[by_object["green_wall"]][0], [0.14, 0.45, 0.091])
    np.testing.assert_allclose(scene.reflectance[by_object["floor"]][0], [0.725, 0.71, 0.68])
    np.testing.assert_allclose(scene.emission[by_object["light"]][0], np.pi * np.array([17.0, 12.0, 4.0]))
    assert not scene.emission[~by_object["light"]].any()
    # metres, not millimetres: the room is 0.55 m across
    extent = np.ptp(scene.patch_quads.reshape(-1, 3), axis=0)
    assert 0.5 < extent.max() < 0.6


def test_cornell_light_faces_down_and_room_faces_inwards():
    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    centre = np.array([0.278, 0.274, 0.28])
    for k, name in enumerate(scene.objects):
        mask = scene.patch_object == k
        facing = np.einsum("nc,nc->n", scene.patch_normal[mask], centre - scene.patch_centroid[mask])
        if name.endswith("block"):
            continue
        assert (facing > 0).all(), name


def test_emission_exitance_mode(tmp_path):
    path = radiosity.bundled_scene("cornell_box")
    radiance = radiosity.load_scene(path)
    exitance = radiosity.load_scene(path, emission="exitance")
    np.testing.assert_allclose(radiance.emission, np.pi * exitance.emission)


def closed_cube(patch_size: float):
    return radiosity.load_scene(radiosity.bundled_scene("unit_cube"), max_patch_size=patch_size)


@pytest.mark.parametrize("patch_size", [1.0, 0.5])
def test_closed_cube_rows_sum_to_one(patch_size):
    scene = closed_cube(patch_size)
    F = radiosity.view_factors(scene, cache=False)
    rows = np.asarray(F.sum(axis=1)).ravel()
    np.testing.assert_allclose(rows, 1.0, atol=2e-3)


def test_reciprocity_in_closed_cube():
    scene = closed_cube(0.5)
    F = radiosity.view_factors(scene, cache=False).toarray()
    exchange = scene.patch_area[:, None] * F
    scale = exchange.max()
    assert np.abs(exchange - exchange.T).max() < 2e-3 * scale


def test_furnace_closed_box_uniform_reflectance():
    """Every face emits E and reflects rho: B = E / (1 - rho) everywhere."""
    scene = closed_cube(0.5).with_materials(reflectance=0.5, emission=1.0)
    solution = radiosity.solve(scene, preset="draft", cache=False)
    np.testing.assert_allclose(solution.radiosity, 2.0, rtol=3e-3)


def test_cornell_energy_balance(cornell_draft):
    e = {k: np.array(v) for k, v in cornell_draft.energy.items()}
    np.testing.assert_allclose(e["emitted"], e["absorbed"] + e["escaped"], rtol=1e-8)
    escaped_fraction = e["escaped"] / e["emitted"]
    # The open front lets roughly a quarter to a third of the power out (field notes: 26-32%).
    assert ((escaped_fraction > 0.2) & (escaped_fraction < 0.4)).all()
    emitted = (cornell_draft.scene.patch_area[:, None] * cornell_draft.scene.emission).sum(axis=0)
    np.testing.assert_allclose(e["emitted"], emitted)


def test_cornell_colour_bleeding(cornell_draft):
    """The floor next to the red wall (x ~ 0.55) is redder than next to the green wall (x = 0)."""
    s = cornell_draft.scene
    floor = s.patch_object == s.objects.index("floor")
    x = s.patch_centroid[:, 0]
    b = cornell_draft.radiosity
    near_red = floor & (x > 0.45)
    near_green = floor & (x < 0.10)
    ratio_red = (b[near_red, 0] / b[near_red, 1]).mean()
    ratio_green = (b[near_green, 0] / b[near_green, 1]).mean()
    assert ratio_red > ratio_green * 1.05
    green_side = (b[near_green, 1] / b[near_green, 0]).mean()
    assert green_side > (b[near_red, 1] / b[near_red, 0]).mean()


def test_cornell_results_are_finite_and_positive(cornell_draft):
    assert np.isfinite(cornell_draft.radiosity).all()
    assert (cornell_draft.radiosity >= 0).all()
    objects = cornell_draft.object_radiosity()
    assert set(objects) == set(cornell_draft.scene.objects)
    for name, value in objects.items():
        assert value.shape == (3,) and np.isfinite(value).all(), name


def test_block_shadows_the_floor(cornell_draft):
    """A block blocks the light: the floor right behind the tall block is darker than open floor."""
    s = cornell_draft.scene
    floor = np.flatnonzero(s.patch_object == s.objects.index("floor"))
    b = cornell_draft.radiosity[floor, 0]
    assert b.min() < 0.5 * np.median(b)


def test_two_facing_plates_match_closed_form(tmp_path):
    """Parallel unit squares 1 apart: F = 0.1998248957 (Howell C-11)."""
    lower = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    upper = lower[::-1] + [0, 0, 1]
    path = write_obj(tmp_path / "plates.obj", {"lower": [lower], "upper": [upper]})
    scene = radiosity.load_scene(path)
    F = radiosity.view_factors(scene, cache=False).toarray()
    np.testing.assert_allclose(F[0, 1], 0.1998248957, rtol=1e-6)
    np.testing.assert_allclose(F[1, 0], 0.1998248957, rtol=1e-6)

"""Knobs: one spelling each (docs/options.md); the old spellings still work, and warn."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import radiosity
from radiosity import RadiosityWarning
from radiosity.cli import main
from radiosity.options import DEPRECATED_OPTIONS, Options

CUBE = radiosity.bundled_scene("unit_cube")


@pytest.mark.parametrize(("old", "new"), sorted(DEPRECATED_OPTIONS.items()))
def test_old_option_names_give_the_new_field_and_warn(old, new):
    with pytest.warns(RadiosityWarning, match=f"{old!r} is deprecated; use {new!r}"):
        via_old = Options.from_preset("draft", **{old: 3e-7})
    assert via_old == Options.from_preset("draft", **{new: 3e-7})
    assert getattr(via_old, new) == getattr(via_old, old) == 3e-7  # read-only old attribute


@pytest.mark.parametrize(("old", "new"), sorted(DEPRECATED_OPTIONS.items()))
def test_old_and_new_name_together_are_refused(old, new):
    with pytest.raises(TypeError, match=f"give only {new!r}"):
        Options.from_preset("default", **{old: 1e-6, new: 1e-6})


def test_visibility_rtol_alias_gives_the_same_view_factors():
    scene = radiosity.load_scene(CUBE, max_patch_size=0.5)
    new = radiosity.view_factors(scene, cache=False, visibility_atol=1e-3)
    with pytest.warns(RadiosityWarning, match="'visibility_atol'"):
        old = radiosity.view_factors(scene, cache=False, visibility_rtol=1e-3)
    assert (new != old).nnz == 0


@pytest.fixture(scope="module")
def solved():
    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    return radiosity.solve(scene, preset="draft", cache=False, solver="bicgstab", solver_rtol=1e-8)


def test_rtol_alias_gives_the_same_solution(solved):
    with pytest.warns(RadiosityWarning, match="'solver_rtol'"):
        old = radiosity.solve(solved.scene, preset="draft", cache=False, solver="bicgstab", rtol=1e-8)
    assert old.options == solved.options
    np.testing.assert_array_equal(old.radiosity, solved.radiosity)


def test_irradiance_rtol_alias_gives_the_same_values(solved):
    points = np.array([[0.3, 0.01, 0.3], [0.2, 0.3, 0.1]]) * solved.scene.patch_quads.max()
    normals = np.tile([0.0, 1.0, 0.0], (2, 1))
    new = solved.irradiance(points, normals, sensor_rtol=1e-2)
    with pytest.warns(RadiosityWarning, match="'sensor_rtol'"):
        old = solved.irradiance(points, normals, rtol=1e-2)
    np.testing.assert_array_equal(old, new)


def test_irradiance_samples_warns_and_changes_nothing(solved):
    """``samples`` is accepted (older calls still run), warns that it is ignored, and is: the
    shadows are exact, so the values are those of a call without it."""
    points = np.array([[0.3, 0.01, 0.3], [0.2, 0.3, 0.1]]) * solved.scene.patch_quads.max()
    normals = np.tile([0.0, 1.0, 0.0], (2, 1))
    new = solved.irradiance(points, normals)
    with pytest.warns(RadiosityWarning, match="'samples' is deprecated and ignored"):
        old = solved.irradiance(points, normals, samples=16)
    np.testing.assert_array_equal(old, new)


def test_cli_patch_size_goes_to_the_loading_door(tmp_path):
    """--max-patch-size cuts the scene as load_scene(max_patch_size=) does, not as solve would."""
    out = tmp_path / "F.npz"
    assert main(["viewfactors", "--max-patch-size", "0.5", str(CUBE), "-o", str(out), "--no-cache"]) == 0
    expected = radiosity.view_factors(radiosity.load_scene(CUBE, max_patch_size=0.5), cache=False)
    got = sp.load_npz(out)
    assert got.shape == expected.shape == (24, 24)
    np.testing.assert_array_equal(got.toarray(), expected.toarray())

"""The public names and signatures that users and outside checks rely on (CONTRACT.md)."""

from __future__ import annotations

import inspect

import numpy as np
import scipy.sparse as sp

import radiosity

CONTRACT_NAMES = {"point_to_polygon", "polygon_to_polygon", "load_scene", "solve", "view_factors", "SceneError"}


def test_contract_names_are_public():
    assert CONTRACT_NAMES <= set(radiosity.__all__)
    for name in radiosity.__all__:
        assert hasattr(radiosity, name), name


def test_signatures():
    p2p = inspect.signature(radiosity.polygon_to_polygon)
    assert p2p.parameters["rtol"].default == 1e-6
    assert p2p.parameters["rtol"].kind is inspect.Parameter.KEYWORD_ONLY
    load = inspect.signature(radiosity.load_scene)
    assert load.parameters["max_patch_size"].default is None
    assert load.parameters["emission"].default == "radiance"
    assert inspect.signature(radiosity.solve).parameters["preset"].default == "default"
    assert list(inspect.signature(radiosity.point_to_polygon).parameters) == ["points", "normals", "polygon"]


def test_scene_and_solution_attributes():
    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    n = len(scene.patch_area)
    assert scene.patch_object.shape == (n,) and scene.patch_area.shape == (n,)
    assert isinstance(scene.objects, list) and all(isinstance(o, str) for o in scene.objects)
    solution = radiosity.solve(scene, preset="draft", cache=False)
    assert solution.radiosity.shape == (solution.scene.n_patches, 3)
    assert isinstance(solution.object_radiosity()["floor"], np.ndarray)
    F = radiosity.view_factors(scene, preset="draft", cache=False)
    assert isinstance(F, sp.csr_matrix) and F.shape == (n, n)


def test_presets_are_ordered_by_patch_size():
    sizes = [radiosity.PRESETS[p].patch_size_rel for p in ("draft", "default", "fine")]
    assert sizes == sorted(sizes, reverse=True)


def test_unknown_option_and_preset_are_type_errors_listing_valid_names():
    scene = radiosity.load_scene(radiosity.bundled_scene("unit_cube"))
    import pytest

    with pytest.raises(TypeError, match="near_order"):
        radiosity.solve(scene, quality=3)
    with pytest.raises(TypeError, match="draft"):
        radiosity.solve(scene, preset="ultra")
    with pytest.raises(TypeError, match="units"):
        radiosity.load_scene(radiosity.bundled_scene("unit_cube"), colour="red")


def test_point_to_polygon_ignores_winding_and_never_returns_nan():
    square = np.array([[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
    pts = np.array([[0, 0, 0], [0.5, 0.5, 1.0], [2, 2, 1], [0, 0, 1]], float)
    normals = np.tile([0, 0, 1.0], (4, 1))
    a = radiosity.point_to_polygon(pts, normals, square)
    b = radiosity.point_to_polygon(pts, normals, square[::-1])
    np.testing.assert_array_equal(a, b)
    assert np.isfinite(a).all()
    degenerate = radiosity.point_to_polygon(pts, normals, np.array([[0, 0, 1], [1, 1, 1], [2, 2, 1]], float))
    np.testing.assert_array_equal(degenerate, 0.0)


def test_import_makes_openmp_wait_passively_unless_the_user_chose():
    """numba's spinning OpenMP workers ran the open 16 x 16 plates 5x slower (docs/formfactors.md)."""
    import os
    import subprocess
    import sys

    code = "import os, radiosity; print(os.environ.get('OMP_WAIT_POLICY'))"
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    for given, expected in ((None, "PASSIVE"), ("ACTIVE", "ACTIVE")):
        run_env = env if given is None else {**env, "OMP_WAIT_POLICY": given}
        out = subprocess.run([sys.executable, "-c", code], env=run_env, capture_output=True, text=True, check=True)
        assert out.stdout.strip() == expected

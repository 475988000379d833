"""View3D .vs3 models: read, write, round trip, obstructions."""

from __future__ import annotations

import numpy as np
import pytest

import radiosity
from radiosity.io.view3d import read_vs3, write_vs3

from helpers import PLATES



@pytest.fixture()
def plates(tmp_path):
    path = tmp_path / "plates.vs3"
    path.write_text(PLATES)
    return path


def test_reads_surfaces_obstructions_and_emissivity(plates):
    data = read_vs3(plates)
    assert data["names"] == ["lower", "upper", "obstruction_3"]
    assert data["obstruction"].tolist() == [False, False, True]
    np.testing.assert_allclose(data["emissivity"][:2], [0.9, 0.8])
    scene = radiosity.load_scene(plates)
    assert scene.patch_obstruction.tolist() == [False, False, True]
    np.testing.assert_allclose(scene.reflectance[:2, 0], [0.1, 0.2])


def test_obstruction_blocks_but_does_not_exchange(plates):
    scene = radiosity.load_scene(plates)
    F = radiosity.view_factors(scene, cache=False).toarray()
    assert F[2].sum() == 0 and F[:, 2].sum() == 0
    assert 0.0 < F[0, 1] < 0.1998248957  # blocked in part


def test_unobstructed_plates_match_closed_form(tmp_path):
    text = PLATES.split("O 3")[0] + "E\n"
    path = tmp_path / "open.vs3"
    path.write_text(text)
    F = radiosity.view_factors(radiosity.load_scene(path), cache=False).toarray()
    np.testing.assert_allclose(F[0, 1], 0.1998248957, rtol=2e-4)


def test_round_trip_keeps_geometry_and_kinds(plates, tmp_path):
    scene = radiosity.load_scene(plates)
    out = tmp_path / "again.vs3"
    write_vs3(scene, out)
    again = radiosity.load_scene(out)
    np.testing.assert_allclose(again.patch_quads, scene.patch_quads)
    assert again.patch_obstruction.tolist() == scene.patch_obstruction.tolist()
    np.testing.assert_allclose(again.reflectance, scene.reflectance, atol=1e-6)


def test_cornell_box_exports_to_view3d(tmp_path):
    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    write_vs3(scene, tmp_path / "cornell.vs3")
    again = radiosity.load_scene(tmp_path / "cornell.vs3")
    assert again.n_patches == scene.n_patches
    np.testing.assert_allclose(again.patch_area.sum(), scene.patch_area.sum(), rtol=1e-12)


@pytest.mark.parametrize("line, message", [
    ("V 7 0 0 0", "out of sequence"),
    ("S 1 1 2 3 9 0 0 0.9 x", "uses vertex 9"),
    ("Q 1", "unknown View3D identifier"),
    ("V 4 0 zero 0", "must be a number"),
    ("F 2", "only 3-D"),
])
def test_bad_lines_name_file_and_line(tmp_path, line, message):
    path = tmp_path / "bad.vs3"
    path.write_text(f"T bad\nV 1 0 0 0\nV 2 1 0 0\nV 3 0 1 0\n{line}\nE\n")
    with pytest.raises(radiosity.SceneError, match=message) as info:
        radiosity.load_scene(path)
    assert "bad.vs3:" in str(info.value)

"""The bundled scenes do not warn about themselves; a user's non-planar face still does."""

from __future__ import annotations

import shutil
import warnings

import radiosity
from radiosity.scene import MEASURED


def test_bundled_cornell_box_loads_without_warnings():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    measured = [n for n in scene.notes if "not planar" in n]
    assert measured and all(n.endswith(MEASURED) for n in measured)


def test_a_copy_of_the_box_is_a_user_file_and_warns(tmp_path):
    import pytest

    source = radiosity.bundled_scene("cornell_box")
    for suffix in (".obj", ".mtl"):
        shutil.copy(source.with_suffix(suffix), tmp_path / f"box{suffix}")
    (tmp_path / "box.obj").write_text((tmp_path / "box.obj").read_text().replace("cornell_box.mtl", "box.mtl"))
    with pytest.warns(radiosity.RadiosityWarning, match="is not planar") as caught:
        scene = radiosity.load_scene(tmp_path / "box.obj")
    assert not any(MEASURED in str(w.message) for w in caught)
    assert not any(MEASURED in n for n in scene.notes)

"""View3D models as View3D means them: subsurfaces separated, cmb combined, F 3a, comments, encl/emit."""

from __future__ import annotations

import numpy as np
import pytest

import radiosity
from radiosity.io.view3d import read_vs3

from helpers import CUBE_3A
from helpers import ROOM_VS3 as ROOM


def _write(tmp_path, text, name="model.vs3"):
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.fixture()
def room(tmp_path):
    return _write(tmp_path, ROOM, "room.vs3")


def test_inline_comments_are_not_part_of_names(room):
    model = read_vs3(room)
    assert model.names == ["floor", "ceiling", "south", "north", "west", "east", "door", "window"]
    assert model.base == [0, 0, 0, 0, 0, 0, 3, 3]
    assert model.enclosure and not model.emittances


def test_subsurfaces_are_cut_out_of_their_base(room):
    scene = radiosity.load_scene(room)
    area = np.bincount(scene.patch_face, weights=scene.patch_area)
    np.testing.assert_allclose(area, [12, 12, 10 - 0.9 * 2 - 1.5 * 1, 10, 7.5, 7.5, 1.8, 1.5], rtol=1e-12)
    assert scene.enclosure
    np.testing.assert_allclose(scene.reflectance[scene.patch_face == 7], 0.9)


def test_door_and_window_floor_row_sums_to_one(room):
    vf = radiosity.compute_view_factors(room and radiosity.load_scene(room), cache=False)
    rows = vf.row_sums
    np.testing.assert_allclose(rows, 1.0, atol=1e-6)  # 1.068 when the door overlapped its wall
    faces = vf.grouped("face")
    np.testing.assert_allclose(faces.row_sums, 1.0, atol=1e-6)
    G = faces.area[:, None] * faces.F.toarray()
    np.testing.assert_allclose(G, G.T, atol=1e-6 * G.max())


def test_separation_is_view3d_algebra(room):
    """F(floor -> wall minus openings) = F(floor -> whole wall) - F(floor -> door) - F(floor -> window)."""
    model = read_vs3(room)
    poly = [model.vertices[s] for s in model.surfaces]
    faces = radiosity.compute_view_factors(radiosity.load_scene(room), cache=False).grouped("face")
    whole = radiosity.polygon_to_polygon(poly[0], poly[2], rtol=1e-9)
    door = radiosity.polygon_to_polygon(poly[0], poly[6], rtol=1e-9)
    window = radiosity.polygon_to_polygon(poly[0], poly[7], rtol=1e-9)
    F = faces.F.toarray()
    np.testing.assert_allclose(F[0, 2], whole - door - window, rtol=1e-6)
    np.testing.assert_allclose(F[0, 6], door, rtol=1e-6)


# The top of a unit cube in two halves, the second combined with the first (cmb = 6).
SPLIT_CUBE = """T cube with a split top
F 3
V 1 0 0 0
V 2 1 0 0
V 3 1 1 0
V 4 0 1 0
V 5 0 0 1
V 6 1 0 1
V 7 1 1 1
V 8 0 1 1
V 9 0.5 0 1
V 10 0.5 1 1
S 1 1 2 3 4 0 0 0.5 bottom
S 2 1 4 8 5 0 0 0.5 west
S 3 1 5 6 2 0 0 0.5 south
S 4 2 6 7 3 0 0 0.5 east
S 5 4 3 7 8 0 0 0.5 north
S 6 5 8 10 9 0 0 0.5 top
S 7 9 10 7 6 0 6 0.5 top_east_half
E
"""


def test_combined_surfaces_are_one_output_surface(tmp_path):
    scene = radiosity.load_scene(_write(tmp_path, SPLIT_CUBE))
    assert scene.objects == ["bottom", "west", "south", "east", "north", "top"]
    assert scene.patch_face.tolist() == list(range(7)) and scene.patch_object.tolist() == [0, 1, 2, 3, 4, 5, 5]
    out = radiosity.compute_view_factors(scene, cache=False).grouped("object")
    F = out.F.toarray()
    np.testing.assert_allclose(out.area, 1.0, rtol=1e-12)
    np.testing.assert_allclose(F[0, 5], 0.1998248957, rtol=1e-6)  # opposite faces of a cube
    np.testing.assert_allclose(F[5, 1], 0.2000437761, rtol=1e-6)
    np.testing.assert_allclose(out.row_sums, 1.0, atol=1e-6)




def test_format_3a_cube(tmp_path):
    scene = radiosity.load_scene(_write(tmp_path, CUBE_3A))
    assert scene.objects == ["bottom", "south", "north", "west", "east", "top", "obstruction_8"]
    np.testing.assert_allclose(scene.patch_area, [1, 1, 1, 1, 1, 0.5, 0.5, 0.25], rtol=1e-12)
    inward = (0.5 - scene.patch_centroid[:7]) * scene.patch_normal[:7]
    assert (inward.sum(axis=1) > 0.49).all()  # every face looks into the cube
    corners = scene.patch_quads[:5].reshape(-1, 3)
    assert set(map(tuple, np.round(corners, 12))) <= {(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)}
    np.testing.assert_allclose(scene.patch_centroid[7], [0.5, 0.5, 0.5], atol=1e-12)
    assert scene.patch_obstruction.tolist() == [False] * 7 + [True]


@pytest.mark.parametrize("surfaces, message", [
    ("S 1 1 2 3 4 0 0 0.9 wall\nS 2 5 6 7 8 1 0 0.9 door\n", "not in the plane of its base"),
    ("S 1 1 2 3 4 0 0 0.9 wall\nS 2 9 10 11 12 1 0 0.9 door\n", "not entirely within its base"),
    ("S 1 1 2 3 4 0 0 0.9 wall\nS 2 16 15 14 13 1 0 0.9 door\n", "must face the same way"),
    ("S 1 1 2 3 4 0 0 0.9 wall\nS 2 13 14 15 16 1 0 0.9 a\nS 3 13 14 15 16 1 0 0.9 b\n", "overlap"),
    ("S 1 1 2 3 4 0 0 0.9 a\nS 2 5 6 7 8 0 1 0.9 b\nS 3 9 10 11 12 0 2 0.9 c\n", "do not chain"),
    ("S 1 1 2 3 4 0 0 0.9 a\nS 2 5 6 7 8 0 3 0.9 b\nS 3 9 10 11 12 0 0 0.9 c\n", "earlier surface"),
    ("O 1 1 2 3 4\nS 2 5 6 7 8 0 0 0.9 b\n", "after an obstruction"),
    ("S 1 1 2 3 4 2 0 0.9 a\nS 2 5 6 7 8 0 0 0.9 b\n", "comes before its base"),
])
def test_bad_subsurfaces_and_combinations(tmp_path, surfaces, message):
    vertices = ["0 0 0", "4 0 0", "4 3 0", "0 3 0", "1 1 1", "2 1 1", "2 2 1", "1 2 1",
                "3 2 0", "5 2 0", "5 3 0", "3 3 0", "1 1 0", "2 1 0", "2 2 0", "1 2 0"]
    text = "T bad\nF 3\n" + "".join(f"V {k} {v}\n" for k, v in enumerate(vertices, 1)) + surfaces + "E\n"
    with pytest.raises(radiosity.SceneError, match=message) as info:
        radiosity.load_scene(_write(tmp_path, text, "bad.vs3"))
    assert "bad.vs3:" in str(info.value)


def test_emit_is_refused_with_a_note(tmp_path):
    text = ROOM.replace("C encl=1 eps=1e-6", "C encl=0 emit=1")
    with pytest.warns(radiosity.RadiosityWarning, match="script-F"):
        scene = radiosity.load_scene(_write(tmp_path, text))
    assert not scene.enclosure


def test_encl_means_closure_under_enforce_auto(room):
    scene = radiosity.load_scene(room)
    vf = radiosity.compute_view_factors(scene, enforce="auto", cache=False)
    assert vf.enforced == "closure"
    np.testing.assert_allclose(vf.row_sums, 1.0, atol=1e-12)


def test_room_as_vs3_and_as_obj_agree(room, tmp_path):
    """The OBJ of the same room (door and window as objects lying on the wall) is imprinted:
    the wall under them is hidden. Its object sums equal the View3D model's separated ones."""
    model = read_vs3(room)
    lines = [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in model.vertices]
    for name, refs in zip(model.names, model.surfaces):
        lines += [f"o {name}", "f " + " ".join(str(r + 1) for r in refs)]
    obj = tmp_path / "room.obj"
    obj.write_text("\n".join(lines) + "\n")
    with pytest.warns(radiosity.RadiosityWarning):  # no materials, nothing emits
        as_obj = radiosity.compute_view_factors(radiosity.load_scene(obj), cache=False).grouped("object")
    as_vs3 = radiosity.compute_view_factors(radiosity.load_scene(room), cache=False).grouped("object")
    assert as_obj.names == as_vs3.names
    np.testing.assert_allclose(as_obj.area, as_vs3.area, rtol=1e-12)
    np.testing.assert_allclose(as_obj.F.toarray(), as_vs3.F.toarray(), atol=1e-7)

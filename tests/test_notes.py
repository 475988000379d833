"""Notes for common modelling mistakes (issue 12, item 6) and a camera that shows what was
modelled (item 7): each note fires on the mistake, says what was done, and stays silent on the
same scene done right."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import radiosity
from radiosity._errors import RadiosityWarning
from radiosity._lightpaths import N_RAYS, _triangles
from radiosity.cli import main
from radiosity.viz import auto_camera, choose_camera, parse_camera

from helpers import ROOM

MTL = """newmtl white
Kd 0.7 0.7 0.7
newmtl grey
Kd 0.5 0.5 0.5
newmtl light
Kd 0.5 0.5 0.5
Ke 10 10 10
"""


def load(path, **options):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RadiosityWarning)
        return radiosity.load_scene(path, **options)


def notes_with(scene, text: str) -> list[str]:
    return [n for n in scene.notes if text in n]


# --- a box room, written the way an exporter would (one o per face) --------------------------

def _box(x0, y0, z0, x1, y1, z1, inward: bool) -> dict[str, list[tuple]]:
    """Corners of a box's six faces, counter-clockwise seen from outside (or inside if inward)."""
    v = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0), (x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]
    faces = {"floor": [0, 1, 5, 4], "ceiling": [3, 7, 6, 2], "front_wall": [0, 3, 2, 1],
             "back_wall": [4, 5, 6, 7], "left_wall": [0, 4, 7, 3], "right_wall": [1, 2, 6, 5]}
    return {k: [v[i] for i in (f[::-1] if inward else f)] for k, f in faces.items()}


def write_room(folder: Path, name: str, *, flip_room=False, flip_light=False, flip_wall=None, boxes=True,
               light_in_ceiling=False) -> Path:
    """A closed 4 x 2.5 x 3 m room, a 0.8 x 0.6 m light 1 cm under the ceiling facing down, two boxes.

    ``light_in_ceiling``: the light is a piece of the ceiling (the room stays closed without it).
    """
    lines, count = ["mtllib rooms.mtl"], 0

    def face(obj, corners, material):
        nonlocal count
        lines.extend([f"o {obj}", f"usemtl {material}"] + ["v %r %r %r" % c for c in corners])
        lines.append("f " + " ".join(str(count + k + 1) for k in range(len(corners))))
        count += len(corners)

    for wall, corners in _box(0, 0, 0, 4, 2.5, 3, inward=True).items():
        if flip_room or wall == flip_wall:
            corners = corners[::-1]
        if wall == "ceiling" and light_in_ceiling:
            # the ceiling as four strips around the light's hole, same winding
            for x0, x1, z0, z1 in ((0, 4, 0, 1.2), (0, 4, 1.8, 3), (0, 1.6, 1.2, 1.8), (2.4, 4, 1.2, 1.8)):
                strip = [(x0, 2.5, z0), (x0, 2.5, z1), (x1, 2.5, z1), (x1, 2.5, z0)]
                face("ceiling", strip[::-1] if flip_room else strip, "white")
            continue
        face(wall, corners, "white")
    y = 2.5 if light_in_ceiling else 2.49
    light = [(1.6, y, 1.2), (2.4, y, 1.2), (2.4, y, 1.8), (1.6, y, 1.8)]  # faces down
    face("light", light[::-1] if flip_light else light, "light")
    if boxes:
        for b, (x, z, h) in enumerate([(0.8, 0.7, 0.8), (2.6, 1.6, 1.4)]):
            for side, corners in _box(x, 0, z, x + 0.7, h, z + 0.7, inward=False).items():
                if side != "floor":
                    face(f"box{b}", corners, "grey")
    (folder / "rooms.mtl").write_text(MTL)
    path = folder / f"{name}.obj"
    path.write_text("\n".join(lines) + "\n")
    return path


# --- light on back faces, rooms wound inside-out -----------------------------------------------

def test_right_room_and_cornell_box_have_no_back_face_note(tmp_path):
    for scene in (load(write_room(tmp_path, "ok")), load(radiosity.bundled_scene("cornell_box"))):
        assert not notes_with(scene, "back of faces") and not notes_with(scene, "inside-out")
    assert scene.light_paths["back"] == 0.0
    # The Cornell box's open front: the light's rays that miss everything (first bounce only).
    assert 0.1 < scene.light_paths["escaped"] < 0.3


def test_a_lamp_box_flush_with_the_ceiling_sends_no_light_out_of_a_closed_room(tmp_path):
    """A lamp modelled as a box, every face emitting, its top face on the ceiling: that face is
    hidden by the contact and emits nothing into the room, so none of the emitters' rays may
    escape the closed room (its rays used to cross the ceiling's plane: 48% "escaped")."""
    from helpers import axis_box, write_obj

    path = write_obj(tmp_path / "lamp.obj", {"room": axis_box((0, 0, 0), (4, 3, 2.5), inward=True),
                                            "lamp": axis_box((1.6, 1.1, 2.48), (2.4, 1.9, 2.5), inward=False)},
                     materials={"grey": ((0.5, 0.5, 0.5), (0, 0, 0)), "light": ((0.8, 0.8, 0.8), (10, 10, 10))},
                     object_material={"room": "grey", "lamp": "light"})
    scene = load(path)
    assert scene.patch_hidden.any()  # the lamp's top and the ceiling under it
    assert scene.light_paths["escaped"] == 0.0 and scene.light_paths["back"] == 0.0
    assert not notes_with(scene, "escape")


@pytest.mark.parametrize("variant", [dict(flip_room=True), dict(flip_room=True, flip_light=True),
                                     dict(flip_room=True, flip_light=True, light_in_ceiling=True, boxes=False)])
def test_room_wound_inside_out_is_named(tmp_path, variant):
    """Room inverted under a right light, room inverted with the light (it faces into the
    ceiling's back), and room and light inverted together in the ceiling plane (the light
    shines out of the room, whose inside its back side sees)."""
    scene = load(write_room(tmp_path, "inside_out", **variant))
    [note] = notes_with(scene, "inside-out")
    assert "reverse the winding" in note and str(tmp_path) in note
    assert ("escapes" in note) == bool(variant.get("light_in_ceiling"))


def test_share_on_a_flipped_wall_is_its_view_factor(tmp_path):
    """With one wall wound backwards, the share of the light landing on its back is the light's
    view factor to that wall (occlusion included), to the rays' statistical error."""
    right = load(write_room(tmp_path, "ok", boxes=True))
    F = radiosity.view_factors(right, preset="draft", cache=False)
    light = right.patch_object == right.objects.index("light")
    wall = right.patch_object == right.objects.index("back_wall")
    area = right.patch_area
    expected = float((area[light, None] * F[light][:, wall].toarray()).sum() / area[light].sum())
    flipped = load(write_room(tmp_path, "flipped", flip_wall="back_wall"))
    [note] = notes_with(flipped, "back of faces")
    assert "back_wall" in note and "inside-out" not in note
    share = flipped.light_paths["back_objects"]["back_wall"]
    sigma = np.sqrt(expected * (1 - expected) / N_RAYS)
    assert abs(share - expected) < 4 * sigma, (share, expected)


# --- materials ---------------------------------------------------------------------------------

def test_non_diffuse_materials_are_named_and_plain_exports_are_not(tmp_path):
    (tmp_path / "m.mtl").write_text(
        "newmtl mirror\nKa 0.01 0.01 0.01\nKd 0.01 0.01 0.01\nKs 0.95 0.95 0.95\nNs 1000\nillum 5\n"
        "newmtl glass\nKd 0.5 0.5 0.5\nNi 1.6\nTf 0.95 0.95 0.95\n"
        # diffuse, written the way McGuire's and 3ds Max's files write it
        "newmtl floor\nNs 10\nNi 1000\nillum 2\nKa 0 0 0\nKd 0.71 0.71 0.71\nKs 0 0 0\nTf 0 0 0\n"
        "newmtl max\nNs 10\nNi 1.5\nd 1\nTr 0\nTf 1 1 1\nillum 2\nKa 0.6 0.6 0.6\nKd 0.6 0.6 0.6\nKs 0 0 0\nKe 0 0 0\n"
        "newmtl lamp\nKd 0.78 0.78 0.78\nKa 17 12 4\n")
    faces = []
    for k, material in enumerate(["mirror", "glass", "floor", "max", "lamp"]):
        faces.append(f"usemtl {material}\nv {k} 0 0\nv {k + 1} 0 0\nv {k + 1} 1 0\nf -3 -2 -1")
    (tmp_path / "m.obj").write_text("mtllib m.mtl\n" + "\n".join(faces) + "\n")
    scene = load(tmp_path / "m.obj")
    [glossy] = notes_with(scene, "only diffuse reflection")
    assert "'mirror' (Kd 0.01 0.01 0.01; Ks 0.95 0.95 0.95, Ns 1000, illum 5)" in glossy
    assert "'glass'" in glossy and "Tf 0.95 0.95 0.95" in glossy
    assert "'floor'" not in glossy and "'max'" not in glossy and "'lamp'" not in glossy
    [ambient] = notes_with(scene, "have Ka but no Ke")
    assert "'lamp' (Ka 17 12 4)" in ambient and "'max'" not in ambient and "'mirror'" not in ambient
    assert notes_with(scene, "no face emits light")  # the Ka lamp indeed emits nothing


def test_diffuse_scene_has_no_material_note():
    scene = load(ROOM)
    assert not notes_with(scene, "only diffuse") and not notes_with(scene, "Ka but no Ke")


# --- groups named after their faces ------------------------------------------------------------

TRAILING = """mtllib t.mtl
# a room's walls name themselves first; the blocks' names come after their faces
v 0 0 0
v 2 0 0
v 2 0 -2
v 0 0 -2
g floor
usemtl white
f -4 -3 -2 -1
v 0 0 0
v 0 0 -2
v 0 2 -2
v 0 2 0
g leftWall
usemtl white
f -4 -3 -2 -1
usemtl grey
v 0.5 0.5 -0.5
v 1 0.5 -0.5
v 1 0.5 -1
v 0.5 0.5 -1
f -4 -3 -2 -1
f -4 -3 -2 -1
g shortBox
usemtl grey

usemtl grey
v 0.5 1.5 -0.5
v 1.5 1.5 -0.5
v 1.5 1.5 -1.5
f -3 -2 -1
g tallBox
usemtl grey
v 0.8 1.9 -0.8
v 0.8 1.9 -1.2
v 1.2 1.9 -1.2
v 1.2 1.9 -0.8
g light
usemtl light
f -4 -3 -2 -1
"""


def test_group_lines_after_their_faces_name_those_faces(tmp_path):
    (tmp_path / "t.mtl").write_text("newmtl white\nKd 0.7 0.7 0.7\nnewmtl grey\nKd 0.5 0.5 0.5\n"
                                    "newmtl light\nKd 0.5 0.5 0.5\nKe 1 1 1\n")
    (tmp_path / "t.obj").write_text(TRAILING)
    scene = load(tmp_path / "t.obj")
    area = {name: scene.patch_area[scene.patch_object == k].sum() for k, name in enumerate(scene.objects)}
    assert scene.objects == ["floor", "leftWall", "shortBox", "tallBox", "light"]
    # Read as written, leftWall would hold the short block's face and shortBox the tall one's.
    assert area["leftWall"] == pytest.approx(4.0)
    assert area["shortBox"] == pytest.approx(0.25)  # one of the two identical faces is dropped
    assert area["tallBox"] == pytest.approx(0.5)
    assert area["light"] == pytest.approx(0.16)
    [note] = notes_with(scene, "names groups after their faces")
    lines = TRAILING.splitlines()
    tall, short = lines.index("g tallBox") + 1, lines.index("g shortBox") + 1
    assert note.startswith(f"{tmp_path / 't.obj'}:{tall}: 'g tallBox' comes right after faces")
    assert f"'shortBox' (line {short}: 2 face(s)" in note and f"'tallBox' (line {tall}: 1 face(s)" in note


def test_groups_before_their_faces_are_unchanged(tmp_path):
    """All vertices first, then g + faces (every g right after the previous group's faces), and
    a bare g at the end: nothing is renamed."""
    verts = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\n"
    text = verts + "g a\nf 1 2 3\ng b\nf 1 3 4\ng c\nf 1 2 6 5\ng\n"
    (tmp_path / "lead.obj").write_text(text)
    scene = load(tmp_path / "lead.obj")
    assert scene.objects == ["a", "b", "c"]
    area = [scene.patch_area[scene.patch_object == k].sum() for k in range(3)]
    assert area == pytest.approx([0.5, 0.5, 1.0])
    assert not notes_with(scene, "after their faces")


def test_an_empty_object_between_others_names_nothing(tmp_path):
    """Blender-like: an object without faces (o Light) right after another's faces is not a
    trailing name: its name matches neither their material nor a usemtl after it."""
    (tmp_path / "b.mtl").write_text("newmtl Mat\nKd 0.5 0.5 0.5\nnewmtl Mat2\nKd 0.5 0.5 0.5\n")
    text = ("mtllib b.mtl\no Cube\nv 0 0 0\nv 1 0 0\nv 1 1 0\nusemtl Mat\ns off\nf 1 2 3\no Light\n"
            "o Sphere\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\nusemtl Mat2\nf 4 5 6 7\n")
    (tmp_path / "b.obj").write_text(text)
    scene = load(tmp_path / "b.obj")
    assert scene.objects == ["Cube", "Sphere"]
    assert [scene.patch_area[scene.patch_object == k].sum() for k in range(2)] == pytest.approx([0.5, 1.0])
    assert not notes_with(scene, "after their faces")


def test_an_object_name_on_two_o_lines_is_noted_and_a_reopened_group_is_not(tmp_path):
    """Two o lines of one name make one object (one mean): said, with both lines. A g name
    repeated is OBJ's way to add faces to a group: silent."""
    verts = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\n"
    (tmp_path / "o.obj").write_text(verts + "o Cube\nf 1 2 3\no Other\nf 1 3 4\no Cube\nf 1 2 6 5\n")
    scene = load(tmp_path / "o.obj")
    assert scene.objects == ["Cube", "Other"]
    [note] = notes_with(scene, "more than one 'o' line")
    assert note.startswith(f"{tmp_path / 'o.obj'}: object name(s) 'Cube' (lines 7 and 11)")
    (tmp_path / "g.obj").write_text(verts + "g Cube\nf 1 2 3\ng Other\nf 1 3 4\ng Cube\nf 1 2 6 5\n")
    assert not notes_with(load(tmp_path / "g.obj"), "more than one 'o' line")


@pytest.mark.parametrize("sunk, crossing", [(0.0, False), (0.002, False), (0.05, True)])
def test_a_box_sunk_into_the_floor_is_noted_and_one_standing_on_it_is_not(tmp_path, sunk, crossing):
    """Imprinting cuts along contacts only. A box 5 cm into a 4 x 3 x 2.5 m room's floor (9 contact
    tolerances) is not cut where it enters, and its floor neighbours read 2.3% low in a furnace
    room: noted, naming the faces. Standing on the floor, or 2 mm in (within the tolerance): no note."""
    from helpers import axis_box, write_obj

    room = axis_box((0, 0, 0), (4, 3, 2.5), inward=True)
    box = axis_box((1, 1, -sunk), (2, 2, 1), inward=False)
    scene = load(write_obj(tmp_path / "room.obj", {"room": room, "box": box}))
    notes = notes_with(scene, "pass through each other")
    assert bool(notes) == crossing
    if crossing:
        assert notes[0].startswith(f"{tmp_path / 'room.obj'}: faces of different objects pass through each other: line ")
        assert "(room) and line" in notes[0] and "(box)" in notes[0]


# --- duplicate faces ---------------------------------------------------------------------------

def test_duplicate_faces_are_dropped_and_opposite_ones_kept(tmp_path):
    text = ("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 1 1 0\n"
            "o a\nf 1 2 3 4\nf 2 3 4 1\n"  # the same face from another corner
            "o b\nf 1 2 5 4\n"  # same corners (vertex 5 is at vertex 3's place), same winding
            "o c\nf 4 3 2 1\n")  # opposite winding: a two-sided sheet, kept
    (tmp_path / "d.obj").write_text(text)
    scene = load(tmp_path / "d.obj")
    assert scene.patch_area.sum() == pytest.approx(2.0)  # a's face and c's
    dups = notes_with(scene, "duplicates face")
    assert len(dups) == 2
    assert dups[0].startswith(f"{tmp_path / 'd.obj'}:8: face 2 (a) duplicates face 1 (line 7, a)")
    assert "dropped" in dups[1] and "face 3 (b)" in dups[1]
    # b keeps its name but has no patch left: its mean is 0 (no area), never NaN
    assert scene.objects == ["a", "b", "c"] and not (scene.patch_object == 1).any()


def test_cornell_box_has_no_duplicates():
    scene = load(radiosity.bundled_scene("cornell_box"))
    assert not notes_with(scene, "duplicates face")


# --- how Ke was read ---------------------------------------------------------------------------

@pytest.mark.parametrize("mode", ["radiance", "exitance"])
def test_summary_says_how_ke_was_read(tmp_path, capsys, mode):
    out = tmp_path / "out"
    assert main(["solve", str(ROOM), "--preset", "draft", "--no-picture", "-o", str(out), "--emission", mode]) == 0
    stdout = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["emission"]["ke_read_as"] == mode
    assert f"Ke read as {mode}" in stdout
    rays = summary["emitter_rays"]
    assert rays["front"] + rays["back"] + rays["escaped"] == pytest.approx(1.0, abs=1e-3)
    assert f"of {N_RAYS} rays from the emitters: {100 * rays['front']:.0f}% on the front" in stdout
    # The lamp (Ke 10, 0.16 m^2): pi * 10 * 0.16 W as radiance, 10 * 0.16 W as exitance.
    emitted = summary["energy_W"]["emitted"][0]
    assert emitted == pytest.approx((np.pi if mode == "radiance" else 1.0) * 10 * 0.16)


# --- the camera --------------------------------------------------------------------------------

def test_parse_camera():
    cam = parse_camera("1,2,3", focal_default=(0, 0, 0))
    assert cam.position == (1, 2, 3) and cam.focal_point == (0, 0, 0) and cam.how == "--camera"
    cam = parse_camera("0,5,0:0,0,0:30")
    assert cam.up == (0.0, 0.0, 1.0) and cam.view_angle == 30  # looking straight down
    for bad in ("1,2", "1,2,3:4", "a,b,c", "1,2,3:1,2,3", "1,2,nan", "1,2,3:0,0,0:200", "1,2,3:0,0,0:40:1"):
        with pytest.raises(ValueError):
            parse_camera(bad)


class _Solved:
    """Enough of a Solution for choose_camera."""

    def __init__(self, scene):
        self.scene = scene


def _looks_at(cam):
    d = np.subtract(cam.focal_point, cam.position)
    return d / np.linalg.norm(d)


def test_camera_hint_still_wins_and_cornell_box_is_seen_through_its_open_front(tmp_path):
    scene = load(radiosity.bundled_scene("cornell_box"))
    cam = choose_camera(_Solved(scene))
    assert "# camera:" in cam.how and cam.position == (0.278, 0.273, -0.8)
    auto = auto_camera(_triangles(scene.patch_quads[~scene.patch_hidden])[0])
    assert "open side" in auto.how
    assert auto.position[2] < 0 and _looks_at(auto) @ [0, 0, 1] > 0.99  # from the front, along +z
    assert np.allclose(auto.position, (0.278, 0.274, -0.8), atol=0.05)  # about the published camera


def test_a_room_modelled_z_up_is_seen_upright_past_its_partition(tmp_path):
    """The furnished office (tests/helpers.office_scene) is modelled z-up, as thermal models
    often are: the camera stands z-up (it took y before, and looked at the room on its side),
    and the wall spot behind the partition, 0.7 m before it, gives way to one with a clear view."""
    from helpers import office_scene

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RadiosityWarning)
        scene = office_scene(tmp_path / "office.obj")
    cam = auto_camera(_triangles(scene.patch_quads[~scene.patch_hidden])[0])
    assert cam.how.startswith("inside the room") and cam.up == (0.0, 0.0, 1.0)
    assert 0 < cam.position[2] < 2.5 and cam.position[0] > 1.0  # east of the partition (x = 1)
    room = load(write_room(tmp_path, "y_up"))  # y-up rooms keep y
    assert auto_camera(_triangles(room.patch_quads)[0]).up == (0.0, 1.0, 0.0)


def test_closed_room_is_seen_from_inside_and_a_box_from_outside(tmp_path):
    room = load(write_room(tmp_path, "ok"))
    cam = auto_camera(_triangles(room.patch_quads)[0])
    assert cam.how.startswith("inside the room")
    assert all(0 < p < s for p, s in zip(cam.position, (4, 2.5, 3)))
    box = load(radiosity.bundled_scene("unit_cube"))
    normals = box.patch_normal
    outward = np.einsum("nc,nc->n", normals, box.patch_centroid - box.patch_centroid.mean(axis=0)) > 0
    expected_room = not outward.all()
    assert (auto_camera(_triangles(box.patch_quads)[0]) is not None) == expected_room


def test_terrain_under_a_lamp_is_seen_from_outside():
    """A ground of hills with a lamp above it: points under the lamp see mostly fronts (ground and
    lamp), but the light leaves them all round. It is no room: the exterior view (None), not a
    camera under the lamp looking straight down along its up vector (a black picture)."""
    g = np.linspace(0.0, 20.0, 21)
    x, z = np.meshgrid(g, g)
    y = 0.3 * np.sin(x / 3.0) * np.cos(z / 4.0)
    v = np.stack([x, y, z], axis=-1)
    a, b, c, d = v[:-1, :-1], v[1:, :-1], v[1:, 1:], v[:-1, 1:]  # wound to face +y
    ground = np.concatenate([np.stack([a, b, c], axis=-2).reshape(-1, 3, 3),
                             np.stack([a, c, d], axis=-2).reshape(-1, 3, 3)])
    lamp = np.array([[[8, 4, 8], [12, 4, 8], [12, 4, 12]], [[8, 4, 8], [12, 4, 12], [8, 4, 12]]], float)
    up = np.cross(ground[:, 1] - ground[:, 0], ground[:, 2] - ground[:, 0])[:, 1]
    assert (up > 0).all()
    assert auto_camera(np.concatenate([ground, lamp])) is None


def test_pictures_of_a_closed_room_show_its_inside(tmp_path, capsys):
    """From outside, a closed room's picture shows the back of its walls around a background;
    the automatic camera is inside, so walls fill the frame and the boxes are in view."""
    from PIL import Image

    scene = write_room(tmp_path, "ok")
    out = tmp_path / "out"
    assert main(["solve", str(scene), "--preset", "draft", "-o", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["camera"]["how"].startswith("inside the room")
    image = np.asarray(Image.open(out / "picture.png"))[..., :3]
    background = (image.max(axis=2) == 0).mean()
    assert background < 0.01  # the frame is all room
    # --camera sets it (here from a corner inside the room) and summary.json records it
    out2 = tmp_path / "out2"
    assert main(["solve", str(scene), "--preset", "draft", "-o", str(out2), "--camera", "3.5,2,2.5:0,0.5,0:60"]) == 0
    summary = json.loads((out2 / "summary.json").read_text())
    assert summary["camera"]["how"] == "--camera" and summary["camera"]["view_angle"] == 60
    # view reuses the recorded camera; --camera overrides it; a bad --camera is a usage error
    assert main(["view", str(out), "--screenshot", str(tmp_path / "v.png")]) == 0
    assert np.asarray(Image.open(tmp_path / "v.png")).max() > 0
    assert main(["view", str(out), "--screenshot", str(tmp_path / "v2.png"), "--camera", "1,1,1"]) == 0
    capsys.readouterr()
    assert main(["view", str(out), "--camera", "1,2"]) == 2
    assert "camera must be" in capsys.readouterr().err


def test_compiled_first_hits_match_numpy():
    """The compiled ray loop and the numpy reference find the same first hits and sides."""
    from radiosity._lightpaths import _first_hits_compiled, _first_hits_numpy

    rng = np.random.default_rng(3)
    triangles = rng.uniform(-1, 1, (60, 3, 3))
    origins = rng.uniform(-1.5, 1.5, (500, 3))
    directions = rng.normal(size=(500, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    hit, side = _first_hits_compiled(origins, directions, triangles, 1e-9)
    ref_hit, ref_side = _first_hits_numpy(origins, directions, triangles, 1e-9)
    assert (hit >= 0).sum() > 100 and np.array_equal(hit, ref_hit)
    found = hit >= 0
    assert np.array_equal(np.sign(side[found]), np.sign(ref_side[found]))


def test_duplicate_pairs_do_not_trust_the_hash(monkeypatch):
    """Duplicate faces are found by a hash of each corner cycle, then compared as rows: with
    every hash equal (all collide) the pairs are the same."""
    import radiosity._checks as checks

    rng = np.random.default_rng(5)
    vertices = rng.integers(0, 3, (30, 3)).astype(float)
    faces = [rng.choice(30, int(rng.integers(3, 6)), replace=False) for _ in range(200)]
    faces += [np.roll(faces[i], int(rng.integers(4))) for i in rng.integers(0, 200, 40)]  # rotated copies
    faces += [faces[i][::-1].copy() for i in rng.integers(0, 200, 10)]  # opposite windings: kept
    pairs = checks._duplicate_pairs(vertices, faces, 1e-9)
    monkeypatch.setattr(checks, "_HASH_A", np.uint64(0))
    monkeypatch.setattr(checks, "_HASH_B", np.uint64(0))
    assert checks._duplicate_pairs(vertices, faces, 1e-9) == pairs
    assert len(pairs) >= 40 and all(later > first for later, first in pairs)

"""OBJ/MTL reading: every broken file in tests/data gives its SceneError; messy files load.

Each ``tests/data/bad_*.obj`` starts with ``# expect: <message>``: the text its SceneError must
contain (the same text docs/errors.md quotes). A fuzz test mutates a valid OBJ and MTL and
checks that nothing but SceneError ever comes out, and never a NaN.
"""

from __future__ import annotations

import re
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import radiosity
from radiosity import RadiosityError, RadiosityWarning, SceneError
from radiosity.io.obj import read_mtl, read_obj

from helpers import DATA
BAD = sorted(DATA.glob("bad_*.obj"))


def expected_message(path: Path) -> str:
    if path.name == "bad_binary.obj":
        return "is not a text OBJ file (binary data)"
    first = path.read_text().splitlines()[0]
    match = re.match(r"# expect: (.*)", first)
    assert match, f"{path.name} must start with '# expect: <message>'"
    return match.group(1)


def load_quiet(path, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RadiosityWarning)
        return radiosity.load_scene(path, **kwargs)


def assert_finite(scene) -> None:
    for name in ("patch_quads", "reflectance", "emission", "patch_area", "patch_normal"):
        assert np.isfinite(getattr(scene, name)).all(), name


@pytest.mark.parametrize("path", BAD, ids=[p.stem for p in BAD])
def test_every_broken_file_gives_its_message(path):
    with pytest.raises(SceneError) as info:
        load_quiet(path)
    message = str(info.value)
    assert expected_message(path) in message
    assert "\n" not in message
    assert path.name in message or path.with_suffix(".mtl").name in message  # names the file


def test_messages_carry_the_line_number():
    with pytest.raises(SceneError, match=r"bad_face_index_range\.obj:10: face 2 uses vertex 9"):
        load_quiet(DATA / "bad_face_index_range.obj")
    with pytest.raises(SceneError, match=r"bad_mtl_kd_not_number\.mtl:2: Kd has a value"):
        load_quiet(DATA / "bad_mtl_kd_not_number.obj")
    # the missing MTL is reported at the mtllib line of the OBJ
    with pytest.raises(SceneError, match=r"bad_mtllib_missing\.obj:2: MTL file '.*no_such_file\.mtl' does not exist"):
        load_quiet(DATA / "bad_mtllib_missing.obj")
    # the unknown material at its (first) usemtl line
    with pytest.raises(SceneError, match=r"bad_unknown_material\.obj:3: unknown material 'chrome'"):
        load_quiet(DATA / "bad_unknown_material.obj")


def test_scene_error_is_a_value_error():
    assert issubclass(SceneError, ValueError) and issubclass(SceneError, RadiosityError)


def test_missing_and_unreadable_obj(tmp_path):
    with pytest.raises(SceneError, match=r"OBJ file '.*nothere\.obj' does not exist"):
        radiosity.load_scene(tmp_path / "nothere.obj")
    with pytest.raises(SceneError, match="is a folder, not a file"):
        radiosity.load_scene(tmp_path)
    (tmp_path / "empty.obj").write_text("")
    with pytest.raises(SceneError, match="the scene has no faces"):
        radiosity.load_scene(tmp_path / "empty.obj")


def test_mtllib_naming_a_folder_or_a_nul_byte(tmp_path):
    (tmp_path / "sub.mtl").mkdir()
    (tmp_path / "a.obj").write_text("mtllib sub.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(SceneError, match=r"a\.obj:1: MTL file .* is a folder"):
        read_obj(tmp_path / "a.obj")
    (tmp_path / "b.obj").write_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n" + b"x" * 9000 + b"\nmtllib a\xc0.mtl\n")
    with pytest.raises(SceneError, match="MTL file"):
        read_obj(tmp_path / "b.obj")


# --- messy but valid input ---------------------------------------------------------------

ROOM = (DATA / "room.obj").read_text()


def copy_room(tmp_path: Path, obj_text: str | bytes, name: str = "scene.obj") -> Path:
    shutil.copy(DATA / "room.mtl", tmp_path / "room.mtl")
    path = tmp_path / name
    if isinstance(obj_text, str):
        obj_text = obj_text.encode()
    path.write_bytes(obj_text)
    return path


def reference():
    return load_quiet(DATA / "room.obj")


def same_scene(a, b) -> None:
    assert a.objects == b.objects
    np.testing.assert_allclose(a.patch_quads, b.patch_quads)
    np.testing.assert_allclose(a.reflectance, b.reflectance)
    np.testing.assert_allclose(a.emission, b.emission)


@pytest.mark.parametrize("ending", ["\r\n", "\r"], ids=["windows", "classic-mac"])
def test_line_endings(tmp_path, ending):
    same_scene(load_quiet(copy_room(tmp_path, ROOM.replace("\n", ending))), reference())


def test_byte_order_mark_and_latin1(tmp_path):
    same_scene(load_quiet(copy_room(tmp_path, b"\xef\xbb\xbf" + ROOM.encode())), reference())
    latin = ROOM.replace("o floor", "o sol_\xe9t\xe9").encode("latin-1")
    with pytest.warns(RadiosityWarning, match="is not UTF-8 .*read as Latin-1"):
        scene = radiosity.load_scene(copy_room(tmp_path, latin))
    assert scene.objects[0] == "sol_\xe9t\xe9"


def test_line_continuation(tmp_path):
    text = ROOM.replace("f 1 2 3 4", "f 1 2 \\\n  3 4").replace("v 0.3 0.3 1", "v 0.3 \\\n0.3 \\\n1")
    same_scene(load_quiet(copy_room(tmp_path, text)), reference())
    # errors after a continuation report the line the statement starts on
    bad = ROOM.replace("f 1 2 3 4", "f 1 2 \\\n 3 99")
    with pytest.raises(SceneError, match=r"scene\.obj:9: face 1 uses vertex 99"):
        load_quiet(copy_room(tmp_path, bad))


def test_comment_ending_in_backslash_continues_nothing(tmp_path):
    text = "# exported from C:\\models\\\n" + ROOM.replace("o wall", "o wall # C:\\walls\\")
    same_scene(load_quiet(copy_room(tmp_path, text)), reference())


def test_texture_normal_and_negative_references(tmp_path):
    text = (ROOM.replace("f 1 2 3 4", "vt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3//1 4/1")
            .replace("f 9 10 11 12", "f -4 -3 -2 -1"))
    same_scene(load_quiet(copy_room(tmp_path, text)), reference())


def test_empty_groups_unused_materials_and_comments(tmp_path):
    text = "# header\ng empty_group\no empty_object\n" + ROOM.replace("o wall", "o wall # trailing comment\ns off")
    scene = load_quiet(copy_room(tmp_path, text))
    same_scene(scene, reference())
    assert "empty_group" not in scene.objects  # objects with no faces are dropped


def test_usemtl_before_mtllib(tmp_path):
    lines = ROOM.splitlines()
    lines.remove("mtllib room.mtl")
    same_scene(load_quiet(copy_room(tmp_path, "\n".join(lines) + "\nmtllib room.mtl\n")), reference())


def test_mtllib_with_two_files(tmp_path):
    shutil.copy(DATA / "room.mtl", tmp_path / "a.mtl")
    (tmp_path / "b.mtl").write_text("newmtl extra\nKd 0.1\n")
    text = ROOM.replace("mtllib room.mtl", "mtllib a.mtl b.mtl").replace("usemtl grey", "usemtl extra", 1)
    scene = load_quiet(copy_room(tmp_path, text))
    np.testing.assert_allclose(scene.reflectance[scene.patch_object == 0], 0.1)  # grey Kd: one number


def test_faces_without_material_and_ignored_elements(tmp_path):
    text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\nl 1 2\np 3\n" + ROOM
    with pytest.warns(RadiosityWarning) as caught:
        scene = radiosity.load_scene(copy_room(tmp_path, text))
    messages = [str(w.message) for w in caught]
    assert any("scene.obj:4: 1 face(s) come before any usemtl and have no material" in m for m in messages)
    assert any("1 'l' (line) element(s) ignored" in m for m in messages)
    assert scene.reflectance[scene.patch_face == 0].max() == 0


def test_repeated_vertices_and_extra_vertex_components(tmp_path):
    text = ROOM.replace("f 1 2 3 4", "f 1 2 2 3 4 4").replace("v 0 0 0", "v 0 0 0 1.0 0.5 0.5 0.5")
    same_scene(load_quiet(copy_room(tmp_path, text)), reference())


def test_read_mtl_grey_and_redefinition(tmp_path):
    (tmp_path / "m.mtl").write_text("newmtl a\nKd 0.2\nKe 3\nnewmtl a\nKd 0.4 0.5 0.6\n")
    materials = read_mtl(tmp_path / "m.mtl")
    assert materials["a"].kd == (0.4, 0.5, 0.6) and materials["a"].ke == (0.0, 0.0, 0.0)


def test_tiny_faces_with_coincident_vertices():
    scene = load_quiet(DATA / "tiny_coincident_vertices.obj")  # found by fuzzing: crashed imprinting
    assert_finite(scene)
    assert (scene.patch_area > 0).all()


def test_self_touching_faces_give_scene_error_or_load():
    try:
        scene = load_quiet(DATA / "self_touching_faces.obj")
    except RadiosityError:
        return
    assert_finite(scene)


# --- fuzzing -----------------------------------------------------------------------------

TOKENS = [b"v", b"f", b"o", b"g", b"usemtl", b"mtllib", b"newmtl", b"Kd", b"Ke", b"1", b"-1", b"0",
          b"nan", b"inf", b"1e400", b"1e300", b"-1e-300", b"/", b"//", b"1/2/3", b"\\", b"\n", b"#",
          b"room.mtl", b"lamp", b"grey", b"\x00", b"\xff", b"\r"]
ROOM_BYTES = (DATA / "room.obj").read_bytes()
MTL_BYTES = (DATA / "room.mtl").read_bytes()


@st.composite
def mutations(draw):
    """A sequence of (target, operation, position, argument) edits of the OBJ or MTL."""
    ops = []
    for _ in range(draw(st.integers(1, 6))):
        target = draw(st.sampled_from(["obj", "obj", "obj", "mtl"]))
        op = draw(st.sampled_from(["flip", "truncate", "insert", "swap", "drop_line", "dup_line"]))
        ops.append((target, op, draw(st.floats(0, 1)), draw(st.integers(0, 255)),
                    draw(st.sampled_from(TOKENS)), draw(st.floats(0, 1))))
    return ops


def mutate(data: bytes, op: str, where: float, byte: int, token: bytes, other: float) -> bytes:
    buf = bytearray(data)
    if not buf:
        return bytes([byte])
    k = min(int(where * len(buf)), len(buf) - 1)
    if op == "flip":
        buf[k] = byte
    elif op == "truncate":
        del buf[k:]
    elif op == "insert":
        buf[k:k] = b" " + token + b" "
    elif op == "swap":
        parts = bytes(buf).split(b" ")
        i, j = int(where * (len(parts) - 1)), int(other * (len(parts) - 1))
        parts[i], parts[j] = parts[j], parts[i]
        return b" ".join(parts)
    else:
        lines = bytes(buf).split(b"\n")
        i = int(where * (len(lines) - 1))
        if op == "drop_line":
            del lines[i]
        else:
            lines.insert(int(other * len(lines)), lines[i])
        return b"\n".join(lines)
    return bytes(buf)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(edits=mutations())
def test_fuzz_mutated_obj_and_mtl(tmp_path, edits):
    obj, mtl = ROOM_BYTES, MTL_BYTES
    for target, *edit in edits:
        if target == "obj":
            obj = mutate(obj, *edit)
        else:
            mtl = mutate(mtl, *edit)
    (tmp_path / "room.obj").write_bytes(obj)
    (tmp_path / "room.mtl").write_bytes(mtl)
    try:
        scene = load_quiet(tmp_path / "room.obj")
    except SceneError as exc:
        assert str(exc) and "\n" not in str(exc)
        return
    assert_finite(scene)
    assert (scene.reflectance >= 0).all() and (scene.reflectance < 1).all()
    assert (scene.emission >= 0).all()
    assert (scene.patch_area > 0).all()
    assert len(scene.objects) >= 1 and scene.patch_object.max() < len(scene.objects)

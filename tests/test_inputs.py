"""Every input is bounded (issue 19): regular files only, a stated size limit, one grammar."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import radiosity
from radiosity import SceneError
from radiosity.io._text import ENV_MAX_INPUT, excerpt, parse_float, split_lines
from helpers import PLATES

TRIANGLE = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
VS3_SQUARES = PLATES.split("O 3")[0] + "E\n"  # the two plates without their blocker


def test_a_fifo_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "scene.obj"
    os.mkfifo(fifo)
    outcome = {}

    def load():
        try:
            radiosity.load_scene(fifo)
        except SceneError as exc:
            outcome["error"] = str(exc)

    worker = threading.Thread(target=load, daemon=True)
    worker.start()
    worker.join(timeout=20)
    assert not worker.is_alive(), "reading a FIFO blocked"
    assert "FIFO" in outcome["error"] and "scene.obj" in outcome["error"]


def test_mtllib_naming_a_device_is_refused(tmp_path):
    obj = tmp_path / "a.obj"
    obj.write_text("mtllib /dev/zero\n" + TRIANGLE)
    with pytest.raises(SceneError, match=r"a\.obj:1: .*character device"):
        radiosity.load_scene(obj)


def test_files_above_the_input_limit_are_refused_with_the_limit(tmp_path, monkeypatch):
    obj = tmp_path / "big.obj"
    obj.write_text(TRIANGLE + "# padding\n" * 200)
    monkeypatch.setenv(ENV_MAX_INPUT, "1000")
    with pytest.raises(SceneError, match=r"above the input limit of 1,000 bytes .*RADIOSITY_MAX_INPUT_BYTES"):
        radiosity.load_scene(obj)
    vs3 = tmp_path / "big.vs3"
    vs3.write_text(VS3_SQUARES + "! padding\n" * 200)
    with pytest.raises(SceneError, match="above the input limit"):
        radiosity.load_scene(vs3)


def test_a_byte_order_mark_is_accepted_in_obj_and_vs3(tmp_path):
    plain = tmp_path / "plain.vs3"
    plain.write_text(VS3_SQUARES)
    bom = tmp_path / "bom.vs3"
    bom.write_bytes(b"\xef\xbb\xbf" + VS3_SQUARES.encode())
    a, b = radiosity.load_scene(plain), radiosity.load_scene(bom)
    np.testing.assert_array_equal(a.patch_area, b.patch_area)
    obj = tmp_path / "bom.obj"
    obj.write_bytes(b"\xef\xbb\xbf" + TRIANGLE.encode())
    assert radiosity.load_scene(obj).n_patches == 1


def test_a_lone_cr_ends_a_line(tmp_path):
    """A lone CR among LF lines used to merge two lines silently."""
    obj = tmp_path / "cr.obj"
    obj.write_bytes(b"v 0 0 0\nv 1 0 0\rv 0 1 0\nf 1 2 3\n")
    scene = radiosity.load_scene(obj)
    assert scene.n_patches == 1
    np.testing.assert_allclose(scene.patch_area.sum(), 0.5)
    assert split_lines("a\r\nb\rc\nd") == ["a", "b", "c", "d"]
    assert split_lines("a\x0cb\u2028c\n") == ["a\x0cb\u2028c"]  # not line ends in these formats


@pytest.mark.parametrize("token", ["1_0", "\u0661\u0660", "0x10", "1e", "--1", "", " 1", "1,5", "\uff11"])
def test_numbers_follow_one_ascii_grammar(token):
    with pytest.raises(ValueError):
        parse_float(token)


@pytest.mark.parametrize("token, value", [("-1", -1.0), (".5", 0.5), ("2.", 2.0), ("1e-3", 1e-3),
                                          ("+4E+2", 400.0), ("inf", np.inf), ("-Infinity", -np.inf)])
def test_decimal_numbers_parse(token, value):
    assert parse_float(token) == value


@settings(max_examples=200, deadline=None)
@given(st.floats(allow_nan=False))
def test_every_float_repr_round_trips(x):
    assert parse_float(repr(x)) == x


def test_underscores_and_foreign_digits_are_refused_with_their_line(tmp_path):
    obj = tmp_path / "a.obj"
    obj.write_text("v 0 0 0\nv 1_0 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(SceneError, match=r"a\.obj:2: .*not a number"):
        radiosity.load_scene(obj)
    obj.write_text("v 0 0 0\nv \u0661 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(SceneError, match=r"a\.obj:2: .*not a number"):
        radiosity.load_scene(obj)
    vs3 = tmp_path / "a.vs3"
    vs3.write_text(VS3_SQUARES.replace("V 2 1 0 0", "V 2 1_0 0 0"))
    with pytest.raises(SceneError, match=r"a\.vs3:6: .*must be a number"):
        radiosity.load_scene(vs3)
    vs3.write_text(VS3_SQUARES.replace("V 2 1 0 0", "V \u0662 1 0 0"))
    with pytest.raises(SceneError, match=r"a\.vs3:6: .*must be a number"):
        radiosity.load_scene(vs3)


def test_a_vs3_coordinate_that_would_overflow_is_refused(tmp_path):
    """A .vs3 vertex at 1e200 gave an OverflowError traceback."""
    vs3 = tmp_path / "a.vs3"
    vs3.write_text(VS3_SQUARES.replace("V 7 1 1 1", "V 7 1e200 1 1"))
    with pytest.raises(SceneError, match=r"a\.vs3:11: a coordinate is beyond"):
        radiosity.load_scene(vs3)


def test_messages_quote_a_short_excerpt(tmp_path):
    obj = tmp_path / "long.obj"
    obj.write_text("v 0 0 0\nv 1 0 " + "x" * 500_000 + "\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(SceneError) as info:
        radiosity.load_scene(obj)
    assert len(str(info.value)) < 400 and "characters)" in str(info.value)
    assert excerpt("short") == "short"


def test_an_emission_that_would_overflow_is_refused_with_its_line(tmp_path):
    """Ke 1e300 put NaN residuals in summary.json; from about 1e38 solution.ply held inf."""
    (tmp_path / "a.mtl").write_text("newmtl lamp\nKd 0.5 0.5 0.5\nKe 1e300 1 1\n")
    obj = tmp_path / "a.obj"
    obj.write_text("mtllib a.mtl\nusemtl lamp\n" + TRIANGLE)
    with pytest.raises(SceneError, match=r"a\.mtl:3: Ke is beyond 1e\+30"):
        radiosity.load_scene(obj)


def test_points_files_follow_the_same_rules(tmp_path):
    from radiosity.cli._solve import read_points

    bom = tmp_path / "bom.txt"
    bom.write_bytes(b"\xef\xbb\xbf0 0 0 0 0 1\r0.5 0.5 0 0 0 1\n")  # BOM, and a lone CR between lines
    np.testing.assert_array_equal(read_points(bom)[:, 0], [0.0, 0.5])
    bad = tmp_path / "bad.txt"
    bad.write_text("0 0 0 0 0 1\n1_0 0 0 0 0 1\n")
    with pytest.raises(SceneError, match=r"bad\.txt:2: expected 6 numbers"):
        read_points(bad)
    fifo = tmp_path / "fifo.txt"
    os.mkfifo(fifo)
    with pytest.raises(SceneError, match="FIFO"):
        read_points(fifo)
    with pytest.raises(SceneError, match="character device"):
        read_points(Path("/dev/zero"))

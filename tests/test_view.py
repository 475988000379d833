"""``radiosity view`` without a display: one line and exit 2, or an off-screen screenshot; no VTK noise."""

from __future__ import annotations

import numpy as np
import pytest

from radiosity.cli import main

from helpers import ROOM


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    out = tmp_path_factory.mktemp("view") / "out"
    assert main(["solve", str(ROOM), "--preset", "draft", "--no-picture", "-o", str(out)]) == 0
    return out


@pytest.fixture
def no_display(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr("sys.platform", "linux")


def test_no_display_is_one_line_and_exit_2(solved, no_display, capfd):
    capfd.readouterr()
    assert main(["view", str(solved)]) == 2
    captured = capfd.readouterr()
    lines = captured.err.strip().splitlines()
    assert lines == [lines[0]] and lines[0].startswith("radiosity: error: no display")
    assert "--screenshot" in lines[0] and captured.out == ""


def test_screenshot_without_display_is_quiet_and_not_blank(solved, no_display, tmp_path, capfd):
    from PIL import Image

    capfd.readouterr()
    target = tmp_path / "shot.png"
    assert main(["view", str(solved), "--screenshot", str(target)]) == 0
    captured = capfd.readouterr()
    assert captured.err == "", captured.err
    pixels = np.asarray(Image.open(target).convert("RGB")).astype(int)
    assert pixels.std() > 5  # a lit scene, not a flat background

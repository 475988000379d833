"""Command-line conventions: --version, help for every option, internal errors, --units everywhere."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import numpy as np
import pytest

import radiosity
from radiosity.cli import build_parser, main

from helpers import DATA, ROOM


def test_version_matches_the_package_metadata(capsys):
    from importlib.metadata import version

    assert radiosity.__version__ == version("radiosity")
    assert re.fullmatch(r"\d+\.\d+(\.\d+)?.*", radiosity.__version__)
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"radiosity {radiosity.__version__}"


def _subparsers(parser: argparse.ArgumentParser):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            yield from action.choices.items()


def test_every_option_has_help():
    parser = build_parser()
    parsers = [("radiosity", parser), *_subparsers(parser)]
    for name, sub in list(parsers):
        parsers += [(f"{name} {n}", p) for n, p in _subparsers(sub) if sub is not parser]
    for name, sub in parsers:
        for action in sub._actions:
            if isinstance(action, argparse._SubParsersAction):
                continue
            assert action.help and action.help is not argparse.SUPPRESS, (name, action.option_strings or action.dest)


def test_help_is_for_users(capsys):
    assert main(["--help"]) == 0
    top = capsys.readouterr().out
    assert "main(argv)" not in top and "``" not in top
    assert "exit status" in top.lower()
    assert main(["solve", "--help"]) == 0
    text = capsys.readouterr().out
    assert "--solver" in text and "bicgstab and" not in text
    assert "direct sparse LU" in " ".join(text.split())


def test_internal_error_is_exit_1_and_says_how_to_report(tmp_path, capsys, monkeypatch):
    from radiosity.cli import _solve

    def bug(*args, **kwargs):
        raise KeyError("patch_frobnication")

    monkeypatch.setattr(_solve, "solve", bug)
    argv = ["solve", str(ROOM), "--preset", "draft", "--no-picture", "-o", str(tmp_path / "out")]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.startswith("radiosity: internal error: KeyError: 'patch_frobnication'")
    assert "please report it" in err and "--debug" in err and "Traceback" not in err
    with pytest.raises(KeyError):
        main(["--debug", *argv])


def test_bad_input_stays_exit_2(tmp_path, capsys):
    code = main(["solve", str(DATA / "bad_no_faces.obj"), "-o", str(tmp_path / "out")])
    assert code == 2
    assert capsys.readouterr().err.startswith("radiosity: error: ")


def _room_in_millimetres(tmp_path: Path) -> Path:
    (tmp_path / "room.mtl").write_text((DATA / "room.mtl").read_text())
    lines = []
    for line in ROOM.read_text().splitlines():
        if line.startswith("v "):
            line = "v " + " ".join(f"{1000 * float(t):g}" for t in line.split()[1:])
        lines.append(line)
    scene = tmp_path / "mm.obj"
    scene.write_text("\n".join(lines) + "\n")
    return scene


def test_units_apply_to_the_points_file(tmp_path, capsys):
    """The same sensors in metres (metre scene) and in millimetres (--units mm) read the same."""
    sensors = np.array([[0.5, 0.5, 0.01, 0, 0, 1], [0.5, 0.9, 0.5, 0, -1, 0], [0.2, 0.3, 0.02, 0, 0, 1]])
    (tmp_path / "m.txt").write_text("\n".join(" ".join(f"{v:g}" for v in row) for row in sensors) + "\n")
    mm = sensors.copy()
    mm[:, :3] *= 1000
    (tmp_path / "mm.txt").write_text("\n".join(" ".join(f"{v:g}" for v in row) for row in mm) + "\n")
    base = ["--preset", "draft", "--no-picture", "--no-cache"]
    assert main(["solve", str(ROOM), *base, "-o", str(tmp_path / "a"), "--points", str(tmp_path / "m.txt")]) == 0
    assert main(["solve", str(_room_in_millimetres(tmp_path)), *base, "--units", "mm", "-o", str(tmp_path / "b"),
                 "--points", str(tmp_path / "mm.txt")]) == 0
    capsys.readouterr()
    a = np.loadtxt(tmp_path / "a" / "irradiance.csv", delimiter=",", skiprows=1)
    b = np.loadtxt(tmp_path / "b" / "irradiance.csv", delimiter=",", skiprows=1)
    assert np.allclose(b[:, :3], mm[:, :3])  # written back in the units they were given in
    assert (a[:, 6:] > 0).all()
    np.testing.assert_allclose(b[:, 6:], a[:, 6:], rtol=1e-6)
    assert "x,y,z (mm)" in (tmp_path / "b" / "irradiance.csv").read_text().splitlines()[0]

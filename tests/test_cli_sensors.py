"""``radiosity solve --points FILE [--sensor-rtol RTOL]``: the file is checked before the solve."""

from __future__ import annotations

import numpy as np
import pytest

from radiosity.cli import _solve, build_parser, main

from helpers import assert_one_line_error, solve_args


def never(*args, **kwargs):
    raise AssertionError("solved before the points file was checked")


@pytest.mark.parametrize("line, part", [
    ("0.5 0.5 0.5 0 0 0", "points.txt:2: the normal (nx ny nz) is zero"),
    ("1e300 0.5 0.5 0 0 1", "points.txt:2: a coordinate exceeds"),
    ("0.5 0.5 0.5 0 0 inf", "points.txt:2: expected 6 finite numbers"),
])
def test_bad_points_fail_before_the_solve(tmp_path, capsys, monkeypatch, line, part):
    points = tmp_path / "points.txt"
    points.write_text(f"0.5 0.5 0.01 0 0 1\n{line}\n")
    monkeypatch.setattr(_solve, "solve", never)
    assert_one_line_error(capsys, main(solve_args(tmp_path / "out", "--points", str(points))), part)


def test_tiny_and_huge_normals_give_the_unit_normal_values(tmp_path, capsys):
    points = tmp_path / "points.txt"
    points.write_text("0.5 0.5 0.01 0 0 1\n0.5 0.5 0.01 0 0 1e-320\n0.5 0.5 0.01 0 0 1e300\n"
                      "0.5 0.5 0.01 1e-300 0 1e-300\n0.5 0.5 0.01 1 0 1\n")
    out = tmp_path / "out"
    assert main(solve_args(out, "--points", str(points), "--sensor-rtol", "0")) == 0
    table = np.loadtxt(out / "irradiance.csv", delimiter=",", skiprows=1)
    assert (table[0, 6:] > 0).all()
    np.testing.assert_array_equal(table[1, 6:], table[0, 6:])
    np.testing.assert_array_equal(table[2, 6:], table[0, 6:])
    np.testing.assert_array_equal(table[3, 6:], table[4, 6:])


@pytest.mark.parametrize("value", ["-0.1", "1", "nan", "x"])
def test_bad_sensor_rtol_is_one_line(tmp_path, capsys, value):
    code = main(solve_args(tmp_path / "out", f"--sensor-rtol={value}"))
    assert_one_line_error(capsys, code, "--sensor-rtol")


def test_help_names_sensor_rtol():
    text = build_parser()._subparsers._group_actions[0].choices["solve"].format_help()
    assert "--sensor-rtol" in text and "every shadow exact" in text

"""``radiosity exchange`` in process: conditions files (TOML, JSON), outputs, one-line errors."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

import radiosity
from radiosity.cli import main
from radiosity.exchange import STEFAN_BOLTZMANN as SIGMA

from helpers import assert_one_line_error, square_at, write_obj

CUBE = radiosity.bundled_scene("unit_cube")

TOML = """
[default]
emissivity = 1.0
temperature = 300.0

[objects.top]
temperature = 600.0

[objects.bottom]
emissivity = 0.5
heat_flux = 0.0
"""


def read_rows(path):
    with open(path, newline="") as fh:
        return {row["object"]: row for row in csv.DictReader(fh)}


def test_exchange_writes_table_csv_and_vtp(tmp_path, capsys):
    conditions = tmp_path / "conditions.toml"
    conditions.write_text(TOML)
    out = tmp_path / "out"
    assert main(["exchange", str(CUBE), "--conditions", str(conditions), "-o", str(out)]) == 0
    stdout = capsys.readouterr().out
    assert "energy balance" in stdout and "top" in stdout
    rows = read_rows(out / "exchange.csv")
    assert list(rows) == ["bottom", "top", "left", "right", "front", "back"]
    assert rows["bottom"]["prescribed"] == "q" and float(rows["bottom"]["net_power_W"]) == 0.0
    assert rows["top"]["prescribed"] == "T" and float(rows["top"]["emissivity"]) == 1.0
    assert float(rows["bottom"]["emissivity"]) == 0.5
    assert sum(float(r["net_power_W"]) for r in rows.values()) == pytest.approx(0.0, abs=1e-6)
    # the adiabatic bottom re-radiates: the top face loses less than to a black cold bottom
    assert 0 < float(rows["top"]["net_power_W"]) < SIGMA * (600.0**4 - 300.0**4)
    import pyvista as pv

    mesh = pv.read(out / "exchange.vtp")
    assert mesh.n_cells == 6 and mesh.active_scalars_name == "net_flux"
    np.testing.assert_allclose(mesh.cell_data["net_flux"].sum(), 0.0, atol=1e-6)
    assert (out / "exchange_patches.csv").read_text().count("\n") == 7


def test_json_conditions_and_ambient_for_an_open_scene(tmp_path, capsys):
    obj = write_obj(tmp_path / "roof.obj", {"roof": [square_at(0.0, facing_down=False)]})
    conditions = tmp_path / "c.json"
    conditions.write_text(json.dumps({"ambient": 230.0, "objects": {"roof": {"emissivity": 0.9, "temperature": 310}}}))
    assert main(["exchange", obj, "--conditions", str(conditions), "-o", str(tmp_path / "out")]) == 0
    rows = read_rows(tmp_path / "out" / "exchange.csv")
    assert float(rows["roof"]["net_flux_W_m2"]) == pytest.approx(0.9 * SIGMA * (310.0**4 - 230.0**4), rel=1e-9)
    assert float(rows["(ambient)"]["net_power_W"]) == pytest.approx(-float(rows["roof"]["net_power_W"]), rel=1e-9)
    # without the ambient the open scene is refused, and the message says what to give
    conditions.write_text(json.dumps({"objects": {"roof": {"emissivity": 0.9, "temperature": 310}}}))
    code = main(["exchange", obj, "--conditions", str(conditions), "-o", str(tmp_path / "out2")])
    message = assert_one_line_error(capsys, code, "open", "ambient")
    assert "roof.obj" in message and "c.json" not in message  # the scene's fault, not the conditions'
    # --ambient on the command line does it too
    assert main(["exchange", obj, "--conditions", str(conditions), "--ambient", "230",
                 "-o", str(tmp_path / "out3")]) == 0


def test_view_factors_from_a_file(tmp_path, capsys):
    conditions = tmp_path / "c.toml"
    conditions.write_text(TOML)
    F = tmp_path / "F.npz"
    assert main(["viewfactors", str(CUBE), "-o", str(F)]) == 0
    assert main(["exchange", str(CUBE), "--conditions", str(conditions), "--view-factors", str(F),
                 "-o", str(tmp_path / "out")]) == 0
    assert "energy balance" in capsys.readouterr().out


@pytest.mark.parametrize("text, parts", [
    ("[objects.roof]\nemissivity = 0.5\ntemperature = 300\n", ["c.toml", "unknown object", "'roof'"]),
    ("[objects.top]\nemisivity = 0.5\n", ["c.toml", "objects.top", "'emisivity'"]),
    ("[default]\nemissivity = 0.5\n", ["c.toml", "no temperature or heat_flux", "'bottom'"]),
    ("[default]\nemissivity = 2.0\ntemperature = 300\n", ["c.toml", "emissivity", "(0, 1]"]),
    ("[default]\nemissivity = 'high'\ntemperature = 300\n", ["c.toml", "default.emissivity", "number"]),
    ("temperature = 300\n", ["c.toml", "unknown key", "'temperature'"]),
    ("[default\n", ["c.toml", "not valid TOML"]),
])
def test_bad_conditions_files_are_one_line_errors(tmp_path, capsys, text, parts):
    conditions = tmp_path / "c.toml"
    conditions.write_text(text)
    code = main(["exchange", str(CUBE), "--conditions", str(conditions), "-o", str(tmp_path / "out")])
    assert_one_line_error(capsys, code, *parts)
    assert not (tmp_path / "out").exists()  # nothing half-written


def test_missing_or_unknown_conditions_file(tmp_path, capsys):
    code = main(["exchange", str(CUBE), "--conditions", str(tmp_path / "none.toml"), "-o", str(tmp_path / "o")])
    assert_one_line_error(capsys, code, "none.toml", "does not exist")
    other = tmp_path / "c.yaml"
    other.write_text("x: 1\n")
    code = main(["exchange", str(CUBE), "--conditions", str(other), "-o", str(tmp_path / "o")])
    assert_one_line_error(capsys, code, "c.yaml", ".toml or .json")


def test_bad_ambient_on_the_command_line(tmp_path, capsys):
    conditions = tmp_path / "c.toml"
    conditions.write_text(TOML)
    code = main(["exchange", str(CUBE), "--conditions", str(conditions), "--ambient", "-5", "-o", str(tmp_path / "o")])
    assert_one_line_error(capsys, code, "--ambient", "temperature in K")

"""``radiosity exchange``: grey-body radiative exchange from a conditions file (TOML or JSON).

The conditions file gives each object an emissivity and either a temperature (K) or a net heat
flux (W/m^2, leaving); an optional ``[default]`` table covers objects not listed, and an
optional top-level ``ambient`` (K) is the sky or surroundings of an open scene::

    ambient = 293.15
    [default]
    emissivity = 0.9
    temperature = 300.0
    [objects.heater]
    emissivity = 0.8
    heat_flux = 500.0
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import tomllib
import warnings
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from .._errors import SceneError
from ..exchange import OpenSceneError, exchange
from ..io.export import atomic_path, staged_outputs
from ..scene import bundled_scene, load_scene
from ._common import add_scene_args

NAME = "exchange"
HELP = "grey-body radiative exchange: net heat flux and temperature per object (net radiation method)"

TOP_KEYS = ("ambient", "default", "objects")
OBJECT_KEYS = ("emissivity", "temperature", "heat_flux")
CSV_COLUMNS = ("object", "area_m2", "emissivity", "temperature_K", "net_power_W", "net_flux_W_m2", "prescribed")


def kelvin(text: str) -> float:
    """argparse type: a finite temperature >= 0 K."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"must be a temperature in K (>= 0), got {text!r}")
    return value


def add_args(parser) -> None:
    add_scene_args(parser, optional_scene=False)
    parser.add_argument("--conditions", type=Path, required=True, metavar="FILE",
                        help="TOML or JSON file: emissivity and temperature or heat_flux per object")
    parser.add_argument("--ambient", type=kelvin, default=None, metavar="K",
                        help="ambient (sky) temperature for an open scene, overriding the file's")
    parser.add_argument("--view-factors", type=Path, default=None, metavar="F.npz",
                        help="use this matrix (from 'radiosity viewfactors') instead of computing it")
    parser.add_argument("-o", "--output", type=Path, default=Path("radiosity-out"), metavar="OUTDIR",
                        help="output folder for exchange.csv, exchange_patches.csv, exchange.vtp "
                             "(default: %(default)s)")


# --- the conditions file --------------------------------------------------------------------

def _parse(path: Path) -> dict:
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise SceneError(f"conditions file '{path}' does not exist") from None
    except OSError as exc:
        raise SceneError(f"cannot read conditions file '{path}': {exc.strerror or exc}") from None
    suffix = path.suffix.lower()
    try:
        if suffix == ".toml":
            return tomllib.loads(data.decode("utf-8"))
        if suffix == ".json":
            doc = json.loads(data.decode("utf-8"))
            if not isinstance(doc, dict):
                raise SceneError(f"{path}: expected a JSON object at the top, got {type(doc).__name__}")
            return doc
    except (tomllib.TOMLDecodeError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise SceneError(f"{path}: not valid {suffix[1:].upper()}: {exc}") from None
    raise SceneError(f"conditions file '{path}' must end in .toml or .json")


def _number(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SceneError(f"{where} must be a finite number, got {value!r}")
    return float(value)


def _entry(table, where: str) -> dict[str, float]:
    if not isinstance(table, dict):
        raise SceneError(f"{where} must be a table of {', '.join(OBJECT_KEYS)}, got {table!r}")
    unknown = sorted(set(table) - set(OBJECT_KEYS))
    if unknown:
        raise SceneError(f"{where}: unknown key(s) {', '.join(map(repr, unknown))}; valid: {', '.join(OBJECT_KEYS)}")
    return {key: _number(value, f"{where}.{key}") for key, value in table.items()}


def read_conditions(path: Path, objects: list[str]) -> dict:
    """Keyword arguments of :func:`radiosity.exchange` from a conditions file.

    An object's own ``temperature`` or ``heat_flux`` replaces the default's condition (both of
    them); its emissivity is taken from the default if it gives none.
    """
    doc = _parse(path)
    unknown = sorted(set(doc) - set(TOP_KEYS))
    if unknown:
        raise SceneError(f"{path}: unknown key(s) {', '.join(map(repr, unknown))}; valid: {', '.join(TOP_KEYS)}")
    default = _entry(doc.get("default", {}), f"{path}: default")
    tables = doc.get("objects", {})
    if not isinstance(tables, dict):
        raise SceneError(f"{path}: objects must be a table of object names, got {tables!r}")
    entries = {name: _entry(table, f"{path}: objects.{name}") for name, table in tables.items()}
    missing = [name for name in entries if name not in objects]
    if missing:
        raise SceneError(f"{path}: unknown object(s) {', '.join(map(repr, missing))}; "
                         f"the scene's objects: {', '.join(objects)}")
    kwargs = {"emissivity": {}, "temperature": {}, "heat_flux": {}}
    for name in objects:
        own = entries.get(name, {})
        condition = {k: v for k, v in own.items() if k != "emissivity"}
        if not condition:
            condition = {k: v for k, v in default.items() if k != "emissivity"}
        emissivity = own.get("emissivity", default.get("emissivity"))
        if emissivity is not None:
            kwargs["emissivity"][name] = emissivity
        for key, value in condition.items():
            kwargs[key][name] = value
    if "ambient" in doc:
        kwargs["ambient"] = _number(doc["ambient"], f"{path}: ambient")
    return kwargs


# --- outputs --------------------------------------------------------------------------------

def object_rows(ex) -> list[tuple]:
    """One row per object (CSV_COLUMNS), then the ambient's if there is one."""
    area = ex.scene.patch_area
    power, flux, temp, emis = ex.object_net_power(), ex.object_net_flux(), ex.object_temperature(), ex.object_emissivity()
    rows = []
    for index, name in enumerate(ex.scene.objects):
        mask = (ex.scene.patch_object == index) & ex.active
        given = "+".join(sorted(set(ex.prescribed[mask]))) if mask.any() else "-"
        rows.append((name, float(area[ex.scene.patch_object == index].sum()), emis[name], temp[name], power[name],
                     flux[name], given))
    if ex.ambient is not None:
        rows.append(("(ambient)", "", 1.0, ex.ambient, ex.ambient_net_power, "", "T"))
    return rows


def format_table(ex) -> str:
    lines = [f"{'object':<18}{'area m2':>11}{'emissivity':>11}{'T K':>10}{'net W':>14}{'net W/m2':>13}  given"]
    for name, area, emis, temp, power, flux, given in object_rows(ex):
        area_text = f"{area:>11.5g}" if area != "" else " " * 11
        flux_text = f"{flux:>13.6g}" if flux != "" else " " * 13
        lines.append(f"{name:<18}{area_text}{emis:>11.4g}{temp:>10.2f}{power:>14.6g}{flux_text}  {given}")
    e = ex.energy_balance()
    lines.append(f"energy balance: surfaces {e['surfaces_W']:.6g} W + ambient {e['ambient_W']:.6g} W = "
                 f"{e['residual_W']:.2g} W (relative {e['relative']:.1e})")
    return "\n".join(lines)


def _write_csv(path: Path, header, rows) -> None:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    writer.writerows([[f"{v:.10g}" if isinstance(v, float) else v for v in row] for row in rows])
    with atomic_path(path) as tmp:
        tmp.write_text(buffer.getvalue())


def _patch_rows(ex) -> list[tuple]:
    s = ex.scene
    return [(i, s.objects[s.patch_object[i]], float(s.patch_area[i]), float(ex.emissivity[i]),
             float(ex.temperature[i]), float(ex.net_flux[i]), float(ex.radiosity[i]), ex.prescribed[i])
            for i in range(s.n_patches)]


def write_vtp(ex, path: Path) -> None:
    """The patches as VTK PolyData, cells and points coloured by net flux (also T and J)."""
    from ..solution import Solution
    from ..viz import to_polydata

    fields = ("net_flux", "temperature", "radiosity")
    packed = np.column_stack([ex.net_flux, ex.temperature, ex.radiosity])
    # to_polydata welds the patches' vertices and averages a 3-column field onto them.
    mesh = to_polydata(Solution(scene=ex.scene, radiosity=packed, F=sp.csr_matrix(ex.F.shape)))
    cell, point = mesh.cell_data["radiosity"].copy(), mesh.point_data["radiosity"].copy()
    del mesh.cell_data["radiosity"], mesh.point_data["radiosity"]
    for k, name in enumerate(fields):
        mesh.cell_data[name] = cell[:, k]
        mesh.point_data[name] = point[:, k]
    mesh.cell_data["emissivity"] = ex.emissivity
    mesh.set_active_scalars("net_flux", preference="cell")
    with atomic_path(path) as tmp:
        mesh.save(str(tmp))


def _load(args):
    path = args.scene if args.scene is not None else bundled_scene("cornell_box")
    options = {"allow_clamp": args.allow_clamp}
    if args.units is not None:
        options["units"] = args.units
    # The conditions and the matrix must share the patches: cut once, at load time.
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*no face emits light")  # light is not the point here
        return load_scene(path, max_patch_size=args.max_patch_size, emission=args.emission, **options)


def _read_matrix(path: Path):
    try:
        return sp.load_npz(path)
    except FileNotFoundError:
        raise SceneError(f"view-factor file '{path}' does not exist") from None
    except (OSError, ValueError, KeyError) as exc:
        raise SceneError(f"{path}: not a view-factor .npz ({exc})") from None


def run(args) -> int:
    scene = _load(args)
    kwargs = read_conditions(args.conditions, scene.objects)
    if args.ambient is not None:
        kwargs["ambient"] = args.ambient
    with staged_outputs(args.output) as stage:
        if args.view_factors is not None:
            kwargs["view_factors"] = _read_matrix(args.view_factors)
        else:
            kwargs.update(preset=args.preset, cache=not args.no_cache)
        try:
            ex = exchange(scene, **kwargs)
        except OpenSceneError as exc:  # the scene's or the matrix's, not the conditions'
            raise SceneError(f"{args.view_factors or args.scene}: {exc}") from exc
        except ValueError as exc:  # name the file the bad condition came from
            raise SceneError(f"{args.conditions}: {exc}") from exc
        print(format_table(ex))
        _write_csv(stage / "exchange.csv", CSV_COLUMNS, object_rows(ex))
        _write_csv(stage / "exchange_patches.csv", ("patch", "object", "area_m2", "emissivity", "temperature_K",
                                                    "net_flux_W_m2", "radiosity_W_m2", "prescribed"), _patch_rows(ex))
        write_vtp(ex, stage / "exchange.vtp")
    print(f"wrote {args.output / 'exchange.csv'}, exchange_patches.csv, exchange.vtp")
    return 0

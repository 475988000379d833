"""``radiosity solve``: solve a scene, print a summary, write picture, meshes and summary.json."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from .._errors import SceneError
from ..io.export import atomic_path, staged_outputs, write_ply, write_png, write_summary, write_vtp
from ..io.obj import MAX_COORDINATE
from ..solve import solve
from ._common import add_scene_args, load, overrides

SENSOR_RTOL = 1e-3  # default bound on a sensor value's relative error from shadows

NAME = "solve"
HELP = "solve a scene's radiosity and write a picture, meshes and summary.json"
SHOWS_NOTES = True  # the summary lists the scene's notes; main need not repeat them


def add_args(parser) -> None:
    add_scene_args(parser, optional_scene=True)
    parser.add_argument("-o", "--output", type=Path, default=Path("radiosity-out"), metavar="OUTDIR",
                        help="output folder (default: %(default)s)")
    parser.add_argument("--solver", default="auto",
                        choices=("auto", "direct", "bicgstab", "gmres", "jacobi", "gauss-seidel", "progressive"))
    parser.add_argument("--no-picture", action="store_true", help="skip the PNG")
    parser.add_argument("--points", type=Path, default=None, metavar="FILE",
                        help="text file of receiver points 'x y z nx ny nz' per line; writes irradiance.csv")
    parser.add_argument("--sensor-rtol", type=sensor_rtol, default=SENSOR_RTOL, metavar="RTOL",
                        help="bound on the relative error of each --points value due to shadows "
                             "(0: every shadow exact; default: %(default)g)")


def sensor_rtol(text: str) -> float:
    """argparse type of ``--sensor-rtol``: a finite number in [0, 1)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0.0 <= value < 1.0:
        raise argparse.ArgumentTypeError(f"must be in [0, 1), got {text!r}")
    return value


def format_summary(solution, load_seconds: float) -> str:
    s = solution.summary()
    lines = [f"scene      {s['source']}",
             f"patches    {s['patches']}   view factors {s['nonzeros']:,}   rays {s['rays'] or 0:,}"
             + ("   (form factors from cache)" if s["cache_hit"] else "")]
    times = {"load": load_seconds, **s["timings_s"]}
    lines.append("time (s)   " + "   ".join(f"{k} {v:.2f}" for k, v in times.items()))
    sol = s["solver"]
    lines.append(f"solver     {sol['method']}, iterations {sol['iterations']}, residual {max(sol['residual']):.1e}")
    e = s["energy_W"]
    em, ab, es = (np.array(e[k]) for k in ("emitted", "absorbed", "escaped"))
    lines.append("energy (W) emitted " + fmt3(em) + "  absorbed " + fmt3(ab) + "  escaped " + fmt3(es))
    lines.append(f"{'object':<16}{'radiosity R':>12}{'G':>10}{'B':>10}   W/m^2")
    for name, (r, g, b) in s["objects"].items():
        lines.append(f"{name:<16}{r:>12.4f}{g:>10.4f}{b:>10.4f}")
    for note in s["notes"]:
        lines.append(f"note: {note}")
    return "\n".join(lines)


def fmt3(v) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"


def read_points(path: Path) -> np.ndarray:
    """Receiver points and normals (m, 6) from a text file, one 'x y z nx ny nz' per line."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise SceneError(f"points file '{path}' does not exist") from None
    except OSError as exc:
        raise SceneError(f"cannot read points file '{path}': {exc.strerror or exc}") from None
    rows = []
    for number, line in enumerate(data.decode("utf-8", errors="replace").splitlines(), start=1):
        text = line.split("#", 1)[0].strip().replace(",", " ")
        if not text:
            continue
        try:
            values = [float(t) for t in text.split()]
        except ValueError:
            raise SceneError(f"{path}:{number}: expected 6 numbers 'x y z nx ny nz', got {line!r}") from None
        if len(values) != 6 or not np.isfinite(values).all():
            raise SceneError(f"{path}:{number}: expected 6 finite numbers 'x y z nx ny nz', got {line!r}")
        rows.append(_checked_point(path, number, values))
    if not rows:
        raise SceneError(f"{path}: no points (expected lines of 'x y z nx ny nz')")
    return np.asarray(rows)


def _checked_point(path: Path, number: int, values: list[float]) -> list[float]:
    """One receiver 'x y z nx ny nz' with its normal made unit, or a SceneError naming the line.

    The normal is scaled by its largest component before it is normalised, so tiny (1e-320) and
    huge (1e300) normals keep their direction instead of underflowing or overflowing.
    """
    point, normal = np.array(values[:3]), np.array(values[3:])
    if np.abs(point).max() > MAX_COORDINATE:
        raise SceneError(f"{path}:{number}: a coordinate exceeds {MAX_COORDINATE:g} in absolute value")
    largest = np.abs(normal).max()
    if largest == 0.0:
        raise SceneError(f"{path}:{number}: the normal (nx ny nz) is zero")
    normal = normal / largest
    normal /= np.linalg.norm(normal)
    return [*point.tolist(), *normal.tolist()]


def run(args) -> int:
    t0 = time.perf_counter()
    scene = load(args)
    points = read_points(args.points) if args.points else None
    load_seconds = time.perf_counter() - t0
    out = args.output
    written = ["solution.vtp", "solution.ply"] + ([] if args.no_picture else ["picture.png"])
    written += (["irradiance.csv"] if points is not None else []) + ["summary.json"]
    # Everything goes to a staging folder first and is moved into OUTDIR only when all of it is
    # written: a failed or interrupted run leaves an earlier run's outputs as they were.
    with staged_outputs(out) as stage:
        solution = solve(scene, preset=args.preset, solver=args.solver, progress=sys.stderr.isatty(),
                         **overrides(args))
        h = None
        if points is not None:
            h = solution.irradiance(points[:, :3], points[:, 3:], rtol=args.sensor_rtol)
        summary = solution.summary()
        write_vtp(solution, stage / "solution.vtp")
        write_ply(solution, stage / "solution.ply")
        if not args.no_picture:
            summary["exposure"] = write_png(solution, stage / "picture.png")
        if h is not None:
            with atomic_path(stage / "irradiance.csv") as tmp:
                np.savetxt(tmp, np.column_stack([points, h]), delimiter=",", fmt="%.9g",
                           header="x,y,z,nx,ny,nz,H_r,H_g,H_b (W/m^2)", comments="")
        write_summary(summary, stage / "summary.json")
    print(format_summary(solution, load_seconds))
    print(f"wrote      {out}/: {' '.join(written)}")
    return 0

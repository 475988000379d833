"""``radiosity solve``: solve a scene, print a summary, write picture, meshes and summary.json."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from .._errors import SceneError
from .._kernels import FIRST_RUN_MESSAGE, compile_timer, kernels_on_disk, warm_up
from ..io.export import (atomic_path, check_free_space, output_bytes, staged_outputs, write_glb, write_ply,
                         write_png, write_summary, write_vtp)
from ..io.html import write_html
from ..io._text import decode, excerpt, parse_float, read_input, split_lines
from ..io.obj import MAX_COORDINATE
from ..solve import solve
from ..methods.uniform.system import DIRECT_MAX
from ..viz import auto_exposure, white_balanced
from ._common import (add_camera_arg, add_scene_args, fraction_or_zero, load, overrides, positive_fraction,
                      positive_metres, unit_scale)
from ._record import run_record

SENSOR_RTOL = 1e-3  # default bound on a sensor value's relative error from shadows

NAME = "solve"
HELP = "solve a scene's radiosity and write a picture, meshes and summary.json"
SHOWS_NOTES = True  # the summary lists the scene's notes; main need not repeat them


def add_args(parser) -> None:
    add_scene_args(parser, optional_scene=True)
    parser.add_argument("-o", "--output", type=Path, default=Path("radiosity-out"), metavar="OUTDIR",
                        help="output folder (default: %(default)s)")
    parser.add_argument("--solver", default="auto",
                        choices=("auto", "direct", "bicgstab", "gmres", "jacobi", "gauss-seidel", "progressive"),
                        help="linear solver for (I - rho F) B = E: auto takes a direct sparse LU up to "
                             f"{DIRECT_MAX:,} patches and bicgstab beyond; jacobi, gauss-seidel and "
                             "progressive (shooting) are there to compare (default: %(default)s)")
    parser.add_argument("--method", choices=("auto", "uniform", "hierarchical"), default="auto",
                        help="uniform: fill the view-factor matrix of the cut patches; hierarchical: refine "
                             "element quadtrees and links only where the light needs them, for large or finely "
                             "cut scenes (docs/hierarchical.md); auto: hierarchical when the uniform fill would "
                             "pair too many patches (minutes, gigabytes), else uniform (default: %(default)s)")
    parser.add_argument("--link-tolerance", type=positive_fraction, default=None, metavar="TOL",
                        help="hierarchical: refine a link while its radiosity error bound exceeds TOL times the "
                             "scene's mean emitted exitance (default: the preset's)")
    parser.add_argument("--leaf-tolerance", type=fraction_or_zero, default=None, metavar="TOL",
                        help="hierarchical: split an element while what its links together push onto the leaves "
                             "below strays past TOL times the scene's mean emitted exitance; 0: off (default: the "
                             "preset's)")
    parser.add_argument("--min-element-size", type=positive_metres, default=None, metavar="METRES",
                        help="hierarchical: smallest element edge (default: the preset's share of the scene size)")
    parser.add_argument("--no-picture", action="store_true", help="skip the PNG")
    add_camera_arg(parser)
    parser.add_argument("--white-balance", choices=("none", "light"), default="none",
                        help="picture.png only: 'none' shows the light's own colour (the bundled box's measured "
                             "light is yellowish, Ke 17 12 4), 'light' scales the channels so the light looks "
                             "white, as a camera would (default: %(default)s; the files keep physical values)")
    parser.add_argument("--html", action="store_true",
                        help="also write solution.html, a self-contained interactive page (orbit, values on "
                             "hover, colour bar) that opens offline in any browser")
    parser.add_argument("--points", type=Path, default=None, metavar="FILE",
                        help="text file of receiver points 'x y z nx ny nz' per line, in the scene's "
                             "--units; writes irradiance.csv")
    parser.add_argument("--sensor-rtol", type=sensor_rtol, default=SENSOR_RTOL, metavar="RTOL",
                        help="bound on the relative error of each --points value due to shadows "
                             "(0: every shadow exact; default: %(default)g)")


def _method_options(args) -> dict:
    """The solve options of ``--method`` and the hierarchical knobs given."""
    out = {"method": args.method}
    if args.link_tolerance is not None:
        out["link_tolerance"] = args.link_tolerance
    if args.leaf_tolerance is not None:
        out["leaf_tolerance"] = args.leaf_tolerance
    if args.min_element_size is not None:
        out["min_element_size"] = args.min_element_size
    return out


def sensor_rtol(text: str) -> float:
    """argparse type of ``--sensor-rtol``: a finite number in [0, 1)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0.0 <= value < 1.0:
        raise argparse.ArgumentTypeError(f"must be in [0, 1), got {text!r}")
    return value


def format_summary(solution, load_seconds: float, compile_seconds: float = 0.0) -> str:
    s = solution.summary()
    lines = [f"scene      {s['source']}",
             f"patches    {s['patches']}   view factors {s['nonzeros']:,}   rays {s['rays'] or 0:,}"
             + ("   (form factors from cache)" if s["cache_hit"] else "")]
    times = {"load": load_seconds, **s["timings_s"]}
    lines.append("time (s)   " + "   ".join(f"{k} {v:.2f}" for k, v in times.items())
                 + (f"   (and compiling kernels {compile_seconds:.1f}, first run only)" if compile_seconds >= 0.5 else ""))
    storage = s.get("view_factors") or {}
    if storage.get("where") == "out of core":  # F did not fit the budget: say how it was solved
        lines.append(f"matrix     out of core: F needs up to {storage['estimate_in_memory']}, budget "
                     f"{storage['budget']}; {storage['shards']} shards of {storage['pairs_per_block']:,} pairs, "
                     f"{storage['passes']} passes over them")
    if s.get("hierarchy"):
        h = s["hierarchy"]
        lines.append(f"hierarchy  {h['roots']} input patches -> {h['leaves']:,} leaves (level {h['max_level']}), "
                     f"{h['links']:,} links ({h['partly_visible_links']:,} partly visible), {h['rounds']} rounds"
                     + ("" if h["converged"] else " (stopped at the cap: not converged)"))
    sol = s["solver"]
    fallback = sorted({f for f in sol.get("fallback", []) if f})
    lines.append(f"solver     {sol['method']}, iterations {sol['iterations']}, residual {max(sol['residual']):.1e}"
                 + (f"   (stopped at its cap: solved with {', '.join(fallback)})" if fallback else ""))
    e = s["energy_W"]
    em, ab, es = (np.array(e[k]) for k in ("emitted", "absorbed", "escaped"))
    lines.append("emission   " + _emission_line(s["emission"]["ke_read_as"]))
    lines.append("energy (W) emitted " + fmt3(em) + "  absorbed " + fmt3(ab) + "  escaped " + fmt3(es))
    gaining = s.get("energy_gaining") or []
    bounded = s.get("rows_bounded") or 0
    # name the rows of F above 1 where they matter: "escaped" negative, or (bounded) gaining more
    # than the fill's tolerance; the bundled box's 1 + 7e-5 rows are not news
    if ((es < 0).any() or s.get("gain_beyond_tolerance")) and gaining:
        lines.append("gaining    " + ", ".join(f"{g['object']} patch {g['patch']} (row sum 1{g['share'] - 1:+.1e})"
                                              for g in gaining[:5])
                     + (f"; {bounded:,} rows scaled down to 1 before the solve" if bounded else ""))
    rays = s.get("emitter_rays")
    if rays:
        # "escaped" above mixes openings and back faces; the emitters' rays tell them apart.
        lines.append(f"first hit  of {rays['rays']} rays from the emitters: {100 * rays['front']:.0f}% on the front "
                     f"of faces, {100 * rays['back']:.0f}% on the back (lost), {100 * rays['escaped']:.0f}% escape")
    lines.append(f"{'object':<16}{'radiosity R':>12}{'G':>10}{'B':>10}   W/m^2")
    for name, (r, g, b) in s["objects"].items():
        lines.append(f"{name:<16}{r:>12.4f}{g:>10.4f}{b:>10.4f}")
    for note in s["notes"]:
        lines.append(f"note: {note}")
    return "\n".join(lines)


def _emission_line(mode: str) -> str:
    if mode == "exitance":
        return "Ke read as exitance: E = Ke W/m^2 (--emission radiance reads it as radiance, E = pi Ke)"
    return "Ke read as radiance in W/(m^2 sr): E = pi Ke (--emission exitance reads it as E)"


def fmt3(v) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"


def read_points(path: Path) -> np.ndarray:
    """Receiver points and normals (m, 6) from a text file, one 'x y z nx ny nz' per line."""
    try:
        data = read_input(path, "points")  # regular files only, below the input limit
    except FileNotFoundError:
        raise SceneError(f"points file '{path}' does not exist") from None
    except OSError as exc:
        raise SceneError(f"cannot read points file '{path}': {exc.strerror or exc}") from None
    rows = []
    for number, line in enumerate(split_lines(decode(data)), start=1):  # BOM dropped, lone CR ends a line
        text = line.split("#", 1)[0].strip().replace(",", " ")
        if not text:
            continue
        try:
            values = [parse_float(t) for t in text.split()]
        except ValueError:
            raise SceneError(f"{path}:{number}: expected 6 numbers 'x y z nx ny nz', got {excerpt(line)!r}") from None
        if len(values) != 6 or not np.isfinite(values).all():
            raise SceneError(f"{path}:{number}: expected 6 finite numbers 'x y z nx ny nz', got {excerpt(line)!r}")
        rows.append(_checked_point(path, number, values))
    if not rows:
        raise SceneError(f"{path}: no points (expected lines of 'x y z nx ny nz')")
    return np.asarray(rows)


def _interactive() -> bool:
    return sys.stderr.isatty()


def _write_picture(solution, path: Path, exposure: float, white_balance: str, camera=None) -> dict | None:
    """picture.png, white-balanced to the light if asked; returns what the balance did, or None."""
    if white_balance == "none":
        write_png(solution, path, exposure=exposure, camera=camera)
        return None
    shown, gains = white_balanced(solution)
    picture_exposure = auto_exposure(shown)
    write_png(shown, path, exposure=picture_exposure, camera=camera)
    return {"mode": white_balance, "gains_rgb": [float(g) for g in gains], "picture_exposure": picture_exposure,
            "applies_to": "picture.png only"}


# Every file a solve may write: those of an earlier run that this run does not write are removed.
OUTPUT_NAMES = ("solution.vtp", "solution.ply", "solution.glb", "solution.html", "picture.png", "irradiance.csv",
                "summary.json")


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
    to_metres = unit_scale(args)  # the points are in the scene's coordinates, like the OBJ
    load_seconds = time.perf_counter() - t0
    out = args.output
    written = ["solution.vtp", "solution.ply", "solution.glb"] + (["solution.html"] if args.html else [])
    written += [] if args.no_picture else ["picture.png"]
    written += (["irradiance.csv"] if points is not None else []) + ["summary.json"]
    # Everything goes to a staging folder first and is moved into OUTDIR only when all of it is
    # written: a failed or interrupted run leaves an earlier run's outputs as they were.
    with staged_outputs(out, owned=OUTPUT_NAMES) as stage, compile_timer() as compiled:
        if not kernels_on_disk():
            if _interactive():  # like the progress bar: for a person at a terminal, not for logs
                print(FIRST_RUN_MESSAGE, file=sys.stderr, flush=True)
            warm_up()
        solution = solve(scene, preset=args.preset, solver=args.solver, progress=sys.stderr.isatty(),
                         **overrides(args), **_method_options(args))
        check_free_space(out, output_bytes(solution.scene.n_patches, 0 if points is None else len(points)))
        h = None
        if points is not None:
            h = solution.irradiance(points[:, :3] * to_metres, points[:, 3:], sensor_rtol=args.sensor_rtol)
        summary = solution.summary()
        write_vtp(solution, stage / "solution.vtp")
        write_ply(solution, stage / "solution.ply")
        exposure = auto_exposure(solution)
        write_glb(solution, stage / "solution.glb", exposure=exposure)
        if args.html:
            write_html(solution, stage / "solution.html", exposure=exposure)
        balance = None
        if not args.no_picture:
            from ..viz import choose_camera

            camera = choose_camera(solution, args.camera)
            summary["camera"] = camera.as_dict() if camera is not None else {"how": "outside (isometric view)"}
            balance = _write_picture(solution, stage / "picture.png", exposure, args.white_balance, camera)
        if h is not None:
            with atomic_path(stage / "irradiance.csv") as tmp:
                np.savetxt(tmp, np.column_stack([points, h]), delimiter=",", fmt="%.9g",
                           header=f"x,y,z ({args.units or 'm'}),nx,ny,nz,H_r,H_g,H_b (W/m^2)", comments="")
        summary.update(run_record(args, solution, exposure=exposure, load_seconds=load_seconds,
                                  compile_seconds=compiled.seconds, outputs=written))
        if balance is not None:
            summary["white_balance"] = balance
        write_summary(summary, stage / "summary.json")
    print(format_summary(solution, load_seconds, compiled.seconds))
    print(f"wrote      {out}/: {' '.join(written)}")
    return 0

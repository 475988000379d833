"""Arguments shared by subcommands, and loading the scene they name."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from ..scene import UNITS, bundled_scene, load_scene


def positive_metres(text: str) -> float:
    """argparse type: a positive, finite number of metres."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a positive number of metres, got {text!r}")
    return value


def positive_fraction(text: str) -> float:
    """argparse type of tolerances (``--link-tolerance``): a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return value


def fraction_or_zero(text: str) -> float:
    """argparse type of ``--leaf-tolerance``: a finite number >= 0 (0: off)."""
    try:
        if float(text) == 0.0:
            return 0.0
    except ValueError:
        pass
    return positive_fraction(text)


def add_scene_args(parser: argparse.ArgumentParser, *, optional_scene: bool) -> None:
    nargs = "?" if optional_scene else None
    parser.add_argument("scene", nargs=nargs, type=Path,
                        help="OBJ file (with its MTL) or View3D .vs3 model"
                        + ("; default: the bundled Cornell box" if optional_scene else ""))
    parser.add_argument("--preset", choices=("draft", "default", "fine"), default="default",
                        help="speed/accuracy trade (default: %(default)s)")
    parser.add_argument("--max-patch-size", type=positive_metres, default=None, metavar="METRES",
                        help="longest patch edge, overriding the preset")
    parser.add_argument("--units", choices=tuple(UNITS), default=None,
                        help="units of the scene's coordinates, for the OBJ and the points file alike "
                             "(default: metres, with a note if the scene is more than 50 m across)")
    parser.add_argument("--emission", choices=("radiance", "exitance"), default="radiance",
                        help="read Ke as radiance (E = pi Ke) or as exitance")
    parser.add_argument("--allow-clamp", action="store_true", help="clamp reflectances >= 1 instead of refusing")
    parser.add_argument("--no-cache", action="store_true", help="do not read or write the form-factor cache")
    parser.add_argument("--no-imprint", action="store_true",
                        help="do not cut faces along the outlines of other objects touching them (contacts "
                             "then get no sharp light/dark edge and covered parts are not hidden)")


def add_camera_arg(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--camera", default=None, metavar="X,Y,Z[:TX,TY,TZ[:ANGLE]]", type=camera_text,
                        help="picture camera position (metres), optional target (default: the scene's centre) "
                             "and vertical view angle (degrees, default 50); default: the OBJ's '# camera:' "
                             "line, else inside the room (through its open side if it has one), else outside")


def camera_text(text: str) -> str:
    """argparse type: a camera the pictures can use (checked now, applied later)."""
    from ..viz import parse_camera

    try:
        parse_camera(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def load(args):
    path = args.scene if args.scene is not None else bundled_scene("cornell_box")
    options = {"allow_clamp": args.allow_clamp}
    if getattr(args, "no_imprint", False):
        options["imprint"] = False
    if args.units is not None:
        options["units"] = args.units
    # One door for the patch size: the scene is cut as it is loaded (as in Python, where
    # load_scene(max_patch_size=...) is the documented way); solve then keeps those patches.
    return load_scene(path, max_patch_size=args.max_patch_size, emission=args.emission, **options)


def unit_scale(args) -> float:
    """Metres per unit of the scene's coordinates (``--units``); every input in scene
    coordinates (the OBJ, the points file) is scaled by it."""
    return UNITS[args.units or "m"]


def overrides(args) -> dict:
    """Options of ``solve``/``view_factors`` from the flags (the patch size went to ``load``)."""
    return {"cache": not args.no_cache}

"""What ``summary.json`` records beyond the solution: enough to reproduce and to read the run."""

from __future__ import annotations

import math
import platform
import sys
from dataclasses import asdict
from pathlib import Path

TONE_MAP = ("picture.png and the colours of solution.ply, .glb and .html show the radiance L = B/pi of "
            "each channel times 'exposure', clipped to [0, 1] and encoded as 8-bit sRGB (IEC 61966-2-1). "
            "'exposure' (1/(W m^-2 sr^-1)) puts the 98th percentile of the luminance "
            "(0.2126 R + 0.7152 G + 0.0722 B) of the non-emitting patches at 0.85 of white, so the "
            "light itself saturates; the radiosity values in the files are not tone-mapped.")


def _jsonable(value):
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, float) and not math.isfinite(value):  # JSON has no inf or NaN
        return str(value)
    return value


def command_options(args) -> dict:
    """Every command-line option of the run, as given or defaulted (not the internals)."""
    skip = {"run", "shows_notes", "command"}
    return {k: _jsonable(v) for k, v in sorted(vars(args).items()) if k not in skip}


def _command_line() -> list[str] | None:
    """The command line when the process is the ``radiosity`` command (script or ``-m``), else None."""
    if not sys.argv:
        return None
    script = Path(sys.argv[0])
    if script.name == "radiosity" or (script.name == "__main__.py" and script.parent.name == "radiosity"):
        return ["radiosity", *sys.argv[1:]]
    return None


def run_record(args, solution, *, exposure: float, load_seconds: float, compile_seconds: float,
               outputs: list[str]) -> dict:
    """The reproducibility block of ``summary.json``: version, preset, options, units, emission,
    tone map, timings and compile time."""
    from .. import __version__

    from ..options import DEPRECATED_OPTIONS

    options = asdict(solution.options) if solution.options is not None else {}
    if options:  # the old names too, for readers of earlier summaries (docs/options.md)
        options.update({old: options[new] for old, new in DEPRECATED_OPTIONS.items()})
    return {
        "version": __version__,
        "python": platform.python_version(),
        "command": _command_line(),
        "preset": args.preset,
        "options": command_options(args),
        "solver_options": {k: _jsonable(v) for k, v in options.items()},
        "units": args.units or "m",
        "emission_mode": args.emission,
        "exposure": exposure,
        "tone_map": TONE_MAP,
        "load_s": round(load_seconds, 4),
        "compile_s": round(compile_seconds, 4),
        "compile_note": "numba compile time, kept out of timings_s; non-zero on the first run after an install",
        "outputs": outputs,
    }

"""The ``radiosity`` command: solve, view, viewfactors. ``main(argv)`` returns the exit code.

Bad input (a ``RadiosityError`` or ``ValueError``) ends with one line on stderr and exit
status 2; ``--debug`` shows the traceback instead. Anything else is a bug and shows its
traceback.
"""

from __future__ import annotations

import argparse
import sys
import warnings

from .._errors import RadiosityError, RadiosityWarning
from . import _solve, _view, _viewfactors

__all__ = ["main"]

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="radiosity", description=__doc__.splitlines()[0])
    parser.add_argument("--debug", action="store_true", help="show tracebacks for bad input")
    sub = parser.add_subparsers(dest="command", required=True)
    for module in (_solve, _view, _viewfactors):
        p = sub.add_parser(module.NAME, help=module.HELP, description=module.HELP)
        p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                       help="show tracebacks for bad input")
        module.add_args(p)
        p.set_defaults(run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore", RadiosityWarning)  # the summary lists them as notes
    try:
        return int(args.run(args))
    except (RadiosityError, ValueError, MemoryError, OSError) as exc:
        if args.debug:
            raise
        message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"radiosity: error: {message}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("radiosity: interrupted; outputs and cache left as they were", file=sys.stderr)
        return EXIT_INTERRUPTED

"""The ``radiosity`` command: solve, view, viewfactors, exchange, cache. ``main(argv)`` returns the exit code.

Bad input (a ``RadiosityError``, ``ValueError`` or ``OSError``, a request too big for the
machine, a bad command line) ends with exactly one line on stderr, ``radiosity: error: ...``,
and exit status 2; ``--debug`` shows the traceback instead. Ctrl-C ends with one line and
exit status 130 (SIGTERM: 143), also during the imports (``radiosity._startup``); outputs are written through a staging folder and the cache atomically, so
neither is left half-written. Anything else is a bug: ``radiosity: internal error: ...`` with
how to report it, exit status 1 (``--debug`` shows the traceback).

Scene notes (``RadiosityWarning``: a non-planar face split, no emitter, ...) are printed by
``solve`` in its summary; other commands print them on stderr as ``radiosity: note: ...``.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings

from .._errors import MemoryBudgetError, RadiosityError, RadiosityWarning
from .._startup import INTERRUPTED_LINE, PROG, catching_signals, exit_status, guard_imports, signal_received

with guard_imports():
    from . import _cache, _exchange, _solve, _view, _viewfactors

__all__ = ["main", "entry"]

EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_BAD_INPUT = 2
DESCRIPTION = ("Diffuse radiosity and exact view factors on polygon meshes. Exit status: 0 success, "
               "1 internal error, 2 bad input, 130 interrupted (143 on SIGTERM).")
REPORT_HINT = ("this is a bug in radiosity, not in your input; please report it with the command line, "
               "the output of 'radiosity --version' and the traceback that --debug prints")

_OUT_OF_MEMORY_HINT = ("use a coarser preset (--preset draft) or a larger --max-patch-size; "
                       "RADIOSITY_MEMORY_BUDGET (bytes) makes the check before allocation stricter")


class UsageError(Exception):
    """A bad command line (unknown option, missing argument, bad value)."""


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line, handled by ``main`` like any bad input."""

    def error(self, message: str):  # noqa: D102 - argparse hook
        raise UsageError(f"{message} (see '{self.prog} --help')")


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = _Parser(prog=PROG, description=DESCRIPTION)
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}",
                        help="print the version and exit")
    parser.add_argument("--debug", action="store_true", help="show tracebacks for bad input and internal errors")
    sub = parser.add_subparsers(dest="command", required=True)
    for module in (_solve, _view, _viewfactors, _exchange, _cache):
        p = sub.add_parser(module.NAME, help=module.HELP, description=module.HELP)
        p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                       help="show tracebacks for bad input and internal errors")
        module.add_args(p)
        p.set_defaults(run=module.run, shows_notes=getattr(module, "SHOWS_NOTES", False))
    return parser


def _one_line(exc: BaseException) -> str:
    """The first line of an exception's message; OSErrors as 'file: reason'."""
    if isinstance(exc, OSError) and exc.strerror:
        where = exc.filename if exc.filename is not None else ""
        text = f"{where}: {exc.strerror}" if where else exc.strerror
    else:
        text = str(exc)
    lines = [line for line in text.splitlines() if line.strip()]
    return lines[0].strip() if lines else type(exc).__name__


def _error(message: str) -> int:
    print(f"{PROG}: error: {message}", file=sys.stderr)
    return EXIT_BAD_INPUT


def _internal_error(exc: BaseException) -> int:
    print(f"{PROG}: internal error: {type(exc).__name__}: {_one_line(exc)}", file=sys.stderr)
    print(f"{PROG}: {REPORT_HINT}", file=sys.stderr)
    return EXIT_INTERNAL


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status (0 ok, 1 internal error, 2 bad input, 130 Ctrl-C,
    143 SIGTERM)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except UsageError as exc:
        return _error(str(exc))
    except SystemExit as exc:  # --help, --version
        return exc.code if isinstance(exc.code, int) else EXIT_OK
    caught: list[warnings.WarningMessage] = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", RadiosityWarning)
            code = int(args.run(args))
    except KeyboardInterrupt as exc:
        return _interrupted(exc)
    except SystemError as exc:
        # Ctrl-C inside a compiled kernel surfaces as "<function> returned a result with an
        # exception set", the KeyboardInterrupt as its cause.
        if not _is_interrupt(exc):
            if args.debug:
                raise
            return _internal_error(exc)
        return _interrupted(exc)
    except MemoryBudgetError as exc:
        if args.debug:
            raise
        return _error(_one_line(exc))
    except MemoryError as exc:
        if args.debug:
            raise
        detail = _one_line(exc) if str(exc) else "an allocation failed"
        return _error(f"ran out of memory ({detail}); {_OUT_OF_MEMORY_HINT}")
    except (RadiosityError, ValueError, OSError) as exc:
        if args.debug:
            raise
        return _error(_one_line(exc))
    except Exception as exc:  # noqa: BLE001 - not bad input: a bug, reported as one
        if _is_interrupt(exc):  # e.g. VTK's loader turns a Ctrl-C inside its import into ImportError
            return _interrupted(exc)
        if args.debug:
            raise
        return _internal_error(exc)
    _report_warnings(caught, show_notes=not args.shows_notes)
    return code


def _interrupted(exc: BaseException) -> int:
    """One line, and 130 for Ctrl-C or 143 for SIGTERM."""
    print(INTERRUPTED_LINE, file=sys.stderr)
    return exit_status(exc)


def _is_interrupt(exc: BaseException | None) -> bool:
    """Whether ``exc`` is, or was raised while handling, a Ctrl-C or SIGTERM, or the command
    received one (a library may drop the interrupt from the error it raises instead)."""
    while exc is not None:
        if isinstance(exc, KeyboardInterrupt):
            return True
        exc = exc.__cause__ or exc.__context__
    return signal_received() is not None


def entry() -> None:
    """The console script: ``main``, then an exit that cannot crash on the way out.

    numba's and Embree's worker threads may still exist when ``main`` returns; a Ctrl-C that
    lands while the interpreter tears down under them crashed it (segfaults, numba
    ``SystemError``). Every output is written, renamed and closed by then (the staging folder and
    the cache are handled in ``finally`` blocks inside ``main``), so the process flushes its
    streams and leaves at once with the status ``main`` chose.
    """
    with catching_signals():  # never left: the process ends inside
        try:
            code = main()
        except KeyboardInterrupt as exc:  # between main's own handlers, e.g. while printing the summary
            code = _interrupted(exc)
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        except (KeyboardInterrupt, OSError):  # a closed pipe, or a second Ctrl-C
            pass
        os._exit(code)


def _report_warnings(caught, *, show_notes: bool) -> None:
    """Print scene notes on stderr (unless the command printed them) and re-issue other warnings."""
    seen = set()
    for w in caught:
        if issubclass(w.category, RadiosityWarning):
            text = str(w.message)
            if show_notes and text not in seen:
                print(f"{PROG}: note: {text}", file=sys.stderr)
            seen.add(text)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, source=w.source)

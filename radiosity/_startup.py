"""Start-up of the ``radiosity`` command: signals before and during the seconds of imports.

Importing the package loads numpy, scipy, numba and trimesh, which takes seconds. A Ctrl-C or
SIGTERM in that time used to end in a ``KeyboardInterrupt`` traceback and a death by signal
(exit -2 / -15). When this process is the command (console script or ``python -m radiosity``),
the imports run under ``guard_imports``: a signal then ends the process with one line and the
shell's status (130, 143). A library import leaves the host program's signals alone.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading

PROG = "radiosity"
INTERRUPTED_LINE = f"{PROG}: interrupted; earlier outputs and the cache are left as they were"
EXIT_INTERRUPTED = 130  # 128 + SIGINT
EXIT_TERMINATED = 143  # 128 + SIGTERM


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that staging folders and caches are cleaned up the same way."""


def _raise_terminated(signum, frame):
    raise Terminated()


def started_as_command() -> bool:
    """Whether this process is the ``radiosity`` command (console script or ``python -m``)."""
    argv = list(getattr(sys, "orig_argv", sys.argv))
    if "-m" in argv[:-1]:  # python -m radiosity: runpy imports the package before __main__ exists
        return argv[argv.index("-m") + 1] == PROG
    script = os.path.basename(getattr(sys.modules.get("__main__"), "__file__", None) or "")
    return script == PROG


def exit_status(exc: BaseException) -> int:
    """130 for Ctrl-C, 143 for SIGTERM (also when the signal is the cause of another error)."""
    while exc is not None:
        if isinstance(exc, Terminated):
            return EXIT_TERMINATED
        exc = exc.__cause__ or exc.__context__
    return EXIT_INTERRUPTED


@contextlib.contextmanager
def signals_held():
    """Hold SIGINT and SIGTERM back for the block; one that came meanwhile is handled after it.

    For imports of C extensions whose module initialisation crashes when a Python exception
    interrupts it (VTK segfaulted when Ctrl-C landed inside ``import pyvista``). Only the main
    thread can change the mask meaningfully, and not on every platform: elsewhere a no-op.
    """
    held = {signal.SIGINT, signal.SIGTERM}
    can_hold = hasattr(signal, "pthread_sigmask") and threading.current_thread() is threading.main_thread()
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, held) if can_hold else None
    try:
        yield
    finally:
        if can_hold:
            signal.pthread_sigmask(signal.SIG_SETMASK, previous)


@contextlib.contextmanager
def guard_imports():
    """Run the package's imports; if this is the command, a signal among them exits cleanly."""
    command = started_as_command()
    if command:
        signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    except KeyboardInterrupt as exc:
        if not command:
            raise
        print(INTERRUPTED_LINE, file=sys.stderr)
        os._exit(exit_status(exc))

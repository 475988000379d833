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


# Signals the command received, newest last: a library can lose the exception a signal raised
# inside it (VTK's module loader turns a SIGTERM among its imports into "ImportError: Failed to
# load vtkIOXML: No module named vtkm...", without the Terminated as its cause), and the command
# must still end as interrupted, not with "internal error".
_received: list[int] = []

# How many blocks of the command are ready to turn the exception a signal raises into its clean
# exit (guard_imports' imports, cli.entry). Between them (runpy finishing the package's import
# and starting ``radiosity.__main__``, say) nothing would catch it: the handler exits itself.
_catchers = 0


@contextlib.contextmanager
def catching_signals():
    """Mark a block that catches KeyboardInterrupt and ends the command cleanly itself."""
    global _catchers
    _catchers += 1
    try:
        yield
    finally:
        _catchers -= 1


def _exit_uncaught(signum: int) -> None:
    """Outside every catching block nothing has been written yet: one line and the status."""
    if _catchers == 0:
        print(INTERRUPTED_LINE, file=sys.stderr)
        os._exit(EXIT_TERMINATED if signum == signal.SIGTERM else EXIT_INTERRUPTED)


def _raise_terminated(signum, frame):
    _received.append(signum)
    _exit_uncaught(signum)
    raise Terminated()


def _raise_interrupted(signum, frame):
    _received.append(signum)
    _exit_uncaught(signum)
    raise KeyboardInterrupt()


def signal_received() -> int | None:
    """The last SIGINT or SIGTERM the command received (None: none, or not the command)."""
    return _received[-1] if _received else None


def started_as_command() -> bool:
    """Whether this process is the ``radiosity`` command (console script or ``python -m``)."""
    argv = list(getattr(sys, "orig_argv", sys.argv))
    if "-m" in argv[:-1]:  # python -m radiosity: runpy imports the package before __main__ exists
        return argv[argv.index("-m") + 1] == PROG
    script = os.path.basename(getattr(sys.modules.get("__main__"), "__file__", None) or "")
    return script == PROG


def exit_status(exc: BaseException) -> int:
    """130 for Ctrl-C, 143 for SIGTERM (also when the signal is the cause of another error, or
    the error lost its cause but the command received the signal)."""
    ctrl_c = False
    while exc is not None:
        if isinstance(exc, Terminated):
            return EXIT_TERMINATED
        ctrl_c |= isinstance(exc, KeyboardInterrupt)
        exc = exc.__cause__ or exc.__context__
    return EXIT_TERMINATED if not ctrl_c and signal_received() == signal.SIGTERM else EXIT_INTERRUPTED


HELD_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class _SignalDeferral:
    """Ctrl-C and SIGTERM noted instead of raised between :meth:`hold` and :meth:`release`.

    Python runs signal handlers in the main thread between bytecodes, also inside ctypes
    callbacks and C extensions' module initialisation, where an exception is swallowed or
    crashes. Masking the signal does not help: the kernel hands a process-directed signal to
    any thread that does not block it (numpy's BLAS and numba start several). So while held,
    the handler only notes the signal; :meth:`release` puts the old handlers back and raises
    what came meanwhile, in plain Python code. Nested holds count; only the main thread holds.
    """

    def __init__(self):
        self._depth = 0
        self._saved: dict[int, object] = {}
        self._pending: list[int] = []

    def _note(self, signum, frame):
        if signum not in self._pending:
            self._pending.append(signum)

    def hold(self) -> None:
        if threading.current_thread() is not threading.main_thread():
            return
        if self._depth == 0:
            saved = {signum: signal.getsignal(signum) for signum in HELD_SIGNALS}
            if any(handler is None for handler in saved.values()):  # set from C: cannot be put back
                return
            self._saved = saved
            for signum in HELD_SIGNALS:
                signal.signal(signum, self._note)
        self._depth += 1

    def release(self) -> None:
        if threading.current_thread() is not threading.main_thread() or self._depth == 0:
            return
        self._depth -= 1
        if self._depth == 0:
            for signum, handler in self._saved.items():
                signal.signal(signum, handler)
            pending, self._pending = self._pending, []
            for signum in pending:
                signal.raise_signal(signum)


_deferral = _SignalDeferral()


@contextlib.contextmanager
def signals_held():
    """Hold SIGINT and SIGTERM back for the block; one that came meanwhile is raised after it.

    For imports of C extensions whose module initialisation crashes when a Python exception
    interrupts it (VTK segfaulted when Ctrl-C landed inside ``import pyvista``).
    """
    _deferral.hold()
    try:
        yield
    finally:
        _deferral.release()


class _HeldWhileCompiling:
    """Holds signals (see :class:`_SignalDeferral`) while numba's compiler lock is taken.

    numba compiles, and loads kernels from its disk cache, under one compiler lock, and LLVM
    calls back into Python through ctypes meanwhile. A Ctrl-C raised inside such a callback
    was swallowed by ctypes ("Exception ignored on calling ctypes callback function", with a
    traceback) and the run went on with numba half-initialised.
    """

    def on_start(self, event) -> None:
        _deferral.hold()

    def on_end(self, event) -> None:
        _deferral.release()


_compile_listener = None


def hold_signals_while_compiling() -> None:
    """Register :class:`_HeldWhileCompiling` with numba (once per process; no-op without numba)."""
    global _compile_listener
    if _compile_listener is not None:
        return
    try:
        from numba.core import event
    except ImportError:
        return
    # numba accepts only subclasses of its Listener, which this module cannot import at load time
    listener_class = type("HeldWhileCompiling", (_HeldWhileCompiling, event.Listener), {})
    _compile_listener = listener_class()
    event.register("numba:compiler_lock", _compile_listener)


@contextlib.contextmanager
def guard_imports():
    """Run the package's imports; if this is the command, a signal among them exits cleanly."""
    command = started_as_command()
    # numba's OpenMP workers spin between parallel loops by default, taking the CPU the serial
    # passes between them need: passive waiting made the plates' fill 1.4-1.9x faster on a
    # shared 2-core machine, and a library import without it ran the open 16 x 16 plates 5x
    # slower than the command (docs/formfactors.md). So the import sets it too, before numba
    # starts its threads; an OMP_WAIT_POLICY the user set wins (and one read already by an
    # OpenMP runtime started earlier in the process stays as it was).
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    if command:
        signal.signal(signal.SIGTERM, _raise_terminated)
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # not ignored by the caller
            signal.signal(signal.SIGINT, _raise_interrupted)
    try:
        with catching_signals():
            if command:  # inside the try: it imports numba, seconds in which a Ctrl-C may come
                hold_signals_while_compiling()
            yield
    except KeyboardInterrupt as exc:
        if not command:
            raise
        print(INTERRUPTED_LINE, file=sys.stderr)
        os._exit(exit_status(exc))

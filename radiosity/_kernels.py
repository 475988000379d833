"""The compiled (numba) kernels: are they on disk yet, compiling them up front, timing compiles.

Every kernel is ``njit(cache=True)``: numba writes the machine code next to the sources
(``radiosity/__pycache__``, or ``NUMBA_CACHE_DIR``) on first use and later processes load it
in milliseconds. Only the first run after an install (or an upgrade of the package, numba or
Python) compiles, for one to three minutes on two cores. The command line says so before it
starts, compiles every kernel on a tiny scene first (so the stage times of the real run hold
no compile time) and reports the compile time on its own.
"""

from __future__ import annotations

import contextlib
import importlib
import time
import warnings

__all__ = ["kernels_on_disk", "compile_timer", "warm_up"]

# Kernels every solve runs (form factors, near-pair flags, rays and exact shadows). If their
# disk cache holds a fresh entry, the rest were compiled by the same run too.
CORE_KERNELS = (
    ("radiosity.formfactors._quadrature", "_pair_setup_loop"),
    ("radiosity.formfactors._quadrature", "_near_flags_loop"),
    ("radiosity.formfactors._lambert", "_quadrature_source_kernel"),
    ("radiosity.visibility._ray_kernel", "segment_fractions"),
    ("radiosity.visibility._exact_kernel", "exact_pairs"),
)

FIRST_RUN_MESSAGE = ("radiosity: compiling kernels, first run only (1-3 minutes; "
                     "later runs load them from disk)")


def _dispatchers():
    try:
        from numba.core.registry import CPUDispatcher
    except ImportError:  # no numba: nothing is compiled
        return []
    out = []
    for module_name, name in CORE_KERNELS:
        kernel = getattr(importlib.import_module(module_name), name, None)
        if isinstance(kernel, CPUDispatcher):
            out.append(kernel)
    return out


def kernels_on_disk() -> bool:
    """True when every core kernel has a fresh entry in numba's disk cache (or numba is absent).

    numba keeps an index per kernel, stamped with the source file's time and size; a missing
    or stale index (new install, edited source) means the next call compiles.
    """
    for kernel in _dispatchers():
        cache = getattr(kernel, "_cache", None)
        index = getattr(getattr(cache, "_cache_file", None), "_load_index", None)
        if index is None:
            continue  # caching disabled (NUMBA_DISABLE_JIT) or an unknown numba: nothing to say
        try:
            if not index():
                return False
        except Exception:  # noqa: BLE001 - an unreadable index is recompiled by numba too
            return False
    return True


class CompileTimer:
    """Seconds spent compiling numba kernels (outermost compiles only), readable at any time."""

    def __init__(self, listener=None):
        self._listener = listener

    @property
    def seconds(self) -> float:
        done = self._listener is not None and self._listener.done
        return float(self._listener.duration) if done else 0.0


@contextlib.contextmanager
def compile_timer():
    """Time every numba compile inside the block; yields a :class:`CompileTimer`."""
    try:
        from numba.core import event
    except ImportError:
        yield CompileTimer()
        return
    listener = event.TimingListener()
    with event.install_listener("numba:compile", listener):
        yield CompileTimer(listener)


def warm_up() -> float:
    """Compile (or load) every kernel by solving a tiny bundled scene; returns the seconds taken.

    The scene is the Cornell box cut into about 70 patches, with exact shadows and rays, so
    each kernel meets the argument types of a real run. Nothing is written to the form-factor
    cache and the scene's notes are not reported.
    """
    from .scene import bundled_scene, load_scene
    from .solve import solve

    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(bundled_scene("cornell_box"), max_patch_size=0.3)
        solve(scene, preset="default", cache=False)
    return time.perf_counter() - start

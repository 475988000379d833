"""Shared test setup: off-screen pyvista, a private form-factor cache, hypothesis profiles."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")

from hypothesis import HealthCheck, settings  # noqa: E402

settings.register_profile("deterministic", derandomize=True, deadline=None, max_examples=60,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("thorough", deadline=None, max_examples=500)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "deterministic"))


def pytest_configure(config):
    """Under xdist, compile the numba kernels before the workers start (``warm_kernels.py``)."""
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return  # a worker, or a single process that compiles as it goes
    if os.environ.get("RADIOSITY_TEST_WARMUP", "1") == "0":
        return
    from radiosity._kernels import kernels_on_disk

    if kernels_on_disk():
        config.stash[_WARMUP] = "numba kernels on disk already"
        return
    config.stash[_WARMUP] = _warm_kernels()


_WARMUP = pytest.StashKey[str]()
_ROOT = Path(__file__).resolve().parents[1]


def _warm_kernels() -> str:
    """Run warm_kernels.py's shares, a phase at a time; a failure is reported, not raised (the
    tests then compile what is missing themselves and fail where the fault is)."""
    from warm_kernels import PHASES

    # the tests import radiosity from the checkout, so the cache must be written for its files
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(_ROOT), os.environ.get("PYTHONPATH")])))
    script = Path(__file__).with_name("warm_kernels.py")
    start = time.perf_counter()
    failed = []
    for phase in PHASES:
        runs = {share: subprocess.Popen([sys.executable, str(script), share], cwd=_ROOT, env=env,
                                        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
                for share in phase}
        for share, run in runs.items():
            _, err = run.communicate()
            if run.returncode:
                last = err.strip().splitlines()[-1:] or [f"exit {run.returncode}"]
                failed.append(f"{share}: {last[0]}")
    took = f"numba kernels compiled up front in {time.perf_counter() - start:.0f} s"
    return took + (f" (failed: {'; '.join(failed)})" if failed else "")


def pytest_report_header(config):
    import importlib.metadata as md

    lines = [config.stash[_WARMUP]] if _WARMUP in config.stash else []
    parts = []
    for name in ("numpy", "scipy", "trimesh", "embreex", "pyvista", "numba"):
        try:
            parts.append(f"{name} {md.version(name)}")
        except md.PackageNotFoundError:
            parts.append(f"{name} missing")
    return ["radiosity deps: " + ", ".join(parts), *lines]


@pytest.fixture(scope="session", autouse=True)
def _no_user_cache(tmp_path_factory):
    """Module and session fixtures fill with a private cache too: they are set up before any
    function fixture, and with the user's cache they read matrices an older version had stored
    there (the spheres of test_exchange passed on one machine and failed on a fresh one)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("RADIOSITY_CACHE", str(tmp_path_factory.mktemp("session-cache")))
        yield


@pytest.fixture(autouse=True)
def _private_cache(tmp_path_factory, monkeypatch):
    """Every test gets its own empty form-factor cache folder (never the user's)."""
    monkeypatch.setenv("RADIOSITY_CACHE", str(tmp_path_factory.mktemp("cache")))


@pytest.fixture(scope="session", autouse=True)
def _pyvista_off_screen():
    import pyvista

    pyvista.OFF_SCREEN = True
    yield


@pytest.fixture(scope="session")
def concentric_prisms(tmp_path_factory):
    """An 8-sided prism (r 0.5, 4 m long, facing out) inside a closed one (r 1, 4.8 m, facing in),
    and its view factors at view_factors' defaults: one matrix for test_closure and test_exchange.

    Eight sides, not twelve: from the outer wall a point then sees at most ``MAX_UNION`` hidden
    polygons, and the 12-sided pair's shapely unions took 100 s (2.8 s here).
    """
    import warnings

    import radiosity
    from helpers import prism, write_obj

    objects = {"inner": prism(0.5, 4.0, 8, inward=False), "outer": prism(1.0, 4.8, 8, inward=True, z0=-0.4)}
    with warnings.catch_warnings():  # no emitter: a note says so
        warnings.simplefilter("ignore", radiosity.RadiosityWarning)
        scene = radiosity.load_scene(write_obj(tmp_path_factory.mktemp("prisms") / "prisms.obj", objects))
        return scene, radiosity.view_factors(scene, cache=False)

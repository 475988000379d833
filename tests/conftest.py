"""Shared test setup: off-screen pyvista, a private form-factor cache, hypothesis profiles."""

from __future__ import annotations

import os

import pytest

os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")

from hypothesis import HealthCheck, settings  # noqa: E402

settings.register_profile("deterministic", derandomize=True, deadline=None, max_examples=60,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("thorough", deadline=None, max_examples=500)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "deterministic"))


def pytest_report_header(config):
    import importlib.metadata as md

    parts = []
    for name in ("numpy", "scipy", "trimesh", "embreex", "pyvista", "numba"):
        try:
            parts.append(f"{name} {md.version(name)}")
        except md.PackageNotFoundError:
            parts.append(f"{name} missing")
    return "radiosity deps: " + ", ".join(parts)


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

"""Compiled kernels: cached on disk, the first run announced, compile time reported on its own."""

from __future__ import annotations

import json

import pytest

from radiosity import _kernels
from radiosity.cli import main

from helpers import ROOM


def test_every_kernel_is_cached_on_disk():
    """All njit kernels ask numba to cache, so only the first process compiles."""
    numba = pytest.importorskip("numba")
    from numba.core.registry import CPUDispatcher

    import radiosity.formfactors._lambert
    import radiosity.formfactors._quadrature
    import radiosity.visibility._exact_kernel
    import radiosity.visibility._ray_kernel

    modules = (radiosity.formfactors._lambert, radiosity.formfactors._quadrature, radiosity.visibility._exact_kernel,
               radiosity.visibility._ray_kernel)
    kernels = [v for m in modules for v in vars(m).values() if isinstance(v, CPUDispatcher)]
    assert len(kernels) > 20 and numba
    assert all(type(k._cache).__name__ == "FunctionCache" for k in kernels), "a kernel without cache=True"


def test_after_a_warm_up_the_kernels_are_on_disk():
    _kernels.warm_up()
    assert _kernels.kernels_on_disk()


def test_compile_timer_sees_a_compile_and_nothing_else():
    numba = pytest.importorskip("numba")

    with _kernels.compile_timer() as nothing:
        sum(range(1000))
    assert nothing.seconds == 0.0

    @numba.njit(cache=False)
    def add(a, b):
        return a + b

    with _kernels.compile_timer() as compiled:
        assert add(1, 2) == 3
    assert compiled.seconds > 0.0


def test_first_run_is_announced_and_compile_time_kept_apart(tmp_path, capsys, monkeypatch):
    from radiosity.cli import _solve

    monkeypatch.setattr(_solve, "kernels_on_disk", lambda: False)
    monkeypatch.setattr(_solve, "_interactive", lambda: True)

    def compiling_warm_up():
        import numba

        numba.njit(cache=False)(lambda x: x + 1)(1)  # a real compile, timed by the listener

    monkeypatch.setattr(_solve, "warm_up", compiling_warm_up)
    out = tmp_path / "out"
    assert main(["solve", str(ROOM), "--preset", "draft", "--no-picture", "--no-cache", "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert "compiling kernels, first run only" in captured.err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["compile_s"] > 0
    assert "compile" not in summary["timings_s"]


def test_later_runs_say_nothing(tmp_path, capsys, monkeypatch):
    from radiosity.cli import _solve

    monkeypatch.setattr(_solve, "kernels_on_disk", lambda: True)
    monkeypatch.setattr(_solve, "_interactive", lambda: True)
    assert main(["solve", str(ROOM), "--preset", "draft", "--no-picture", "-o", str(tmp_path / "o")]) == 0
    assert "compiling" not in capsys.readouterr().err


def test_logs_get_no_announcement_but_the_warm_up_still_runs(tmp_path, capsys, monkeypatch):
    """Not a terminal (CI, scripts): stderr stays for errors; the compile is still kept apart."""
    from radiosity.cli import _solve

    calls = []
    monkeypatch.setattr(_solve, "kernels_on_disk", lambda: False)
    monkeypatch.setattr(_solve, "warm_up", lambda: calls.append(1))
    assert main(["solve", str(ROOM), "--preset", "draft", "--no-picture", "-o", str(tmp_path / "o")]) == 0
    assert capsys.readouterr().err == "" and calls == [1]

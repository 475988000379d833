"""Signals at random moments: exit 130 (Ctrl-C) or 143 (SIGTERM) with one line, never a crash.

Each trial runs the real console entry point in a subprocess, interrupts it at a moment drawn
from a seeded generator over the length of an uninterrupted run, then checks the outcome class
and the output folder: nothing of the interrupted run, no staging folder, and a rerun gives the
uninterrupted run's numbers.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from radiosity._startup import INTERRUPTED_LINE
from radiosity.io.export import STAGING_PREFIX

ROOM = Path(__file__).parent / "data" / "room.obj"


def run_cli(out: Path, cache: Path, *, interrupt_after: float | None = None,
            sig: int = signal.SIGINT) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", "radiosity", "solve", str(ROOM), "--preset", "draft",
               "--no-picture", "-o", str(out)]
    env = {"RADIOSITY_CACHE": str(cache), "PYTHONFAULTHANDLER": "1", "PATH": "/usr/bin:/bin"}
    # A shell's background jobs inherit SIGINT ignored, and Python then keeps it ignored: reset it.
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    if interrupt_after is not None:
        time.sleep(interrupt_after)
        process.send_signal(sig)
    stdout, stderr = process.communicate(timeout=300)
    return subprocess.CompletedProcess(command, process.returncode, stdout, stderr)


@pytest.mark.slow
def test_signals_at_random_moments_end_cleanly(tmp_path):
    cache = tmp_path / "cache"
    reference = tmp_path / "reference"
    start = time.perf_counter()
    done = run_cli(reference, cache)
    duration = time.perf_counter() - start
    assert done.returncode == 0, done.stderr
    expected = json.loads((reference / "summary.json").read_text())["objects"]

    rng = np.random.default_rng(20261201)
    moments = np.sort(rng.uniform(0.0, 1.1 * duration, 4))
    signals = [signal.SIGINT, signal.SIGTERM, signal.SIGINT, signal.SIGTERM]
    outcomes = []
    for k, (moment, sig) in enumerate(zip(moments, signals)):
        out = tmp_path / f"out{k}"
        result = run_cli(out, tmp_path / f"cache{k}", interrupt_after=float(moment), sig=sig)
        outcomes.append(result.returncode)
        assert "Traceback" not in result.stderr and "Fatal Python error" not in result.stderr, result.stderr
        if result.returncode == 0:  # finished before the signal: a complete result
            assert (out / "summary.json").exists()
            continue
        assert result.returncode == (130 if sig == signal.SIGINT else 143), (moment, result.stderr)
        assert result.stderr.strip().splitlines()[-1] == INTERRUPTED_LINE
        leftovers = [p.name for p in out.iterdir()] if out.exists() else []
        assert not [n for n in leftovers if n.startswith(STAGING_PREFIX)], leftovers
        assert "summary.json" not in leftovers
        rerun = run_cli(out, tmp_path / f"cache{k}")
        assert rerun.returncode == 0, rerun.stderr
        again = json.loads((out / "summary.json").read_text())["objects"]
        for name, value in expected.items():
            np.testing.assert_allclose(again[name], value, rtol=1e-12)
    assert any(code != 0 for code in outcomes), outcomes  # the draw did interrupt something

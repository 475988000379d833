"""Shared helpers for the benchmark scripts: a timer, the ``--quick`` flag, a JSON writer.

Every script in ``bench/`` is a plain program (``python bench/bench_x.py [--quick]``) that
prints a table and writes one JSON file to ``bench/results/``. Keep this module free of
radiosity imports so any script can use it.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"


def parse_args(description: str, argv=None, extra: Callable[[argparse.ArgumentParser], None] | None = None
               ) -> argparse.Namespace:
    """Parse the common flags: ``--quick`` (small sizes, few repeats) and ``--out PATH``."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--quick", action="store_true", help="small sizes and few repeats")
    parser.add_argument("--out", default=None, help="JSON output path (default: bench/results/<name>.json)")
    if extra is not None:
        extra(parser)
    return parser.parse_args(argv)


def best_time(fn: Callable[[], object], *, repeat: int = 3, number: int = 1, warmup: int = 1) -> float:
    """Best wall time of ``number`` calls to ``fn`` over ``repeat`` runs, in seconds per call."""
    for _ in range(warmup):
        fn()
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - t0) / number)
    return best


class Timer:
    """Context manager measuring wall time: ``with Timer() as t: ...; t.seconds``."""

    def __enter__(self):
        self._t0 = time.perf_counter()
        self.seconds = float("nan")
        return self

    def __exit__(self, *exc):
        self.seconds = time.perf_counter() - self._t0
        return False


def machine_info() -> dict:
    """What a reader needs to compare numbers between machines."""
    info = {"python": sys.version.split()[0], "platform": platform.platform(),
            "cpus": os.cpu_count(), "time": time.strftime("%Y-%m-%dT%H:%M:%S")}
    for name in ("numpy", "scipy", "numba"):
        try:
            import importlib.metadata as md

            info[name] = md.version(name)
        except Exception:  # noqa: BLE001 - optional packages
            info[name] = None
    return info


def write_json(name: str, payload: dict, out: str | None = None) -> Path:
    """Write ``payload`` plus machine info to ``bench/results/<name>.json`` (or ``out``)."""
    path = Path(out) if out else RESULTS / f"{name}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    data = {"machine": machine_info(), **payload}
    path.write_text(json.dumps(data, indent=2, default=float) + "\n")
    return path


def run_cases(script: str | Path, specs, *, cwd: Path, tail: int = 800, timeout: float | None = None) -> list[dict]:
    """Each spec (a JSON-able dict) measured by ``script --case SPEC`` in a fresh process (so
    peak memory and compile state are its own): the JSON row its last line prints, or the spec
    with ``failed`` (stderr's last line) when it exits non-zero. Prints each row as it comes.

    With ``timeout`` (seconds) a case still running then is killed (its whole process group)
    and recorded as the spec with ``failed: "not finished in ..."`` and ``timed_out: True``."""
    import signal
    import subprocess

    rows = []
    for spec in specs:
        command = [sys.executable, str(script), "--case", json.dumps(spec)]
        if timeout is None:
            done = subprocess.run(command, capture_output=True, text=True, cwd=cwd, check=False)
            stdout, stderr, returncode = done.stdout, done.stderr, done.returncode
        else:
            t0 = time.perf_counter()
            proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=cwd,
                                    start_new_session=True)
            try:
                stdout, stderr = proc.communicate(timeout=timeout)
            except BaseException as stop:  # the timeout, or Ctrl-C here (the case's session would not see it)
                try:
                    os.killpg(proc.pid, signal.SIGKILL)  # the case's own session: it and anything it started
                except ProcessLookupError:
                    pass
                if not isinstance(stop, subprocess.TimeoutExpired):
                    proc.wait()
                    raise
                stdout, stderr = proc.communicate()
                wall = time.perf_counter() - t0
                rows.append({**spec, "failed": f"not finished in {timeout / 60:g} min", "timed_out": True,
                             "wall_seconds": wall})
                print(spec, f"killed: not finished in {timeout / 60:g} min", flush=True)
                continue
            returncode = proc.returncode
        if returncode != 0:
            rows.append({**spec, "failed": stderr.strip().splitlines()[-1:]})
            print(spec, "failed:", stderr[-tail:], flush=True)
            continue
        rows.append(json.loads(stdout.strip().splitlines()[-1]))
        print(json.dumps(rows[-1]), flush=True)
    return rows


def print_table(rows: list[dict], columns: list[str] | None = None, *, title: str | None = None) -> None:
    """Print ``rows`` (dicts) as an aligned plain-text table."""
    if not rows:
        return
    columns = columns or list(rows[0])

    def fmt(v):
        if isinstance(v, float):
            return f"{v:.4g}"
        return str(v)

    cells = [[fmt(r.get(c, "")) for c in columns] for r in rows]
    widths = [max(len(c), *(len(row[k]) for row in cells)) for k, c in enumerate(columns)]
    if title:
        print(f"\n{title}")
    print("  ".join(c.rjust(w) for c, w in zip(columns, widths)))
    for row in cells:
        print("  ".join(v.rjust(w) for v, w in zip(row, widths)))


def plate_quads(n: int, blocked: bool):
    """(2 n^2 [+ 1], 4, 3) quads of the benchmark plates: two unit squares 1 apart, each cut
    n x n, the lower facing up, the upper facing down, and with ``blocked`` the centred
    0.5 x 0.5 blocker midway (FIELD_NOTES' reference values)."""
    import numpy as np

    h = 1.0 / n
    a, b = np.meshgrid(np.arange(n) * h, np.arange(n) * h, indexing="ij")
    a, b = a.ravel(), b.ravel()
    sq = np.stack([np.column_stack([a, b]), np.column_stack([a + h, b]), np.column_stack([a + h, b + h]),
                   np.column_stack([a, b + h])], axis=1)
    low = np.concatenate([sq, np.zeros(sq.shape[:2] + (1,))], axis=2)
    up = np.concatenate([sq, np.ones(sq.shape[:2] + (1,))], axis=2)[:, ::-1]  # facing down
    parts = [low, up]
    if blocked:
        parts.append(np.array([[[0.25, 0.25, 0.5], [0.75, 0.25, 0.5], [0.75, 0.75, 0.5], [0.25, 0.75, 0.5]]]))
    return np.concatenate(parts)

"""The issue-18 scale run: the finely cut Cornell box filled out of core, then solved from its shards.

Two phases, each its own process (run it under ``/usr/bin/time -v`` for the peak resident
memory; the script also prints its own ``ru_maxrss``):

- ``fill``: the bundled Cornell box cut to ``--max-patch-size`` (0.011 m: 18,490 patches), with
  the options ``radiosity solve`` uses for ``--preset`` (default), written block by block into
  the shard folder ``--shards`` by :func:`radiosity.shards.write_shards`, blocks planned from
  ``RADIOSITY_MEMORY_BUDGET`` (:func:`radiosity._memory.plan_fill_block`);
- ``solve``: B of (I - rho F) B = E from those shards (:func:`radiosity.methods.uniform.outofcore.solve_shards`,
  the path ``radiosity solve`` takes when F does not fit the budget), and the energy balance
  (emitted = absorbed + escaped, two more passes).

Run::

    RADIOSITY_MEMORY_BUDGET=4G nice /usr/bin/time -v python bench/bench_out_of_core.py \
        --phase fill --shards /tmp/F18k.shards
    RADIOSITY_MEMORY_BUDGET=4G nice /usr/bin/time -v python bench/bench_out_of_core.py \
        --phase solve --shards /tmp/F18k.shards

Each phase prints one JSON line and writes ``bench/results/out_of_core_<phase>.json``.
"""

from __future__ import annotations

import json
import resource
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _common import parse_args, write_json  # noqa: E402


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def fill(size: float, preset: str, shards: Path) -> dict:
    import radiosity
    from radiosity import _memory
    from radiosity.methods.uniform.cluster import FillProblem
    from radiosity.options import Options
    from radiosity.methods.uniform.shards import write_shards
    from radiosity.solve import _cut, _fill_settings

    t0 = time.perf_counter()
    options = Options.from_preset(preset, max_patch_size=size, cache=False)
    cut = _cut(radiosity.load_scene(radiosity.bundled_scene("cornell_box")), options)
    problem = FillProblem.from_scene(cut, _fill_settings(options), ~cut.patch_inactive)
    budget, source = _memory.budget_bytes()
    pairs = _memory.plan_fill_block(cut.n_patches)
    print(f"{cut.n_patches} patches; budget {_memory.format_bytes(budget)} ({source}); in-memory fill estimate "
          f"{_memory.format_bytes(_memory.fill_bytes(cut.n_patches))}; {pairs:,} pairs per block", flush=True)
    done = [0, 0.0]

    def progress(rows: int) -> None:
        done[0] += rows
        now = time.perf_counter() - t0
        if now - done[1] > 60 or done[0] == cut.n_patches:
            done[1] = now
            print(f"  {now:7.0f} s: {done[0]:,}/{cut.n_patches:,} rows, peak {_peak_mb():.0f} MB", flush=True)

    t1 = time.perf_counter()
    F, stats = write_shards(problem, cut, shards, pairs_per_block=pairs, progress=progress,
                            settings={"preset": preset, "max_patch_size": size})
    t2 = time.perf_counter()
    return {"phase": "fill", "patches": cut.n_patches, "nnz": F.nnz, "shards": F.n_blocks,
            "pairs_per_block": pairs, "budget_mb": budget / 2**20,
            "in_memory_estimate_mb": _memory.fill_bytes(cut.n_patches) / 2**20,
            "setup_s": t1 - t0, "fill_s": t2 - t1, "peak_mb": _peak_mb(),
            "disk_mb": sum(p.stat().st_size for p in Path(shards).iterdir()) / 2**20,
            "stats": {k: getattr(stats, k) for k in type(stats).__dataclass_fields__}}


class _Logged:
    """F with a line per pass over the shards (the 18k solve runs for many minutes)."""

    def __init__(self, F, t0: float):
        self.F, self.t0, self.shape, self.passes = F, t0, F.shape, 0

    def __matmul__(self, x):
        y = self.F @ x
        self.passes += 1
        print(f"  {time.perf_counter() - self.t0:7.0f} s: pass {self.passes}, peak {_peak_mb():.0f} MB", flush=True)
        return y


def solve(shards: Path, rtol: float) -> dict:
    import numpy as np

    from radiosity.methods.uniform.outofcore import solve_shards
    from radiosity.methods.uniform.shards import load_view_factors
    from radiosity.methods.uniform.system import energy_balance

    F = load_view_factors(shards)
    patches = F.patches()
    t0 = time.perf_counter()
    B, info = solve_shards(_Logged(F, t0), patches["reflectance"], patches["emission"], rtol=rtol)
    t1 = time.perf_counter()
    balance = energy_balance(F, patches["area"], patches["reflectance"], patches["emission"], B)
    emitted = np.array(balance["emitted"])
    closure = (np.array(balance["absorbed"]) + np.array(balance["escaped"])) / emitted
    return {"phase": "solve", "patches": F.shape[0], "nnz": F.nnz, "shards": F.n_blocks, "solve_s": t1 - t0,
            "peak_mb": _peak_mb(), "finite": bool(np.isfinite(B).all()), **info, "energy_W": balance,
            "absorbed_plus_escaped_over_emitted": closure.tolist(), "mean_B": B.mean(axis=0).tolist()}


def main() -> None:
    args = parse_args(__doc__.splitlines()[0], extra=lambda p: (
        p.add_argument("--phase", choices=("fill", "solve"), required=True),
        p.add_argument("--shards", type=Path, required=True),
        p.add_argument("--max-patch-size", type=float, default=0.011),
        p.add_argument("--preset", default="default"),
        p.add_argument("--rtol", type=float, default=1e-10)))
    if args.phase == "fill":
        out = fill(args.max_patch_size, args.preset, args.shards)
    else:
        out = solve(args.shards, args.rtol)
    print(json.dumps(out), flush=True)
    path = write_json(f"out_of_core_{args.phase}", out, args.out)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

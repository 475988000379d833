"""The view-factor fill on 1 and 2 Dask workers, and out of core under a budget smaller than F.

Each case runs in a fresh child process (so its peak resident memory, ``ru_maxrss``, is its
own) on the bundled Cornell box cut to ``--max-patch-size``:

- ``local``: ``radiosity.view_factors`` in process (the baseline);
- ``workers=1``, ``workers=2``: the same fill with its row blocks as tasks on a
  ``LocalCluster`` of that many processes (cluster start-up timed apart from the fill; peak
  memory is the client's, the workers' is summed from their own ``ru_maxrss``);
- ``out-of-core``: ``radiosity.write_view_factors`` with ``RADIOSITY_MEMORY_BUDGET`` set to
  half the in-memory fill's worst-case estimate, then the solve from the shards (bicgstab).

Printed: patches, seconds (fill, and cluster start-up), peak MB, speed-up of the fill over the
local one measured in the same run, and whether F is bit-identical to the local matrix.
Run: ``python bench/bench_cluster.py [--quick] [--max-patch-size M] [--cases local,out-of-core]``
(the first case is the baseline). Writes
``bench/results/cluster.json``. On a 2-core machine shared with others the 2-worker speed-up is
bounded by the cores actually free; numba already uses both cores in process.
"""

from __future__ import annotations

import hashlib
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _common import parse_args, print_table, write_json  # noqa: E402


def _digest(F) -> str:
    F = F.tocsr()
    F.sort_indices()
    h = hashlib.sha256(F.indptr.tobytes() + F.indices.tobytes() + F.data.tobytes())
    return h.hexdigest()[:16]


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def child(case: str, size: float, preset: str) -> dict:
    import numpy as np

    import radiosity
    from radiosity import _memory

    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"), max_patch_size=size)
    out = {"case": case, "patches": scene.n_patches}
    if case == "local":
        t0 = time.perf_counter()
        F = radiosity.view_factors(scene, preset=preset, cache=False)
        out.update(fill_s=time.perf_counter() - t0, nnz=F.nnz, digest=_digest(F),
                   estimate_mb=_memory.fill_bytes(scene.n_patches) / 2**20)
    elif case.startswith("workers="):
        from radiosity.methods.uniform.cluster import FillProblem, cluster_client, fill_matrix
        from radiosity.solve import _fill_settings, _view_factor_options

        options = _view_factor_options(preset, {"cache": False})
        problem = FillProblem.from_scene(scene, _fill_settings(options), ~scene.patch_inactive)
        t0 = time.perf_counter()
        with cluster_client(workers=int(case.split("=")[1])) as client:
            client.run(lambda: __import__("radiosity.methods.uniform.assembly"))  # imports (numba cache) in the start-up
            t1 = time.perf_counter()
            F, _ = fill_matrix(problem, client=client)
            t2 = time.perf_counter()
            worker_mb = sum(client.run(_peak_mb).values())
        out.update(startup_s=t1 - t0, fill_s=t2 - t1, nnz=F.nnz, digest=_digest(F), worker_peak_mb=worker_mb)
    elif case == "out-of-core":
        budget = _memory.fill_bytes(scene.n_patches) // 2
        os.environ[_memory.ENV_BUDGET] = str(budget)
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            F = radiosity.write_view_factors(scene, Path(tmp) / "F.shards", preset=preset)
            t1 = time.perf_counter()
            B = F.solve(rtol=1e-8)
            t2 = time.perf_counter()
            os.environ.pop(_memory.ENV_BUDGET)
            out["peak_mb"] = _peak_mb()  # before the whole matrix is loaded for the comparison
            full = F.tocsr()
            out.update(fill_s=t1 - t0, solve_s=t2 - t1, nnz=F.nnz, digest=_digest(full), shards=F.n_blocks,
                       budget_mb=budget / 2**20, pairs_per_block=F.index["pairs_per_block"],
                       finite=bool(np.isfinite(B).all()))
    out.setdefault("peak_mb", _peak_mb())
    return out


def main() -> None:
    args = parse_args(__doc__.splitlines()[0], extra=lambda p: (
        p.add_argument("--max-patch-size", type=float, default=None),
        p.add_argument("--preset", default="draft"),
        p.add_argument("--cases", default="local,workers=1,workers=2,out-of-core"),
        p.add_argument("--child", default=None, help=argparse_hidden())))
    if args.child:
        print(json.dumps(child(args.child, args.max_patch_size, args.preset)))
        return
    size = args.max_patch_size or (0.1 if args.quick else 0.06)
    rows = []
    for case in args.cases.split(","):
        proc = subprocess.run([sys.executable, __file__, "--child", case, "--max-patch-size", str(size),
                               "--preset", args.preset], capture_output=True, text=True, check=True)
        rows.append(json.loads(proc.stdout.strip().splitlines()[-1]))
        print(f"{case}: {rows[-1]}", flush=True)
    base = rows[0]
    for r in rows:
        r["speedup"] = base["fill_s"] / r["fill_s"]
        r["same_bits"] = r["digest"] == base["digest"]
    print_table(rows, ["case", "patches", "nnz", "fill_s", "startup_s", "solve_s", "peak_mb", "worker_peak_mb",
                       "budget_mb", "shards", "speedup", "same_bits"],
                title=f"Cornell box, max_patch_size {size} m, preset {args.preset}")
    path = write_json("cluster", {"max_patch_size": size, "preset": args.preset, "rows": rows}, args.out)
    print(f"wrote {path}")


def argparse_hidden():
    import argparse

    return argparse.SUPPRESS


if __name__ == "__main__":
    main()

"""The view-factor fill in row blocks, in process or on a Dask cluster.

The fill's unit of work is :func:`radiosity.methods.uniform.assembly.fill_block`: the pairs (i, j > i) of a
range of rows and their mirrors. A block's result depends only on the geometry, the settings
and its rows, so F is the same bit for bit however the blocks are scheduled: in this process,
on a local cluster (``workers=N``, a ``dask.distributed.LocalCluster`` of N processes) or on a
running one (``scheduler="tcp://host:8786"``).

On a cluster the :class:`FillProblem` (patch arrays and settings) is scattered to every worker
once; each block is a task. A worker builds the visibility structures (occluders, bounding-volume
hierarchy) on its first block and keeps them in :data:`_WORKER_VISIBILITY`, keyed by the
problem's hash, for the blocks after it. A block lost with its worker is run again elsewhere by
the scheduler (``distributed.scheduler.allowed-failures``, 3 by default).

``dask[distributed]`` is an optional dependency: ``pip install radiosity[cluster]``.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .assembly import FILL_PAIRS, FillSettings, FillStats, _row_blocks, add_stats, coo_parts_to_csr, fill_block

__all__ = ["FillProblem", "blocks_of", "run_blocks", "fill_matrix", "cluster_client"]

# Visibility structures built on a worker, by FillProblem.key: built on its first block only.
_WORKER_VISIBILITY: dict[str, object] = {}
# Problems a worker keeps structures for at once (a long-lived cluster serves many scenes).
_WORKER_KEEP = 2
# Blocks per worker when a cluster fill plans its blocks (a few, so a slow block or a lost
# worker does not leave the others idle), and the fewest pairs worth a task.
TASKS_PER_WORKER = 4
MIN_TASK_PAIRS = 20_000


@dataclass(frozen=True, eq=False)
class FillProblem:
    """Everything a block of the fill needs: the patches, the active mask and the settings.

    Attributes
    ----------
    quads, normals, centroid : (n, 4, 3), (n, 3), (n, 3) float
    area : (n,) float
    groups : (n,) int
        Object of each patch (coplanar occluders of one object are merged).
    scale : float
        The scene's diagonal, metres.
    active : (n,) bool or None
        Patches that exchange light (None: all).
    settings : FillSettings
    """

    quads: np.ndarray
    normals: np.ndarray
    centroid: np.ndarray
    area: np.ndarray
    groups: np.ndarray
    scale: float
    active: np.ndarray | None
    settings: FillSettings

    @classmethod
    def from_scene(cls, scene, settings: FillSettings, active: np.ndarray | None = None) -> "FillProblem":
        return cls(scene.patch_quads, scene.patch_normal, scene.patch_centroid, scene.patch_area,
                   np.asarray(scene.patch_object), float(scene.scale), active, settings)

    @property
    def n(self) -> int:
        return len(self.quads)

    @property
    def key(self) -> str:
        """Hash of geometry, active mask and settings: the worker cache's key."""
        digest = hashlib.sha256(np.ascontiguousarray(self.quads, np.float64).tobytes())
        digest.update(np.ascontiguousarray(self.groups).tobytes())
        if self.active is not None:
            digest.update(np.packbits(self.active).tobytes())
        digest.update(repr(self.settings).encode())
        return digest.hexdigest()[:32]

    def visibility(self):
        """A new Visibility for these patches (what ``solve.prepare`` builds in process)."""
        from ...visibility import Visibility

        return Visibility(self.quads, self.normals, self.groups, self.scale,
                          samples=self.settings.visibility_samples, max_samples=self.settings.visibility_max_samples)

    def block(self, visibility, start: int, stop: int):
        """:func:`radiosity.methods.uniform.assembly.fill_block` of rows ``start:stop``."""
        return fill_block(self.quads, self.normals, self.centroid, self.area, visibility, self.settings, start, stop,
                          active=self.active)


def blocks_of(n: int, pairs_per_block: int = FILL_PAIRS // 2) -> list[tuple[int, int]]:
    """The row blocks of an n-patch fill: about ``pairs_per_block`` pairs (i, j > i) each."""
    return _row_blocks(n, pairs_per_block)


def _worker_visibility(problem: FillProblem):
    """The visibility structures of ``problem`` on this worker, built once."""
    key = problem.key
    vis = _WORKER_VISIBILITY.get(key)
    if vis is None:
        while len(_WORKER_VISIBILITY) >= _WORKER_KEEP:
            _WORKER_VISIBILITY.pop(next(iter(_WORKER_VISIBILITY)))
        vis = _WORKER_VISIBILITY[key] = problem.visibility()
    return vis


def _run_block(problem: FillProblem, start: int, stop: int):
    """A task: one block on a worker (module-level, so it pickles by reference)."""
    return problem.block(_worker_visibility(problem), start, stop)


def run_blocks(problem: FillProblem, blocks: list[tuple[int, int]], *, client=None, visibility=None
               ) -> Iterator[tuple[int, tuple[np.ndarray, np.ndarray, np.ndarray, FillStats]]]:
    """Fill ``blocks``, yielding ``(block index, (i, j, v, stats))`` as each one completes.

    In process (``client=None``) blocks come in order, with ``visibility`` (built here if None);
    on a cluster in the order they finish.
    """
    if client is None:
        vis = problem.visibility() if visibility is None else visibility
        for k, (start, stop) in enumerate(blocks):
            yield k, problem.block(vis, start, stop)
        return
    from distributed import as_completed

    shared = client.scatter(problem, broadcast=True, hash=False)
    futures = {client.submit(_run_block, shared, start, stop, pure=False, key=f"radiosity-block-{k}-{problem.key}"): k
               for k, (start, stop) in enumerate(blocks)}
    for future in as_completed(futures):
        yield futures[future], future.result()
        future.release()


def cluster_block_pairs(n: int, client=None, pairs_per_block: int = FILL_PAIRS // 2) -> int:
    """Pairs per block on ``client``'s cluster: no more than ``pairs_per_block``, and small enough
    that every worker gets about ``TASKS_PER_WORKER`` blocks (a one-block fill would use one)."""
    if client is None:
        return pairs_per_block
    workers = max(1, len(client.scheduler_info().get("workers", {})))
    total = n * (n - 1) // 2
    return int(max(MIN_TASK_PAIRS, min(pairs_per_block, total // (TASKS_PER_WORKER * workers) + 1)))


def fill_matrix(problem: FillProblem, *, client=None, progress: Callable[[int], None] | None = None,
                pairs_per_block: int | None = None) -> tuple[sp.csr_matrix, FillStats]:
    """The sparse F of ``problem`` and its statistics, in process or on ``client``'s cluster.

    ``progress(rows)`` is called as each block completes. The blocks are put together in row
    order; a block's factors do not depend on the blocking, so the result is the in-process
    fill's, bit for bit. ``pairs_per_block`` default: :func:`cluster_block_pairs`.
    """
    if pairs_per_block is None:
        pairs_per_block = cluster_block_pairs(problem.n, client)
    blocks = blocks_of(problem.n, pairs_per_block)
    parts: list = [None] * len(blocks)
    stats = FillStats()
    for k, (i, j, v, block_stats) in run_blocks(problem, blocks, client=client):
        parts[k] = (i, j, v)
        add_stats(stats, block_stats)
        if progress is not None:
            progress(blocks[k][1] - blocks[k][0])
    return coo_parts_to_csr(parts, problem.n), stats


@contextlib.contextmanager
def cluster_client(workers: int | None = None, scheduler: str | None = None):
    """A ``distributed.Client``: to the cluster at ``scheduler``, or to a new local cluster of
    ``workers`` processes (one Dask thread each; numba's loops get cores / workers threads each),
    closed on exit.
    Yields None when neither is given (the in-process fill)."""
    if workers is None and scheduler is None:
        yield None
        return
    if workers is not None and scheduler is not None:
        raise ValueError("give workers (a local cluster) or scheduler (an existing one), not both")
    if workers is not None and (not isinstance(workers, int) or workers < 1):
        raise ValueError(f"workers must be a positive number of processes, got {workers!r}")
    try:
        from distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - depends on the installation
        raise ImportError("the cluster fill needs dask.distributed: pip install 'radiosity[cluster]'") from None
    if scheduler is not None:
        with Client(scheduler) as client:
            yield client
        return
    # numba's parallel loops take every core in each process: split the cores between the
    # workers instead of running N x cores threads (unless the user set NUMBA_NUM_THREADS).
    threads = os.environ.get("NUMBA_NUM_THREADS") or str(max(1, (os.cpu_count() or 1) // workers))
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                      env={"NUMBA_NUM_THREADS": threads}) as cluster, Client(cluster) as client:
        yield client

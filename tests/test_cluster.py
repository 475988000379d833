"""The fill on a 2-worker Dask LocalCluster: the in-process matrix bit for bit, and blocks lost
with a worker run again.

One cluster serves the whole module (starting one costs more than every fill here), on a
106-patch Cornell box; each expensive result (the in-process fill, the first cluster fill) is a
module fixture that several tests read, and the worker kill comes last among the cluster tests
(its restarted worker would otherwise start cold under the others)."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

pytest.importorskip("embreex")
distributed = pytest.importorskip("distributed")

import radiosity  # noqa: E402
from radiosity.methods.uniform import cluster  # noqa: E402
from radiosity.methods.uniform.assembly import FillSettings, assemble  # noqa: E402

PAIRS = 400  # pairs per block: the small scene becomes about a dozen tasks


@pytest.fixture(scope="module")
def client():
    with cluster.cluster_client(workers=2) as c:
        yield c


@pytest.fixture(scope="module")
def problem():
    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"), max_patch_size=0.2)
    settings = FillSettings(visibility="auto", visibility_rtol=1e-4, formfactor_rtol=1e-5)  # cheap: no shadow cells
    active = np.ones(scene.n_patches, bool)
    active[::11] = False  # inactive patches are left out of F, and still block
    return cluster.FillProblem.from_scene(scene, settings, active)


@pytest.fixture(scope="module")
def local(problem):
    vis = problem.visibility()
    return assemble(problem.quads, problem.normals, problem.centroid, problem.area, vis, problem.settings,
                    active=problem.active, pairs_per_block=PAIRS)


def same_bits(A, B):
    A, B = A.tocsr(), B.tocsr()
    A.sort_indices()
    B.sort_indices()
    return (A.shape == B.shape and np.array_equal(A.indptr, B.indptr) and np.array_equal(A.indices, B.indices)
            and A.data.tobytes() == B.data.tobytes())


@pytest.fixture(scope="module")
def on_cluster(client, problem):
    """The cluster fill in blocks of PAIRS, its progress calls, and each worker's visibility cache
    right after it."""
    done = []
    F, stats = cluster.fill_matrix(problem, client=client, progress=done.append, pairs_per_block=PAIRS)
    built = client.run(lambda: list(cluster._WORKER_VISIBILITY))
    return F, stats, done, built


def test_two_workers_give_the_local_matrix_bit_for_bit(problem, local, on_cluster):
    F_local, stats_local = local
    F, stats, done, _ = on_cluster
    assert len(cluster.blocks_of(problem.n, PAIRS)) > 8
    assert same_bits(F, F_local)
    assert F.nnz > 0 and stats.n_traced_pairs > 0  # occlusion was exercised
    assert (stats.n_pairs, stats.n_rays, stats.n_exact_pairs) == (stats_local.n_pairs, stats_local.n_rays,
                                                                  stats_local.n_exact_pairs)
    assert sum(done) == problem.n  # progress counted every row once


def test_the_blocking_does_not_change_the_bits(client, problem, local):
    """The cluster's own block plan (here one block: the scene has fewer pairs than a task's
    minimum) against the in-process fill in blocks of PAIRS."""
    own = cluster.cluster_block_pairs(problem.n, client)
    assert len(cluster.blocks_of(problem.n, own)) < len(cluster.blocks_of(problem.n, PAIRS))
    F, _ = cluster.fill_matrix(problem, client=client)
    assert same_bits(F, local[0])


def test_each_worker_builds_visibility_once(problem, on_cluster):
    """Visibility structures are cached per worker by the problem's key: one entry per worker
    that ran a block, however many blocks it ran."""
    built = on_cluster[3]
    assert all(keys in ([], [problem.key]) for keys in built.values())
    assert any(built.values())


def test_view_factors_takes_workers(client, problem):
    """The public API with ``scheduler=``: the same matrix as without."""
    scene = radiosity.load_scene(radiosity.bundled_scene("unit_cube"), max_patch_size=0.5)
    F0 = radiosity.view_factors(scene, preset="draft", cache=False)
    F1 = radiosity.view_factors(scene, preset="draft", cache=False, scheduler=client.scheduler.address)
    assert same_bits(F0, F1)


def test_bad_worker_counts_are_refused():
    with pytest.raises(ValueError, match="workers"):
        with cluster.cluster_client(workers=0):
            pass
    with pytest.raises(ValueError, match="not both"):
        with cluster.cluster_client(workers=1, scheduler="tcp://127.0.0.1:1"):
            pass


def test_cli_scheduler(client, tmp_path, capsys):
    """``radiosity viewfactors --scheduler ADDRESS``: the same F.npz matrix as the in-process CLI."""
    import scipy.sparse as sp

    from radiosity.cli import main

    obj = str(radiosity.bundled_scene("unit_cube"))
    args = ["viewfactors", obj, "--max-patch-size", "0.5", "--preset", "draft", "--no-cache"]
    assert main(args + ["-o", str(tmp_path / "a.npz")]) == 0
    assert main(args + ["-o", str(tmp_path / "b.npz"), "--scheduler", client.scheduler.address]) == 0
    assert same_bits(sp.load_npz(tmp_path / "a.npz"), sp.load_npz(tmp_path / "b.npz"))
    assert main(["viewfactors", obj, "-o", str(tmp_path / "c.npz"), "--workers", "0"]) == 2
    capsys.readouterr()


def test_a_block_lost_with_its_worker_is_run_again(client, problem, local):
    """SIGKILL one worker process once the first block is back: its blocks run elsewhere (the
    nanny restarts the worker), and F is unchanged."""
    F_local, _ = local
    pids = list(client.run(os.getpid).values())
    blocks = cluster.blocks_of(problem.n, PAIRS)
    parts = [None] * len(blocks)
    killed = False
    for k, (i, j, v, _) in cluster.run_blocks(problem, blocks, client=client):
        parts[k] = (i, j, v)
        if not killed:
            os.kill(pids[0], signal.SIGKILL)
            killed = True
    from radiosity.methods.uniform.assembly import coo_parts_to_csr

    assert all(p is not None for p in parts)
    assert pids[0] not in client.run(os.getpid).values()  # the worker did die mid-run
    assert same_bits(coo_parts_to_csr(parts, problem.n), F_local)

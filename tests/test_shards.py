"""Out-of-core view factors: shards written as filled, read lazily, solved from the shards."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("embreex")

import radiosity  # noqa: E402
from radiosity import _memory  # noqa: E402
from radiosity._errors import MemoryBudgetError  # noqa: E402
from radiosity.cli import main  # noqa: E402


# view_factors' tolerances but for the form factors' (1e-6 there): exact shadows still decide the
# partly occluded pairs (visibility_rtol 1e-6), at a ninth of the fill's time.
TOLERANCES = {"formfactor_rtol": 1e-4}


@pytest.fixture(scope="module")
def scene():
    return radiosity.load_scene(radiosity.bundled_scene("cornell_box"), max_patch_size=0.2)


@pytest.fixture(scope="module")
def in_memory(scene):
    return radiosity.view_factors(scene, cache=False, **TOLERANCES)


@pytest.fixture(scope="module")
def sharded(scene, tmp_path_factory):
    path = tmp_path_factory.mktemp("vf") / "F.shards"
    radiosity.write_view_factors(scene, path, pairs_per_block=1500, **TOLERANCES)
    return radiosity.load_view_factors(path)


def test_shards_hold_the_in_memory_matrix(sharded, in_memory):
    assert sharded.n_blocks > 2
    assert sharded.shape == in_memory.shape and sharded.nnz == in_memory.nnz
    assert (sharded.tocsr() != in_memory).nnz == 0  # the same factors, bit for bit
    assert sharded.index["stats"]["n_exact_pairs"] > 0  # exact shadow clipping was exercised


def test_lazy_rows_blocks_and_products(sharded, in_memory):
    rng = np.random.default_rng(3)
    x = rng.random(sharded.shape[0])
    np.testing.assert_allclose(sharded @ x, in_memory @ x, rtol=1e-13, atol=1e-15)
    X = rng.random((sharded.shape[0], 3))
    np.testing.assert_allclose(sharded @ X, in_memory @ X, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(sharded.rmatvec(x), in_memory.T @ x, rtol=1e-13, atol=1e-15)
    a, b = sharded.blocks[1]
    assert (sharded[a:b] != in_memory[a:b]).nnz == 0
    assert (sharded[b] != in_memory[b]).nnz == 0
    total = sum(sharded.block(k) for k in range(sharded.n_blocks))
    assert (total != in_memory).nnz == 0  # the shards partition F


def test_solve_from_shards_matches_the_in_memory_solve(sharded, scene, in_memory):
    """(I - rho F) B = E by bicgstab over the shards equals a direct solve of the same F."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    B = sharded.solve(rtol=1e-12)
    A = (sp.identity(scene.n_patches) - sp.diags(scene.reflectance[:, 0]) @ in_memory).tocsc()
    np.testing.assert_allclose(B[:, 0], spla.spsolve(A, scene.emission[:, 0]), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(sharded.solve(method="gmres", rtol=1e-12), B, rtol=1e-8, atol=1e-9)


def test_index_describes_the_folder(sharded):
    index = json.loads((sharded.path / "index.json").read_text())
    assert index["format"] == "radiosity-shards/1"
    assert sum(s["nnz"] for s in index["shards"]) == index["nnz"]
    starts = [s["start"] for s in index["shards"]]
    stops = [s["stop"] for s in index["shards"]]
    assert starts[0] == 0 and stops[-1] == index["shape"][0] and starts[1:] == stops[:-1]
    assert sharded.patches()["area"].shape == (index["shape"][0],)


def test_block_size_follows_the_budget():
    big = _memory.plan_fill_block(18_000, budget=4 << 30)
    small = _memory.plan_fill_block(18_000, budget=300 << 20)
    assert small < big
    # one block's temporaries (and the scene's) stay within the budget
    assert 18_000 * _memory.BYTES_PER_FILL_PATCH + 2 * small * _memory.BYTES_PER_BLOCK_PAIR <= 300 << 20
    with pytest.raises(MemoryBudgetError, match="out-of-core"):
        _memory.plan_fill_block(18_000, budget=18 << 20)


def test_not_a_shard_folder_is_refused(tmp_path):
    with pytest.raises(ValueError, match="not a view-factor shard folder"):
        radiosity.load_view_factors(tmp_path)


def test_cli_out_of_core_under_a_budget_smaller_than_the_matrix(tmp_path, monkeypatch, capsys):
    """240 patches: the in-memory fill (up to 2.07 MB) is refused under a 2 MB budget; --out-of-core
    fills it in blocks of about 1,100 pairs."""
    obj = str(radiosity.bundled_scene("cornell_box"))
    args = ["viewfactors", obj, "--max-patch-size", "0.12", "--preset", "draft", "--no-cache"]
    budget = 2_000_000
    assert _memory.fill_bytes(240) > budget
    monkeypatch.setenv(_memory.ENV_BUDGET, str(budget))
    assert main(args + ["-o", str(tmp_path / "F.npz")]) == 2
    assert "budget" in capsys.readouterr().err
    out = tmp_path / "F.shards"
    assert main(args + ["--out-of-core", "-o", str(out)]) == 0
    assert "shards" in capsys.readouterr().out
    F = radiosity.load_view_factors(out)
    assert F.shape == (240, 240) and F.n_blocks > 10
    assert F.index["pairs_per_block"] == _memory.plan_fill_block(240, budget=budget)
    monkeypatch.delenv(_memory.ENV_BUDGET)
    whole = radiosity.compute_view_factors(radiosity.load_scene(obj), preset="draft", max_patch_size=0.12,
                                           cache=False).F
    assert (F.tocsr() != whole).nnz == 0  # what the in-memory fill gives where it fits
    assert main(args + ["--out-of-core", "--vf", str(tmp_path / "x.vf"), "-o", str(out)]) == 2
    assert "--out-of-core" in capsys.readouterr().err


def test_a_shard_folder_on_a_disk_too_small_is_refused_before_any_shard(scene, tmp_path, monkeypatch):
    """The shards' worst case is checked against the file system of the (not yet made) folder."""
    import shutil
    from collections import namedtuple

    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage(10**9, 10**9 - 10**4, 10**4))
    target = tmp_path / "new" / "F.shards"
    with pytest.raises(OSError, match="needs up to .* on disk for its shards") as caught:
        radiosity.write_view_factors(scene, target)
    assert not (tmp_path / "new").exists()
    assert "larger disk" in str(caught.value) and "TMPDIR" not in str(caught.value)  # the user chose the folder

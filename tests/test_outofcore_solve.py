"""``solve`` when F does not fit the memory budget: filled into shards, solved over them.

The Cornell box cut to 240 patches needs up to 2.07 MB for the in-memory fill; under a 2 MB
budget ``solve`` fills it out of core (about 1,100 pairs per block) and iterates over the
shards, and gets the in-memory solve's radiosity within the solver's tolerance.
"""

from __future__ import annotations

import gc
import importlib

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("embreex")

import radiosity  # noqa: E402
from radiosity import _memory  # noqa: E402
from radiosity._errors import MemoryBudgetError  # noqa: E402
from radiosity.methods.uniform.outofcore import solve_shards  # noqa: E402
from radiosity.methods.uniform.shards import ShardedViewFactors  # noqa: E402

_solve_module = importlib.import_module("radiosity.solve")  # the module (radiosity.solve is the function)

SIZE = 0.12  # metres: 240 patches
BUDGET = 2_000_000  # bytes: below the in-memory fill's 2.07 MB, above the out-of-core fill's 1.85 MB


@pytest.fixture(scope="module")
def scene():
    return radiosity.load_scene(radiosity.bundled_scene("cornell_box"))


@pytest.fixture(scope="module")
def in_memory(scene):
    """The in-memory solve, with rows above 1 left as filled: the shard solve does not bound them
    (system.bound_rows), and this compares the two solvers on one matrix."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(_solve_module, "bound_rows",
                   lambda F, area: (F, 0))
        return radiosity.solve(scene, preset="draft", max_patch_size=SIZE, cache=False)


@pytest.fixture(scope="module")
def out_of_core(scene):
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(_memory.ENV_BUDGET, str(BUDGET))
        return radiosity.solve(scene, preset="draft", max_patch_size=SIZE, cache=False)


def test_the_budget_sits_between_the_two_fills(in_memory):
    n = in_memory.scene.n_patches
    assert _memory.fill_bytes(n) > BUDGET  # the in-memory fill would be refused
    assert _memory.plan_fill_block(n, budget=BUDGET) < n * (n - 1) // 2 // 10  # at least ten blocks


def test_out_of_core_solve_gives_the_in_memory_radiosity(in_memory, out_of_core):
    assert in_memory.view_factor_storage == {"where": "in memory"}
    storage = out_of_core.view_factor_storage
    assert storage["where"] == "out of core" and storage["shards"] >= 10
    assert isinstance(out_of_core.F, ShardedViewFactors)
    assert (out_of_core.F.tocsr() != in_memory.F).nnz == 0  # the same matrix, from the shards
    B, B0 = out_of_core.radiosity, in_memory.radiosity
    assert np.isfinite(B).all()
    # both solves stop at relative residual ~1e-10; the system is well conditioned (rho F < 0.8)
    np.testing.assert_allclose(B, B0, rtol=1e-7, atol=1e-8 * B0.max())
    assert max(out_of_core.solver.residual) <= 1e-8
    np.testing.assert_allclose(out_of_core.patch_irradiance, in_memory.patch_irradiance, rtol=1e-7,
                               atol=1e-8 * B0.max())


def test_out_of_core_energy_balances(out_of_core, in_memory):
    e = {k: np.array(v) for k, v in out_of_core.energy.items()}
    np.testing.assert_allclose(e["absorbed"] + e["escaped"], e["emitted"], rtol=1e-7)
    for k, v in in_memory.energy.items():
        np.testing.assert_allclose(e[k], v, rtol=1e-7)


def test_summary_says_out_of_core(out_of_core, in_memory):
    from radiosity.cli._solve import format_summary

    assert out_of_core.summary()["view_factors"]["where"] == "out of core"
    assert in_memory.summary()["view_factors"] == {"where": "in memory"}
    text = format_summary(out_of_core, 0.0)
    assert "matrix     out of core: F needs up to" in text and "shards of" in text
    assert "out of core" not in format_summary(in_memory, 0.0)


def test_shards_are_removed_with_the_matrix(scene, monkeypatch):
    monkeypatch.setenv(_memory.ENV_BUDGET, str(BUDGET))
    solution = radiosity.solve(scene, preset="draft", max_patch_size=SIZE, cache=False, solver="bicgstab")
    assert "bicgstab" in solution.solver.method
    folder = solution.F.path
    assert (folder / "index.json").is_file()
    del solution
    gc.collect()
    assert not folder.parent.exists()


def test_a_budget_too_small_even_for_shards_keeps_the_refusal(scene, monkeypatch):
    monkeypatch.setenv(_memory.ENV_BUDGET, "1000000")  # below the out-of-core fill's 1.85 MB
    with pytest.raises(MemoryBudgetError, match="view-factor matrix of 240 patches needs .*max-patch-size"):
        radiosity.solve(scene, preset="draft", max_patch_size=SIZE, cache=False)
    monkeypatch.setenv(_memory.ENV_BUDGET, str(BUDGET))
    with pytest.raises(MemoryBudgetError, match="direct solver needs F in memory"):
        radiosity.solve(scene, preset="draft", max_patch_size=SIZE, cache=False, solver="direct")


def _system(seed: int, n: int):
    """A random sparse F with row sums below 1, reflectances below 1, one channel unlit."""
    rng = np.random.default_rng(seed)
    F = sp.random(n, n, density=0.3, random_state=rng, format="csr")
    F = sp.diags(rng.uniform(0.2, 1.0, n) / np.maximum(np.asarray(F.sum(axis=1)).ravel(), 1e-12)) @ F
    rho = rng.uniform(0.0, 0.95, (n, 3))
    e = rng.uniform(0.0, 5.0, (n, 3)) * (rng.random((n, 1)) < 0.3)
    e[:, 2] = 0.0
    return F.tocsr(), rho, e


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 60), method=st.sampled_from(["auto", "bicgstab", "jacobi"]))
def test_solve_shards_matches_a_direct_solve(seed, n, method):
    """The channel-sharing iteration gives each channel's direct solution; an unlit channel stays 0."""
    F, rho, e = _system(seed, n)
    B, info = solve_shards(F, rho, e, method=method, rtol=1e-10)
    for c in range(3):
        A = (sp.identity(n) - sp.diags(rho[:, c]) @ F).tocsc()
        exact = spla.spsolve(A, e[:, c]) if e[:, c].any() else np.zeros(n)
        np.testing.assert_allclose(B[:, c], np.clip(exact, 0, None), rtol=1e-7, atol=1e-8 * max(1.0, np.abs(exact).max()))
    assert not B[:, 2].any()
    assert max(info["residual"]) <= 1e-8 and info["passes"] >= 1


def test_solve_shards_refuses_solvers_that_need_F():
    F, rho, e = _system(0, 5)
    with pytest.raises(ValueError, match="needs F in memory"):
        solve_shards(F, rho, e, method="direct")


def test_a_disk_too_small_for_the_shards_is_refused_before_the_fill(scene, monkeypatch, tmp_path):
    """The shards' worst case (16 bytes a pair) is checked against the free space first: the fill
    never starts, no shard folder is left, and the message names the estimate and the knobs."""
    import shutil
    import tempfile
    from collections import namedtuple

    monkeypatch.setenv(_memory.ENV_BUDGET, str(BUDGET))
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda path: usage(10**9, 10**9 - 10**5, 10**5))
    with pytest.raises(OSError, match=r"needs up to .* on disk for its shards .* TMPDIR") as caught:
        radiosity.solve(scene, preset="draft", max_patch_size=SIZE, cache=False)
    assert caught.value.errno == 28  # ENOSPC: the CLI's one-line exit 2
    assert not list(tmp_path.iterdir())  # no radiosity-F-* folder was made


def test_the_out_of_core_summary_states_the_disk_estimate(out_of_core):
    n = out_of_core.scene.n_patches
    assert out_of_core.view_factor_storage["disk_estimate"] == _memory.format_bytes(n * n * 16)

"""The form-factor cache stays under its cap (least recently used go first); `radiosity cache info|clear`."""

from __future__ import annotations

import os

import pytest
import scipy.sparse as sp

from radiosity.methods.uniform.assembly import FillSettings, FillStats
from radiosity.methods.uniform.cache import FormFactorCache, cache_dir
from radiosity.cli import main


def _matrix(seed: int) -> sp.csr_matrix:
    return sp.random(60, 60, density=0.2, random_state=seed, format="csr")


def _stats() -> FillStats:
    import dataclasses

    return FillStats(**{f.name: 0 for f in dataclasses.fields(FillStats)})


def _store(cache, key, seed, when):
    path = cache.store(key, FillSettings(), _matrix(seed), _stats())
    os.utime(path, (when, when))  # a controlled LRU clock
    return path


def test_least_recently_used_are_evicted_first(tmp_path):
    cache = FormFactorCache(tmp_path, limit=10**9)
    paths = [_store(cache, f"geometry-{k}", k, 1_000_000 + k) for k in range(4)]
    size = paths[0].stat().st_size
    assert cache.load("geometry-0", FillSettings()) is not None  # a hit: now the most recent
    cache.limit = int(2.5 * size)
    new = cache.store("geometry-new", FillSettings(), _matrix(9), _stats())
    left = {p.name for p, _, _ in cache.entries()}
    assert left == {paths[0].name, new.name}  # 1, 2, 3 were least recently used
    assert sum(s for _, s, _ in cache.entries()) <= cache.limit
    F, _ = cache.load("geometry-0", FillSettings())
    assert (F != _matrix(0)).nnz == 0


def test_the_entry_just_written_is_kept_even_over_the_cap(tmp_path):
    cache = FormFactorCache(tmp_path, limit=1)
    path = cache.store("big", FillSettings(), _matrix(1), _stats())
    assert path.exists() and [p for p, _, _ in cache.entries()] == [path]


def test_cache_size_from_the_environment(tmp_path, monkeypatch):
    from radiosity.methods.uniform.cache import cache_limit

    monkeypatch.setenv("RADIOSITY_CACHE_SIZE", "500M")
    assert cache_limit() == 500 * 2**20
    monkeypatch.setenv("RADIOSITY_CACHE_SIZE", "lots")
    with pytest.raises(ValueError, match="RADIOSITY_CACHE_SIZE"):
        cache_limit()


def test_cli_cache_info_and_clear(capsys):
    cache = FormFactorCache(cache_dir())
    for k in range(3):
        _store(cache, f"g{k}", k, 2_000_000 + k)
    (cache.folder / "stray.tmp").write_bytes(b"x")
    total = sum(s for _, s, _ in cache.entries())
    assert main(["cache", "info"]) == 0
    out = capsys.readouterr().out
    assert str(cache.folder) in out and "entries    3," in out and "2 GiB" in out
    assert main(["cache", "clear"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("removed 3 entries") and str(cache.folder) in out
    assert cache.entries() == [] and not (cache.folder / "stray.tmp").exists()
    assert total > 0
    assert main(["cache", "info"]) == 0
    assert "entries    0, 0 bytes" in capsys.readouterr().out


def test_cli_cache_needs_an_action(capsys):
    assert main(["cache"]) == 2
    assert "required: action" in capsys.readouterr().err

"""A disk cache of view-factor matrices keyed by geometry and accuracy settings.

F depends only on the patches and the fill settings, never on materials, so changing a colour
or a light re-solves from the cached F. Entries are written to a temporary file and renamed,
and carry a checksum of their payload: a torn or corrupted entry is detected, dropped and
rebuilt.

The cache is capped (``$RADIOSITY_CACHE_SIZE``, default 2 GiB): after each store the least
recently used entries (by modification time, which a hit refreshes) are removed until the
rest fits. The entry just written is always kept. ``radiosity cache info|clear`` shows and
empties it.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import tempfile
from dataclasses import asdict
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from .assembly import FillSettings, FillStats

__all__ = ["FormFactorCache", "cache_dir", "cache_limit"]

FORMAT_VERSION = 1
# Part of every key: bump it when the fill gives different numbers for the same settings, so
# that no cached matrix of the older rules is served. 2: the fine preset's exact shadows at fixed
# receiver points (visibility._constants.SHADOW_CELLS_BELOW), after SHADOW_ORDER_EXTRA. 3: exact
# shadows outside the cells on adaptively refined receiver squares (Visibility.adaptive_hidden).
# 4: those squares start about square on elongated patches, and at view_factors' tolerances
# check their corners for kinks; shadow cells out of points retry, then fall back, and take
# pairs behind up to 8 occluders (2026-12-04). 5: shadow cells integrate quadrilaterals with a
# tensor Gauss rule, not as two triangles, far ones with a Bernstein-ellipse bound, and take
# pairs behind up to 16 occluders (session 16). 6: at view_factors' tolerances the squares test
# for shadows between their points to 6 levels and split to 7 (SHADOW_TIGHT_MAX_DEPTH), and shadow
# cells whose grading was capped are settled on both sides (Visibility._settle_capped). 7: an
# occluder whose crossings lie inside it or on its edges hides the whole pair, coplanar occluders
# of different objects merge, squares keep their own occluders (session 21). 8: shadow cells out
# of points try the source's side, looser fills test one level for penumbrae (session 25), and
# the squares cut needle triangles from their tips (formfactors.tip_collapsed, session 26).
# 9: each separated pair takes its own two-area order and raw-sum choice, not its run's
# (F no longer depends on the fill's block sizes; session 27).
FILL_VERSION = 9
ENV_SIZE = "RADIOSITY_CACHE_SIZE"
DEFAULT_LIMIT = 2 << 30  # 2 GiB: a few hundred Cornell-box-sized matrices, a handful of big ones


def cache_limit() -> int:
    """Bytes the cache may hold: ``$RADIOSITY_CACHE_SIZE`` (``500M``, ``4G``, bytes) or 2 GiB."""
    from ..._memory import _parse_bytes

    text = os.environ.get(ENV_SIZE)
    if not text:
        return DEFAULT_LIMIT
    try:
        return _parse_bytes(text)
    except ValueError:
        raise ValueError(f"{ENV_SIZE} must be a number of bytes (e.g. 500M, 4G), got {text!r}") from None


def cache_dir() -> Path:
    """``$RADIOSITY_CACHE`` or ``$XDG_CACHE_HOME/radiosity`` or ``~/.cache/radiosity``."""
    env = os.environ.get("RADIOSITY_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "radiosity"


class FormFactorCache:
    """View-factor matrices on disk, one ``.npz`` per (geometry, settings) key."""

    def __init__(self, folder: Path, limit: int | None = None):
        self.folder = Path(folder)
        self.limit = limit

    @classmethod
    def default(cls) -> "FormFactorCache":
        return cls(cache_dir())

    @staticmethod
    def key(geometry_hash: str, settings: FillSettings) -> str:
        text = json.dumps({"geometry": geometry_hash, "settings": asdict(settings), "v": FORMAT_VERSION,
                           "fill": FILL_VERSION}, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:32]

    def path(self, geometry_hash: str, settings: FillSettings) -> Path:
        return self.folder / f"F-{self.key(geometry_hash, settings)}.npz"

    @staticmethod
    def _checksum(F: sp.csr_matrix) -> str:
        h = hashlib.sha256()
        for arr in (F.data, F.indices, F.indptr):
            h.update(np.ascontiguousarray(arr).tobytes())
        return h.hexdigest()

    def load(self, geometry_hash: str, settings: FillSettings) -> tuple[sp.csr_matrix, FillStats] | None:
        """The cached F and its fill statistics, or None (missing, stale or corrupted)."""
        path = self.path(geometry_hash, settings)
        if not path.exists():
            return None
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                F = sp.csr_matrix((z["data"], z["indices"], z["indptr"]), shape=tuple(meta["shape"]))
            if meta.get("checksum") != self._checksum(F) or meta.get("geometry") != geometry_hash:
                raise ValueError("checksum mismatch")
            _touch(path)  # recently used: the last to be evicted
            return F, FillStats(**meta["stats"])
        except Exception:  # noqa: BLE001 - any unreadable entry is rebuilt, never trusted
            path.unlink(missing_ok=True)
            return None

    def store(self, geometry_hash: str, settings: FillSettings, F: sp.csr_matrix, stats: FillStats) -> Path | None:
        """Write an entry atomically; a cache that cannot be written is skipped silently."""
        path = self.path(geometry_hash, settings)
        meta = {"shape": list(F.shape), "checksum": self._checksum(F), "geometry": geometry_hash,
                "stats": asdict(stats), "settings": asdict(settings)}
        tmp = None
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=self.folder, suffix=".tmp")
            with os.fdopen(fd, "wb") as fh:
                np.savez(fh, data=F.data, indices=F.indices, indptr=F.indptr, meta=json.dumps(meta))
            os.replace(tmp, path)
            self.evict(keep=path)
            return path
        except OSError:
            return None
        finally:
            # An interrupted write (Ctrl-C, full disk) leaves no stray temporary file.
            if tmp is not None and os.path.exists(tmp):
                os.unlink(tmp)

    def entries(self) -> list[tuple[Path, int, float]]:
        """Cache entries as (path, bytes, last used), least recently used first."""
        out = []
        try:
            candidates = list(self.folder.glob("F-*.npz"))
        except OSError:
            return []
        for path in candidates:
            try:
                st = path.stat()
            except OSError:  # removed meanwhile by another process
                continue
            out.append((path, st.st_size, st.st_mtime))
        return sorted(out, key=lambda e: (e[2], e[0].name))

    def evict(self, *, keep: Path | None = None, limit: int | None = None) -> list[Path]:
        """Remove least recently used entries until the cache fits ``limit``; returns them."""
        limit = limit if limit is not None else (self.limit if self.limit is not None else cache_limit())
        entries = self.entries()
        total = sum(size for _, size, _ in entries)
        removed = []
        for path, size, _ in entries:
            if total <= limit:
                break
            if keep is not None and path == keep:
                continue
            try:
                path.unlink()
            except OSError:
                continue
            total -= size
            removed.append(path)
        return removed

    def info(self) -> dict:
        """Folder, number of entries, bytes held and the cap."""
        entries = self.entries()
        return {"folder": str(self.folder), "entries": len(entries), "bytes": sum(e[1] for e in entries),
                "limit": self.limit if self.limit is not None else cache_limit()}

    def clear(self) -> tuple[int, int]:
        """Remove every entry (and stray temporary files); returns (entries, bytes) removed."""
        count = size = 0
        for path, nbytes, _ in self.entries():
            try:
                path.unlink()
            except OSError:
                continue
            count += 1
            size += nbytes
        for stray in self.folder.glob("*.tmp") if self.folder.is_dir() else ():
            with contextlib.suppress(OSError):
                stray.unlink()
        return count, size


def _touch(path: Path) -> None:
    """Mark an entry as just used (its mtime is the LRU clock; atime is often not kept)."""
    with contextlib.suppress(OSError):
        os.utime(path)

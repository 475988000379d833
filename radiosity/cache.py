"""A disk cache of view-factor matrices keyed by geometry and accuracy settings.

F depends only on the patches and the fill settings, never on materials, so changing a colour
or a light re-solves from the cached F. Entries are written to a temporary file and renamed,
and carry a checksum of their payload: a torn or corrupted entry is detected, dropped and
rebuilt.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from dataclasses import asdict
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from .assembly import FillSettings, FillStats

__all__ = ["FormFactorCache", "cache_dir"]

FORMAT_VERSION = 1


def cache_dir() -> Path:
    """``$RADIOSITY_CACHE`` or ``$XDG_CACHE_HOME/radiosity`` or ``~/.cache/radiosity``."""
    env = os.environ.get("RADIOSITY_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "radiosity"


class FormFactorCache:
    """View-factor matrices on disk, one ``.npz`` per (geometry, settings) key."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)

    @classmethod
    def default(cls) -> "FormFactorCache":
        return cls(cache_dir())

    @staticmethod
    def key(geometry_hash: str, settings: FillSettings) -> str:
        text = json.dumps({"geometry": geometry_hash, "settings": asdict(settings), "v": FORMAT_VERSION},
                          sort_keys=True)
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
            return path
        except OSError:
            return None
        finally:
            # An interrupted write (Ctrl-C, full disk) leaves no stray temporary file.
            if tmp is not None and os.path.exists(tmp):
                os.unlink(tmp)

"""Files written atomically: to a temporary name beside the target, renamed into place on success.

An interrupted or failed run never leaves a half-written file or destroys an earlier one. Every
writer of the package (results, view-factor matrices, View3D models, HTML pages) goes through here.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

__all__ = ["atomic_path", "atomic_paths"]


@contextlib.contextmanager
def atomic_path(target: str | Path):
    """Yield a temporary path beside ``target``; rename it onto ``target`` on success only."""
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.stem}-", suffix=target.suffix)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; results should be readable like any file
    try:
        yield Path(tmp)
        os.replace(tmp, target)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)


@contextlib.contextmanager
def atomic_paths(targets: list[str | Path]):
    """Temporary paths beside each target, all renamed onto their targets only if the block succeeds.

    A run that writes several files (``F.npz`` and ``F.vf``) either leaves all of them new or
    all of them as they were, never one of each (short of a failure between two renames).
    """
    targets = [Path(t) for t in targets]
    if len({t.resolve() for t in targets}) != len(targets):
        raise ValueError(f"two outputs go to the same file: {', '.join(map(str, targets))}")
    with contextlib.ExitStack() as stack:
        temps = []
        for target in targets:
            target.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.stem}-", suffix=target.suffix)
            os.close(fd)
            stack.callback(_unlink, tmp)
            temps.append(Path(tmp))
        yield temps
        umask = os.umask(0)
        os.umask(umask)
        for tmp, target in zip(temps, targets):
            os.chmod(tmp, 0o666 & ~umask)
            os.replace(tmp, target)


def _unlink(path) -> None:
    with contextlib.suppress(FileNotFoundError):
        os.unlink(path)

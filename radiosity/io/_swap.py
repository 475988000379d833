"""Publishing a run's outputs in one step: the staging folder and OUTDIR swap places.

``staged_outputs`` (export.py) has every output written into a staging folder beside OUTDIR.
When all of it is written, the user's own files in OUTDIR (anything this kind of run does not
write) are hard-linked into the staging folder, and the two folders are exchanged by one
``renameat2(RENAME_EXCHANGE)`` call: OUTDIR holds the old set up to that instant and the new
set from it on, with no moment in between. The old folder, now at the staging path, is then
removed; user subfolders (which cannot be hard-linked) are moved back from it first.

Where the exchange is not possible (not Linux, a file system without it, OUTDIR a mount point or
otherwise on another file system than its parent, its parent not writable, or OUTDIR the current
folder or above it, whose swap would leave the shell in a deleted folder), the outputs are renamed
in one by one, each atomically, as before.

A staging folder's name holds the owning process's id; a later run removes those whose process
is gone (after moving back any user subfolder an exchange left in one).
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import os
import re
import shutil
import stat
import tempfile
from pathlib import Path

__all__ = ["STAGING_PREFIX", "make_stage", "publish", "restore_subfolders", "sweep_stale"]

STAGING_PREFIX = ".radiosity-partial-"
_OWNER = re.compile(r"-(\d+)-[^-]*$")
_AT_FDCWD = -100
_RENAME_EXCHANGE = 2


def make_stage(folder: Path) -> tuple[Path, bool]:
    """A new staging folder for outputs going to ``folder`` (which exists), and whether it sits
    beside ``folder`` (True: publish by exchange) or inside it (False: file by file)."""
    pid = os.getpid()
    if _can_swap(folder):
        try:
            return Path(tempfile.mkdtemp(dir=folder.parent, prefix=f"{STAGING_PREFIX}{folder.name}-{pid}-")), True
        except OSError:
            pass  # the parent is not writable: stage inside
    return Path(tempfile.mkdtemp(dir=folder, prefix=f"{STAGING_PREFIX}-{pid}-")), False


def _can_swap(folder: Path) -> bool:
    try:
        here = Path.cwd().resolve()
    except OSError:
        here = None
    if here is not None and (here == folder or folder in here.parents):
        return False
    if folder.parent == folder or _renameat2() is None:
        return False
    try:  # a mount point (a container's volume): beside it is another file system
        return os.stat(folder).st_dev == os.stat(folder.parent).st_dev
    except OSError:
        return False


def _renameat2():
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        function = libc.renameat2
    except (OSError, AttributeError):
        return None
    function.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    function.restype = ctypes.c_int
    return function


def exchange(a: Path, b: Path) -> bool:
    """Swap the folders at ``a`` and ``b`` atomically; False if this system cannot."""
    function = _renameat2()
    if function is None:
        return False
    if function(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.ENOSYS, errno.EINVAL, errno.EXDEV, errno.EBUSY, errno.EPERM, errno.ENOTSUP):
        return False
    raise OSError(code, os.strerror(code), str(b))


def publish(stage: Path, folder: Path, owned: tuple[str, ...], beside: bool, swapped: list) -> None:
    """Make the outputs in ``stage`` the ones in ``folder``; names in ``owned`` this run did not
    write are dropped, every other file of ``folder`` is kept. ``swapped`` gets an entry the
    moment the folders are exchanged (the stage path then holds the old folder)."""
    written = {p.name for p in stage.iterdir() if not p.name.startswith(".")}
    if beside and _swap(stage, folder, written, set(owned), swapped):
        return
    for name in sorted(written):
        os.replace(stage / name, folder / name)
    for name in set(owned) - written:
        with contextlib.suppress(FileNotFoundError, IsADirectoryError):
            (folder / name).unlink()


def _swap(stage: Path, folder: Path, written: set[str], owned: set[str], swapped: list) -> bool:
    """Link the user's files into ``stage``, exchange the folders, move the user's subfolders
    back; False (nothing changed in ``folder``) if the exchange is not possible here."""
    subfolders = []
    for entry in os.scandir(folder):
        if entry.name in written or entry.name in owned or entry.name.startswith(STAGING_PREFIX):
            continue
        if entry.is_dir(follow_symlinks=False):
            subfolders.append(entry.name)
        else:
            _link_or_copy(Path(entry.path), stage / entry.name)
    os.chmod(stage, stat.S_IMODE(os.stat(folder).st_mode))  # mkdtemp makes 0700
    if not exchange(stage, folder):
        return False
    swapped.append(True)
    restore_subfolders(stage, folder)  # the exchange put the old folder at the stage path
    return True


def _link_or_copy(source: Path, target: Path) -> None:
    try:
        os.link(source, target, follow_symlinks=False)
    except OSError:  # no hard links on this file system, or a special file
        if source.is_symlink():
            os.symlink(os.readlink(source), target)
        else:
            shutil.copy2(source, target)


def sweep_stale(folder: Path) -> None:
    """Remove staging folders of ``folder`` left by processes that are gone.

    Only files can be in a stale one that are also in ``folder`` (outputs, or links to the
    user's files); a subfolder in one is the user's, left by an exchange cut short, and goes
    back into ``folder``.
    """
    for place, of in ((folder.parent, folder.name), (folder, "")):
        with contextlib.suppress(OSError):
            for entry in os.scandir(place):
                if not (entry.name.startswith(STAGING_PREFIX) and entry.is_dir(follow_symlinks=False)):
                    continue
                owner = _OWNER.search(entry.name)
                name = entry.name[len(STAGING_PREFIX):owner.start()] if owner else ""
                if place == folder.parent and name != of:
                    continue  # another folder's (or not ours at all)
                if owner is None or not _alive(int(owner.group(1))):
                    restore_subfolders(Path(entry.path), folder)
                    shutil.rmtree(entry.path, ignore_errors=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True  # someone else's process, or not a process id: leave it
    return True


def restore_subfolders(old: Path, folder: Path) -> None:
    """Move the subfolders of the old folder ``old`` (after an exchange) back into ``folder``."""
    with contextlib.suppress(OSError):
        for entry in os.scandir(old):
            if entry.is_dir(follow_symlinks=False) and not (folder / entry.name).exists():
                with contextlib.suppress(OSError):
                    os.rename(entry.path, folder / entry.name)

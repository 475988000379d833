"""Outputs are published by one folder exchange (``io/_swap.py``): OUTDIR holds the whole old
set or the whole new one, the user's own files and folders in it survive, and staging folders
never outlive their run."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

import radiosity.io._swap as swap
from radiosity.io.export import STAGING_PREFIX, staged_outputs

OWNED = ("summary.json", "picture.png", "irradiance.csv")
needs_exchange = pytest.mark.skipif(swap._renameat2() is None, reason="no renameat2 here")


def _leftovers(folder):
    places = [folder.parent] + ([folder] if folder.exists() else [])
    return [p.name for place in places for p in place.iterdir() if p.name.startswith(STAGING_PREFIX)]


def _old_run(out):
    out.mkdir()
    (out / "summary.json").write_text("old")
    (out / "picture.png").write_text("old picture")
    (out / "notes.txt").write_text("mine")  # the user's
    (out / "drafts").mkdir()
    (out / "drafts" / "a.txt").write_text("mine too")
    os.symlink("notes.txt", out / "link.txt")


@needs_exchange
def test_a_run_swaps_the_folder_and_keeps_the_users_files(tmp_path):
    out = tmp_path / "out"
    _old_run(out)
    os.chmod(out, 0o750)
    before = os.stat(out).st_ino
    with staged_outputs(out, owned=OWNED) as stage:
        assert stage.parent == tmp_path  # staged beside OUTDIR, not in it
        (stage / "summary.json").write_text("new")
    assert os.stat(out).st_ino != before  # one folder replaced the other
    assert (out / "summary.json").read_text() == "new"
    assert not (out / "picture.png").exists()  # owned, not written this time: not passed off as new
    assert (out / "notes.txt").read_text() == "mine"
    assert (out / "drafts" / "a.txt").read_text() == "mine too"
    assert os.readlink(out / "link.txt") == "notes.txt"
    assert oct(os.stat(out).st_mode & 0o777) == oct(0o750)
    assert not _leftovers(out)


def test_a_failure_leaves_the_old_set_whole(tmp_path):
    out = tmp_path / "out"
    _old_run(out)
    with pytest.raises(RuntimeError):
        with staged_outputs(out, owned=OWNED) as stage:
            (stage / "summary.json").write_text("new")
            raise RuntimeError
    assert (out / "summary.json").read_text() == "old"
    assert (out / "picture.png").read_text() == "old picture"
    assert (out / "drafts" / "a.txt").exists() and not _leftovers(out)


@needs_exchange
def test_a_failure_at_the_exchange_leaves_the_old_set_whole(tmp_path, monkeypatch):
    out = tmp_path / "out"
    _old_run(out)

    def broken(a, b):
        raise KeyboardInterrupt  # a signal at the worst moment: everything linked, nothing swapped

    monkeypatch.setattr(swap, "exchange", broken)
    with pytest.raises(KeyboardInterrupt):
        with staged_outputs(out, owned=OWNED) as stage:
            (stage / "summary.json").write_text("new")
    assert (out / "summary.json").read_text() == "old"
    assert sorted(p.name for p in out.iterdir()) == ["drafts", "link.txt", "notes.txt", "picture.png", "summary.json"]
    assert not _leftovers(out)


@needs_exchange
def test_a_signal_right_after_the_exchange_keeps_the_users_subfolders(tmp_path, monkeypatch):
    out = tmp_path / "out"
    _old_run(out)

    def interrupted(old, folder):
        raise KeyboardInterrupt  # before the subfolders were moved back

    real = swap.restore_subfolders
    monkeypatch.setattr(swap, "restore_subfolders", interrupted)
    with pytest.raises(KeyboardInterrupt):
        with staged_outputs(out, owned=OWNED) as stage:
            (stage / "summary.json").write_text("new")
    monkeypatch.setattr(swap, "restore_subfolders", real)
    assert (out / "summary.json").read_text() == "new"  # the swap happened: the new set, whole
    assert (out / "drafts" / "a.txt").read_text() == "mine too"  # the clean-up moved it back
    assert not _leftovers(out)


def test_without_the_exchange_files_are_renamed_in(tmp_path, monkeypatch):
    out = tmp_path / "out"
    _old_run(out)
    monkeypatch.setattr(swap, "exchange", lambda a, b: False)
    with staged_outputs(out, owned=OWNED) as stage:
        (stage / "summary.json").write_text("new")
    assert (out / "summary.json").read_text() == "new" and not (out / "picture.png").exists()
    assert (out / "notes.txt").read_text() == "mine" and (out / "drafts" / "a.txt").exists()
    assert not _leftovers(out)


def test_outdir_the_current_folder_is_not_swapped(tmp_path, monkeypatch):
    """Swapping the folder a shell is in would leave it in a deleted folder: file by file then."""
    out = tmp_path / "out"
    _old_run(out)
    monkeypatch.chdir(out)
    before = os.stat(out).st_ino
    with staged_outputs(".", owned=OWNED) as stage:
        assert stage.parent == out
        (stage / "summary.json").write_text("new")
    assert os.stat(out).st_ino == before and (out / "summary.json").read_text() == "new"
    assert not _leftovers(out)


def test_stale_staging_folders_are_swept(tmp_path):
    out = tmp_path / "out"
    _old_run(out)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True).stdout.strip()
    beside = tmp_path / f"{STAGING_PREFIX}out-{dead}-abc"  # an exchange cut short by SIGKILL
    (beside / "kept").mkdir(parents=True)
    (beside / "summary.json").write_text("x")
    inside = out / f"{STAGING_PREFIX}zz81"  # an older version's, inside OUTDIR
    inside.mkdir()
    alive = tmp_path / f"{STAGING_PREFIX}out-{os.getpid()}-live"  # a running process's: left alone
    alive.mkdir()
    other = tmp_path / f"{STAGING_PREFIX}out-7-{dead}-abc"  # folder "out-7"'s: not ours to sweep
    other.mkdir()
    with staged_outputs(out, owned=OWNED) as stage:
        (stage / "summary.json").write_text("new")
    assert not beside.exists() and not inside.exists()
    assert (out / "kept").is_dir()  # the user's subfolder went back
    assert alive.exists() and other.exists()


def test_outdir_on_another_file_system_than_its_parent_is_staged_inside(tmp_path, monkeypatch):
    """A mount point: a stage beside it would be on the parent's file system (no rename across)."""
    out = tmp_path / "out"
    _old_run(out)
    real_stat = os.stat

    def other_device(path, *args, **kwargs):
        info = real_stat(path, *args, **kwargs)
        if os.fspath(path) == os.fspath(out):
            fields = list(info)
            fields[2] += 1  # st_dev
            return os.stat_result(fields)
        return info

    monkeypatch.setattr(swap.os, "stat", other_device)
    with staged_outputs(out, owned=OWNED) as stage:
        assert stage.parent == out
        (stage / "summary.json").write_text("new")
    monkeypatch.setattr(swap.os, "stat", real_stat)
    assert (out / "summary.json").read_text() == "new" and (out / "drafts" / "a.txt").exists()
    assert not _leftovers(out)

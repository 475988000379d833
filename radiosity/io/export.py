"""Writing results: summary.json, PLY, VTP, PNG and the view-factor .npz, all atomically.

Every file is written to a temporary name in the target folder and renamed into place, so
an interrupted or failed run never leaves a half-written file or destroys an earlier one.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import scipy.sparse as sp

__all__ = ["atomic_path", "staged_outputs", "write_summary", "write_ply", "write_vtp", "write_png", "write_view_factors"]


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


STAGING_PREFIX = ".radiosity-partial-"


@contextlib.contextmanager
def staged_outputs(folder: str | Path):
    """Yield a hidden staging folder inside ``folder``; move its files into ``folder`` on success.

    Every output of a run is written into the staging folder first. Only when the whole block
    succeeds are the files renamed into ``folder`` (each rename is atomic), so a run that fails
    or is interrupted leaves the outputs of an earlier run untouched, not a mix of old and new.
    The folder is created (and checked for writing) on entry, before any long computation; if
    it was created here and the run fails, it is removed again.

    Raises
    ------
    NotADirectoryError
        ``folder`` exists and is not a folder.
    OSError
        ``folder`` cannot be created or written to.
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, "exists and is not a folder; give -o a folder", str(folder))
    created = not folder.exists()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        stage = Path(tempfile.mkdtemp(dir=folder, prefix=STAGING_PREFIX))
    except OSError as exc:
        if created:
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise OSError(exc.errno, f"cannot write outputs there ({exc.strerror or exc})", str(folder)) from exc
    ok = False
    try:
        yield stage
        for item in sorted(stage.iterdir()):
            if not item.name.startswith("."):
                os.replace(item, folder / item.name)
        ok = True
    finally:
        shutil.rmtree(stage, ignore_errors=True)
        if not ok and created:
            with contextlib.suppress(OSError):
                folder.rmdir()  # only if empty


def write_summary(summary: dict, path: str | Path) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(summary, indent=2) + "\n")


def write_ply(solution, path: str | Path) -> None:
    """Binary PLY: vertices with radiosity (float) and sRGB colour; faces with radiosity."""
    from ..viz import auto_exposure, tone_map

    vertices, faces, vertex_b = solution.vertex_mesh
    colour = tone_map(vertex_b / np.pi, auto_exposure(solution))
    vdtype = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("radiosity_r", "<f4"), ("radiosity_g", "<f4"),
                       ("radiosity_b", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    vrec = np.empty(len(vertices), dtype=vdtype)
    for name, col in zip(("x", "y", "z"), vertices.T):
        vrec[name] = col
    for k, c in enumerate("rgb"):
        vrec[f"radiosity_{c}"] = vertex_b[:, k]
    for name, col in zip(("red", "green", "blue"), colour.T):
        vrec[name] = col
    header = ["ply", "format binary_little_endian 1.0", "comment radiosity W/m^2 per vertex and per face",
              f"element vertex {len(vertices)}"]
    header += [f"property float {n}" for n in ("x", "y", "z", "radiosity_r", "radiosity_g", "radiosity_b")]
    header += ["property uchar red", "property uchar green", "property uchar blue",
               f"element face {len(faces)}", "property list uchar int vertex_indices",
               "property float radiosity_r", "property float radiosity_g", "property float radiosity_b",
               "end_header"]
    chunks = []
    for f, b in zip(faces, solution.radiosity.astype("<f4")):
        chunks.append(np.uint8(len(f)).tobytes() + np.asarray(f, "<i4").tobytes() + b.tobytes())
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        fh.write(("\n".join(header) + "\n").encode())
        fh.write(vrec.tobytes())
        fh.write(b"".join(chunks))


def write_vtp(solution, path: str | Path) -> None:
    from ..viz import to_polydata

    with atomic_path(path) as tmp:
        to_polydata(solution).save(str(tmp.with_suffix(".vtp")) if tmp.suffix != ".vtp" else str(tmp))


def write_png(solution, path: str | Path, **kwargs) -> float:
    from ..viz import render

    with atomic_path(path) as tmp:
        return render(solution, tmp, **kwargs)


def write_view_factors(F: sp.csr_matrix, area: np.ndarray, patch_object: np.ndarray, objects: list[str],
                       path: str | Path) -> None:
    """``F.npz`` readable by ``scipy.sparse.load_npz``, plus ``area``, ``patch_object``, ``objects``."""
    F = F.tocsr()
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, format=np.array("csr"), shape=np.array(F.shape), data=F.data, indices=F.indices,
                            indptr=F.indptr, area=area, patch_object=patch_object, objects=np.array(objects))

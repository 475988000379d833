"""Writing results: summary.json, PLY, VTP, PNG and the view-factor .npz, all atomically.

Every file is written to a temporary name in the target folder and renamed into place, so
an interrupted or failed run never leaves a half-written file or destroys an earlier one.
"""

from __future__ import annotations

import contextlib
import errno
import json
import shutil
import tempfile
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ._files import atomic_path, atomic_paths
from ._swap import STAGING_PREFIX, make_stage, publish, restore_subfolders, sweep_stale

__all__ = ["STAGING_PREFIX", "atomic_path", "atomic_paths", "staged_outputs", "triangles", "write_summary", "write_ply",
           "write_vtp", "write_png", "write_glb", "write_view_factors", "view_factor_arrays", "write_vf"]




# Bytes a solve's outputs take per patch (VTP + PLY + glb + HTML, measured on the Cornell box:
# about 620 per patch), with room to spare, plus the picture and summary.
OUTPUT_BYTES_PER_PATCH = 2048
OUTPUT_BYTES_FIXED = 4 << 20
OUTPUT_BYTES_PER_POINT = 160  # irradiance.csv


def output_bytes(n_patches: int, n_points: int = 0) -> int:
    """A generous estimate of the bytes ``radiosity solve`` writes for a solution."""
    return OUTPUT_BYTES_FIXED + OUTPUT_BYTES_PER_PATCH * int(n_patches) + OUTPUT_BYTES_PER_POINT * int(n_points)


def check_free_space(folder: str | Path, needed: int) -> None:
    """Refuse before writing when ``folder``'s file system has less than ``needed`` bytes free.

    VTK aborts the whole process (SIGABRT, no message) when a write runs out of space half-way,
    so a full disk has to be caught before the first file is written.
    """
    free = shutil.disk_usage(folder).free
    if free < needed:
        raise OSError(errno.ENOSPC, f"not enough free space to write the outputs: about {needed / 1e6:,.1f} MB "
                                    f"needed, {free / 1e6:,.1f} MB free", str(folder))


@contextlib.contextmanager
def staged_outputs(folder: str | Path, owned: tuple[str, ...] = ()):
    """Yield a hidden staging folder for the outputs of ``folder``; publish them on success.

    Every output of a run is written into the staging folder first (beside ``folder``). Only
    when the whole block succeeds do the two folders swap places, in one atomic exchange
    (``io/_swap.py``): ``folder`` holds the whole old set or the whole new one at every moment,
    so a run that fails or is interrupted, even during the publishing, leaves the outputs of an
    earlier run untouched. Files of ``folder`` that this run does not own (anything not named
    in ``owned`` and not written) are the user's: they are kept, hard-linked into the new
    folder before the swap, and user subfolders are moved over after it. Files named in
    ``owned`` that this run did not write are dropped, so an earlier run's ``picture.png`` or
    ``irradiance.csv`` does not pass for this run's. Where the exchange is not possible the
    files are renamed in one by one (each atomically). The staging folder is removed on every
    way out, and stale ones of dead processes are swept up on entry.

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
    target = folder
    try:
        folder.mkdir(parents=True, exist_ok=True)
        target = folder.resolve()  # a symlink to a folder: its target is what swaps
        sweep_stale(target)
        Path(tempfile.mkdtemp(dir=target, prefix=STAGING_PREFIX)).rmdir()  # can we write there?
        stage, beside = make_stage(target)
    except OSError as exc:
        if created:
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise OSError(exc.errno, f"cannot write outputs there ({exc.strerror or exc})", str(folder)) from exc
    ok = False
    swapped: list = []
    try:
        yield stage
        publish(stage, target, owned, beside, swapped)
        ok = True
    finally:
        if swapped:  # the stage path holds the old folder: the user's subfolders go back first
            restore_subfolders(stage, target)
        shutil.rmtree(stage, ignore_errors=True)
        if not ok and created:
            with contextlib.suppress(OSError):
                target.rmdir()  # only if empty


def write_summary(summary: dict, path: str | Path) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(summary, indent=2) + "\n")


def triangles(solution) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The solved mesh as triangles: vertices (v, 3), triangles (t, 3) and each one's patch (t,).

    Each patch outline of ``Solution.vertex_mesh`` (which carries its neighbours' T-junction
    vertices) is fanned from its first corner; triangles of collinear corners (zero area) are
    dropped, so every triangle is proper and every patch keeps at least one.
    """
    vertices, faces, _ = solution.vertex_mesh
    counts = np.array([len(f) - 2 for f in faces])
    tris = np.concatenate([np.column_stack([np.full(len(f) - 2, f[0]), f[1:-1], f[2:]]) for f in faces])
    patch = np.repeat(np.arange(len(faces)), counts)
    a, b, c = (vertices[tris[:, k]] for k in range(3))
    twice_area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    keep = twice_area > 1e-12 * max(solution.scene.scale, 1e-300) ** 2
    return vertices, tris[keep], patch[keep]


def write_ply(solution, path: str | Path) -> None:
    """ASCII PLY of triangles, readable by trimesh, meshio, pyvista/VTK and MeshLab.

    Vertex properties: ``x y z``, float ``radiosity_r/g/b`` (W/m^2, area-weighted over the
    patches of one object meeting there) and 8-bit sRGB ``red green blue`` (the picture's tone
    map). Face properties: float ``radiosity_r/g/b`` (the patch's value), ``patch`` (row of
    ``Solution.radiosity``) and ``object`` (index into the ``comment object`` names).
    Faces are triangles because several readers refuse mixed polygon sizes.
    """
    from ..viz import auto_exposure, tone_map

    vertices, tris, patch = triangles(solution)
    vertex_b = solution.vertex_mesh[2]
    colour = tone_map(vertex_b / np.pi, auto_exposure(solution))
    header = ["ply", "format ascii 1.0", "comment radiosity W/m^2 per vertex and per face",
              "comment red green blue: sRGB of radiance B/pi times the picture's exposure"]
    header += [f"comment object {k} {name}" for k, name in enumerate(solution.scene.objects)]
    header += [f"element vertex {len(vertices)}"]
    header += [f"property float {n}" for n in ("x", "y", "z", "radiosity_r", "radiosity_g", "radiosity_b")]
    header += ["property uchar red", "property uchar green", "property uchar blue",
               f"element face {len(tris)}", "property list uchar int vertex_indices",
               "property float radiosity_r", "property float radiosity_g", "property float radiosity_b",
               "property int patch", "property int object", "end_header"]
    # ASCII: meshio's binary reader takes face properties column by column, which misreads any
    # binary PLY with more than the vertex list per face; every reader agrees on ASCII.
    vertex_rows = np.column_stack([vertices, vertex_b, colour])
    face_rows = np.column_stack([np.full(len(tris), 3), tris, solution.radiosity[patch], patch,
                                 solution.scene.patch_object[patch]])
    with atomic_path(path) as tmp, open(tmp, "w", encoding="ascii") as fh:
        fh.write("\n".join(header) + "\n")
        np.savetxt(fh, vertex_rows, fmt=["%.9g"] * 6 + ["%d"] * 3)
        np.savetxt(fh, face_rows, fmt=["%d"] * 4 + ["%.9g"] * 3 + ["%d"] * 2)


def write_vtp(solution, path: str | Path) -> None:
    from ..viz import to_polydata

    with atomic_path(path) as tmp:
        to_polydata(solution).save(str(tmp.with_suffix(".vtp")) if tmp.suffix != ".vtp" else str(tmp))


def write_png(solution, path: str | Path, **kwargs) -> float:
    from ..viz import render

    with atomic_path(path) as tmp:
        return render(solution, tmp, **kwargs)


def write_view_factors(F, area: np.ndarray | None = None, patch_object: np.ndarray | None = None,
                       objects: list[str] | None = None, path: str | Path | None = None, *, grouped=None) -> None:
    """``F.npz`` readable by ``scipy.sparse.load_npz``, with the patches it belongs to.

    Either ``write_view_factors(vf, path=...)`` with a :class:`radiosity.factors.ViewFactors`
    (everything below is taken from it, so the file is consistent by construction), or the
    older ``write_view_factors(F, area, patch_object, objects, path)``.

    Besides the matrix (``format``, ``shape``, ``data``, ``indices``, ``indptr``) the file holds
    ``area``, ``patch_object``, ``objects`` and, from a ViewFactors, ``patch_quads``,
    ``patch_face``, ``patch_hidden``, ``patch_obstruction``, ``sky_factor``, ``enforced``,
    ``formfactor_rtol``, ``visibility_rtol``; with ``grouped`` (a
    :class:`radiosity.factors.SurfaceFactors`) also ``group_by``, ``group_names``,
    ``group_area``, ``group_sky_factor``, ``patch_group`` and the summed matrix as
    ``group_data``, ``group_indices``, ``group_indptr``, ``group_shape`` (CSR).

    Raises
    ------
    ValueError
        Arrays that do not belong to the matrix (lengths differ from its size).
    """
    if path is None and isinstance(area, (str, Path)):
        path, area = area, None
    arrays = view_factor_arrays(F, area, patch_object, objects, grouped=grouped)
    with atomic_path(path) as tmp:
        save_arrays(arrays, tmp)


def save_arrays(arrays: dict, path: Path) -> None:
    with open(path, "wb") as fh:
        np.savez_compressed(fh, **arrays)


def view_factor_arrays(F, area=None, patch_object=None, objects=None, *, grouped=None) -> dict:
    """The arrays of a view-factor ``.npz`` (see :func:`write_view_factors`), checked for size."""
    extra = {}
    if hasattr(F, "scene"):  # a ViewFactors
        vf, scene = F, F.scene
        F, area, patch_object, objects = vf.F, scene.patch_area, scene.patch_object, scene.objects
        extra = {"patch_quads": scene.patch_quads, "patch_face": scene.patch_face, "patch_hidden": scene.patch_hidden,
                 "patch_obstruction": scene.patch_obstruction, "sky_factor": vf.sky_factor,
                 "enforced": np.array(vf.enforced), **{k: np.array(v) for k, v in vf.settings.items()}}
        if vf.error is not None:  # same layout as F: error_data, error_indices, error_indptr
            E = sp.csr_matrix(vf.error)
            extra.update(error_data=E.data, error_indices=E.indices, error_indptr=E.indptr)
    F = sp.csr_matrix(F)
    n = F.shape[0]
    if F.shape != (n, n) or len(area) != n or len(patch_object) != n:
        msg = (f"view-factor matrix {F.shape} with {len(area)} areas and {len(patch_object)} patch objects: "
               "they must all describe the same patches")
        raise ValueError(msg)
    arrays = {"format": np.array("csr"), "shape": np.array(F.shape), "data": F.data, "indices": F.indices,
              "indptr": F.indptr, "area": np.asarray(area), "patch_object": np.asarray(patch_object),
              "objects": np.array(objects), **extra}
    if grouped is not None:
        G = grouped.F.tocsr()
        arrays.update(group_by=np.array(grouped.by), group_names=np.array(grouped.names), group_area=grouped.area,
                      group_sky_factor=grouped.sky_factor, group_emissivity=grouped.emissivity,
                      patch_group=grouped.patch_group, group_data=G.data, group_indices=G.indices,
                      group_indptr=G.indptr, group_shape=np.array(G.shape))
    return arrays


# View3D's view-factor files (savevf.c of View3D 3.3): a header line of 30 characters plus the
# line end, "program version format encl emit N"; then the N areas, the N x N matrix row by
# row (F[m, n] = F(m -> n)) and the N emissivities. Format 0 is text, 1 is binary (float32).
VF_HEADER_WIDTH = 30


def vf_header(n: int, *, binary: bool, enclosure: bool, emit: bool = False) -> str:
    """View3D's header line, ``radiosity <version> <format> <encl> <emit> <N>`` padded to 30."""
    try:
        from importlib.metadata import version

        release = version("radiosity")
    except Exception:  # noqa: BLE001 - not installed: the header still needs a version word
        release = "0"
    tail = f" {int(binary)} {int(enclosure)} {int(emit)} {n}"
    head = f"radiosity {release}"[: VF_HEADER_WIDTH - len(tail)].rstrip()
    header = head + tail
    if len(header) > VF_HEADER_WIDTH:
        raise ValueError(f"{n} surfaces do not fit View3D's {VF_HEADER_WIDTH}-character header")
    return header.ljust(VF_HEADER_WIDTH)


def write_vf(F: sp.spmatrix, area: np.ndarray, emissivity: np.ndarray, path: str | Path, *, binary: bool = False,
             enclosure: bool = False, digits: int = 6) -> None:
    """Write F in View3D's output format (``.vf``), text (View3D's ``out=0``) or binary (``out=1``).

    Parameters
    ----------
    F : (n, n) sparse
        F[m, n] = F(m -> n); written dense, one row at a time.
    area : (n,) float
        Surface areas, m^2.
    emissivity : (n,) float
        Written as the last record (View3D's ``emit`` column).
    path : str or Path
    binary : bool, default: False
        View3D's binary layout: a 32-byte header ending in CR LF, then little-endian float32
        areas, rows and emissivities.
    enclosure : bool, default: False
        The ``encl`` flag of the header.
    digits : int, default: 6
        Decimals of the text matrix (View3D writes 6, which rounds factors under 5e-7 to 0).

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp, tempfile, pathlib
    >>> out = pathlib.Path(tempfile.mkdtemp()) / "F.vf"
    >>> write_vf(sp.csr_matrix(np.array([[0, 1.0], [0.5, 0.5]])), np.array([1.0, 2.0]), np.array([0.9, 0.9]), out)
    >>> out.read_text().splitlines()[1:]
    ['1 2', '0.000000 1.000000', '0.500000 0.500000', '0.900 0.900']
    """
    F = sp.csr_matrix(F)
    n = F.shape[0]
    if F.shape != (n, n) or len(area) != n or len(emissivity) != n:
        raise ValueError(f"view-factor matrix {F.shape}, {len(area)} areas and {len(emissivity)} emissivities differ")
    header = vf_header(n, binary=binary, enclosure=enclosure)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        if binary:
            fh.write(header.encode("ascii") + b"\r\n")
            fh.write(np.asarray(area, "<f4").tobytes())
        else:
            fh.write((header + "\n").encode("ascii"))
            fh.write((" ".join(f"{a:g}" for a in area) + "\n").encode("ascii"))
        for start in range(0, n, _VF_ROWS):
            block = F[start:start + _VF_ROWS].toarray()
            if binary:
                fh.write(block.astype("<f4").tobytes())
            else:
                fh.write("".join(" ".join(f"{v:.{digits}f}" for v in row) + "\n" for row in block).encode("ascii"))
        if binary:
            fh.write(np.asarray(emissivity, "<f4").tobytes())
        else:
            fh.write((" ".join(f"{e:.3f}" for e in emissivity) + "\n").encode("ascii"))


# Rows of F made dense at a time while writing a .vf (bounded memory for any n).
_VF_ROWS = 256


def read_vf(path: str | Path) -> dict:
    """Read a View3D ``.vf`` file (text or binary): ``header``, ``area``, ``F`` (dense), ``emissivity``."""
    raw = Path(path).read_bytes()
    header = raw[:VF_HEADER_WIDTH].decode("ascii", "replace")
    words = header.split()
    fmt, n = int(words[2]), int(words[5])
    if fmt == 1:
        values = np.frombuffer(raw[32:], "<f4").astype(float)
    else:
        values = np.array(raw[VF_HEADER_WIDTH:].split(), dtype=float)
    if len(values) != n * (n + 2):
        raise ValueError(f"{path}: expected {n * (n + 2)} numbers after the header, got {len(values)}")
    return {"header": header, "area": values[:n], "F": values[n:n + n * n].reshape(n, n), "emissivity": values[-n:]}


def linear_colours(radiance: np.ndarray, exposure: float) -> np.ndarray:
    """Radiance (..., 3) times exposure, clipped to [0, 1]: linear display values (glTF's COLOR_0)."""
    return np.clip(np.asarray(radiance) * exposure, 0.0, 1.0)


def _unlit(tree: dict) -> None:
    """glTF post-processing: every primitive gets one unlit white material (KHR_materials_unlit),
    so viewers show the baked radiosity as it is instead of lighting it again."""
    tree["materials"] = [{"name": "radiosity (baked, unlit)",
                          "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0],
                                                   "metallicFactor": 0.0, "roughnessFactor": 1.0},
                          "extensions": {"KHR_materials_unlit": {}}}]
    for mesh in tree.get("meshes", []):
        for primitive in mesh["primitives"]:
            primitive["material"] = 0
    used = set(tree.get("extensionsUsed", [])) | {"KHR_materials_unlit"}
    tree["extensionsUsed"] = sorted(used)


def write_glb(solution, path: str | Path, *, exposure: float | None = None) -> None:
    """glTF 2.0 binary (.glb): one node per object, radiosity baked into vertex colours.

    ``COLOR_0`` holds the radiance B/pi times ``exposure`` (the picture's, by default), clipped
    to [0, 1], as linear values (glTF's convention: viewers encode to sRGB on display). The
    material is unlit (``KHR_materials_unlit``). Each vertex also carries the float radiosity
    (W/m^2) as the application attribute ``_RADIOSITY``. Written with trimesh's exporter, with
    Ctrl-C and SIGTERM held back (:func:`radiosity._startup.signals_held`): trimesh imports its
    optional modules under ``except BaseException`` and keeps the exception in their place, so a
    signal landing in one of them became "TypeError: unsupported operand type(s) for |:
    'ExceptionWrapper'" (exit 1) instead of the clean interruption (exit 130/143).
    """
    from .._startup import signals_held

    with signals_held():
        _write_glb(solution, path, exposure)


def _write_glb(solution, path: str | Path, exposure: float | None) -> None:
    import trimesh

    from ..viz import auto_exposure

    exposure = auto_exposure(solution) if exposure is None else exposure
    vertices, tris, patch = triangles(solution)
    vertex_b = solution.vertex_mesh[2]
    colour = np.round(255 * linear_colours(vertex_b / np.pi, exposure)).astype(np.uint8)
    rgba = np.column_stack([colour, np.full(len(colour), 255, np.uint8)])
    scene = trimesh.Scene()
    tri_object = solution.scene.patch_object[patch]
    for index, name in enumerate(solution.scene.objects):
        own = tris[tri_object == index]
        if not len(own):
            continue
        used, local = np.unique(own, return_inverse=True)
        mesh = trimesh.Trimesh(vertices[used], local.reshape(-1, 3), vertex_colors=rgba[used], process=False)
        mesh.vertex_attributes["_RADIOSITY"] = vertex_b[used].astype(np.float32)
        scene.add_geometry(mesh, geom_name=name, node_name=name)
    data = trimesh.exchange.gltf.export_glb(scene, include_normals=False, tree_postprocessor=_unlit)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)

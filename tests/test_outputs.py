"""The files of a solve load where users load them: PLY in trimesh, meshio and pyvista, the
.vtp's name table, summary.json enough to reproduce the run, F.npz's hidden flags, no stale files."""

from __future__ import annotations

import json

import numpy as np
import pytest

import radiosity
from radiosity.cli import main
from radiosity.io.export import triangles, write_ply

from helpers import DATA, ROOM

# A floor with a block standing on it and a lamp above: the block's footprint is hidden.
BLOCK_SCENE = """mtllib room.mtl
o floor
usemtl grey
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
f 1 2 3 4
o block
v 0.4 0.4 0
v 0.6 0.4 0
v 0.6 0.6 0
v 0.4 0.6 0
v 0.4 0.4 0.2
v 0.6 0.4 0.2
v 0.6 0.6 0.2
v 0.4 0.6 0.2
f 5 8 7 6
f 9 10 11 12
f 5 6 10 9
f 6 7 11 10
f 7 8 12 11
f 8 5 9 12
o lamp
usemtl lamp
v 0.3 0.3 1
v 0.3 0.7 1
v 0.7 0.7 1
v 0.7 0.3 1
f 13 14 15 16
"""


@pytest.fixture(scope="module")
def solution():
    scene = radiosity.load_scene(ROOM)
    return radiosity.solve(scene, preset="draft", cache=False)


@pytest.fixture(scope="module")
def ply(solution, tmp_path_factory):
    path = tmp_path_factory.mktemp("ply") / "solution.ply"
    write_ply(solution, path)
    return path


def _triangle_area(vertices, tris):
    a, b, c = (vertices[tris[:, k]] for k in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def test_triangles_cover_every_patch_exactly(solution):
    vertices, tris, patch = triangles(solution)
    assert set(np.unique(patch)) == set(range(solution.scene.n_patches))
    area = np.bincount(patch, weights=_triangle_area(vertices, tris), minlength=solution.scene.n_patches)
    np.testing.assert_allclose(area, solution.scene.patch_area, rtol=1e-9)


def test_ply_reads_in_trimesh(solution, ply):
    import trimesh

    mesh = trimesh.load(ply, process=False)
    vertices, tris, patch = triangles(solution)
    assert isinstance(mesh, trimesh.Trimesh)
    np.testing.assert_allclose(mesh.vertices, vertices, atol=1e-7)
    np.testing.assert_array_equal(mesh.faces, tris)
    raw = mesh.metadata["_ply_raw"]
    vdata, fdata = raw["vertex"]["data"], raw["face"]["data"]
    vertex_b = np.column_stack([vdata[f"radiosity_{c}"] for c in "rgb"]).astype(float)
    np.testing.assert_allclose(vertex_b, solution.vertex_mesh[2], rtol=1e-7)
    face_b = np.column_stack([fdata[f"radiosity_{c}"] for c in "rgb"]).astype(float).reshape(-1, 3)
    np.testing.assert_allclose(face_b, solution.radiosity[patch], rtol=1e-7)
    assert mesh.visual.vertex_colors.shape == (len(vertices), 4)


def test_ply_reads_in_meshio(solution, ply):
    meshio = pytest.importorskip("meshio")
    mesh = meshio.read(ply)
    vertices, tris, patch = triangles(solution)
    assert [block.type for block in mesh.cells] == ["triangle"]
    np.testing.assert_array_equal(mesh.cells[0].data, tris)
    vertex_b = np.column_stack([mesh.point_data[f"radiosity_{c}"] for c in "rgb"])
    np.testing.assert_allclose(vertex_b, solution.vertex_mesh[2], rtol=1e-7)
    face_b = np.column_stack([mesh.cell_data[f"radiosity_{c}"][0] for c in "rgb"])
    np.testing.assert_allclose(face_b, solution.radiosity[patch], rtol=1e-7)
    np.testing.assert_array_equal(mesh.cell_data["object"][0], solution.scene.patch_object[patch])


def test_ply_reads_in_pyvista(solution, ply):
    import pyvista as pv

    vertices, tris, patch = triangles(solution)
    native = pv.read(ply)  # VTK's PLY reader: geometry and the 8-bit colours only
    assert native.n_points == len(vertices) and native.n_cells == len(tris)
    assert native.is_all_triangles
    full = pv.read_meshio(ply)  # every property, as float
    np.testing.assert_allclose(full.point_data["radiosity_r"], solution.vertex_mesh[2][:, 0], rtol=1e-7)
    np.testing.assert_allclose(full.cell_data["radiosity_g"], solution.radiosity[patch, 1], rtol=1e-7)


def test_ply_names_the_objects(solution, ply):
    header = ply.read_text().split("end_header")[0]
    for k, name in enumerate(solution.scene.objects):
        assert f"comment object {k} {name}" in header


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    out = tmp_path_factory.mktemp("solved") / "out"
    points = out.parent / "points.txt"
    points.write_text("0.5 0.5 0.01 0 0 1\n")
    assert main(["solve", str(ROOM), "--preset", "draft", "--no-picture", "-o", str(out),
                 "--points", str(points)]) == 0
    return out


def test_summary_records_the_run(solved):
    s = json.loads((solved / "summary.json").read_text())
    assert s["version"] == radiosity.__version__
    assert s["preset"] == "draft" and s["units"] == "m" and s["emission_mode"] == "radiance"
    assert s["options"]["solver"] == "auto" and s["options"]["no_picture"] is True
    assert s["options"]["points"].endswith("points.txt")
    draft = radiosity.Options.from_preset("draft")
    expected = {k: (v if not isinstance(v, float) or np.isfinite(v) else str(v)) for k, v in draft.__dict__.items()}
    expected.update(rtol=draft.solver_rtol, visibility_rtol=draft.visibility_atol)  # the old keys stay
    assert s["solver_options"] == expected
    assert s["exposure"] > 0 and "sRGB" in s["tone_map"] and "98th percentile" in s["tone_map"]
    assert set(s["timings_s"]) >= {"patches", "form factors", "visibility", "solve"}
    assert s["compile_s"] >= 0 and "compile" in s["compile_note"]
    assert s["outputs"] == ["solution.vtp", "solution.ply", "solution.glb", "irradiance.csv", "summary.json"]


def test_vtp_has_the_object_name_table(solved):
    import pyvista as pv

    mesh = pv.read(solved / "solution.vtp")
    names = list(mesh.field_data["object_names"])
    assert names == ["floor", "wall", "lamp"]
    ids = np.asarray(mesh.cell_data["object"])
    assert ids.min() >= 0 and ids.max() < len(names)


def test_stale_outputs_of_an_earlier_run_are_removed(solved, tmp_path, capsys):
    import shutil

    out = tmp_path / "out"
    shutil.copytree(solved, out)
    (out / "picture.png").write_bytes(b"an old picture")
    (out / "my notes.txt").write_text("the user's own file")
    assert main(["solve", str(ROOM), "--preset", "draft", "--no-picture", "-o", str(out)]) == 0
    capsys.readouterr()
    assert sorted(p.name for p in out.iterdir()) == ["my notes.txt", "solution.glb", "solution.ply",
                                                     "solution.vtp", "summary.json"]


def test_view_factor_file_has_hidden_flags(tmp_path, capsys):
    (tmp_path / "room.mtl").write_text((DATA / "room.mtl").read_text())
    scene_path = tmp_path / "block.obj"
    scene_path.write_text(BLOCK_SCENE)
    target = tmp_path / "F.npz"
    assert main(["viewfactors", str(scene_path), "-o", str(target), "--preset", "draft", "--no-cache"]) == 0
    capsys.readouterr()
    scene = radiosity.load_scene(scene_path)
    with np.load(target) as z:
        hidden = z["patch_hidden"]
        indptr = z["indptr"]
    assert hidden.dtype == bool and hidden.shape == (scene.n_patches,)
    np.testing.assert_array_equal(hidden, scene.patch_hidden)
    assert hidden.any()  # the block's footprint on the floor and its bottom face
    row_nnz = np.diff(indptr)
    assert (row_nnz[hidden] == 0).all()

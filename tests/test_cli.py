"""The command line, in process (meshio-style): exit codes, one-line errors, outputs kept safe."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from radiosity.cli import main
from radiosity.io.export import STAGING_PREFIX

from helpers import DATA, ROOM, assert_one_line_error, solve_args

OUTPUTS = ["solution.glb", "solution.ply", "solution.vtp", "summary.json"]


def snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    """One successful solve of the small room into OUTDIR (shared, never modified by tests)."""
    out = tmp_path_factory.mktemp("solved") / "out"
    assert main(solve_args(out)) == 0
    return out


def fresh_copy(solved: Path, tmp_path: Path) -> Path:
    out = tmp_path / "out"
    shutil.copytree(solved, out)
    return out


def test_solve_writes_outputs(tmp_path, capsys):
    points = tmp_path / "points.txt"
    points.write_text("# x y z nx ny nz\n0.5 0.5 0.01 0 0 1\n0.5, 0.9, 0.5, 0, -1, 0\n")
    out = tmp_path / "out"
    assert main(solve_args(out, "--points", str(points))) == 0
    stdout = capsys.readouterr().out
    assert "wrote" in stdout and "picture.png" not in stdout and "irradiance.csv" in stdout
    assert sorted(p.name for p in out.iterdir()) == ["irradiance.csv", *OUTPUTS]
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["objects"]) == {"floor", "wall", "lamp"}
    table = np.loadtxt(out / "irradiance.csv", delimiter=",", skiprows=1)
    assert table.shape == (2, 9) and np.isfinite(table).all() and (table[:, 6:] > 0).all()


def test_failed_solve_keeps_earlier_outputs(solved, tmp_path, capsys):
    out = fresh_copy(solved, tmp_path)
    before = snapshot(out)
    code = main(solve_args(out, scene=DATA / "bad_face_index_range.obj"))
    assert_one_line_error(capsys, code, "bad_face_index_range.obj:10: face 2 uses vertex 9")
    assert snapshot(out) == before


def test_solve_failing_while_writing_keeps_earlier_outputs(solved, tmp_path, capsys, monkeypatch):
    from radiosity.cli import _solve

    out = fresh_copy(solved, tmp_path)
    before = snapshot(out)

    def disk_full(summary, path):
        Path(path).write_text("{half")
        raise OSError(28, "No space left on device", str(path))

    monkeypatch.setattr(_solve, "write_summary", disk_full)
    code = main(solve_args(out))
    assert_one_line_error(capsys, code, "summary.json: No space left on device")
    assert snapshot(out) == before  # the new .vtp/.ply already written were not moved in


def test_interrupted_solve_keeps_outputs(solved, tmp_path, capsys, monkeypatch):
    from radiosity.cli import _solve

    out = fresh_copy(solved, tmp_path)
    before = snapshot(out)

    def ctrl_c(solution, path):
        Path(path).write_bytes(b"ply\npartial")
        raise KeyboardInterrupt

    monkeypatch.setattr(_solve, "write_ply", ctrl_c)
    assert main(solve_args(out)) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["radiosity: interrupted; earlier outputs and the cache are left as they were"]
    assert snapshot(out) == before
    assert not any(p.name.startswith(STAGING_PREFIX) for p in out.iterdir())


def test_memory_budget_refusal_is_one_line(solved, tmp_path, capsys, monkeypatch):
    out = fresh_copy(solved, tmp_path)
    before = snapshot(out)
    monkeypatch.setenv("RADIOSITY_MEMORY_BUDGET", "100000")
    code = main(solve_args(out, "--no-cache"))
    assert_one_line_error(capsys, code, "needs up to", "budget (set by RADIOSITY_MEMORY_BUDGET)", "--max-patch-size")
    assert snapshot(out) == before


def test_real_memory_error_is_one_line(tmp_path, capsys, monkeypatch):
    from radiosity.cli import _solve

    def out_of_memory(*args, **kwargs):
        raise MemoryError("Unable to allocate 359. GiB for an array")

    monkeypatch.setattr(_solve, "solve", out_of_memory)
    code = main(solve_args(tmp_path / "out"))
    assert_one_line_error(capsys, code, "ran out of memory (Unable to allocate 359. GiB", "--max-patch-size")
    assert not (tmp_path / "out").exists()


def test_huge_patch_count_refused(tmp_path, capsys):
    # Refused by the estimate once solve.py calls _memory.check_cut before re-cutting; until then
    # numpy's own MemoryError (728 TiB) is reported: one line, exit 2, the knob named, either way.
    code = main(solve_args(tmp_path / "out", "--max-patch-size", "1e-7"))
    assert_one_line_error(capsys, code, "--max-patch-size")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("name", ["bad_vertex_not_finite", "bad_mtllib_missing", "bad_unknown_material",
                                  "bad_mtl_reflectance_one", "bad_binary", "bad_all_degenerate"])
def test_bad_scene_is_one_line(tmp_path, capsys, name):
    code = main(solve_args(tmp_path / "out", scene=DATA / f"{name}.obj"))
    assert_one_line_error(capsys, code, f"{name}.")
    assert not (tmp_path / "out").exists()


def test_debug_shows_the_traceback(tmp_path):
    from radiosity import SceneError

    with pytest.raises(SceneError, match="uses vertex 9"):
        main(["--debug", *solve_args(tmp_path / "out", scene=DATA / "bad_face_index_range.obj")])
    with pytest.raises(SceneError):
        main([*solve_args(tmp_path / "out", scene=DATA / "bad_face_index_range.obj"), "--debug"])


@pytest.mark.parametrize("argv, part", [
    (["solve", "--preset", "dfault"], "argument --preset: invalid choice: 'dfault'"),
    (["solve", "--max-patch-size", "-1"], "must be a positive number of metres, got '-1'"),
    (["solve", "--max-patch-size", "nan"], "must be a positive number of metres, got 'nan'"),
    (["solve", "--units", "inch"], "argument --units: invalid choice: 'inch'"),
    (["solve", "--frobnicate"], "unrecognized arguments: --frobnicate"),
    (["viewfactors", str(ROOM)], "the following arguments are required: -o/--output"),
    ([], "the following arguments are required: command"),
])
def test_usage_errors_are_one_line(capsys, argv, part):
    assert_one_line_error(capsys, main(argv), part, "--help")


def test_help_exits_zero(capsys):
    assert main(["--help"]) == 0
    assert "solve" in capsys.readouterr().out


def test_missing_scene_and_bad_output_folder(tmp_path, capsys):
    code = main(solve_args(tmp_path / "out", scene=tmp_path / "nothere.obj"))
    assert_one_line_error(capsys, code, "OBJ file", "nothere.obj' does not exist")
    (tmp_path / "a_file").write_text("")
    code = main(solve_args(tmp_path / "a_file"))
    assert_one_line_error(capsys, code, "a_file: exists and is not a folder")


def test_unwritable_output_folder_fails_before_solving(tmp_path, capsys, monkeypatch):
    from radiosity.cli import _solve
    from radiosity.io import export

    def denied(**kwargs):
        raise PermissionError(13, "Permission denied", str(tmp_path / "out" / ".x"))

    def never(*args, **kwargs):
        raise AssertionError("solved before checking the output folder")

    monkeypatch.setattr(export.tempfile, "mkdtemp", denied)
    monkeypatch.setattr(_solve, "solve", never)
    code = main(solve_args(tmp_path / "out"))
    assert_one_line_error(capsys, code, "out: cannot write outputs there (Permission denied)")
    assert not (tmp_path / "out").exists()


def test_bad_points_file(tmp_path, capsys):
    points = tmp_path / "points.txt"
    for text, part in [("1 2 3\n", "points.txt:1: expected 6 finite numbers"),
                       ("0 0 0 0 0 0\n", "points.txt:1: the normal (nx ny nz) is zero"),
                       ("0 0 x 0 0 1\n", "points.txt:1: expected 6 numbers"),
                       ("# nothing\n", "points.txt: no points")]:
        points.write_text(text)
        assert_one_line_error(capsys, main(solve_args(tmp_path / "out", "--points", str(points))), part)
    code = main(solve_args(tmp_path / "out", "--points", str(tmp_path / "none.txt")))
    assert_one_line_error(capsys, code, "points file", "does not exist")


def test_no_emitter_says_the_solution_is_zero(tmp_path, capsys):
    (tmp_path / "room.mtl").write_text((DATA / "room.mtl").read_text())
    scene = tmp_path / "dark.obj"
    scene.write_text(ROOM.read_text().replace("usemtl lamp", "usemtl grey"))
    assert main(solve_args(tmp_path / "out", scene=scene)) == 0
    out = capsys.readouterr().out
    assert "note: " in out and "no face emits light" in out and "the solution is all zero" in out
    assert "nan" not in out.lower()
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert all(v == [0.0, 0.0, 0.0] for v in summary["objects"].values())


def test_units_note_and_option(tmp_path, capsys):
    (tmp_path / "room.mtl").write_text((DATA / "room.mtl").read_text())
    scene = tmp_path / "mm.obj"
    lines = []
    for line in ROOM.read_text().splitlines():
        if line.startswith("v "):
            line = "v " + " ".join(f"{1000 * float(t):g}" for t in line.split()[1:])
        lines.append(line)
    scene.write_text("\n".join(lines) + "\n")
    assert main(["viewfactors", str(scene), "-o", str(tmp_path / "F.npz"), "--preset", "draft"]) == 0
    err = capsys.readouterr().err
    assert "radiosity: note: " in err and "--units mm" in err
    assert main(["viewfactors", str(scene), "-o", str(tmp_path / "G.npz"), "--preset", "draft", "--units", "mm"]) == 0
    assert "--units mm" not in capsys.readouterr().err
    assert sp.load_npz(tmp_path / "G.npz").shape[0] > 0


def test_viewfactors_failure_keeps_earlier_file(tmp_path, capsys):
    target = tmp_path / "F.npz"
    assert main(["viewfactors", str(ROOM), "-o", str(target), "--preset", "draft"]) == 0
    capsys.readouterr()
    before = target.read_bytes()
    F = sp.load_npz(target)
    with np.load(target) as z:
        assert {"area", "patch_object", "objects"} <= set(z.files)
    assert F.shape[0] == F.shape[1] > 0
    code = main(["viewfactors", str(DATA / "bad_no_faces.obj"), "-o", str(target)])
    assert_one_line_error(capsys, code, "the scene has no faces")
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["F.npz"]


def test_view_rejects_what_is_not_a_result(tmp_path, capsys):
    code = main(["view", str(tmp_path / "missing")])
    assert_one_line_error(capsys, code, "no such result")
    (tmp_path / "x.vtp").write_text("not xml")
    assert_one_line_error(capsys, main(["view", str(tmp_path / "x.vtp")]), "not a radiosity result")
    (tmp_path / "y.vtp").write_text('<?xml version="1.0"?><VTKFile')
    assert_one_line_error(capsys, main(["view", str(tmp_path / "y.vtp")]), "not a radiosity result")


def test_bundled_cornell_box_with_picture(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["solve", "--preset", "draft", "-o", str(out)]) == 0
    assert "picture.png" in capsys.readouterr().out
    assert (out / "picture.png").stat().st_size > 1000
    assert sorted(p.name for p in out.iterdir()) == ["picture.png", *OUTPUTS]


def test_a_full_disk_is_refused_before_any_output_is_written(tmp_path, capsys, monkeypatch):
    """VTK aborted the process (exit 134, no message) when solution.vtp did not fit."""
    import collections
    import shutil as shutil_module

    out = tmp_path / "out"
    assert main(solve_args(out)) == 0
    before = snapshot(out)
    capsys.readouterr()
    usage = collections.namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil_module, "disk_usage", lambda path: usage(10**9, 10**9 - 1000, 1000))
    code = main(solve_args(out))
    line = assert_one_line_error(capsys, code, "not enough free space", "MB needed")
    assert str(out) in line
    assert snapshot(out) == before
    assert not [p for p in out.iterdir() if p.name.startswith(STAGING_PREFIX)]

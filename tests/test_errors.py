"""Bad scenes, faults and requests too big for the machine, through the Python API.

Scene validation (non-planar, degenerate, reflectance, emission, units), the memory budget
(``RADIOSITY_MEMORY_BUDGET``), atomic outputs and an interrupted cache write.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import radiosity
from radiosity import MemoryBudgetError, RadiosityError, RadiosityWarning, SceneError
from radiosity import _memory
from radiosity.io.export import STAGING_PREFIX, atomic_path, staged_outputs, write_view_factors

DATA = Path(__file__).parent / "data"


def scene_file(tmp_path: Path, body: str, mtl: str | None = None, name: str = "s.obj") -> Path:
    """An OBJ using room.mtl (or the given MTL text) with ``body`` after the mtllib line."""
    (tmp_path / "m.mtl").write_text(mtl if mtl is not None else (DATA / "room.mtl").read_text())
    path = tmp_path / name
    path.write_text("mtllib m.mtl\n" + body)
    return path


LAMP = "o lamp\nusemtl lamp\nv 0.3 0.3 1\nv 0.3 0.7 1\nv 0.7 0.7 1\nv 0.7 0.3 1\nf -4 -3 -2 -1\n"
FLOOR = "o floor\nusemtl grey\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf -4 -3 -2 -1\n"


def messages(caught) -> list[str]:
    return [str(w.message) for w in caught if issubclass(w.category, RadiosityWarning)]


# --- geometry ----------------------------------------------------------------------------

def test_nonplanar_quad_is_split_and_reported(tmp_path):
    body = "o floor\nusemtl grey\nv 0 0 0\nv 1 0 0\nv 1 1 0.01\nv 0 1 0\nf 1 2 3 4\n" + LAMP
    with pytest.warns(RadiosityWarning, match=r"s\.obj:8: face 1 is not planar \(off by 0\.0025 m\); "
                                              "split into triangles from its first vertex"):
        scene = radiosity.load_scene(scene_file(tmp_path, body))
    assert (scene.patch_face == 0).sum() == 2
    assert any("not planar" in n for n in scene.notes)


def test_degenerate_faces_are_dropped_with_a_note(tmp_path):
    slivers = "".join(f"v {k} 0 0\nv {k + 1} 0 0\nv {k + 2} 0 0\nf -3 -2 -1\n" for k in range(7))
    with pytest.warns(RadiosityWarning) as caught:
        scene = radiosity.load_scene(scene_file(tmp_path, FLOOR + "usemtl grey\n" + slivers + LAMP))
    notes = messages(caught)
    assert any("s.obj:" in n and "face 2 has zero area; ignored" in n for n in notes)
    assert any("2 more zero-area face(s) ignored" in n for n in notes)  # 7 slivers: 5 named, 2 counted
    assert sorted(set(scene.patch_face.tolist())) == [0, 8]


def test_all_faces_degenerate_is_an_error(tmp_path):
    body = "v 0 0 0\nv 1 1 1\nv 2 2 2\nf 1 2 3\n"
    with pytest.raises(SceneError, match=r"all 1 face\(s\) have zero area \(degenerate\); nothing to solve"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RadiosityWarning)
            radiosity.load_scene(scene_file(tmp_path, body))


def test_too_many_patches_refused_before_cutting(tmp_path):
    with pytest.raises(MemoryBudgetError, match=r"cutting the faces into up to [\d,]+ patches "
                                                r"\(max_patch_size 1e-06 m\) needs up to .* TiB"):
        radiosity.load_scene(DATA / "room.obj", max_patch_size=1e-6)


# --- materials ---------------------------------------------------------------------------

def test_reflectance_one_refused_unless_clamped(tmp_path):
    mtl = "newmtl white\nKd 1 0.5 1\nnewmtl lamp\nKe 1 1 1\n"
    body = FLOOR.replace("grey", "white") + LAMP
    path = scene_file(tmp_path, body, mtl)
    with pytest.raises(SceneError, match=r"m\.mtl:2: material 'white' has Kd 1 0\.5 1; reflectance must be "
                                         r"in \[0, 1\) per channel .*allow_clamp=True \(--allow-clamp\)"):
        radiosity.load_scene(path)
    with pytest.warns(RadiosityWarning, match="material 'white' has Kd 1 0.5 1; clamped to 0.999"):
        scene = radiosity.load_scene(path, allow_clamp=True)
    assert scene.reflectance.max() == pytest.approx(0.999)
    assert any("clamped" in n for n in scene.notes)


def test_with_materials_is_checked_too():
    scene = radiosity.load_scene(DATA / "room.obj")
    with pytest.raises(SceneError, match="reflectance must be in"):
        scene.with_materials(reflectance=1.0)
    with pytest.raises(SceneError, match="emission must be finite and non-negative"):
        scene.with_materials(emission=np.nan)


def test_no_emitter_warns_and_solves_to_zero(tmp_path):
    with pytest.warns(RadiosityWarning, match=r"no face emits light .*; the solution is all zero"):
        scene = radiosity.load_scene(scene_file(tmp_path, FLOOR + LAMP.replace("usemtl lamp", "usemtl grey")))
    solution = radiosity.solve(scene, preset="draft", cache=False)
    assert np.all(solution.radiosity == 0)
    assert all(np.isfinite(v).all() for v in solution.object_radiosity().values())


# --- units -------------------------------------------------------------------------------

MM_BODY = FLOOR.replace(" 1 ", " 1000 ").replace(" 1\n", " 1000\n") + LAMP.replace("0.3", "300").replace(
    "0.7", "700").replace(" 1\n", " 1000\n")


def test_millimetre_scene_is_detected(tmp_path):
    path = scene_file(tmp_path, MM_BODY)
    with pytest.warns(RadiosityWarning, match=r"the scene is 1000 m across \(more than 50 m\); if its coordinates "
                                              r"are millimetres, give units='mm' \(--units mm\)"):
        radiosity.load_scene(path)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RadiosityWarning)
        in_mm = radiosity.load_scene(path, units="mm")
        radiosity.load_scene(path, units="m")  # the user said metres: no warning
    assert in_mm.scale == pytest.approx(radiosity.load_scene(DATA / "room.obj").scale)


def test_unknown_units_and_options():
    with pytest.raises(ValueError, match="units must be one of"):
        radiosity.load_scene(DATA / "room.obj", units="inch")
    with pytest.raises(TypeError, match="unknown load_scene option 'unit'"):
        radiosity.load_scene(DATA / "room.obj", unit="mm")


def test_two_sided_is_refused_not_ignored():
    with pytest.raises(TypeError, match="'two_sided' is not supported: surfaces are one-sided"):
        radiosity.load_scene(DATA / "room.obj", two_sided=True)


# --- memory ------------------------------------------------------------------------------

def test_budget_from_environment(monkeypatch):
    monkeypatch.setenv(_memory.ENV_BUDGET, "2M")
    assert _memory.budget_bytes() == (2 << 20, f"set by {_memory.ENV_BUDGET}")
    with pytest.raises(MemoryBudgetError) as info:
        _memory.check_fill(1000, patch_size=0.05)
    message = str(info.value)
    assert message.startswith("the view-factor matrix of 1,000 patches needs up to 34.3 MiB of memory, "
                              "more than the 2 MiB budget (set by RADIOSITY_MEMORY_BUDGET)")
    assert "--max-patch-size" in message and "--preset draft" in message and "m would fit" in message
    assert isinstance(info.value, MemoryError) and isinstance(info.value, RadiosityError)
    monkeypatch.setenv(_memory.ENV_BUDGET, "lots")
    with pytest.raises(ValueError, match="RADIOSITY_MEMORY_BUDGET must be a number of bytes"):
        _memory.budget_bytes()


def test_solve_refused_under_budget(monkeypatch):
    scene = radiosity.load_scene(DATA / "room.obj")
    monkeypatch.setenv(_memory.ENV_BUDGET, "1000")
    # the first allocation checked (cutting the patches) is refused, with the knob to turn
    with pytest.raises(MemoryBudgetError, match="patches .*needs up to .*max-patch-size"):
        radiosity.solve(scene, preset="draft", cache=False)
    monkeypatch.setenv(_memory.ENV_BUDGET, "300000")
    with pytest.raises(MemoryBudgetError, match="view-factor matrix of .* patches needs"):
        radiosity.solve(scene, preset="draft", cache=False)


def test_direct_solve_estimate_names_the_solver():
    with pytest.raises(MemoryBudgetError, match=r"direct solve .* use an iterative solver \(--solver bicgstab\)"):
        _memory.check_solve(100_000, 10**6, "direct", budget=10**9)


def test_default_budget_is_positive():
    budget, source = _memory.budget_bytes()
    assert budget > 0 and "%" in source


# --- atomic outputs ----------------------------------------------------------------------

def test_atomic_path_keeps_the_old_file_on_failure(tmp_path):
    target = tmp_path / "summary.json"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("boom")
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["summary.json"]


def test_interrupted_view_factor_write_keeps_the_old_file(tmp_path, monkeypatch):
    target = tmp_path / "F.npz"
    F = sp.identity(3, format="csr")
    write_view_factors(F, np.ones(3), np.zeros(3, int), ["a"], target)
    before = target.read_bytes()

    def interrupted(fh, **arrays):
        fh.write(b"PK partial")
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "savez_compressed", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_view_factors(2 * F, np.ones(3), np.zeros(3, int), ["a"], target)
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["F.npz"]


def test_staged_outputs(tmp_path):
    out = tmp_path / "out"
    with staged_outputs(out) as stage:
        (stage / "a.txt").write_text("1")
    assert (out / "a.txt").read_text() == "1"
    with pytest.raises(RuntimeError):
        with staged_outputs(out) as stage:
            (stage / "a.txt").write_text("2")
            raise RuntimeError
    assert (out / "a.txt").read_text() == "1"
    assert not any(p.name.startswith(STAGING_PREFIX) for p in out.iterdir())
    fresh = tmp_path / "fresh"
    with pytest.raises(RuntimeError):
        with staged_outputs(fresh):
            raise RuntimeError
    assert not fresh.exists()  # a folder made for a failed run is removed again
    (tmp_path / "file").write_text("")
    with pytest.raises(NotADirectoryError):
        with staged_outputs(tmp_path / "file"):
            pass


# --- the form-factor cache under Ctrl-C ---------------------------------------------------

def test_interrupted_cache_write_leaves_no_entry(tmp_path, monkeypatch):
    from radiosity.methods.uniform import cache as cache_module

    monkeypatch.setenv("RADIOSITY_CACHE", str(tmp_path / "cache"))
    scene = radiosity.load_scene(DATA / "room.obj")
    real_savez = np.savez

    def interrupted(fh, **arrays):
        fh.write(b"PK\x03\x04 torn")
        raise KeyboardInterrupt

    monkeypatch.setattr(cache_module.np, "savez", interrupted)
    with pytest.raises(KeyboardInterrupt):
        radiosity.solve(scene, preset="draft")
    monkeypatch.setattr(cache_module.np, "savez", real_savez)
    assert not list((tmp_path / "cache").glob("F-*.npz"))  # no torn entry under a real name
    first = radiosity.solve(scene, preset="draft")
    assert not first.cache_hit
    second = radiosity.solve(scene, preset="draft")
    assert second.cache_hit
    np.testing.assert_allclose(second.radiosity, first.radiosity)


def test_solve_takes_a_path_and_refuses_what_is_neither_a_scene_nor_a_path():
    """``solve`` loads a scene file's path itself (the same answer as loading it first); a
    list of faces or an array is refused by name, not with an AttributeError from inside."""
    path = radiosity.bundled_scene("cornell_box")
    by_path = radiosity.solve(path, preset="draft", cache=False)
    loaded = radiosity.solve(radiosity.load_scene(path), preset="draft", cache=False)
    np.testing.assert_array_equal(by_path.radiosity, loaded.radiosity)
    with pytest.raises(TypeError, match="solve takes a Scene .* not ndarray"):
        radiosity.solve(np.zeros((4, 3)))

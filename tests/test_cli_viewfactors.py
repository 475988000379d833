"""``radiosity viewfactors``: subdivided matrices with their patches, sums, .vf files, closure checks."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

import radiosity
from radiosity.cli import main
from radiosity.io.export import read_vf
from helpers import OPEN_BOX, PARALLEL_SQUARES, PERPENDICULAR_SQUARES, ROOM_VS3

CUBE = radiosity.bundled_scene("unit_cube")


def test_subdivided_matrix_comes_with_its_patches(tmp_path, capsys):
    out = tmp_path / "F.npz"
    assert main(["viewfactors", "--max-patch-size", "0.25", str(CUBE), "-o", str(out), "--sum", "object"]) == 0
    printed = capsys.readouterr().out
    assert "96 patches" in printed and "sky factor" in printed
    F = sp.load_npz(out)
    with np.load(out) as z:
        assert F.shape == (96, 96) and z["area"].shape == (96,) and z["patch_quads"].shape == (96, 4, 3)
        assert z["patch_object"].shape == z["patch_face"].shape == z["sky_factor"].shape == (96,)
        np.testing.assert_allclose(z["area"], 1 / 16)
        np.testing.assert_allclose(z["sky_factor"], 0.0, atol=1e-6)
        G = sp.csr_matrix((z["group_data"], z["group_indices"], z["group_indptr"]), shape=tuple(z["group_shape"]))
        assert z["group_names"].tolist() == radiosity.load_scene(CUBE).objects
        assert z["patch_group"].tolist() == z["patch_object"].tolist()
    np.testing.assert_allclose(G.toarray()[0, 1], PARALLEL_SQUARES[1.0], rtol=1e-6)  # bottom -> top
    np.testing.assert_allclose(G.toarray()[0, 2], PERPENDICULAR_SQUARES, rtol=1e-6)


def test_vf_files_text_and_binary(tmp_path, capsys):
    text, binary = tmp_path / "F.vf", tmp_path / "B.vf"
    assert main(["viewfactors", str(CUBE), "-o", str(tmp_path / "F.npz"), "--vf", str(text)]) == 0
    assert main(["viewfactors", str(CUBE), "-o", str(tmp_path / "G.npz"), "--vf", str(binary), "--vf-binary"]) == 0
    F = sp.load_npz(tmp_path / "F.npz").toarray()
    first = text.read_text().splitlines()[0]
    assert len(first) == 30 and first.split()[2:] == ["0", "0", "0", "6"]
    for path, atol in ((text, 5e-7), (binary, 1e-7)):
        data = read_vf(path)
        np.testing.assert_allclose(data["F"], F, atol=atol)
        np.testing.assert_allclose(data["area"], 1.0)
        np.testing.assert_allclose(data["emissivity"], 0.5, atol=5e-4)
    assert binary.read_bytes()[30:32] == b"\r\n" and len(binary.read_bytes()) == 32 + 4 * 6 * 8


def test_closure_on_an_open_box_exits_2_and_writes_nothing(tmp_path, capsys):
    obj = tmp_path / "open_box.obj"
    obj.write_text(OPEN_BOX)
    out, vf = tmp_path / "F.npz", tmp_path / "F.vf"
    code = main(["viewfactors", str(obj), "-o", str(out), "--vf", str(vf), "--enforce", "closure"])
    err = capsys.readouterr().err
    assert code == 2 and "deficit 0.2" in err and "--force" in err
    assert not out.exists() and not vf.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["open_box.obj"]
    assert main(["viewfactors", str(obj), "-o", str(out), "--enforce", "closure", "--force"]) == 0
    np.testing.assert_allclose(np.asarray(sp.load_npz(out).sum(axis=1)).ravel(), 1.0, atol=1e-9)


def test_view3d_model_encl_and_sums(tmp_path, capsys):
    model = tmp_path / "room.vs3"
    model.write_text(ROOM_VS3)
    out, vf = tmp_path / "F.npz", tmp_path / "F.vf"
    assert main(["viewfactors", str(model), "-o", str(out), "--sum", "object", "--vf", str(vf)]) == 0
    printed = capsys.readouterr().out
    assert "enforced: closure" in printed and "window" in printed
    data = read_vf(vf)
    assert data["header"].split()[3] == "1"  # encl
    np.testing.assert_allclose(data["F"].sum(axis=1), 1.0, atol=1e-5)
    np.testing.assert_allclose(data["area"], [12, 12, 6.7, 10, 7.5, 7.5, 1.8, 1.5], rtol=1e-6)
    np.testing.assert_allclose(data["emissivity"], [0.9] * 6 + [0.6, 0.1], atol=5e-4)


def test_outputs_on_one_file_are_refused_before_writing(tmp_path, capsys):
    out = tmp_path / "F.npz"
    code = main(["viewfactors", str(CUBE), "-o", str(out), "--vf", str(out)])
    assert code == 2 and "same file" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_tolerance_trades_accuracy_for_time(tmp_path, capsys):
    """--tolerance sets the fill's error per factor (formfactor_rtol and visibility_atol), for
    models whose 1e-6 fill takes hours; out of [1e-12, 1) it is refused naming the flag."""
    out = tmp_path / "F.npz"
    assert main(["viewfactors", str(CUBE), "-o", str(out), "--tolerance", "1e-3", "--no-cache"]) == 0
    saved = np.load(out)
    assert float(saved["formfactor_rtol"]) == float(saved["visibility_rtol"]) == 1e-3  # the file says what it aimed at
    np.testing.assert_allclose(saved["sky_factor"], 0.0, atol=1e-3)  # a closed cube
    capsys.readouterr()
    for bad in ("0", "1", "-1e-3", "x"):
        assert main(["viewfactors", str(CUBE), "-o", str(tmp_path / "G.npz"), "--tolerance", bad]) == 2
        assert "--tolerance" in capsys.readouterr().err
    assert not (tmp_path / "G.npz").exists()

"""Per-entry error estimates of the view-factor matrix (issue 15 item 3): against exact values."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.sparse as sp

import radiosity
from radiosity.cli import main
from radiosity.formfactors import polygon_to_polygon
from helpers import BLOCKED_PARALLEL_SQUARES, PLATES, grid, write_obj


def _plates_scene(tmp_path, n: int):
    """Two parallel unit plates 1 apart facing each other, each cut n x n (no blocker)."""
    objects = {"lower": list(grid(n, 0.0, down=False)), "upper": list(grid(n, 1.0, down=True))}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", radiosity.RadiosityWarning)  # no emitter
        return radiosity.load_scene(write_obj(tmp_path / "plates.obj", objects))


def test_the_estimate_covers_every_entry_of_open_plates(tmp_path):
    scene = _plates_scene(tmp_path, 3)
    F, error = radiosity.view_factors(scene, cache=False, return_error=True)
    assert error.shape == F.shape and sp.issparse(error)
    quads = scene.patch_quads
    lower = np.flatnonzero(scene.patch_object == scene.objects.index("lower"))
    upper = np.flatnonzero(scene.patch_object == scene.objects.index("upper"))
    F, error = F.toarray(), error.toarray()
    for i in lower:
        for j in upper:
            exact = polygon_to_polygon(quads[i], quads[j], rtol=1e-11)
            assert abs(F[i, j] - exact) <= error[i, j], (i, j, F[i, j] - exact, error[i, j])
            assert error[i, j] <= 1e-4 * exact  # an estimate, not a shrug: view_factors' fill is 1e-6
    assert (error >= 0).all() and np.isfinite(error).all()


@pytest.mark.parametrize("cut", [None, 1 / 3])
def test_the_estimate_covers_the_blocked_plates(tmp_path, cut):
    path = tmp_path / "plates.vs3"
    path.write_text(PLATES)
    scene = radiosity.load_scene(path)
    vf = radiosity.compute_view_factors(scene, cache=False, error_estimate=True,
                                        **({"max_patch_size": cut} if cut else {}))
    s = vf.scene
    first, second = (np.flatnonzero(s.patch_object == k) for k in (0, 1))
    a = s.patch_area
    total = float((a[first, None] * vf.F[first][:, second].toarray()).sum()) / a[first].sum()
    bound = float((a[first, None] * vf.error[first][:, second].toarray()).sum()) / a[first].sum()
    assert abs(total - BLOCKED_PARALLEL_SQUARES) <= bound <= 1e-4 * BLOCKED_PARALLEL_SQUARES


def test_cli_stores_the_estimate_beside_f(tmp_path, capsys):
    path = tmp_path / "plates.vs3"
    path.write_text(PLATES)
    out = tmp_path / "F.npz"
    assert main(["viewfactors", str(path), "-o", str(out), "--error-estimate"]) == 0
    assert "error estimate: largest" in capsys.readouterr().out
    F = sp.load_npz(out)
    with np.load(out) as z:
        E = sp.csr_matrix((z["error_data"], z["error_indices"], z["error_indptr"]), shape=F.shape)
    assert E.nnz >= 1 and (E.data >= 0).all() and E.max() < 1e-5
    assert main(["viewfactors", str(path), "-o", str(tmp_path / "G.npz")]) == 0  # no estimate unless asked
    with np.load(tmp_path / "G.npz") as z:
        assert "error_data" not in z.files

"""ViewFactors: the matrix with its patches, sums back to objects and faces, sky factors, closure."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings, strategies as st

import radiosity
from radiosity.enclosure import NotClosedError, check_closed
from radiosity.factors import group_factors

from helpers import OPEN_BOX, PARALLEL_SQUARES, PERPENDICULAR_SQUARES

CUBE = radiosity.bundled_scene("unit_cube")
OPPOSITE, ADJACENT = PARALLEL_SQUARES[1.0], PERPENDICULAR_SQUARES  # unit cube faces (Hottel)


@pytest.fixture(scope="module")
def cube_cut():
    return radiosity.compute_view_factors(radiosity.load_scene(CUBE), max_patch_size=0.5, cache=False)


def test_matrix_comes_with_the_patches_it_belongs_to(cube_cut):
    vf = cube_cut
    assert vf.F.shape == (24, 24) and vf.scene.n_patches == 24
    assert len(vf.scene.patch_area) == 24 and vf.scene.patch_quads.shape == (24, 4, 3)
    np.testing.assert_allclose(vf.scene.patch_area, 0.25)
    assert np.bincount(vf.scene.patch_object).tolist() == [4] * 6
    np.testing.assert_allclose(vf.sky_factor, 0.0, atol=1e-6)
    with pytest.warns(radiosity.RadiosityWarning, match="6 patches into 24.*compute_view_factors"):
        F = radiosity.view_factors(radiosity.load_scene(CUBE), max_patch_size=0.5, cache=False)
    assert abs(F - vf.F).max() == 0  # the contract's bare matrix is the same one, and says whose it is


def test_object_sums_are_the_unsubdivided_factors(cube_cut):
    out = cube_cut.grouped("object")
    F = out.F.toarray()
    assert out.names == radiosity.load_scene(CUBE).objects
    np.testing.assert_allclose(out.area, 1.0)
    expected = np.where(np.eye(6, dtype=bool), 0.0, ADJACENT)
    for i, j in ((0, 1), (2, 3), (4, 5)):  # bottom/top, left/right, front/back face each other
        expected[i, j] = expected[j, i] = OPPOSITE
    np.testing.assert_allclose(F, expected, rtol=1e-6, atol=1e-12)
    faces = cube_cut.grouped("face")
    assert faces.F.shape == (6, 6) and faces.names[0] == "bottom#1"


def test_mismatched_matrix_is_refused():
    scene = radiosity.load_scene(CUBE)
    with pytest.raises(ValueError, match="does not belong"):
        radiosity.ViewFactors(sp.identity(96, format="csr"), scene)


@settings(max_examples=25, deadline=None)
@given(st.integers(2, 12), st.integers(1, 5), st.integers(0, 2**31 - 1))
def test_group_sums_keep_reciprocity_and_closure(n, m, seed):
    rng = np.random.default_rng(seed)
    G = rng.uniform(0, 1, (n, n))
    G = G + G.T  # symmetric exchange areas A_i F_ij
    area = G.sum(axis=1) * rng.uniform(1.0, 2.0, n)  # rows of F sum to at most 1
    F = G / area[:, None]
    group = rng.integers(-1, m, n)
    Fg, A, kept = group_factors(sp.csr_matrix(F), area, group)
    Gg = A[:, None] * Fg.toarray()
    np.testing.assert_allclose(Gg, Gg.T, atol=1e-12)
    for k, g in enumerate(kept):
        members = group == g
        np.testing.assert_allclose(A[k], area[members].sum())
        inside = np.isin(group, kept)
        np.testing.assert_allclose(Gg[k].sum(), G[members][:, inside].sum(), rtol=1e-12)


def test_closure_refused_where_rows_fall_short():
    F = sp.csr_matrix(np.array([[0, 0.8], [0.8, 0]]))
    with pytest.raises(NotClosedError, match=r"deficit 0\.2.*force"):
        check_closed(F, np.ones(2, bool), 2e-6)
    assert check_closed(F, np.array([False, False]), 2e-6) == 0.0


def test_enforce_closure_on_an_open_box(tmp_path):
    obj = tmp_path / "open_box.obj"
    obj.write_text(OPEN_BOX)
    with pytest.warns(radiosity.RadiosityWarning):
        scene = radiosity.load_scene(obj)
    with pytest.raises(NotClosedError, match="deficit 0.2"):
        radiosity.view_factors(scene, enforce="closure", cache=False)
    forced = radiosity.compute_view_factors(scene, enforce="closure", force=True, cache=False)
    np.testing.assert_allclose(forced.row_sums, 1.0, atol=1e-9)
    np.testing.assert_allclose(radiosity.compute_view_factors(scene, cache=False).sky_factor, 0.2, atol=2e-4)

"""Closure and reciprocity diagnostics and their enforcement."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given
from hypothesis import strategies as st

import radiosity
from radiosity.enclosure import diagnose, enforce_reciprocity


@pytest.fixture(scope="module")
def cube_factors():
    scene = radiosity.load_scene(radiosity.bundled_scene("unit_cube"), max_patch_size=0.5)
    return radiosity.view_factors(scene, cache=False), scene.patch_area


def test_enforced_reciprocity_is_exact_and_small(cube_factors):
    F, area = cube_factors
    before = diagnose(F, area)
    Fr = enforce_reciprocity(F, area)
    after = diagnose(Fr, area)
    assert after.reciprocity_error < 1e-14
    # symmetrising moves each factor by at most half the asymmetry
    assert abs(Fr - F).max() <= 0.5 * before.reciprocity_error * (sp.diags(area) @ F).max() / area.min() + 1e-15


def test_enforced_closure_keeps_reciprocity(cube_factors):
    F, area = cube_factors
    Fc = enforce_reciprocity(F, area, closure=True)
    d = diagnose(Fc, area)
    assert d.closure_error < 1e-12
    assert d.reciprocity_error < 1e-13
    # the correction is of the size of the original errors, not more
    d0 = diagnose(F, area)
    assert abs(Fc - F).max() < 5 * (d0.closure_error + d0.reciprocity_error) + 1e-12


def test_view_factors_enforce_option(cube_factors):
    scene = radiosity.load_scene(radiosity.bundled_scene("unit_cube"), max_patch_size=0.5)
    F = radiosity.view_factors(scene, cache=False, enforce="closure")
    np.testing.assert_allclose(np.asarray(F.sum(axis=1)).ravel(), 1.0, atol=1e-12)
    with pytest.raises(TypeError, match="closure"):
        radiosity.view_factors(scene, cache=False, enforce="rows")


@given(st.integers(3, 12), st.integers(0, 10_000))
def test_closure_scaling_converges_on_random_enclosures(n, seed):
    # a consistent enclosure (symmetric exchange areas whose rows sum to the areas), perturbed
    rng = np.random.default_rng(seed)
    G = rng.uniform(0.01, 1, (n, n))
    G = G + G.T
    np.fill_diagonal(G, 0)
    area = G.sum(axis=1)
    F = sp.csr_matrix(G / area[:, None] * rng.uniform(0.95, 1.05, (n, n)))
    Fc = enforce_reciprocity(F, area, closure=True)
    d = diagnose(Fc, area)
    assert d.closure_error < 1e-10
    assert d.reciprocity_error < 1e-12
    assert (Fc.toarray() >= 0).all()

"""Hemicube / Nusselt-disk estimator (radiosity.alternatives.hemicube): exact texel weights, convergence."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate

from radiosity.alternatives import hemicube
from radiosity.formfactors import point_to_polygon

# Point under the corner of a unit square at height 1 (Howell): (1/2pi) * 2 * atan(1/sqrt 2)/sqrt 2.
HOWELL_UNIT = np.arctan(1 / np.sqrt(2)) / np.sqrt(2) / np.pi


def _rotated_square(angle=0.37, a=1.0, b=1.0, c=1.0):
    """Howell's corner case rotated about z so that no edge lines up with texel boundaries."""
    r = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1.0]])
    return np.array([[0, 0, c], [a, 0, c], [a, b, c], [0, b, c]], float) @ r.T


@pytest.mark.parametrize("res", [2, 8, 64, 100, 512])
def test_delta_form_factors_sum_to_one(res):
    top, side = hemicube.delta_form_factors(res)
    assert top.shape == (res, res) and side.shape == (res // 2, res)
    assert (top > 0).all() and (side > 0).all()
    assert abs(top.sum() + 4 * side.sum() - 1.0) < 1e-14
    (disk,) = hemicube.delta_form_factors(res, method="nusselt")
    assert (disk >= 0).all()
    assert abs(disk.sum() - 1.0) < 1e-14


def test_texel_solid_angles_cover_the_hemisphere():
    top, side = hemicube.texel_solid_angles(32)
    assert abs(top.sum() - 2 * np.pi / 3) < 1e-13
    assert abs(top.sum() + 4 * side.sum() - 2 * np.pi) < 1e-13


def test_top_corner_is_howell():
    top, _ = hemicube.delta_form_factors(2)  # one texel per quadrant
    assert top[1, 1] == pytest.approx(HOWELL_UNIT, rel=1e-10)


def test_side_and_disk_texels_against_quadrature():
    _, side = hemicube.delta_form_factors(8)  # texel s in [-0.25, 0], z in [0.25, 0.5]
    ref = integrate.dblquad(lambda z, s: z / (1 + s * s + z * z) ** 2 / np.pi, -0.25, 0.0, 0.25, 0.5,
                            epsabs=1e-15, epsrel=1e-13)[0]
    assert side[1, 3] == pytest.approx(ref, rel=1e-12)
    (disk,) = hemicube.delta_form_factors(4, method="nusselt")  # texel [0.5, 1] x [0.5, 1]
    seg = integrate.quad(lambda x: max(0.0, np.sqrt(1 - x * x) - 0.5), 0.5, 1.0, epsabs=1e-15)[0]
    assert disk[3, 3] == pytest.approx(seg / np.pi, rel=1e-10)


@pytest.mark.parametrize("method", ["hemicube", "nusselt"])
def test_error_decreases_with_resolution(method):
    poly = _rotated_square()
    errs = [abs(hemicube.hemicube_factors([0, 0, 0], [0, 0, 1], [poly], res, method=method)[0]
                - HOWELL_UNIT) / HOWELL_UNIT for res in (16, 64, 256)]
    assert errs[2] < errs[0] / 10
    assert errs[2] < 2e-4


def test_aligned_square_is_exact_on_the_hemicube():
    square = [[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    f = hemicube.hemicube_factors([0, 0, 0], [0, 0, 1], [square], 32)[0]
    assert f == pytest.approx(HOWELL_UNIT, rel=1e-12)


def test_zbuffer_hides_polygons_behind():
    near = np.array([[-2, -2, 1], [2, -2, 1], [2, 2, 1], [-2, 2, 1.0]])
    far = _rotated_square(c=2.0)
    both = [far, near]
    f = hemicube.hemicube_factors([0, 0, 0], [0, 0, 1], both, 64)
    assert f[0] == 0.0
    assert f[1] == pytest.approx(point_to_polygon([[0, 0, 0]], [[0, 0, 1]], near)[0], rel=2e-2)
    g = hemicube.hemicube_factors([0, 0, 0], [0, 0, 1], both, 64, occlusion=False)
    assert g[1] == f[1]
    assert g[0] == pytest.approx(point_to_polygon([[0, 0, 0]], [[0, 0, 1]], far)[0], rel=2e-2)


def test_frame_and_clipping_follow_lambert():
    """Tilted receiver off the origin, a source crossing its plane, a triangle and a pentagon."""
    rng = np.random.default_rng(3)
    point = np.array([0.3, -0.2, 0.1])
    normal = np.array([0.2, 0.1, 1.0])
    normal /= np.linalg.norm(normal)
    polys = [np.array([[-1, -1, -0.2], [1.5, -1, 0.8], [0.5, 1.5, 1.2]]),
             point + np.c_[np.cos(np.linspace(0, 2 * np.pi, 6)[:-1]),
                           np.sin(np.linspace(0, 2 * np.pi, 6)[:-1]), np.full(5, 0.7)] + rng.normal(scale=0.01)]
    f = hemicube.hemicube_factors(point, normal, polys, 256, method="nusselt", occlusion=False)
    for fi, p in zip(f, polys):
        assert fi == pytest.approx(point_to_polygon([point], [normal], p)[0], rel=5e-3)


def test_bad_arguments_raise():
    sq = _rotated_square()
    with pytest.raises(ValueError, match="resolution"):
        hemicube.hemicube_factors([0, 0, 0], [0, 0, 1], [sq], 15)
    with pytest.raises(ValueError, match="method"):
        hemicube.hemicube_factors([0, 0, 0], [0, 0, 1], [sq], 16, method="sphere")
    with pytest.raises(ValueError, match=r"polygons\[0\]"):
        hemicube.hemicube_factors([0, 0, 0], [0, 0, 1], [[[0, 0, 1], [1, 0, 1]]], 16)
    assert hemicube.hemicube_factors([0, 0, 0], [0, 0, 1], [], 16).shape == (0,)

"""Touching is not covering: a box that touches a pair's faces, edges or corners from outside
the region between them never changes the pair's view factor; bounds always hold."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings as hsettings, strategies as st

from helpers import PARALLEL_SQUARES, fill, grid

pytest.importorskip("embreex")

from radiosity.methods.uniform.assembly import FillSettings  # noqa: E402

TIGHT = FillSettings(formfactor_rtol=1e-6, visibility_rtol=1e-6)  # view_factors' defaults
DEFAULT = FillSettings(formfactor_rtol=1e-4)  # the default preset's accuracy (rays and exact)


def box(lo, hi):
    """The six outward faces of the axis-aligned box [lo, hi]."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    return np.array([
        [[x0, y0, z0], [x0, y1, z0], [x1, y1, z0], [x1, y0, z0]],  # bottom, -z
        [[x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]],  # top, +z
        [[x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1]],  # -y
        [[x0, y1, z0], [x0, y1, z1], [x1, y1, z1], [x1, y1, z0]],  # +y
        [[x0, y0, z0], [x0, y0, z1], [x0, y1, z1], [x0, y1, z0]],  # -x
        [[x1, y0, z0], [x1, y1, z0], [x1, y1, z1], [x1, y0, z1]],  # +x
    ], float)


@st.composite
def touching_box(draw):
    """A box outside the slab [0, 1]^3 between the plates, touching its boundary plane."""
    side = draw(st.sampled_from(["x-", "x+", "y-", "y+", "z-", "z+"]))
    size = [draw(st.floats(0.05, 0.8)) for _ in range(3)]
    lo = [draw(st.floats(-0.5, 1.2)) for _ in range(3)]
    axis, up = "xyz".index(side[0]), side[1] == "+"
    lo[axis] = 1.0 if up else -size[axis]
    hi = [a + s for a, s in zip(lo, size)]
    if not up:
        hi[axis] = 0.0  # exactly on the plane
    return lo, hi


@hsettings(max_examples=12, deadline=None)
@given(touching_box(), st.sampled_from([TIGHT, DEFAULT]))
def test_a_touching_box_never_changes_an_unobstructed_pair(lohi, fill_settings):
    lo, hi = lohi
    parts = [grid(1, 0, down=False), grid(1, 1, down=True)]
    F0, area, _ = fill(parts, fill_settings)
    F, _, _ = fill(parts + [box(lo, hi)], fill_settings)
    assert F[0, 1] == pytest.approx(F0[0, 1], rel=1e-12, abs=1e-15)
    assert F[1, 0] == pytest.approx(F0[1, 0], rel=1e-12, abs=1e-15)
    assert F0[0, 1] == pytest.approx(PARALLEL_SQUARES[1.0], rel=10 * fill_settings.formfactor_rtol)
    assert (F >= 0).all() and (F.sum(axis=1) <= 1 + 1e-6).all()


@pytest.mark.parametrize("fill_settings", [TIGHT, DEFAULT], ids=["tight", "default"])
def test_partition_on_a_floor_pieces_edge_hides_nothing_above_it(fill_settings):
    """A two-sided partition standing on the edge of a floor piece, ceiling strips above the
    piece: the pair is unobstructed (the 398-surface hall's zeroed floor-to-ceiling entries)."""
    floor = grid(1, 0, down=False, x0=0, x1=1, y0=0, y1=1)
    ceiling = grid(2, 1, down=True, x0=0, x1=1, y0=0, y1=1)
    part = np.array([[[1, -0.5, 0], [1, 1.5, 0], [1, 1.5, 0.8], [1, -0.5, 0.8]]], float)  # faces +x
    partition = np.concatenate([part, part[:, ::-1]])  # and -x: two-sided
    beyond = grid(1, 0, down=False, x0=1, x1=2, y0=0, y1=1)  # the next floor piece
    F0, _, _ = fill([floor, ceiling, beyond], fill_settings)
    F, _, _ = fill([floor, ceiling, beyond, partition], fill_settings)
    for j in range(1, 5):
        assert F[0, j] == pytest.approx(F0[0, j], rel=1e-12)
        assert F[j, 0] == pytest.approx(F0[j, 0], rel=1e-12)
    assert (F[:6, :6] <= F0 * (1 + 1e-12) + 1e-15).all()  # 0 <= F_obstructed <= F_unobstructed

"""A pair whose source crosses the receiver's plane (and, reversed, whose receiver crosses the
source's), partly occluded by a blocker that only hides the part behind that plane: both
directions against polygon_to_polygon of the front part, and reciprocity, in the fill's
fixed-point (draft, default) and cell (view_factors, fine) paths."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("embreex")

import radiosity  # noqa: E402
from radiosity.methods.uniform.assembly import FillSettings  # noqa: E402
from helpers import fill  # noqa: E402

FLOOR = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]], float)  # faces +z
WALL = np.array([[[1.2, 0, -0.5], [1.2, 0, 1], [1.2, 1, 1], [1.2, 1, -0.5]]], float)  # faces -x, crosses z = 0
WALL_TOP = np.array([[1.2, 0, 0], [1.2, 0, 1], [1.2, 1, 1], [1.2, 1, 0]], float)
# below the floor's plane, between the floor and the wall's lower part: it hides only segments
# that end behind the floor (no light), yet it leaves the pair partly occluded
BLOCKER = np.array([[[0.8, 0, -0.2], [1.1, 0, -0.2], [1.1, 1, -0.2], [0.8, 1, -0.2]]], float)


@pytest.mark.parametrize("rtol", [1e-4, 1e-6], ids=["fixed-points", "cells"])
def test_straddling_pair_both_directions(rtol):
    settings = FillSettings(visibility="exact", formfactor_rtol=rtol, visibility_rtol=1e-6)
    F, area, stats = fill([FLOOR, WALL, BLOCKER], settings)
    assert stats.n_traced_pairs >= 2  # the blocker leaves both directions partly occluded
    floor_to_wall = radiosity.polygon_to_polygon(FLOOR[0], WALL_TOP, rtol=1e-10)
    top_to_floor = radiosity.polygon_to_polygon(WALL_TOP, FLOOR[0], rtol=1e-10)
    wall_to_floor = top_to_floor * 1.0 / area[1]  # only the top (area 1) sees the floor's front
    tol = 10 * rtol
    assert F[0, 1] == pytest.approx(floor_to_wall, rel=tol)
    assert F[1, 0] == pytest.approx(wall_to_floor, rel=tol)
    assert area[0] * F[0, 1] == pytest.approx(area[1] * F[1, 0], rel=2 * tol)

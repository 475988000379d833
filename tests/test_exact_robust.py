"""Exact visibility never crashes: the shapely union of hidden polygons has fallbacks.

Past ``MAX_UNION`` hidden polygons at one receiver point, exact shadows unite them with
shapely. GEOS's floating overlay can fail on degenerate overlaps ("TopologyException: side
location conflict"); the union is then repaired and redone with snap-rounding, or, as a last
resort, the largest polygon stands for it, and a RadiosityWarning counts those points.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import shapely
from shapely.errors import GEOSException

import radiosity
import radiosity.visibility._pairs as visibility
from radiosity.visibility import _exact

pytest.importorskip("embreex")

from helpers import all_pairs, boxes_scene, make_vis  # noqa: E402

# Two polygons GEOS 3.14 cannot unite, plain or snap-rounded: cells of an imprinted floor next to
# a box foot, one of them invalid (a hole touching its shell), from round-off in a difference.
SIDE_LOCATION_CONFLICT = [
    "010300000002000000050000003AE2AC84EA3DC73F3E0AD7A3703D004030C65E3601F2BF3FF2FB709EA8B5F33F07A6FC245F04893FA157547277D6F33F8214AE47E17A943F3E0AD7A3703D00403AE2AC84EA3DC73F3E0AD7A3703D00400500000005A6FC245F04893FA157547277D6F33F46C11E8B0926773F3E635191295BE23FA0126351CDDCB33F6C2244583B31E23F30C65E3601F2BF3FF2FB709EA8B5F33F05A6FC245F04893FA157547277D6F33F",
    "01030000000100000004000000FB5C1AE23D3DE03F676E2F822046F33F866AECA637E6F43F07934F01585DF23F1B85C659B874E33F56373033C11CED3FFB5C1AE23D3DE03F676E2F822046F33F",
]


def _spy_unions(monkeypatch) -> dict:
    calls = {"rows": 0}
    real = _exact.union_factors

    def spy(x, *args, **kwargs):
        calls["rows"] += len(x)
        return real(x, *args, **kwargs)

    monkeypatch.setattr(_exact, "union_factors", spy)
    return calls


def _shapely_path(monkeypatch) -> None:
    """Send every point with two or more hidden polygons to the shapely union."""
    monkeypatch.setattr(visibility, "MAX_UNION", 1)  # the pair kernel gives up on them ...
    monkeypatch.setattr(_exact, "MAX_UNION", 1)  # ... and so does the group kernel behind it


@pytest.fixture(scope="module")
def boxes():
    quads, groups = boxes_scene()
    i, j = all_pairs(len(quads))
    return quads, groups, i, j, make_vis(quads, groups).fraction(i, j, exact=True, order=3)


def test_shapely_unions_are_reached_and_agree(monkeypatch, boxes):
    """The path the old test was named for: it patched only one of the two MAX_UNION names."""
    quads, groups, i, j, compiled = boxes
    _shapely_path(monkeypatch)
    calls = _spy_unions(monkeypatch)
    vis = make_vis(quads, groups)
    fallback = vis.fraction(i, j, exact=True, order=3)
    assert calls["rows"] > 100
    assert 0 < compiled.mean() < 1
    np.testing.assert_allclose(fallback, compiled, rtol=1e-9, atol=1e-12)
    assert vis.union_note() is None


def _failing_plain_union(monkeypatch, *, snapped_too: bool = False) -> None:
    """GEOS raising a TopologyException on every plain union (and snap-rounded ones too)."""
    real = shapely.union_all

    def union_all(geometries, grid_size=None, axis=None, **kwargs):
        if grid_size is None or snapped_too:
            raise GEOSException("TopologyException: side location conflict at 0 0")
        return real(geometries, grid_size=grid_size, axis=axis, **kwargs)

    monkeypatch.setattr(shapely, "union_all", union_all)


def test_topology_exception_is_snapped_away(monkeypatch, boxes):
    quads, groups, i, j, compiled = boxes
    _shapely_path(monkeypatch)
    _failing_plain_union(monkeypatch)
    vis = make_vis(quads, groups)
    fraction = vis.fraction(i, j, exact=True, order=3)
    np.testing.assert_allclose(fraction, compiled, rtol=1e-8, atol=1e-10)
    assert vis.union_fallbacks["snapped"] > 0 and not vis.union_fallbacks.get("lower_bound")
    assert "snap-rounding" in vis.union_note()


def test_last_resort_is_a_lower_bound_of_the_shadow(monkeypatch, boxes):
    quads, groups, i, j, compiled = boxes
    _shapely_path(monkeypatch)
    _failing_plain_union(monkeypatch, snapped_too=True)
    vis = make_vis(quads, groups)
    fraction = vis.fraction(i, j, exact=True, order=3)
    assert np.isfinite(fraction).all() and (fraction >= 0).all() and (fraction <= 1).all()
    assert (fraction >= compiled - 1e-12).all()  # less hidden: at least as visible
    assert vis.union_fallbacks["lower_bound"] > 0
    assert "lower bound" in vis.union_note()


def test_a_real_side_location_conflict_is_united():
    """GEOS fails on these two polygons for real; _unite repairs and snaps them."""
    polys = np.array([shapely.from_wkb(h) for h in SIDE_LOCATION_CONFLICT], dtype=object)
    with pytest.raises(GEOSException, match="side location conflict"):
        shapely.union_all(polys)
    unions, snapped, lost = _exact._unite(polys[None, :], 1e-12)
    assert snapped.all() and not lost.any()
    union = unions[0]
    assert union.is_valid
    repaired = shapely.make_valid(polys)
    assert union.area == pytest.approx(shapely.union_all(repaired, grid_size=1e-9).area, rel=1e-6)
    assert union.area >= max(shapely.area(repaired)) - 1e-12


def test_solve_finishes_and_notes_the_fallback(monkeypatch, tmp_path):
    """A whole solve with exact shadows whose unions all hit a TopologyException."""
    _shapely_path(monkeypatch)
    _failing_plain_union(monkeypatch)
    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        # 0.25 m patches: every point of the Python union path costs a shapely call
        solution = radiosity.solve(scene, preset="draft", visibility="exact", cache=False, max_patch_size=0.25)
    notes = [str(w.message) for w in caught if issubclass(w.category, radiosity.RadiosityWarning)]
    assert any("snap-rounding" in n for n in notes), notes
    assert np.isfinite(solution.radiosity).all()
    energy = {k: np.asarray(v) for k, v in solution.energy.items()}
    np.testing.assert_allclose(energy["absorbed"] + energy["escaped"], energy["emitted"], rtol=1e-9)

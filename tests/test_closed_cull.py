"""Closed-object culling (``visibility/_closed.py``): a pair keeps only the faces of a closed
object that can be the first to block it, and no fraction changes."""

from __future__ import annotations

import numpy as np
import pytest

from radiosity.geometry import polygon_normals
from radiosity.visibility import FULL, MAYBE, Visibility
from radiosity.visibility._closed import NO_LABEL, winding_labels

from helpers import axis_box, prism


def _scene(objects):
    quads = np.array([q if len(q) == 4 else np.vstack([q, q[-1:]]) for obj in objects for q in obj], float)
    groups = np.repeat(np.arange(len(objects)), [len(o) for o in objects])
    scale = float(np.linalg.norm(np.ptp(quads.reshape(-1, 3), axis=0)))
    return quads, polygon_normals(quads), groups, scale


def test_windings_of_closed_and_open_objects():
    quads, normals, groups, scale = _scene([prism(0.5, 4.0, 12, inward=False),
                                            prism(1.0, 4.8, 12, inward=True, z0=-0.4),
                                            axis_box((2, 2, 0), (3, 3, 1), inward=False)[:5]])  # open: no lid
    column, labels = winding_labels(quads, normals, groups, scale)
    assert column.tolist() == [0, 1, -1]
    assert (labels[:, 0] == 0).all()  # everything in front of the inner prism is outside it
    inside = groups < 2
    assert (labels[inside, 1] == -1).all() and (labels[~inside, 1] == 0).all()  # the open box is outside the shell


def test_a_patch_inside_a_closed_box_keeps_its_occluders():
    """Windings differ across the box's surface: nothing is dropped, the pair stays blocked."""
    inner = np.array([[0.4, 0.4, 0.5], [0.6, 0.4, 0.5], [0.6, 0.6, 0.5], [0.4, 0.6, 0.5]])  # facing up, inside
    lid = np.array([[0, 0, 3.0], [1, 0, 3.0], [1, 1, 3.0], [0, 1, 3.0]])[::-1]  # facing down, above
    quads, normals, groups, scale = _scene([axis_box((0, 0, 0), (1, 1, 1), inward=False), [inner], [lid],
                                            axis_box((-5, -5, -5), (6, 6, 6), inward=True)])
    _, labels = winding_labels(quads, normals, groups, scale)
    a, b = 6, 7
    assert labels[a, 0] == 1 and labels[b, 0] == 0 and NO_LABEL not in labels[[a, b]]
    for closed in (False, True):
        vis = Visibility(quads, normals, groups, scale, closed=closed)
        status, rows, occ = vis.classify(np.array([a, b]), np.array([b, a]))
        assert (status == FULL).all()


def _random_pairs(rng, n_boxes):
    """Two facing plates with random closed boxes (convex occluders) between and around them;
    boxes may overlap each other and cut through the plates (interpenetrating geometry)."""
    objects = [[np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]], float)],
               [np.array([[0, 0, 2], [2, 0, 2], [2, 2, 2], [0, 2, 2]], float)[::-1]]]
    for _ in range(n_boxes):
        lo = rng.uniform([-0.5, -0.5, 0.2], [2.0, 2.0, 1.5])
        objects.append(axis_box(lo, lo + rng.uniform(0.1, 0.8, 3), inward=False))
    objects.append(axis_box((-3, -3, -3), (5, 5, 5), inward=True))  # a closed room around it all
    return _scene(objects)


@pytest.mark.parametrize("seed", range(8))
def test_culling_changes_no_fraction(seed):
    """Exact shadows with and without culling, between plate patches and box faces: 1e-12.
    (Seed 4 has a box through the top plate: the plate crosses the box's surface, so the box's
    faces are not culled for it.)"""
    rng = np.random.default_rng(seed)
    quads, normals, groups, scale = _random_pairs(rng, 3)
    n = len(quads)
    i, j = np.nonzero(~np.eye(n, dtype=bool))
    facing = (np.einsum("pc,pc->p", normals[i], quads[j].mean(1) - quads[i].mean(1)) > 0) & \
             (np.einsum("pc,pc->p", normals[j], quads[i].mean(1) - quads[j].mean(1)) > 0)
    i, j = i[facing], j[facing]
    plain = Visibility(quads, normals, groups, scale, closed=False)
    culled = Visibility(quads, normals, groups, scale)
    st0, _, _ = plain.classify(i, j)
    st1, _, _ = culled.classify(i, j)
    assert culled.n_closed_culled > 0
    assert ((st0 == FULL) == (st1 == FULL)).all()  # culling only drops maybe rows
    part = st0 == MAYBE
    np.testing.assert_allclose(culled.fraction(i, j, exact=True, order=3)[part],
                               plain.fraction(i, j, exact=True, order=3)[part], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(culled.fraction(i, j), plain.fraction(i, j))  # the same rays, blocked alike


def test_a_convex_body_does_not_shade_its_own_faces():
    """Inner prism wall to outer shell wall: the plane-and-bundle test leaves the inner prism's
    neighbouring faces undecided; culling drops them all (the source is behind them) and the
    pair is free."""
    quads, normals, groups, scale = _scene([prism(0.5, 4.0, 12, inward=False),
                                            prism(1.0, 4.8, 12, inward=True, z0=-0.4)])
    inner, outer = np.flatnonzero(groups == 0), np.flatnonzero(groups == 1)
    i, j = np.repeat(inner, len(outer)), np.tile(outer, len(inner))
    plain = Visibility(quads, normals, groups, scale, closed=False)
    culled = Visibility(quads, normals, groups, scale)
    st0, _, _ = plain.classify(i, j)
    st1, rows, occ = culled.classify(i, j)
    assert (st0 == MAYBE).sum() > 0 and not (st1 == MAYBE).any()
    ok = st0 == MAYBE
    np.testing.assert_allclose(plain.fraction(i[ok], j[ok], exact=True, order=4), 1.0, atol=1e-12)

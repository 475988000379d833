"""``subdivide_faces`` decides most faces at once (``_patches_bulk``); the result must be the
per-face path's, bit for bit: same patches, same owners, same face report."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import radiosity._patches_bulk as bulk
import radiosity.patches as patches
from radiosity.io.obj import read_obj
from radiosity.scene import bundled_scene


def _per_face(vertices, faces, max_size, monkeypatch):
    """The per-face path alone (each use is its own monkeypatch context)."""
    with monkeypatch.context() as m:
        m.setattr(patches, "whole_faces", lambda v, f, s: (np.full(len(f), bulk.PER_FACE, np.int8),
                                                           np.empty((len(f), 4, 3))))
        return patches.subdivide_faces(vertices, faces, max_size)


def _assert_same(vertices, faces, max_size, monkeypatch):
    fast, fast_report = patches.subdivide_faces(vertices, faces, max_size)
    slow, slow_report = _per_face(vertices, faces, max_size, monkeypatch)
    assert fast.quads.tobytes() == slow.quads.tobytes()  # bit for bit, signed zeros included
    assert np.array_equal(fast.patch_face, slow.patch_face)
    assert fast_report == slow_report


@pytest.mark.parametrize("name", ["cornell_box", "unit_cube"])
@pytest.mark.parametrize("max_size", [None, 0.05, 0.3, 10.0])
def test_bundled_scenes_cut_alike(name, max_size, monkeypatch):
    data = read_obj(bundled_scene(name))
    _assert_same(data.vertices, data.faces, max_size, monkeypatch)


def _shapes(rng: np.random.Generator, n: int):
    """Triangles and quads of every kind near the thresholds: slivers, zero area, non-planar,
    non-convex, repeated corners, signed zeros, edges just around the patch size."""
    vertices, faces = [], []
    for _ in range(n):
        kind = rng.integers(0, 8)
        base = rng.normal(size=3)
        u, v = rng.normal(size=3), rng.normal(size=3)
        if kind == 0:  # triangle
            pts = [base, base + u, base + v]
        elif kind == 1:  # sliver, area near the degenerate floor
            pts = [base, base + u, base + u * rng.uniform(0.3, 0.7) + v * 10.0 ** rng.uniform(-9, -5)]
        elif kind == 2:  # zero area
            pts = [base, base + u, base + 2 * u]
        elif kind == 3:  # planar convex quad (a parallelogram)
            pts = [base, base + u, base + u + v, base + v]
        elif kind == 4:  # slightly non-planar quad, around PLANAR_REL
            w = np.cross(u, v)
            pts = [base, base + u, base + u + v + w * 10.0 ** rng.uniform(-8, -5), base + v]
        elif kind == 5:  # non-convex quad (a dart)
            pts = [base, base + u, base + 0.2 * (u + v), base + v]
        elif kind == 6:  # a square of side near 1 with signed zeros
            s = 1.0 + rng.choice([-1e-9, 0.0, 1e-9, 1e-6])
            pts = [np.array([-0.0, 0.0, -0.0]), np.array([s, -0.0, 0.0]), np.array([s, s, -0.0]),
                   np.array([0.0, s, 0.0])]
        else:  # a repeated corner
            pts = [base, base + u, base + u, base + v]
        start = len(vertices)
        vertices += [np.asarray(p, float) for p in pts]
        faces.append(np.arange(start, start + len(pts)))
    return np.array(vertices), faces


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), max_size=st.sampled_from([None, 1.0, 0.5, 3.0]))
def test_random_shapes_cut_alike(seed, max_size, monkeypatch):
    vertices, faces = _shapes(np.random.default_rng(seed), 60)
    _assert_same(vertices, faces, max_size, monkeypatch)


def test_most_faces_of_a_triangle_mesh_are_decided_at_once():
    vertices, faces = _shapes(np.random.default_rng(1), 400)
    verdict, _ = bulk.whole_faces(vertices, faces, None)
    assert (verdict != bulk.PER_FACE).mean() > 0.5

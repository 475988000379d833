"""The chunked first-hit kernel (``_lightpaths_chunks``) finds the plain kernel's hits exactly."""

from __future__ import annotations

import numpy as np
import pytest

from radiosity._lightpaths import _first_hits_kernel
from radiosity._lightpaths_chunks import first_hits_chunked


def _both(origins, directions, triangles, offset):
    v0 = np.ascontiguousarray(triangles[:, 0])
    e1 = np.ascontiguousarray(triangles[:, 1] - v0)
    e2 = np.ascontiguousarray(triangles[:, 2] - v0)
    out = []
    for kernel in (_first_hits_kernel, first_hits_chunked):
        hit, side = np.full(len(origins), -1, np.int64), np.zeros(len(origins))
        kernel(origins, directions, v0, e1, e2, offset, hit, side)
        out.append((hit, side))
    return out


def _grid(side: int, jitter: float, rng) -> np.ndarray:
    """A height field as triangles in row order, like an exported terrain."""
    g = np.linspace(0.0, 1.0, side)
    x, z = np.meshgrid(g, g)
    y = jitter * rng.standard_normal(x.shape)
    p = np.stack([x, y, z], axis=-1)
    a, b, c, d = p[:-1, :-1], p[1:, :-1], p[1:, 1:], p[:-1, 1:]
    return np.concatenate([np.stack([a, b, c], -2).reshape(-1, 3, 3), np.stack([a, c, d], -2).reshape(-1, 3, 3)])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_same_hits_as_every_triangle_tested(seed):
    rng = np.random.default_rng(seed)
    tris = _grid(40, 0.02, rng)
    tris = np.concatenate([tris, rng.uniform(-0.5, 1.5, (500, 3, 3))])  # and scattered ones
    origins = rng.uniform(-0.2, 1.2, (600, 3)) + [0.0, 0.5, 0.0]
    directions = rng.standard_normal((600, 3))
    directions[:50, 1:] = 0.0  # axis-parallel rays: zero components in the slab test
    directions[50:100, 0] = 0.0
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    (h0, s0), (h1, s1) = _both(origins, directions, tris, 1e-6)
    assert (h0 >= 0).sum() > 100
    assert np.array_equal(h0, h1) and np.array_equal(s0, s1)


def test_ties_and_shared_edges_pick_the_same_triangle():
    """Rays through shared vertices and edges of the grid: the first of equal hits wins in both."""
    rng = np.random.default_rng(5)
    tris = _grid(20, 0.0, rng)
    g = np.linspace(0.0, 1.0, 20)
    origins = np.stack([np.repeat(g, 20), np.full(400, 1.0), np.tile(g, 20)], axis=1)
    directions = np.tile([0.0, -1.0, 0.0], (400, 1))
    (h0, s0), (h1, s1) = _both(origins, directions, np.concatenate([tris, tris]), 1e-9)
    assert (h0 >= 0).all() and np.array_equal(h0, h1) and np.array_equal(s0, s1)

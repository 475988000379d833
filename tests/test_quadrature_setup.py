"""The compiled per-pair setup loops of radiosity.formfactors._quadrature against their numpy references."""

from __future__ import annotations

import numpy as np

from radiosity.formfactors import _quadrature as Q
from radiosity.formfactors import _reference as R



def grid_patches(rng, n):
    """n small quads and triangles (last vertex repeated) on a few planes, some sharing corners."""
    base = rng.uniform(-1, 1, (n, 3))
    e1, e2 = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    scale = 10.0 ** rng.uniform(-2, 0, (n, 1))
    quads = np.stack([base, base + scale * e1, base + scale * (e1 + e2), base + scale * e2], axis=1)
    tri = rng.random(n) < 0.4
    quads[tri, 3] = quads[tri, 2]
    quads[1::7, 0] = quads[0:-1:7, 1]  # shared vertices: touching heights
    return quads


def test_pair_setup_matches_numpy():
    rng = np.random.default_rng(3)
    quads = grid_patches(rng, 400)
    normals = Q._src_normals(quads)
    centroid, _ = Q.centroids_and_areas(quads)
    r = Q._radius(quads, centroid)
    i, j = rng.integers(0, 400, 20000), rng.integers(0, 400, 20000)
    orders = np.array(Q._APRIORI_ORDERS, dtype=np.int64)
    for limit in (1e-3, 1e-7, 1e-11):
        got = [np.empty(len(i), dtype=bool), np.empty(len(i), dtype=np.int64)]
        ref = [np.empty(len(i), dtype=bool), np.empty(len(i), dtype=np.int64)]
        Q._pair_setup_loop(quads, normals, centroid, r, centroid, normals, r, i, j, orders, limit, *got)
        R._pair_setup_numpy(quads, normals, centroid, r, centroid, normals, r, i, j, orders, limit, *ref)
        assert got[0].any() and np.unique(got[1]).size > 2
        np.testing.assert_array_equal(got[0], ref[0])
        np.testing.assert_array_equal(got[1], ref[1])


def test_near_flags_match_numpy():
    rng = np.random.default_rng(4)
    quads = grid_patches(rng, 300)
    normals = Q._src_normals(quads)
    sources = np.concatenate([quads, quads[:, 3:]], axis=1)  # 5-vertex polygons
    sources[::3, 4] = quads[::3, 3] + 0.01 * normals[::3]
    centroid, _ = Q.centroids_and_areas(quads)
    r = Q._radius(quads, centroid)
    i, j = rng.integers(0, 300, 20000), rng.integers(0, 300, 20000)
    i[:300], j[:300] = np.arange(300), np.roll(np.arange(300), 1)  # neighbours sharing vertices
    i[300:600] = j[300:600] = np.arange(300)  # a patch as its own source: every vertex touches
    size = r[i] + r[j]
    height = Q._source_heights(quads, normals, sources, i, j, size)
    height[::5] = np.where(rng.random((len(height[::5]), 5)) < 0.3, 0.0, height[::5])
    got = [np.empty(len(i), dtype=bool) for _ in range(3)]
    ref = [np.empty(len(i), dtype=bool) for _ in range(3)]
    Q._near_flags_loop(quads, sources, i, j, height, size, *got)
    R._near_flags_numpy(quads, sources, i, j, height, size, *ref)
    for g, f in zip(got, ref):
        np.testing.assert_array_equal(g, f)
    assert all(g.any() for g in got)

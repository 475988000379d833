"""Embree occlusion queries through embreex: the only place float32 and threads appear."""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .. import _tol

__all__ = ["EmbreeOccluder"]


class EmbreeOccluder:
    """Answers "is the segment from origin to end blocked?" for many segments at once.

    Parameters
    ----------
    triangles : (t, 3, 3) float
        Every blocking triangle (both sides block), metres.
    """

    def __init__(self, triangles: np.ndarray, threads: int | None = None):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        self._scene = rtcore_scene.EmbreeScene()
        vertices = np.ascontiguousarray(triangles.reshape(-1, 3), dtype=np.float32)
        faces = np.arange(len(vertices), dtype=np.int32).reshape(-1, 3)
        TriangleMesh(self._scene, vertices, faces)
        self._threads = threads or min(4, os.cpu_count() or 1)
        # The BVH is built lazily on the first query: build it before any thread uses it.
        probe = np.zeros((1, 3), np.float32)
        self._scene.run(probe, np.array([[0, 0, 1]], np.float32), dists=np.array([1e-30], np.float32), query="OCCLUDED")

    def occluded(self, origins: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """(m,) bool: True where something blocks the open segment between the two points."""
        m = len(origins)
        out = np.zeros(m, dtype=bool)
        if m == 0:
            return out
        chunk = max(1, min(_tol.CHUNK_RAYS, -(-m // self._threads)))
        bounds = [(s, min(m, s + chunk)) for s in range(0, m, chunk)]

        def run(bound: tuple[int, int]) -> None:
            s, e = bound
            o = np.ascontiguousarray(origins[s:e], dtype=np.float32)
            d = np.ascontiguousarray(ends[s:e] - origins[s:e], dtype=np.float32)
            # tfar is in units of |d|: stop just short of the end point.
            tfar = np.full(e - s, 1.0 - 1e-4, dtype=np.float32)
            hit = self._scene.run(o, d, dists=tfar, query="OCCLUDED")
            out[s:e] = np.asarray(hit) == 0

        if len(bounds) == 1:
            run(bounds[0])
        else:
            with ThreadPoolExecutor(self._threads) as pool:
                list(pool.map(run, bounds))
        return out

"""Embree occlusion queries through embreex: the only place float32 and threads appear."""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .. import _tol
from ._constants import RAY_TFAR_SHORT

__all__ = ["EmbreeOccluder"]


class EmbreeOccluder:
    """Answers "is the segment from origin to end blocked?" for many segments at once.

    The scene is built in Embree's robust (watertight) mode, so a ray through a shared edge or
    vertex of two triangles hits one of them. Coordinates are shifted to the centre of the
    triangles' bounding box before they are rounded to float32, so a scene far from the origin
    keeps its precision.

    Parameters
    ----------
    triangles : (t, 3, 3) float
        Every blocking triangle (both sides block), metres.
    threads : int, optional
        Worker threads for the ray loop (embreex releases the GIL); default: all cores, at most 8.
    robust : bool, default: True
        Embree's robust traversal (watertight edges); about 10% slower.
    """

    def __init__(self, triangles: np.ndarray, threads: int | None = None, *, robust: bool = True):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        triangles = np.asarray(triangles, dtype=np.float64)
        pts = triangles.reshape(-1, 3)
        self.center = 0.5 * (pts.min(axis=0) + pts.max(axis=0)) if len(pts) else np.zeros(3)
        self.n_triangles = len(triangles)
        self._scene = rtcore_scene.EmbreeScene(robust=robust)
        vertices = np.ascontiguousarray(pts - self.center, dtype=np.float32)
        faces = np.arange(len(vertices), dtype=np.int32).reshape(-1, 3)
        if len(faces):
            TriangleMesh(self._scene, vertices, faces)
        self._threads = threads or max(1, min(8, os.cpu_count() or 1))
        # The BVH is built lazily on the first query: build it before any thread uses it.
        if len(faces):
            probe = np.zeros((1, 3), np.float32)
            self._scene.run(probe, np.array([[0, 0, 1]], np.float32), dists=np.array([1e-30], np.float32),
                            query="OCCLUDED")

    def occluded(self, origins: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """(m,) bool: True where something blocks the open segment between the two points.

        Parameters
        ----------
        origins, ends : (m, 3) float
            Segment ends, metres. Callers pull them off surfaces (``_tol.RAY_OFFSET_REL``).
        """
        m = len(origins)
        out = np.zeros(m, dtype=bool)
        if m == 0 or self.n_triangles == 0:
            return out
        chunk = max(1, min(_tol.CHUNK_RAYS, -(-m // self._threads)))
        bounds = [(s, min(m, s + chunk)) for s in range(0, m, chunk)]

        def run(bound: tuple[int, int]) -> None:
            s, e = bound
            start = origins[s:e] - self.center
            o = np.ascontiguousarray(start, dtype=np.float32)
            d = np.ascontiguousarray(ends[s:e] - self.center - o, dtype=np.float32)
            # tfar is in units of |d|: stop just short of the end point.
            tfar = np.full(e - s, 1.0 - RAY_TFAR_SHORT, dtype=np.float32)
            hit = self._scene.run(o, d, dists=tfar, query="OCCLUDED")
            out[s:e] = np.asarray(hit) == 0

        if len(bounds) == 1:
            run(bounds[0])
        else:
            with ThreadPoolExecutor(self._threads) as pool:
                list(pool.map(run, bounds))
        return out

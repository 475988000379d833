"""Solution: radiosity per patch, per object, per vertex and at arbitrary receiver points."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
import scipy.sparse as sp

from ._validate import as_points, as_unit_vectors
from .options import rename_deprecated, warn_ignored
from .scene import Scene

_SENSOR_ALIAS = {"rtol": "sensor_rtol"}  # docs/options.md

__all__ = ["Solution"]


@dataclass(eq=False)
class Solution:
    """A solved scene.

    Attributes
    ----------
    scene : Scene
        The scene as solved (cut to the preset's patch size).
    radiosity : (n_patches, 3) float
        Radiosity B per patch and RGB channel, W/m^2.
    F : scipy.sparse.csr_matrix or radiosity.shards.ShardedViewFactors
        The view-factor matrix used, ``F[i, j] = F(i -> j)``: on disk in shards when it did not
        fit the memory budget (``view_factor_storage["where"] == "out of core"``). In memory, rows
        the fill left above 1 are scaled down to 1 with their reciprocal entries
        (:func:`radiosity.methods.uniform.system.bound_rows`), so no light is created.
    energy_gaining : list of dict
        The patches whose rows of the filled F summed above 1, largest gain first (up to 10).
    rows_bounded : int
        How many rows were scaled down to 1 before the solve.
    gain_beyond_tolerance : bool
        Whether the light those rows would have created exceeds the fill's tolerance
        (``formfactor_rtol + visibility_atol``) times the emitted power: ``solve`` warned.
    view_factor_storage : dict
        Where F was held: ``{"where": "in memory"}``, or out of core with its shards, block size,
        passes over them, in-memory estimate and budget.
    """

    scene: Scene
    radiosity: np.ndarray
    F: sp.csr_matrix
    options: Any = None
    timings: dict[str, float] = field(default_factory=dict)
    fill: Any = None
    solver: Any = None
    energy: dict[str, list[float]] = field(default_factory=dict)
    cache_hit: bool = False
    view_factor_storage: dict[str, Any] = field(default_factory=lambda: {"where": "in memory"})
    # patches whose share of power landing on fronts exceeds 1 (system.gaining_patches)
    energy_gaining: list[dict] = field(default_factory=list)
    # rows of the filled F above 1 that were scaled down to 1 before the solve (system.bound_rows)
    rows_bounded: int = 0
    gain_beyond_tolerance: bool = False
    _sensors: Any = field(default=None, init=False, repr=False)

    @property
    def patch_irradiance(self) -> np.ndarray:
        """(n, 3) irradiance H arriving at each patch's front, W/m^2 (B = E + rho H)."""
        return self.F @ self.radiosity

    def object_radiosity(self) -> dict[str, np.ndarray]:
        """Area-weighted mean radiosity (3,) of each named object, W/m^2."""
        means = object_means(self.scene.patch_object, self.scene.patch_area, self.radiosity, len(self.scene.objects))
        return dict(zip(self.scene.objects, means))

    @cached_property
    def vertex_mesh(self) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
        """Welded vertices (per face), faces as index lists, and area-weighted vertex radiosity.

        Vertices are merged only within one OBJ face, so light does not bleed across a contact
        or a crease; hidden patches (under a contact) do not weigh on the vertices they share
        with visible ones. A
        vertex of one patch lying inside another patch's edge (a T-junction, where cells cut
        differently meet) is inserted into that patch's outline, so the shading is continuous
        across the edge instead of showing a facet.
        """
        quads = self.scene.patch_quads
        n = len(quads)
        is_tri = (quads[:, 3] == quads[:, 2]).all(axis=1)
        pts = quads.reshape(-1, 3)
        grid = max(self.scene.scale, 1e-300) * 1e-7
        keys = np.column_stack([np.round(pts / grid).astype(np.int64), np.repeat(self.scene.patch_face, 4)])
        _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
        inverse = inverse.reshape(n, 4)
        vertices = pts[first]
        faces = [inverse[i, :3] if is_tri[i] else inverse[i] for i in range(n)]
        faces = _insert_t_junctions(vertices, faces, self.scene.patch_face, grid)
        corner = np.concatenate(faces)
        owner = np.repeat(np.arange(n), [len(f) for f in faces])
        # Hidden patches (covered by a contact) are never seen: they must not darken the
        # visible patches around them. A vertex only they touch keeps their value.
        weight = self.scene.patch_area[owner] * np.where(self.scene.patch_hidden[owner], 1e-9, 1.0)
        sums = np.zeros((len(vertices), 3))
        np.add.at(sums, corner, self.radiosity[owner] * weight[:, None])
        wsum = np.bincount(corner, weights=weight, minlength=len(vertices))
        vertex_b = sums / np.maximum(wsum, 1e-300)[:, None]
        return vertices, faces, vertex_b

    def irradiance(self, points, normals, *, sensor_rtol: float = 1e-3, samples: int | None = None,
                   rtol: float | None = None) -> np.ndarray:
        """Irradiance H (m, 3) at receiver points, W/m^2, occlusion included (final gather).

        Every face shadows every point (faces on the scene's hull too, for points outside it),
        and partly occluded sources are clipped by exact shadows, so a point's value depends
        only on that point: never on the other points or their order.

        Parameters
        ----------
        points : (m, 3) float
            Receiver positions, metres (e.g. a sensor grid on a desk).
        normals : (m, 3) float
            Receiver normals (any non-zero length); only light arriving on their side counts.
        sensor_rtol : float, default: 1e-3
            Bound on each value's relative error from shadows, per channel: partly occluded
            sources whose contributions add up to less than ``2 sensor_rtol H`` are counted half
            visible instead of clipped. 0 clips every shadow exactly. Same as ``--sensor-rtol``.
        samples : None
            Deprecated and ignored: shadows are exact, not sampled. Kept so older calls still
            run; a value other than None warns (``RadiosityWarning``).
        rtol : float, optional
            Old name of ``sensor_rtol`` (deprecated, warns).
        """
        from .visibility import Visibility
        from .visibility._points import SensorGather

        points = as_points(points, "points")
        normals = as_unit_vectors(normals, "normals")
        if len(points) != len(normals):
            raise ValueError(f"points and normals must have the same length, got {len(points)} and {len(normals)}")
        if samples is not None:
            warn_ignored("samples", "irradiance option", "shadows are exact, not sampled")
        if rtol is not None:
            sensor_rtol = rename_deprecated({"rtol": rtol}, "irradiance option", aliases=_SENSOR_ALIAS)["sensor_rtol"]
        if not (np.isfinite(sensor_rtol) and 0.0 <= sensor_rtol < 1.0):
            raise ValueError(f"sensor_rtol must be in [0, 1), got {sensor_rtol!r}")
        scene, origin = self.scene.centred()  # as solve: far from the origin, digits are lost
        # covered patches send nothing (imprint.py): their radiosity is their own emission, and a
        # cover flush on them does not hide them from a point (the segment meets it at its end):
        # under a black panel flush on a luminous ceiling a sensor read 31.6x the light it gets
        # under the same panel hung 1 cm lower
        sending = np.where(scene.patch_hidden[:, None], 0.0, self.radiosity)
        if self._sensors is None or not np.array_equal(self._sensors.radiosity, sending):
            vis = Visibility(scene.patch_quads, scene.patch_normal, scene.patch_object, scene.scale)
            self._sensors = SensorGather(scene.patch_quads, scene.patch_normal, scene.patch_object, scene.scale,
                                         sending, inner=vis.occluders)
        return self._sensors.irradiance(points - origin, normals, rtol=sensor_rtol)

    def summary(self) -> dict[str, Any]:
        """Machine-readable summary (what ``summary.json`` holds)."""
        scene = self.scene
        objects = {k: [float(x) for x in v] for k, v in self.object_radiosity().items()}
        fill = self.fill
        return {
            "source": scene.source,
            "patches": int(scene.n_patches),
            "objects": objects,
            "timings_s": {k: round(v, 4) for k, v in self.timings.items()},
            "cache_hit": self.cache_hit,
            "nonzeros": int(self.F.nnz),
            "view_factors": dict(self.view_factor_storage),
            "pairs": getattr(fill, "n_pairs", None),
            "traced_pairs": getattr(fill, "n_traced_pairs", None),
            "rays": getattr(fill, "n_rays", None),
            "solver": {"method": self.solver.method, "iterations": self.solver.iterations,
                       "residual": self.solver.residual,
                       "fallback": self.solver.fallback} if self.solver else None,
            "energy_W": self.energy,
            "energy_gaining": self.energy_gaining,
            "rows_bounded": self.rows_bounded,
            "gain_beyond_tolerance": self.gain_beyond_tolerance,
            "emission": emission_reading(scene.emission_mode),
            "emitter_rays": scene.light_paths,
            "notes": list(scene.notes),
            "method": "hierarchical" if hasattr(fill, "summary") else "uniform",  # which ran (also under "auto")
            "hierarchy": fill.summary() if hasattr(fill, "summary") else None,
        }


def emission_reading(mode: str) -> dict[str, str]:
    """How ``Ke`` was read, for the summary: ``{"ke_read_as": mode, "exitance": formula}``."""
    if mode == "exitance":
        return {"ke_read_as": "exitance", "exitance": "E = Ke (W/m^2)"}
    return {"ke_read_as": "radiance", "exitance": "E = pi * Ke (Ke in W/(m^2 sr))"}


def _insert_t_junctions(vertices: np.ndarray, faces: list[np.ndarray], patch_face: np.ndarray,
                        tol: float) -> list[np.ndarray]:
    """Patch outlines with the vertices of the same OBJ face that lie inside their edges
    inserted in order along each edge (distance below ``tol``)."""
    out = list(faces)
    for members in patch_groups(patch_face).values():
        if len(members) < 2:  # a patch alone in its face: no other patch's vertex to insert
            continue
        candidates = np.unique(np.concatenate([faces[i] for i in members]))
        points = vertices[candidates]
        for i in members:
            outline = faces[i]
            grown = []
            for a, b in zip(outline, np.roll(outline, -1)):
                grown.append([a])
                d = vertices[b] - vertices[a]
                length2 = float(d @ d)
                if length2 == 0.0:
                    continue
                t = (points - vertices[a]) @ d / length2
                off = points - vertices[a] - t[:, None] * d
                inside = (t > 1e-9) & (t < 1 - 1e-9) & (np.einsum("pc,pc->p", off, off) < tol * tol)
                grown.append(candidates[inside][np.argsort(t[inside])])
            if sum(len(g) for g in grown) > len(outline):
                out[i] = np.concatenate(grown).astype(outline.dtype)
    return out


def patch_groups(labels: np.ndarray) -> dict[int, np.ndarray]:
    """{label: the ascending indices holding it} (patches by object or by OBJ face), from one
    sort: a mask per label costs O(n) each, and with a label per OBJ face a terrain of a million
    triangles spent about five minutes writing its outputs on those masks."""
    labels = np.asarray(labels)
    order = np.argsort(labels, kind="stable")
    cuts = np.flatnonzero(np.diff(labels[order])) + 1
    groups = np.split(order, cuts)
    return {int(labels[g[0]]): g for g in groups if len(g)}


def object_means(patch_object: np.ndarray, area: np.ndarray, values: np.ndarray, n_objects: int) -> list[np.ndarray]:
    """Area-weighted mean of ``values`` (n, 3) over each object's patches, objects 0..n_objects-1
    (zeros for an object without area)."""
    groups = patch_groups(patch_object)
    means = []
    for index in range(n_objects):
        mask = groups.get(index, np.zeros(0, np.int64))
        total = area[mask].sum()
        means.append((area[mask, None] * values[mask]).sum(axis=0) / total if total > 0 else np.zeros(3))
    return means

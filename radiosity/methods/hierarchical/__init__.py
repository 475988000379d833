"""Hierarchical radiosity (Hanrahan, Salzman & Aupperle 1991) with BF refinement.

Each input patch is the root of an element quadtree (:mod:`._elements`); links between
elements are refined where a bound on the radiosity error they make, visibility uncertainty
included, exceeds a tolerance (:mod:`._hierarchy`); form factors come from Lambert's
point-to-polygon kernel and visibility from the shared classification and rays (:mod:`._links`). Refinement and
solving alternate until a pass splits no link. The leaves become the solved scene's patches,
so everything a :class:`radiosity.Solution` offers works unchanged (``radiosity.solve`` makes the
Solution of :class:`HierarchicalResult`: a method does not import the solution stage). See
``docs/hierarchical.md``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from ...options import Options
from ...scene import Scene
from ...visibility import Visibility
from ._hierarchy import Hierarchy, HierarchyStats, LinkOperator, SolveReport, matrix_bytes

__all__ = ["solve_hierarchical", "build_hierarchy", "min_element_size", "Hierarchy", "HierarchyStats",
           "LinkOperator", "HierarchicalResult", "MAX_ROUNDS"]

MAX_ROUNDS = 12  # refinement passes at most (each followed by a solve); a pass that splits nothing ends it


def min_element_size(scene: Scene, options: Options) -> float:
    """The minimum element size of a solve, metres, checked against the scene."""
    size = options.min_element_size
    if size is None:
        size = options.min_element_rel * scene.scale
    if not (np.isfinite(size) and size > 0):
        raise ValueError(f"min_element_size must be a positive number of metres, got {size!r}")
    if size > scene.scale:
        raise ValueError(f"min_element_size {size:g} m is larger than the scene (its bounding-box diagonal "
                         f"is {scene.scale:g} m)")
    return float(size)


def _check_tolerances(options: Options) -> None:
    tolerance, leaf = options.link_tolerance, options.leaf_tolerance
    if not (np.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"link_tolerance must be a positive fraction of the mean emitted exitance, got {tolerance!r}")
    if not (np.isfinite(leaf) and leaf >= 0):
        raise ValueError(f"leaf_tolerance must be a fraction of the mean emitted exitance, 0 or more, got {leaf!r}")


def _roots(scene: Scene, options: Options) -> Scene:
    """The input patches the quadtrees start from: the scene as loaded, or cut if asked."""
    if options.max_patch_size is None or (scene.max_patch_size is not None
                                          and options.max_patch_size >= scene.max_patch_size):
        return scene
    return scene.resubdivided(options.max_patch_size)


def build_hierarchy(scene: Scene, options: Options, *, clusters: bool | None = None) -> Hierarchy:
    """The (unrefined) hierarchy of a scene under ``options`` (for tests and benches).

    ``clusters``: start from a volume hierarchy over the input patches (None: when there are
    many of them, see :data:`._clusters.CLUSTER_MIN_ROOTS`).
    """
    _check_tolerances(options)
    size = min_element_size(scene, options)
    visibility = Visibility(scene.patch_quads, scene.patch_normal, scene.patch_object, scene.scale,
                            samples=options.visibility_samples, max_samples=options.visibility_max_samples)
    return Hierarchy(scene.patch_quads, scene.patch_normal, scene.reflectance, scene.emission, ~scene.patch_inactive,
                     visibility, min_size=size, tolerance=options.link_tolerance,
                     leaf_tolerance=options.leaf_tolerance,
                     formfactor_rtol=options.formfactor_rtol, exact=options.visibility != "rays",
                     clusters=clusters)


@dataclass
class HierarchicalResult:
    """What the method hands back to ``radiosity.solve``, which makes the Solution of it.

    Attributes
    ----------
    scene : Scene
        The leaf mesh (the scene as solved).
    radiosity : (n_leaves, 3) float
    F : LinkOperator
        ``K = P G R`` on the leaves (``K @ B`` is their irradiance).
    stats : HierarchyStats
    report : SolveReport
    timings : dict
    """

    scene: Scene
    radiosity: np.ndarray
    F: LinkOperator
    stats: HierarchyStats
    report: SolveReport
    timings: dict


def solve_hierarchical(scene: Scene, options: Options) -> HierarchicalResult:
    """Solve by hierarchical radiosity; the result's scene is the leaf mesh.

    Stopping rule: refine with the current radiosities, solve, and repeat until a refinement
    pass splits no link (every link then meets the tolerance with the radiosities it was
    solved with), at most :data:`MAX_ROUNDS` passes.
    """
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    roots = _roots(scene, options)
    timings["patches"] = time.perf_counter() - t0
    hier = build_hierarchy(roots, options)
    bar = _progress(options.progress)
    if bar is not None:
        hier.progress = bar.update
    try:
        B, K, leaves, report = _alternate(hier, options, timings, bar)
    finally:
        if bar is not None:
            bar.close()
    _record(hier, K, leaves)
    return HierarchicalResult(_leaf_scene(roots, hier, leaves), B, K, hier.stats, report, timings)


def _progress(enabled: bool):
    """A tqdm bar counting links evaluated (the total is not known in advance), or None."""
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(desc="hierarchy", unit="link", leave=False)


def _alternate(hier: Hierarchy, options: Options, timings: dict, bar):
    """Refine and solve in turn until a pass splits no link (at most MAX_ROUNDS passes).

    The solves that steer refinement scale leaf rows of K past 1 down to 1 (no point sees more
    than its hemisphere). After the first pass only the emitters' links are refined, and the
    coarse cluster links between unlit clusters summed to rows of up to 14 in a furnished room
    (2,076 faces): its solve doubled the light and the next pass split 5.4 M links instead of
    1.4 M. The answer is solved once more without the scaling, which, cutting only the rows
    above 1 of push errors that cancel on average, darkens a surface (the bundled box's ceiling
    at draft: 1.3% -> 2.8% off).
    """
    refine_s = solve_s = 0.0
    clamped = False
    for round_ in range(MAX_ROUNDS):
        if bar is not None:
            bar.set_postfix_str(f"pass {round_ + 1}")
        # the last pass's operator is not held through refinement (about 2.2 GB of a 300k-face
        # sphere's 6.9 GB peak); a pass that splits nothing may still settle links: rebuilt below
        K = None
        t = time.perf_counter()
        split = hier.refine()
        refine_s += time.perf_counter() - t
        hier.stats.rounds = round_ + 1
        if split == 0 and round_ > 0:
            hier.stats.converged = True
            break
        t = time.perf_counter()
        B, K, leaves, report = hier.solve(options.solver_rtol, clamp=True)
        clamped = K.row_scale is not None
        solve_s += time.perf_counter() - t
    if clamped or K is None:
        t = time.perf_counter()
        B, K, leaves, report = hier.solve(options.solver_rtol)
        solve_s += time.perf_counter() - t
    timings["hierarchy"] = refine_s
    timings["solve"] = solve_s
    return B, K, leaves, report


def _leaf_scene(roots: Scene, hier: Hierarchy, leaves: np.ndarray) -> Scene:
    """The scene as solved: one patch per leaf element, with its input patch's object and materials."""
    parent = hier.el.root[leaves]
    return replace(roots, patch_quads=hier.el.quads[leaves], patch_object=roots.patch_object[parent],
                   patch_face=roots.patch_face[parent], reflectance=roots.reflectance[parent],
                   emission=roots.emission[parent], patch_obstruction=roots.patch_obstruction[parent],
                   patch_hidden=roots.patch_hidden[parent], max_patch_size=None)


def _record(hier: Hierarchy, K: LinkOperator, leaves: np.ndarray) -> None:
    stats = hier.stats
    stats.links = len(hier.links) + len(hier.cluster_r) + len(hier.mixed_r) + len(hier.reverse_r)
    stats.cluster_links = len(hier.cluster_r)
    stats.mixed_links = len(hier.mixed_r)
    stats.reverse_mixed_links = len(hier.reverse_r)
    stats.partly_visible_links = int(hier.links.partial.sum())
    stats.pairs_traced = hier.vis.n_traced
    stats.n_rays = hier.vis.n_rays
    stats.elements = len(hier.el)
    stats.leaves = len(leaves)
    stats.max_level = int(hier.el.level.max())
    stats.memory_bytes = int(sum(matrix_bytes(m) for m in (K.push, K.gather, K.pull))
                             + hier.el.quads.nbytes * 3 + stats.links * 50)

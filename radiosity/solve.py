"""Run the stages: patches -> form factors + visibility -> system -> Solution; view_factors."""

from __future__ import annotations

import hashlib
import os
import time
import warnings
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from . import _memory
from ._errors import MemoryBudgetError, RadiosityWarning
from .methods.uniform.assembly import FillSettings, FillStats, assemble
from .methods.uniform.cache import FormFactorCache
from .options import PRESETS, Options, rename_deprecated
from .scene import Scene, load_scene
from .solution import Solution
from .methods.uniform.system import (SolverReport, bound_rows, energy_balance, gain_note, gained_power,
                                     gaining_patches, solve_system)
from .visibility import Visibility

if TYPE_CHECKING:  # the return types of the view-factor entry points, imported where used
    from .factors import ViewFactors
    from .methods.uniform.shards import ShardedViewFactors

__all__ = ["solve", "view_factors", "compute_view_factors", "write_view_factors", "prepare"]


METHODS = ("auto", "uniform", "hierarchical")
# method="auto" takes the hierarchy above this many patch pairs (cut patches squared): the
# uniform fill then takes minutes and gigabytes (FIELD_NOTES: 9,504 patches 182 s / 3.6 GB,
# 18,460 patches 717 s / 13 GB on 2 cores, growing as N^1.8).
AUTO_MAX_PAIRS = 12_000 ** 2
# method="auto" also takes the hierarchy when a sample of the uniform fill's pairs says the fill
# would take longer than this on 2 cores (radiosity.methods.uniform.estimate); scenes with fewer
# active patches than AUTO_SAMPLE_MIN are not sampled (at most 5e5 pairs: a few minutes at worst)
AUTO_MAX_FILL_SECONDS = 600.0
AUTO_SAMPLE_MIN = 1_000


@dataclass
class Prepared:
    """A scene cut for solving and its view-factor matrix, with what it cost."""

    scene: Scene
    F: sp.csr_matrix
    stats: FillStats
    timings: dict[str, float] = field(default_factory=dict)
    cache_hit: bool = False


def _fill_settings(options: Options) -> FillSettings:
    return FillSettings.from_options(options)


def _cut(scene: Scene, options: Options) -> Scene:
    size = options.max_patch_size or scene.max_patch_size
    if size is None:
        size = options.patch_size_rel * scene.scale
    if not np.isfinite(size) or (scene.max_patch_size is not None and size >= scene.max_patch_size):
        return scene
    _memory.check_cut(scene.patch_quads, size)
    return scene.resubdivided(size)


def _progress_bar(enabled: bool, total: int, desc: str):
    if not enabled:
        return None, lambda: None
    from tqdm import tqdm

    bar = tqdm(total=total, desc=desc, unit="patch", leave=False)
    return bar.update, bar.close


def prepare(scene: Scene, options: Options) -> Prepared:
    """Cut the scene to the options' patch size and fill (or fetch) its view-factor matrix."""
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    cut = _cut(scene, options)
    timings["patches"] = time.perf_counter() - t0
    settings = _fill_settings(options)
    _memory.check_fill(cut.n_patches, patch_size=cut.max_patch_size)
    cache = FormFactorCache.default() if options.cache else None
    inactive = cut.patch_inactive
    key = _fill_key(cut.geometry_hash, inactive)
    if cache is not None:
        hit = cache.load(key, settings)
        if hit is not None:
            F, stats = hit
            timings["form factors"] = 0.0
            timings["visibility"] = 0.0
            timings["cache"] = time.perf_counter() - t0 - timings["patches"]
            return Prepared(cut, F, stats, timings, cache_hit=True)
    if options.workers is not None or options.scheduler is not None:
        return _prepare_on_cluster(cut, settings, inactive, options, cache, key, timings)
    visibility = Visibility(cut.patch_quads, cut.patch_normal, cut.patch_object, cut.scale,
                            samples=settings.visibility_samples, max_samples=settings.visibility_max_samples)
    update, close = _progress_bar(options.progress, cut.n_patches, "form factors")
    try:
        F, stats = assemble(cut.patch_quads, cut.patch_normal, cut.patch_centroid, cut.patch_area,
                            visibility, settings, progress=update, active=~inactive)
    finally:
        close()
    timings["form factors"] = stats.seconds_formfactors
    timings["visibility"] = stats.seconds_visibility
    note = visibility.union_note()
    if note is not None:
        warnings.warn(note, RadiosityWarning, stacklevel=3)
    if cache is not None:
        cache.store(key, settings, F, stats)
    return Prepared(cut, F, stats, timings)


def _prepare_on_cluster(cut, settings, inactive, options, cache, key, timings) -> Prepared:
    """The fill of :func:`prepare` with its row blocks as Dask tasks (:mod:`radiosity.methods.uniform.cluster`)."""
    from .methods.uniform.cluster import FillProblem, cluster_client, fill_matrix

    problem = FillProblem.from_scene(cut, settings, ~inactive)
    update, close = _progress_bar(options.progress, cut.n_patches, "form factors")
    try:
        with cluster_client(options.workers, options.scheduler) as client:
            F, stats = fill_matrix(problem, client=client, progress=update)
    finally:
        close()
    timings["form factors"] = stats.seconds_formfactors
    timings["visibility"] = stats.seconds_visibility
    if cache is not None:
        cache.store(key, settings, F, stats)
    return Prepared(cut, F, stats, timings)


def solve(scene: Scene | str | os.PathLike, *, preset: str = "default", **overrides) -> Solution:
    """Solve the scene's radiosity.

    Parameters
    ----------
    scene : Scene, or the path of a scene file
        From :func:`load_scene`; a path is loaded with its defaults.
    preset : {"draft", "default", "fine"}, default: "default"
        Ordered by time and by accuracy; see :data:`radiosity.options.PRESETS`.
    **overrides
        Any field of :class:`radiosity.options.Options` (``max_patch_size``,
        ``near_order``, ``visibility_samples``, ``solver``, ``solver_rtol``, ``cache``, ...).
        ``method="hierarchical"`` solves by hierarchical radiosity instead of the uniform
        fill (:mod:`radiosity.methods.hierarchical`); ``Solution.scene`` is then its leaves.
        ``method="auto"`` (the default) takes the hierarchy when the uniform fill would pair
        more than ``AUTO_MAX_PAIRS`` patches (minutes, and gigabytes), or would take more than
        ``AUTO_MAX_FILL_SECONDS`` by an estimate from a sample of its pairs; the summary's
        ``method`` says which ran, and its notes why the hierarchy was taken.

    Returns
    -------
    Solution

    Notes
    -----
    When the view-factor matrix does not fit the memory budget (``RADIOSITY_MEMORY_BUDGET``), it
    is filled out of core into temporary shards and the system is solved over them by gmres
    (:mod:`radiosity.methods.uniform.outofcore`); ``Solution.view_factor_storage`` says which path ran.

    Examples
    --------
    >>> import radiosity
    >>> scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    >>> solution = radiosity.solve(scene, preset="draft", cache=False)
    >>> sorted(solution.object_radiosity())[:2]
    ['back_wall', 'ceiling']
    """
    if isinstance(scene, (str, os.PathLike)):
        scene = load_scene(scene)
    elif not isinstance(scene, Scene):
        raise TypeError(f"solve takes a Scene (radiosity.load_scene) or a scene file's path, "
                        f"not {type(scene).__name__}")
    options = Options.from_preset(preset, **overrides)
    if options.method not in METHODS:
        raise TypeError(f"unknown method {options.method!r}; valid: {', '.join(METHODS)}")
    local, origin = scene.centred()  # far from the origin, coordinates lose the digits contacts need
    solution = _solve_centred(local, options)
    return replace(solution, scene=solution.scene.moved(origin)) if origin.any() else solution


def _solve_centred(scene: Scene, options: Options) -> Solution:
    """:func:`solve` of a scene near the origin."""
    if options.method == "hierarchical":
        return _solve_hierarchical(scene, options)
    t0 = time.perf_counter()
    cut = _cut(scene, options)
    cut_seconds = time.perf_counter() - t0
    if options.method == "auto":
        method, note = _auto_method(cut, options)  # options keep "auto"; the summary says which ran
        if method == "hierarchical":
            return _solve_hierarchical(replace(scene, notes=scene.notes + (note,)), options)
    try:
        _memory.check_fill(cut.n_patches, patch_size=cut.max_patch_size)
    except MemoryBudgetError as refusal:  # F does not fit: fill it into shards and iterate over them
        return _solve_out_of_core(cut, options, refusal, {"patches": cut_seconds})
    prepared = prepare(cut, options)  # cut already: prepare's own cut is a no-op
    prepared.timings["patches"] += cut_seconds
    cut = prepared.scene
    filled = _without(prepared.F, cut.patch_inactive)
    # rows above 1 would create light (escaped < 0): scale them to 1, reciprocity kept
    F, n_bounded = bound_rows(filled, cut.patch_area)
    _memory.check_solve(F.shape[0], F.nnz, options.solver)
    t0 = time.perf_counter()
    radiosity, report = solve_system(F, cut.reflectance, cut.emission, cut.patch_area,
                                     method=options.solver, rtol=options.solver_rtol)
    timings = dict(prepared.timings)
    timings["solve"] = time.perf_counter() - t0
    balance = _balance(F, cut, radiosity)
    gaining = gaining_patches(filled, cut.patch_area, radiosity, cut.patch_object, cut.objects)
    gained = gained_power(filled, cut.patch_area, radiosity) if n_bounded else None
    note = gain_note(balance, gaining, options.formfactor_rtol + options.visibility_atol, gained=gained)
    if note is not None:  # rows above 1: say where, so the user can look
        warnings.warn(note, RadiosityWarning, stacklevel=2)
    return Solution(scene=cut, radiosity=radiosity, F=F, options=options, timings=timings,
                    fill=prepared.stats, solver=report, energy=balance, cache_hit=prepared.cache_hit,
                    energy_gaining=gaining, rows_bounded=n_bounded, gain_beyond_tolerance=note is not None)


def _solve_out_of_core(cut, options, refusal: MemoryBudgetError, timings: dict[str, float]):
    """The :class:`radiosity.Solution` of ``cut`` (already cut to size) with F in shards.

    ``refusal`` is the in-memory fill's ``MemoryBudgetError``, raised when not even the
    out-of-core fill fits the budget.
    """
    import shutil
    import tempfile
    import weakref
    from pathlib import Path

    from .methods.uniform.cluster import FillProblem, cluster_client
    from .methods.uniform.outofcore import OUT_OF_CORE_SOLVERS, out_of_core_plan, solve_shards
    from .methods.uniform.shards import write_shards
    if options.solver not in OUT_OF_CORE_SOLVERS:
        raise MemoryBudgetError(f"{refusal}; or solve out of core with --solver gmres or bicgstab "
                                f"(the {options.solver} solver needs F in memory)")
    pairs = out_of_core_plan(cut.n_patches, refusal)
    budget, source = _memory.budget_bytes()
    disk = _memory.check_shard_space(cut.n_patches, tempfile.gettempdir())
    folder = Path(tempfile.mkdtemp(prefix="radiosity-F-"))
    inactive = cut.patch_inactive
    problem = FillProblem.from_scene(cut, _fill_settings(options), ~inactive)
    update, close = _progress_bar(options.progress, cut.n_patches, "form factors (out of core)")
    try:
        with cluster_client(options.workers, options.scheduler) as client:
            F, stats = write_shards(problem, cut, folder / "F.shards", client=client, pairs_per_block=pairs,
                                    progress=update)
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    finally:
        close()
    weakref.finalize(F, shutil.rmtree, folder, True)  # the shards live as long as the matrix
    timings["form factors"] = stats.seconds_formfactors
    timings["visibility"] = stats.seconds_visibility
    t0 = time.perf_counter()
    # The fill leaves out the pairs of inactive patches: their rows and columns are already zero.
    radiosity, info = solve_shards(F, cut.reflectance, cut.emission, method=options.solver, rtol=options.solver_rtol)
    radiosity[inactive] = cut.emission[inactive]
    timings["solve"] = time.perf_counter() - t0
    report = SolverReport(f"{info['method']} over the shards", [info["iterations"]] * 3, info["residual"],
                          [None] * 3)
    balance = _balance(F, cut, radiosity)
    storage = {"where": "out of core", "shards": F.n_blocks, "pairs_per_block": pairs,
               "passes": info["passes"], "estimate_in_memory": _memory.format_bytes(_memory.fill_bytes(cut.n_patches)),
               "budget": f"{_memory.format_bytes(budget)} ({source})",
               "disk_estimate": _memory.format_bytes(disk)}
    return Solution(scene=cut, radiosity=radiosity, F=F, options=options, timings=timings, fill=stats,
                    solver=report, energy=balance, view_factor_storage=storage)


def _auto_method(cut: Scene, options: Options) -> tuple[str, str]:
    """The method ``method="auto"`` takes for a scene cut to size, and a note why.

    The hierarchy when the uniform fill would pair more than ``AUTO_MAX_PAIRS`` patches (a
    fill that does not fit a small budget but pairs few patches still goes out of core, as a
    uniform solve does), or when a sample of its pairs says it would take more than
    ``AUTO_MAX_FILL_SECONDS`` (:mod:`radiosity.methods.uniform.estimate`: the clutter of a
    furnished room, not its size, makes its fill slow) and timing a random 2% of its rows
    agrees (:func:`~radiosity.methods.uniform.estimate.time_fill`: at most about 5 s). Scenes of
    fewer than ``AUTO_SAMPLE_MIN`` active patches are not sampled.
    """
    pairs = cut.n_patches ** 2
    if pairs > AUTO_MAX_PAIRS:
        need = _memory.format_bytes(_memory.fill_bytes(cut.n_patches))
        return "hierarchical", (f"method auto: hierarchical, since the uniform fill would pair {cut.n_patches:,} "
                                f"patches ({pairs:.2g} pairs > {AUTO_MAX_PAIRS:.2g}, up to {need}); "
                                f"--method uniform overrides")
    active = ~cut.patch_inactive
    if active.sum() < AUTO_SAMPLE_MIN:
        return "uniform", ""
    from .methods.uniform.estimate import estimate_fill, time_fill

    settings = _fill_settings(options)
    visibility = Visibility(cut.patch_quads, cut.patch_normal, cut.patch_object, cut.scale,
                            samples=settings.visibility_samples, max_samples=settings.visibility_max_samples)
    estimate = estimate_fill(cut.patch_quads, cut.patch_normal, cut.patch_centroid, visibility, settings, active)
    if estimate.seconds <= AUTO_MAX_FILL_SECONDS:
        return "uniform", ""
    # the model's counts can be far off (see estimate.py): time some of the fill's rows first
    timing = time_fill(cut.patch_quads, cut.patch_normal, cut.patch_centroid, cut.patch_area, visibility, settings,
                       active)
    if timing.seconds <= AUTO_MAX_FILL_SECONDS:
        return "uniform", ""
    return "hierarchical", (f"method auto: hierarchical, since the uniform fill of {cut.n_patches:,} patches "
                            f"would take {estimate.describe()}; {timing.describe()}; --method uniform overrides")


def _solve_hierarchical(scene: Scene, options: Options) -> Solution:
    """The Solution of :mod:`radiosity.methods.hierarchical` (its scene: the leaf mesh)."""
    from .methods.hierarchical import solve_hierarchical

    result = solve_hierarchical(scene, options)
    leaves = result.scene
    balance = _balance(result.F, leaves, result.radiosity)
    return Solution(scene=leaves, radiosity=result.radiosity, F=result.F, options=options, timings=result.timings,
                    fill=result.stats, solver=result.report, energy=balance)


def _fill_key(geometry_hash: str, inactive: np.ndarray) -> str:
    """Cache key of a fill: the fill leaves out pairs of inactive patches, so they are part of it."""
    if not inactive.any():
        return geometry_hash
    digest = hashlib.sha256(geometry_hash.encode() + np.packbits(inactive).tobytes())
    return digest.hexdigest()[:32]


def _balance(F, scene: Scene, radiosity: np.ndarray) -> dict[str, list[float]]:
    """:func:`energy_balance` over the patches that are there: a hidden region (under a contact)
    neither emits into the scene nor receives. Counted, its emission went to "escaped": a closed
    furnace room whose ceiling panel and cylinder touch the ceiling and floor reported 4.96 W of
    its 206.4 W escaping, the covered area's emission."""
    area = np.where(scene.patch_hidden, 0.0, scene.patch_area)  # Scene sizes patch_hidden to its patches
    return energy_balance(F, area, scene.reflectance, scene.emission, radiosity)


def _without(F: sp.csr_matrix, inactive: np.ndarray) -> sp.csr_matrix:
    """F with the rows and columns of inactive patches (obstructions) set to zero.

    The fill leaves such pairs out already (``assemble(active=...)``), so this is mostly a
    check; two sparse products took 0.3 ms of a 7 ms fill of View3D's blocked plates."""
    if not inactive.any():
        return F
    F = F.tocsr()
    drop = np.repeat(inactive, np.diff(F.indptr)) | inactive[F.indices]
    if not drop.any():
        return F
    F = F.copy()
    F.data[drop] = 0.0
    F.eliminate_zeros()
    return F


ENFORCE = ("none", "reciprocity", "closure", "auto")


def _view_factor_options(preset: str, overrides: dict) -> Options:
    """The options of a view-factor fill (tighter than a solve's; no cut unless asked)."""
    # The matrix is the product here: each factor to 1e-6 (or tighter) unless asked; partly
    # occluded pairs then take exact shadow clipping ("auto" with visibility_atol 1e-6).
    tight = {"formfactor_rtol": 1e-6, "visibility_atol": 1e-6}
    overrides = rename_deprecated(overrides, "view-factor option", stacklevel=5)
    if preset in PRESETS:
        tight = {k: min(v, getattr(PRESETS[preset], k)) for k, v in tight.items()}
    overrides = {**tight, **overrides}
    options = Options.from_preset(preset, **overrides)
    if options.max_patch_size is None:
        options = Options.from_preset(preset, **{**overrides, "patch_size_rel": np.inf})
    return options


def write_view_factors(scene: Scene, path, *, preset: str = "default", pairs_per_block: int | None = None,
                       **overrides) -> "ShardedViewFactors":
    """The view-factor matrix written out of core, as it is filled, into the shard folder ``path``.

    For matrices larger than memory: only one row block is in memory at a time (its size planned
    from the memory budget, ``RADIOSITY_MEMORY_BUDGET``), and each is written to its shard as
    soon as it is computed. Same options as :func:`view_factors` (``workers=`` or
    ``scheduler=`` fill the blocks on a Dask cluster), except ``enforce``: the shards hold the
    matrix as filled. See :mod:`radiosity.methods.uniform.shards`.

    Returns
    -------
    radiosity.methods.uniform.shards.ShardedViewFactors
        The lazy matrix, as :func:`radiosity.load_view_factors` reads it back.

    Examples
    --------
    >>> import tempfile, numpy as np, radiosity
    >>> scene = radiosity.load_scene(radiosity.bundled_scene("unit_cube"), max_patch_size=0.5)
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     F = radiosity.write_view_factors(scene, tmp + "/F.shards")
    ...     F.shape, bool(np.allclose(F @ np.ones(24), 1.0, atol=1e-6))
    ((24, 24), True)
    """
    from .methods.uniform.cluster import FillProblem, cluster_client
    from .methods.uniform.shards import write_shards

    options = _view_factor_options(preset, {**overrides, "cache": False})
    scene, origin = scene.centred()  # as compute_view_factors; the shards keep the patches where they were
    cut = _cut(scene, options)
    _memory.check_shard_space(cut.n_patches, path, "write them to a larger disk, or use larger patches "
                                                   "(--max-patch-size)")
    settings = _fill_settings(options)
    problem = FillProblem.from_scene(cut, settings, ~cut.patch_inactive)
    update, close = _progress_bar(options.progress, cut.n_patches, "form factors")
    try:
        with cluster_client(options.workers, options.scheduler) as client:
            F, _ = write_shards(problem, cut.moved(origin), path, client=client, pairs_per_block=pairs_per_block,
                                progress=update, settings=_stored_settings(preset, options))
    finally:
        close()
    return F


def _stored_settings(preset: str, options) -> dict:
    """The fill settings a view-factor file or shard folder records (``visibility_rtol``: the
    file key kept from before ``visibility_atol``)."""
    return {"preset": preset, "formfactor_rtol": options.formfactor_rtol, "visibility_rtol": options.visibility_atol}


# The error estimate's second fill tightens both tolerances by this factor, and its difference
# from F counts this many times (the margin covers the second fill's own error); entries never
# read below ERROR_FLOOR_REL of themselves (the kernels' float64 limit: 1e-11 measured on the
# blocked plates). See compute_view_factors.
ERROR_PROBE_FACTOR = 0.01
ERROR_MARGIN = 2.0
ERROR_FLOOR_REL = 1e-10


def compute_view_factors(scene: Scene, *, preset: str = "default", enforce: str = "none", force: bool = False,
                         error_estimate: bool = False, **overrides) -> "ViewFactors":
    """The view-factor matrix together with the patches it belongs to.

    Same parameters as :func:`view_factors`; the result also carries the scene as filled
    (``ViewFactors.scene``: cut further if ``max_patch_size`` asked for it), its sky factors,
    and sums back to objects or faces (``ViewFactors.grouped``).

    ``error_estimate=True`` also fills F a second time with ``formfactor_rtol`` and
    ``visibility_atol`` 100 times tighter (``ERROR_PROBE_FACTOR``), and sets
    ``ViewFactors.error`` to an estimate of each entry's absolute error,

        err_ij = 2 |F_ij - F*_ij| + 1e-10 F_ij  (+ |what enforcement moved|),

    where F* is the tighter fill: its difference from F is F's error up to F*'s own, which the
    factor 2 covers where F* is at least as accurate. This is an estimate, not a bound. On
    parallel plates cut 3 x 3 it is above all 81 entries' true errors (``polygon_to_polygon``
    at 1e-11), the closest at 3.8 times (there the floor decides); on the blocked plates (one
    patch, or cut 3 x 3 or 4 x 4) it is 2.4 to 10 times the plate total's true error. The
    1e-6 the fill aims at would overstate these errors 10^4 to 10^5 times. The second fill
    cost about as much as the first on the blocked plates cut 16 x 16.

    Returns
    -------
    radiosity.factors.ViewFactors

    Examples
    --------
    >>> import radiosity
    >>> scene = radiosity.load_scene(radiosity.bundled_scene("unit_cube"))
    >>> vf = radiosity.compute_view_factors(scene, max_patch_size=0.25, cache=False)
    >>> vf.F.shape == (vf.scene.n_patches, vf.scene.n_patches), len(vf.scene.patch_area)
    (True, 96)
    """
    from .enclosure import check_closed, enforce_reciprocity
    from .factors import ViewFactors

    if enforce not in ENFORCE:
        raise TypeError(f"unknown enforce {enforce!r}; valid: {', '.join(ENFORCE)}")
    if enforce == "auto":  # what the model file asks for (View3D encl=1), else nothing
        enforce = "closure" if getattr(scene, "enclosure", False) else "none"
    options = _view_factor_options(preset, overrides)
    scene, origin = scene.centred()  # far from the origin, coordinates lose the digits contacts need
    prepared = prepare(scene, options)
    cut = prepared.scene
    active = ~cut.patch_inactive
    F = _without(prepared.F, ~active)
    settings = _stored_settings(preset, options)
    if enforce == "closure" and not force:
        check_closed(F, active, options.formfactor_rtol + options.visibility_atol, names=cut.objects,
                     patch_object=cut.patch_object)
    filled = F
    if enforce != "none" and active.any():
        keep = np.flatnonzero(active)
        block = enforce_reciprocity(F[keep][:, keep], cut.patch_area[keep], closure=enforce == "closure")
        block = block.tocoo()
        F = sp.csr_matrix((block.data, (keep[block.row], keep[block.col])), shape=F.shape)
    error = _error_estimate(cut, options, filled, F, active) if error_estimate else None
    return ViewFactors(F, cut.moved(origin), enforce, settings, error)


def _error_estimate(cut: Scene, options: Options, filled: sp.csr_matrix, F: sp.csr_matrix,
                    active: np.ndarray) -> sp.csr_matrix:
    """(n, n) estimated absolute error of each entry of F (see :func:`compute_view_factors`)."""
    tighter = replace(options, formfactor_rtol=options.formfactor_rtol * ERROR_PROBE_FACTOR,
                      visibility_atol=options.visibility_atol * ERROR_PROBE_FACTOR)
    probe = _without(prepare(cut, tighter).F, ~active)
    error = ERROR_MARGIN * abs(filled - probe) + ERROR_FLOOR_REL * filled
    if F is not filled:
        error = error + abs(F - filled)
    return sp.csr_matrix(error)


def view_factors(scene: Scene, *, preset: str = "default", enforce: str = "none", force: bool = False,
                 return_error: bool = False, **overrides) -> sp.csr_matrix | tuple[sp.csr_matrix, sp.csr_matrix]:
    """The patch-to-patch view-factor matrix F with occlusion: F[i, j] = F(i -> j).

    Row i holds the fractions of patch i's emitted power reaching each patch j. The patches
    are the scene's as loaded (``max_patch_size`` at load time), unless ``max_patch_size`` is
    given here; unlike :func:`solve`, presets never cut patches further. If the matrix must
    come with the patches it belongs to (``max_patch_size`` given here), use
    :func:`compute_view_factors`. Obstructions (View3D ``O`` surfaces) block but have zero rows
    and columns.

    Parameters
    ----------
    scene : Scene
    preset : {"draft", "default", "fine"}, default: "default"
        Quadrature and visibility accuracy; here a preset only tightens the 1e-6 below (``"fine"``),
        never loosens it. To trade accuracy for time on a big model, pass ``formfactor_rtol`` and
        ``visibility_atol``: View3D's 398-surface hall (about 80 obstructions) fills in 6 s at
        1e-2 (rows within 2.3e-2), 37 s at 1e-3 (2.1e-3), and about an hour at the 1e-6 defaults
        (4.7e-7); see docs/accuracy.md.
    enforce : {"none", "reciprocity", "closure", "auto"}, default: "none"
        Make ``A_i F_ij = A_j F_ji`` exact by symmetrising exchange areas; ``"closure"`` also
        scales them symmetrically so rows sum to 1 (closed enclosures only). ``"auto"``: what
        the model asks for (closure for a View3D model with ``encl=1``, else none). See
        :mod:`radiosity.enclosure`.
    force : bool, default: False
        Enforce closure even where rows fall short of 1 by more than the fill's error.
        Without it, ``enforce="closure"`` on a scene that is not closed raises
        :class:`radiosity.enclosure.NotClosedError`.
    return_error : bool, default: False
        Also return an estimate of each entry's absolute error, a sparse matrix shaped as F,
        from a second fill 100 times tighter (see :func:`compute_view_factors`): ``(F, error)``.
    **overrides
        Fields of :class:`radiosity.options.Options`; ``formfactor_rtol`` and
        ``visibility_atol`` default to 1e-6 here (each factor to about six digits, partly
        occluded pairs by exact shadow clipping), tighter than :func:`solve` needs.

    Examples
    --------
    >>> import numpy as np, radiosity
    >>> scene = radiosity.load_scene(radiosity.bundled_scene("unit_cube"))
    >>> F = radiosity.view_factors(scene, cache=False)
    >>> bool(np.allclose(F.sum(axis=1), 1.0, atol=1e-6))
    True
    """
    vf = compute_view_factors(scene, preset=preset, enforce=enforce, force=force, error_estimate=return_error,
                              **overrides)
    if vf.scene.n_patches != scene.n_patches:
        warnings.warn(f"view_factors: max_patch_size cut the scene's {scene.n_patches} patches into "
                      f"{vf.scene.n_patches}, and F is for those, which it does not return; "
                      "compute_view_factors returns F with its patches", RadiosityWarning, stacklevel=2)
    return (vf.F, vf.error) if return_error else vf.F

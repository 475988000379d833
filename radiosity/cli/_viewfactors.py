"""``radiosity viewfactors``: the view-factor matrix of a scene, with the patches it belongs to.

Everything is computed and checked before anything is written; all outputs (``F.npz``, and
``--vf``, ``--vs3`` if asked) are then written to temporary files and renamed into place
together, so an error never leaves a file behind (and never replaces an earlier one).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from .._validate import check_rtol
from ..enclosure import NotClosedError, diagnose
from ..factors import GROUPINGS
from ..io.export import atomic_paths, save_arrays, view_factor_arrays, write_vf
from ..io.view3d import write_vs3
from ..solve import compute_view_factors
from ._common import add_scene_args, load, overrides, positive_fraction

NAME = "viewfactors"
HELP = "compute the patch-to-patch view-factor matrix F (F[i, j] = F(i -> j)) with occlusion"
# Up to this many surfaces, the summary lists each one's row sum and sky factor.
_LIST_SURFACES = 40


def add_args(parser) -> None:
    add_scene_args(parser, optional_scene=False)
    parser.add_argument("-o", "--output", type=Path, required=True, metavar="F.npz",
                        help="output .npz: F with its patches (polygons, areas, objects, faces, hidden "
                             "flags, sky factors)")
    parser.add_argument("--enforce", choices=("auto", "none", "reciprocity", "closure"), default="auto",
                        help="symmetrise exchange areas (reciprocity) and also scale rows to 1 (closure, "
                             "closed enclosures only); auto (default): closure if a View3D model says "
                             "encl=1, else none")
    parser.add_argument("--force", action="store_true",
                        help="enforce closure even where rows fall short of 1 by more than the fill's error")
    parser.add_argument("--tolerance", type=_tolerance, default=None, metavar="TOL",
                        help="error per view factor the fill aims at (formfactor_rtol and visibility_atol; "
                             "default 1e-6, or the preset's if tighter): 1e-3 fills a model with many "
                             "obstructions in minutes where 1e-6 takes hours")
    parser.add_argument("--sum", choices=GROUPINGS, default=None, dest="group_by",
                        help="also sum F back to the input surfaces (objects, or faces: a View3D model's "
                             "S lines) and store that matrix in the .npz (group_*)")
    parser.add_argument("--error-estimate", action="store_true",
                        help="also estimate each entry's absolute error from a second fill 100 times tighter, "
                             "stored in the .npz as error_data/error_indices/error_indptr (same shape as F)")
    parser.add_argument("--vf", type=Path, default=None, metavar="F.vf",
                        help="also write View3D's view-factor file (per patch, or per --sum surface)")
    parser.add_argument("--vf-binary", action="store_true", help="write the --vf file in View3D's binary format")
    parser.add_argument("--vs3", type=Path, default=None, metavar="MODEL.vs3",
                        help="also write the patches as a View3D model")
    add_cluster_args(parser)
    parser.add_argument("--out-of-core", action="store_true",
                        help="write F as it is filled into the folder -o names (row-block shards and an "
                             "index.json, for matrices larger than memory; read with "
                             "radiosity.load_view_factors); blocks sized from RADIOSITY_MEMORY_BUDGET")


def _positive_int(text: str) -> int:
    import argparse

    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive whole number of processes, got {text!r}")
    return value


def add_cluster_args(parser) -> None:
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--workers", type=_positive_int, default=None, metavar="N",
                       help="fill the matrix on a local Dask cluster of N processes (needs radiosity[cluster])")
    where.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="fill the matrix on the running Dask cluster at ADDRESS (tcp://HOST:PORT)")


def cluster_overrides(args) -> dict:
    return {k: v for k, v in (("workers", args.workers), ("scheduler", args.scheduler)) if v is not None}


def _tolerance(text: str) -> float:
    """argparse type of ``--tolerance``: a number the fill's kernels take (``check_rtol``)."""
    value = positive_fraction(text)
    try:
        check_rtol(value, "TOL")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return value


def _fill_overrides(args) -> dict:
    """The fill's options from the flags: cache, cluster, and ``--tolerance``."""
    tolerance = {} if args.tolerance is None else {"formfactor_rtol": args.tolerance,
                                                   "visibility_atol": args.tolerance}
    return {**overrides(args), **cluster_overrides(args), **tolerance}


def run(args) -> int:
    scene = load(args)
    if args.out_of_core:
        return _run_out_of_core(scene, args)
    try:
        vf = compute_view_factors(scene, preset=args.preset, enforce=args.enforce, force=args.force,
                                  error_estimate=args.error_estimate, **_fill_overrides(args))
    except NotClosedError as exc:  # the refusal names the scene it is about, as every input error does
        raise NotClosedError(f"{Path(scene.source).name}: {exc}") from None
    cut = vf.scene
    grouped = vf.grouped(args.group_by) if args.group_by else None
    arrays = view_factor_arrays(vf, grouped=grouped)
    d = diagnose(vf.F, cut.patch_area)
    active = vf.active
    targets = [args.output] + [p for p in (args.vf, args.vs3) if p is not None]
    with atomic_paths(targets) as temps:
        save_arrays(arrays, temps[0])
        rest = iter(temps[1:])
        if args.vf is not None:
            if grouped is not None:
                write_vf(grouped.F, grouped.area, grouped.emissivity, next(rest), binary=args.vf_binary,
                         enclosure=vf.enforced == "closure")
            else:
                keep = np.flatnonzero(active)
                write_vf(vf.F[keep][:, keep], cut.patch_area[keep], 1.0 - cut.reflectance[keep].mean(axis=1),
                         next(rest), binary=args.vf_binary, enclosure=vf.enforced == "closure")
        if args.vs3 is not None:
            write_vs3(cut, next(rest))
    _print_summary(vf, d, grouped, args.enforce)
    for target in targets:
        print(f"wrote {target}")
    return 0


def _print_summary(vf, d, grouped, asked: str) -> None:
    cut, active = vf.scene, vf.active
    rows = d.row_sums[active] if active.any() else np.zeros(1)
    sky = vf.sky_factor[active] if active.any() else np.zeros(1)
    print(f"{cut.n_patches} patches ({int(active.sum())} exchanging light), {vf.F.nnz:,} non-zero view factors")
    print(f"row sums {rows.min():.8f} .. {rows.max():.8f}; sky factor (1 - row sum) {sky.min():.3g} .. "
          f"{sky.max():.3g}; reciprocity error {d.reciprocity_error:.2e} (max |A_i F_ij - A_j F_ji| / max A_i F_ij)")
    if vf.enforced != "none" or asked == "auto":
        print(f"enforced: {vf.enforced}")
    if vf.error is not None and vf.error.nnz:
        rel = vf.error.multiply(sp.csr_matrix(vf.F).power(-1)) if vf.F.nnz else vf.error
        print(f"error estimate: largest {vf.error.max():.2e} absolute, {rel.max():.2e} relative to its entry; "
              f"on the row sums {np.asarray(vf.error.sum(axis=1)).max():.2e}")
    if grouped is not None and len(grouped.names) <= _LIST_SURFACES:
        print(f"{'surface':<24} {'area m2':>10} {'row sum':>11} {'sky factor':>11}")
        for name, area, row, escape in zip(grouped.names, grouped.area, grouped.row_sums, grouped.sky_factor):
            print(f"{name[:24]:<24} {area:>10.4g} {row:>11.8f} {escape:>11.3g}")


def _run_out_of_core(scene, args) -> int:
    """``--out-of-core``: the shards and their index, nothing held in memory but one block."""
    from ..solve import write_view_factors

    extra = [name for name, given in (("--vf", args.vf), ("--vs3", args.vs3), ("--sum", args.group_by),
                                      ("--enforce", args.enforce not in ("auto", "none"))) if given]
    if extra:
        raise ValueError(f"{', '.join(extra)} cannot be combined with --out-of-core (the shards hold F as filled)")
    F = write_view_factors(scene, args.output, preset=args.preset, **_fill_overrides(args))
    print(f"{F.shape[0]} patches, {F.nnz:,} non-zero view factors in {F.n_blocks} shards")
    print(f"wrote {args.output}")
    return 0

"""``radiosity viewfactors``: write the view-factor matrix of a scene (scipy sparse .npz)."""

from __future__ import annotations

from pathlib import Path

from ..enclosure import diagnose
from ..io.export import write_view_factors
from ..io.view3d import write_vs3
from ..solve import view_factors
from ._common import add_scene_args, load, overrides

NAME = "viewfactors"
HELP = "compute the patch-to-patch view-factor matrix F (F[i, j] = F(i -> j)) with occlusion"


def add_args(parser) -> None:
    add_scene_args(parser, optional_scene=False)
    parser.add_argument("-o", "--output", type=Path, required=True, metavar="F.npz", help="output .npz")
    parser.add_argument("--enforce", choices=("none", "reciprocity", "closure"), default="none",
                        help="symmetrise exchange areas (reciprocity) and also scale rows to 1 (closure, "
                             "closed enclosures only)")
    parser.add_argument("--vs3", type=Path, default=None, metavar="MODEL.vs3",
                        help="also write the patches as a View3D model")


def run(args) -> int:
    scene = load(args)
    F = view_factors(scene, preset=args.preset, enforce=args.enforce, **overrides(args))
    write_view_factors(F, scene.patch_area, scene.patch_object, scene.objects, args.output,
                       hidden=scene.patch_hidden)
    d = diagnose(F, scene.patch_area)
    print(f"{scene.n_patches} patches, {F.nnz:,} non-zero view factors")
    print(f"row sums {d.row_sums.min():.8f} .. {d.row_sums.max():.8f}; "
          f"reciprocity error {d.reciprocity_error:.2e} (max |A_i F_ij - A_j F_ji| / max A_i F_ij)")
    print(f"wrote {args.output}")
    if args.vs3 is not None:
        write_vs3(scene, args.vs3)
        print(f"wrote {args.vs3}")
    return 0

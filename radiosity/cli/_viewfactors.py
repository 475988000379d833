"""``radiosity viewfactors``: write the view-factor matrix of a scene (scipy sparse .npz)."""

from __future__ import annotations

from pathlib import Path

from ..io.export import write_view_factors
from ..solve import view_factors
from ._common import add_scene_args, load, overrides

NAME = "viewfactors"
HELP = "compute the patch-to-patch view-factor matrix F (F[i, j] = F(i -> j)) with occlusion"


def add_args(parser) -> None:
    add_scene_args(parser, optional_scene=False)
    parser.add_argument("-o", "--output", type=Path, required=True, metavar="F.npz", help="output .npz")


def run(args) -> int:
    scene = load(args)
    F = view_factors(scene, preset=args.preset, **overrides(args))
    write_view_factors(F, scene.patch_area, scene.patch_object, scene.objects, args.output)
    rows = F.sum(axis=1).A1
    print(f"{scene.n_patches} patches, {F.nnz:,} non-zero view factors; row sums {rows.min():.6f} .. {rows.max():.6f}")
    print(f"wrote {args.output}")
    return 0

"""Form factors: Lambert's closed form for points, adaptive quadrature for polygon pairs.

The face of the form-factor stage. Private modules:

- ``_closed_form``: point-to-polygon factors (Lambert's contour sum), with its numpy reference.
- ``_polygon_pairs``: ``polygon_to_polygon``, the receiver cut into pieces integrated adaptively.
- ``_quadrature``: quadrature points on patches and the adaptive per-pair integration
  (``pair_factors``) that the uniform matrix method fills its matrix with.
- ``_lambert``: the numba kernels of the contour sum (points x polygons, indexed pairs,
  quadrature means).

See ``docs/formfactors.md``.
"""

from ._closed_form import lambert_indexed, lambert_pairs, point_to_polygon, point_to_polygons
from ._polygon_pairs import polygon_to_polygon
from ._quadrature import (gauss_legendre_01, pair_factors, patch_points, rect_points, split_patch_points,
                          square_cell_corners, square_cell_points, tip_collapsed)

__all__ = [
    "point_to_polygon",
    "point_to_polygons",
    "polygon_to_polygon",
    "lambert_pairs",
    "lambert_indexed",
    "pair_factors",
    "patch_points",
    "split_patch_points",
    "rect_points",
    "gauss_legendre_01",
    "square_cell_corners",
    "square_cell_points",
    "tip_collapsed",
]

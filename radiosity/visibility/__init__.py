"""Visibility between patches: which pairs can be blocked at all, and how much is blocked.

The face of the visibility stage; ``_pairs`` holds ``Visibility`` (patch pairs: classification,
shadow rays, exact shadows), ``_points`` the same for sensor points. Private modules:
``_occluders`` (culling: hull, BVH, pair classification), ``_exact`` / ``_exact_kernel`` (exact
shadow clipping), ``_cells_kernel`` (shadow cells), ``_ray_kernel`` (stratified shadow rays),
``_points_kernel`` (sensor kernels), ``_embree`` (rays against every patch), ``_constants``.
See ``docs/visibility.md``.
"""

from ._occluders import FREE, FULL, MAYBE
from ._pairs import Visibility, occluder_mask

__all__ = ["Visibility", "occluder_mask", "FREE", "FULL", "MAYBE"]

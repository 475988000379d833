"""Polygon geometry for the numba kernels: the Newell sum, compiled and inlined.

``geometry`` holds the one Newell sum of Python code (centred, vectorised); the kernels need a
scalar loop they can inline, over the first ``n`` rows of a scratch polygon. It sits at the
bottom of the pipeline beside ``geometry`` and imports nothing of the package.

The sum is the plain uncentred one the kernels always used (callers centre their polygons
first where it matters, e.g. relative to a vertex), with the same products and differences
summed in the same order, so moving it here changed no bit.

numba's disk cache of a kernel is keyed on its own file: one that inlines these helpers keeps
the old code after a change here unless its file is touched too (``_exact_kernel``,
``_cells_kernel``, ``_points_kernel``, ``formfactors/_lambert`` and the kernels calling theirs).
"""

from __future__ import annotations

from numba import njit

__all__ = ["newell", "newell_z"]


@njit(cache=True, inline="always")
def newell(poly, n):
    """Twice the vector area of polygon ``poly[:n]`` ((k, 3), k >= n): the Newell sum of
    ``p_k x p_(k+1)`` over consecutive corners, as three floats."""
    ax = 0.0
    ay = 0.0
    az = 0.0
    for k in range(n):
        k2 = k + 1 if k + 1 < n else 0
        ax += poly[k, 1] * poly[k2, 2] - poly[k, 2] * poly[k2, 1]
        ay += poly[k, 2] * poly[k2, 0] - poly[k, 0] * poly[k2, 2]
        az += poly[k, 0] * poly[k2, 1] - poly[k, 1] * poly[k2, 0]
    return ax, ay, az


@njit(cache=True, inline="always")
def newell_z(poly, n):
    """The z component of :func:`newell` (it reads columns 0 and 1 only): twice the signed area
    of a 2-D polygon ``poly[:n]`` ((k, 2) or more columns), positive when counter-clockwise."""
    s = 0.0
    for k in range(n):
        k2 = k + 1 if k + 1 < n else 0
        s += poly[k, 0] * poly[k2, 1] - poly[k, 1] * poly[k2, 0]
    return s

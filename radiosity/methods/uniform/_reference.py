"""Numpy reference of the compiled facing loop in ``assembly`` (the tests compare the two)."""

from __future__ import annotations

import numpy as np


def _facing_numpy(quads, normals, offset, scale, rows, ok):
    """ok[r, j]: a vertex of j lies more than 1e-9 (size_i + size_j) in front of rows[r]'s plane,
    and one of rows[r] in front of j's (numpy: the reference of the compiled loop)."""
    h_ji = np.einsum("rc,nkc->rnk", normals[rows], quads) - offset[rows, None, None]
    h_ij = np.einsum("nc,rkc->rnk", normals, quads[rows]) - offset[None, :, None]
    tol = 1e-9 * (scale[rows, None] + scale[None, :])
    ok[:] = (h_ji.max(axis=2) > tol) & (h_ij.max(axis=2) > tol)
    ok[np.arange(len(rows)), rows] = False

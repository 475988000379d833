"""Validators for public arguments: they name the argument and what was received."""

from __future__ import annotations

import numpy as np

from ._tol import MIN_RTOL


def as_points(x, name: str) -> np.ndarray:
    """Return ``x`` as a finite float64 (m, 3) array or raise ValueError naming ``name``."""
    arr = np.asarray(x, dtype=float)
    if arr.ndim == 1 and arr.shape == (3,):
        arr = arr[None]
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (m, 3), got {np.shape(x)}")
    if not np.isfinite(arr).all():
        bad = int(np.flatnonzero(~np.isfinite(arr).all(axis=1))[0])
        raise ValueError(f"{name} must be finite; row {bad} is {arr[bad].tolist()}")
    return arr


def as_unit_vectors(x, name: str) -> np.ndarray:
    """Return ``x`` as (m, 3) unit vectors (normalised) or raise if a row has zero length."""
    arr = as_points(x, name)
    # scaled by the largest component first, so 1e-320 or 1e300 keep their direction
    largest = np.abs(arr).max(axis=1) if len(arr) else np.zeros(0)
    if (largest == 0).any():
        bad = int(np.flatnonzero(largest == 0)[0])
        raise ValueError(f"{name} must be non-zero vectors; row {bad} is zero")
    arr = arr / largest[:, None]
    return arr / np.linalg.norm(arr, axis=1)[:, None]


def check_rtol(rtol: float, name: str = "rtol") -> None:
    """Raise ValueError naming ``name`` unless ``rtol`` lies in [``MIN_RTOL``, 1): below 1e-12
    the kernels' float64 sums cannot follow (the quadrature's orders run out first)."""
    if not (MIN_RTOL <= rtol < 1):
        raise ValueError(f"{name} must be in [{MIN_RTOL:g}, 1), got {rtol}")


def as_polygon(x, name: str) -> np.ndarray:
    """Return ``x`` as a finite float64 (k, 3) polygon with k >= 3."""
    arr = np.asarray(x, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] < 3:
        raise ValueError(f"{name} must have shape (k, 3) with k >= 3, got {np.shape(x)}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite, got {arr.tolist()}")
    return arr


def reject_unknown(options: dict, allowed, what: str) -> None:
    """Raise TypeError listing the valid names if ``options`` holds a name not in ``allowed``."""
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        msg = f"unknown {what} {', '.join(map(repr, unknown))}; valid: {', '.join(sorted(allowed))}"
        raise TypeError(msg)

"""Memory estimates made before big allocations, so impossible requests are refused early."""

from __future__ import annotations

import os

from . import _tol
from ._errors import MemoryBudgetError

# Bytes per stored view factor in CSR (float64 value + int32 column) plus the COO build copy.
BYTES_PER_FACTOR = 8 + 4 + 8 + 8 + 8


def available_bytes() -> int:
    """Physical memory of the machine (the budget is a fraction of it)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        return 8 << 30


def check_fill(n_patches: int, *, budget: int | None = None) -> int:
    """Estimate the worst-case bytes of the view-factor fill; raise if over budget.

    The worst case is every pair non-zero (a scene with no back-facing pairs): the sparse
    matrix then holds n^2 factors. Returns the estimate in bytes.
    """
    estimate = n_patches**2 * BYTES_PER_FACTOR
    budget = int(_tol.MEMORY_FRACTION * available_bytes()) if budget is None else budget
    if estimate > budget:
        msg = (f"{n_patches} patches need up to {estimate / 2**30:.1f} GiB for the view-factor matrix, "
               f"more than the {budget / 2**30:.1f} GiB available; use a coarser preset or a larger "
               "max_patch_size (patch count falls with its square)")
        raise MemoryBudgetError(msg)
    return estimate

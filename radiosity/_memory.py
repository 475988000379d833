"""Memory estimates made before big allocations, so impossible requests are refused early.

A run that needs more memory than the machine has is refused with a ``MemoryBudgetError``
that gives the estimate, the budget and the knob to turn, before the allocation, instead of
being killed by the operating system halfway through.

The budget is ``MEMORY_FRACTION`` (``_tol.py``) of the machine's memory, or of the container's
limit (cgroup ``memory.max``) if lower. The environment variable ``RADIOSITY_MEMORY_BUDGET``
(bytes, or with a ``K``, ``M`` or ``G`` suffix) replaces it: a test hook that forces the
refusal on a small scene, and a way to keep a shared machine usable.
"""

from __future__ import annotations

import functools
import math
import os
from pathlib import Path

import numpy as np

from . import _tol
from ._errors import MemoryBudgetError

__all__ = ["ENV_BUDGET", "budget_bytes", "check", "check_fill", "check_solve", "check_patches",
           "check_cut", "patch_bound", "fill_bytes", "solve_bytes", "format_bytes", "plan_fill_block"]

ENV_BUDGET = "RADIOSITY_MEMORY_BUDGET"

# Bytes per stored view factor while F is built: the per-block COO parts (int64 i, j and
# float64 value, 24 bytes), their concatenation's int32/float64 CSR result (12 bytes), with
# the parts freed block by block. Multiplied by the worst case of n^2 non-zeros (every pair
# facing), so the estimate is an upper bound: real scenes fill 30-70% of the pairs.
BYTES_PER_FACTOR = 8 + 4 + 8 + 8 + 8

# Bytes per non-zero of F during a solve: the operator I - rho F (CSR, 12 bytes) and the
# product rho F it is built from (12 bytes), next to F itself (already counted by the fill).
SOLVE_BYTES_PER_FACTOR = 24

# A sparse LU of the radiosity system fills in to nearly dense: L and U, float64 each.
DIRECT_BYTES_PER_PAIR = 16

# Bytes per patch while faces are cut: the (n, 4, 3) float64 patch array (96 bytes), the
# sub-grids it is cut from and the concatenation copy, with headroom.
BYTES_PER_PATCH = 400

# The knob to turn, worded for both the Python API and the command line.
_COARSER = "use a coarser preset (--preset draft) or a larger max_patch_size (--max-patch-size)"
_SUFFIXES = {"": 1, "k": 1 << 10, "m": 1 << 20, "g": 1 << 30, "t": 1 << 40}


def format_bytes(n: float) -> str:
    """``n`` bytes in a readable unit: ``'3.2 GiB'``, ``'640 MiB'``, ``'12 KiB'``."""
    for unit, size in (("TiB", 1 << 40), ("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{int(n)} bytes"


@functools.lru_cache(maxsize=1)
def _cgroup_limit() -> int | None:
    # read once a process: four file reads were a tenth of a small fill (the 8 x 8 open plates)
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(path).read_text().strip()
        except OSError:
            continue
        if text.isdigit() and int(text) < 1 << 60:
            return int(text)
    return None


def available_bytes() -> int:
    """Physical memory of the machine, or the container's limit if lower."""
    try:
        physical = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        physical = 8 << 30
    limit = _cgroup_limit()
    return min(physical, limit) if limit else physical


def _parse_bytes(text: str) -> int:
    t = text.strip().lower().removesuffix("ib").removesuffix("b")
    suffix = t[-1:] if t[-1:] in _SUFFIXES and t[-1:] else ""
    try:
        value = float(t[: len(t) - len(suffix)]) * _SUFFIXES[suffix]
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{ENV_BUDGET} must be a number of bytes (e.g. 500M, 4G), got {text!r}")
    return int(value)


def budget_bytes() -> tuple[int, str]:
    """The memory budget in bytes and where it comes from (for the message)."""
    env = os.environ.get(ENV_BUDGET)
    if env:
        return _parse_bytes(env), f"set by {ENV_BUDGET}"
    total = available_bytes()
    return int(_tol.MEMORY_FRACTION * total), f"{_tol.MEMORY_FRACTION:.0%} of {format_bytes(total)}"


def check(what: str, estimate: int, knob: str, *, budget: int | None = None) -> int:
    """Raise ``MemoryBudgetError`` if ``estimate`` bytes exceed the budget; return the estimate.

    Parameters
    ----------
    what : str
        What would be allocated, e.g. ``"the view-factor matrix of 40,000 patches"``.
    estimate : int
        Bytes it needs (an upper bound).
    knob : str
        What the user can change so it fits, e.g. ``"use a coarser preset"``.
    budget : int, optional
        Bytes allowed; default: :func:`budget_bytes`.
    """
    source = "given"
    if budget is None:
        budget, source = budget_bytes()
    if estimate > budget:
        msg = (f"{what} needs up to {format_bytes(estimate)} of memory, more than the "
               f"{format_bytes(budget)} budget ({source}); {knob}")
        raise MemoryBudgetError(msg)
    return estimate


def fill_bytes(n_patches: int) -> int:
    """Worst-case bytes of building the view-factor matrix of ``n_patches`` patches."""
    return int(n_patches) ** 2 * BYTES_PER_FACTOR


# Bytes per factor of the out-of-core shards on disk: row and column (int32 each) and the
# value (float64), as ``methods.uniform.shards`` saves them.
SHARD_BYTES_PER_FACTOR = 4 + 4 + 8


# The end of the out-of-core solve's disk refusal: its shards go to the temp folder, which TMPDIR moves.
SOLVE_SHARD_KNOBS = "set TMPDIR to a larger disk, or use larger patches (--max-patch-size) or --method hierarchical"


def check_shard_space(n_patches: int, folder: str | Path, knobs: str = SOLVE_SHARD_KNOBS) -> int:
    """Refuse an out-of-core fill whose shards may not fit in ``folder``'s file system.

    The same worst case as :func:`check_fill` (every pair non-zero), so a fill that goes ahead
    cannot run the disk full half-way. ``folder`` need not exist yet: its nearest existing
    parent tells the file system. ``knobs`` ends the message: what the caller can change.
    Returns the estimate in bytes.

    Raises
    ------
    OSError
        ``ENOSPC``, naming the estimate, the free space and the knobs.
    """
    import errno
    import shutil

    needed = int(n_patches) ** 2 * SHARD_BYTES_PER_FACTOR
    existing = Path(folder).absolute()
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    free = shutil.disk_usage(existing).free
    if needed > free:
        raise OSError(errno.ENOSPC, f"the out-of-core fill of {n_patches:,} patches needs up to "
                                    f"{format_bytes(needed)} on disk for its shards and {folder} has "
                                    f"{format_bytes(free)} free; {knobs}")
    return needed


def check_fill(n_patches: int, *, budget: int | None = None, patch_size: float | None = None) -> int:
    """Estimate the worst-case bytes of the view-factor fill; raise if over budget.

    The worst case is every pair non-zero (a scene with no back-facing pairs): the sparse
    matrix then holds n^2 factors. Returns the estimate in bytes.

    Parameters
    ----------
    n_patches : int
    budget : int, optional
        Bytes allowed; default: :func:`budget_bytes`.
    patch_size : float, optional
        The patch size (metres) that gave ``n_patches``; the message then suggests one that fits
        (the patch count falls with the square of the size, the fill with its fourth power).

    Examples
    --------
    >>> check_fill(100, budget=10**9)
    360000
    """
    estimate = fill_bytes(n_patches)
    knob = _COARSER + " (the patch count falls with its square)"
    effective = budget if budget is not None else budget_bytes()[0]
    if patch_size and estimate > effective > 0:
        fits = patch_size * (estimate / effective) ** 0.25
        knob = f"{_COARSER}; about {_round_up(fits):g} m would fit (now {patch_size:.3g} m)"
    return check(f"the view-factor matrix of {n_patches:,} patches", estimate, knob, budget=budget)


def _round_up(x: float) -> float:
    """``x`` rounded up to two significant figures."""
    if x <= 0 or not math.isfinite(x):
        return x
    scale = 10 ** (math.floor(math.log10(x)) - 1)
    return math.ceil(x / scale - 1e-9) * scale


def solve_bytes(n_patches: int, nnz: int, method: str = "auto") -> int:
    """Bytes the radiosity solve allocates next to F (operator copies, LU fill-in)."""
    estimate = int(nnz) * SOLVE_BYTES_PER_FACTOR + 16 * 8 * int(n_patches)
    if method == "direct":
        estimate += DIRECT_BYTES_PER_PAIR * int(n_patches) ** 2
    return estimate


def check_solve(n_patches: int, nnz: int, method: str = "auto", *, budget: int | None = None) -> int:
    """Raise before a solve that would not fit (a direct LU of a large system, mostly).

    Examples
    --------
    >>> check_solve(1000, 10**5, "bicgstab", budget=10**9)
    2528000
    """
    knob = _COARSER
    if method == "direct":
        knob = "use an iterative solver (--solver bicgstab) or " + _COARSER.removeprefix("use ")
    return check(f"the {method} solve of {n_patches:,} patches", solve_bytes(n_patches, nnz, method), knob,
                 budget=budget)


def patch_bound(vertices: np.ndarray, faces: list[np.ndarray], max_patch_size: float | None) -> int:
    """An upper bound on the patches that cutting ``faces`` to ``max_patch_size`` makes.

    A face of k vertices is at most k - 2 triangles, and a triangle whose bounding box is e
    across has edges of at most sqrt(3) e, so it is cut into at most ceil(sqrt(3) e / s)^2
    pieces. Vectorised over faces (segment reductions), so it costs far less than the cut.

    Parameters
    ----------
    vertices : (v, 3) float
        Metres.
    faces : list of (k,) int
    max_patch_size : float or None
        Metres; None keeps faces whole.

    Examples
    --------
    >>> square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    >>> patch_bound(square, [np.arange(4)], 0.5)
    32
    """
    if not faces:
        return 0
    sizes = np.fromiter(map(len, faces), dtype=np.int64, count=len(faces))
    pieces = np.maximum(sizes - 2, 1)
    if max_patch_size is None:
        return int(pieces.sum())
    points = vertices[np.concatenate(faces)]
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    extent = (np.maximum.reduceat(points, starts, axis=0) - np.minimum.reduceat(points, starts, axis=0)).max(axis=1)
    cuts = np.maximum(np.ceil(np.sqrt(3.0) * extent / max_patch_size), 1.0)
    return int(min((pieces * cuts**2).sum(), 2.0**62))


def check_patches(vertices: np.ndarray, faces: list[np.ndarray], max_patch_size: float | None, *,
                  budget: int | None = None) -> int:
    """Raise before cutting faces into more patches than memory holds; return the bound.

    Examples
    --------
    >>> square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    >>> check_patches(square, [np.arange(4)], 0.5, budget=10**6)
    32
    """
    n = patch_bound(vertices, faces, max_patch_size)
    size = "" if max_patch_size is None else f" (max_patch_size {max_patch_size:.3g} m)"
    check(f"cutting the faces into up to {n:,} patches{size}", n * BYTES_PER_PATCH,
          "use a larger max_patch_size (--max-patch-size) or a coarser preset (--preset draft)", budget=budget)
    return n


def check_cut(quads: np.ndarray, max_patch_size: float, *, budget: int | None = None) -> int:
    """Raise before cutting existing patches (n, 4, 3) again to ``max_patch_size``; return the bound.

    Meant for ``Scene.resubdivided`` (``solve`` cutting a scene to a preset or to
    ``--max-patch-size``), where a tiny size would otherwise fail inside numpy.

    Examples
    --------
    >>> quad = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]], float)
    >>> check_cut(quad, 0.5, budget=10**6)
    32
    """
    quads = np.asarray(quads, dtype=float)
    extent = np.ptp(quads, axis=1).max(axis=1) if len(quads) else np.zeros(0)
    cuts = np.maximum(np.ceil(np.sqrt(3.0) * extent / max_patch_size), 1.0)
    n = int(min((2 * cuts**2).sum(), 2.0**62))  # a quad is at most two triangles
    check(f"cutting the scene into up to {n:,} patches (max_patch_size {max_patch_size:.3g} m)",
          n * BYTES_PER_PATCH, "use a larger max_patch_size (--max-patch-size) or a coarser preset (--preset draft)",
          budget=budget)
    return n


# Directed pairs per block of the fill (a block's pairs (i, j > i) and their mirrors): bounds the
# per-pair temporaries of form factors and visibility (a few hundred bytes each).
FILL_PAIRS = 2_000_000

# Bytes per directed pair in flight in one fill block: form-factor quadrature temporaries,
# visibility classification and occluder lists, and the block's (i, j, v) output (see
# FILL_PAIRS, whose 2M directed pairs per block are a few hundred MB).
BYTES_PER_BLOCK_PAIR = 400

# Bytes per patch held for the whole out-of-core fill: the patch arrays, the occluders and their
# bounding-volume hierarchy (a block's facing mask, a byte per (row, patch), is per pair).
BYTES_PER_FILL_PATCH = 1024

# Fewest pairs (i, j > i) per block worth a task: below this, per-block overheads dominate.
MIN_BLOCK_PAIRS = 1_000


def plan_fill_block(n_patches: int, *, budget: int | None = None, max_pairs: int | None = None) -> int:
    """Pairs (i, j > i) per block of an out-of-core fill of ``n_patches``, from the budget.

    Only one block is in memory at a time (it is written to its shard, then freed), so the
    fill needs the scene's structures plus one block: the block is the largest that fits in
    half of what is left (the other half is headroom for the allocator and numba's threads).
    Raises ``MemoryBudgetError`` when not even a small block fits.

    Examples
    --------
    >>> plan_fill_block(18_000, budget=4 << 30)
    1000000
    >>> plan_fill_block(18_000, budget=200 << 20)
    119552
    """
    if budget is None:
        budget = budget_bytes()[0]
    max_pairs = FILL_PAIRS // 2 if max_pairs is None else max_pairs
    spare = budget - int(n_patches) * BYTES_PER_FILL_PATCH
    pairs = spare // 2 // (2 * BYTES_PER_BLOCK_PAIR)
    if pairs < MIN_BLOCK_PAIRS:
        need = int(n_patches) * BYTES_PER_FILL_PATCH + 4 * BYTES_PER_BLOCK_PAIR * MIN_BLOCK_PAIRS
        check(f"the out-of-core view-factor fill of {n_patches:,} patches", need, _COARSER, budget=budget)
    return int(min(max_pairs, max(pairs, MIN_BLOCK_PAIRS)))

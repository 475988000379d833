"""The view-factor matrix: candidate pairs, unoccluded form factors, visibility, sparse F.

Row i of F is the receiver: ``F[i, j]`` is F(i -> j), the area average over patch i of the
point-to-polygon form factor to patch j (Lambert's closed form at Gauss points of i), times
the visible fraction of the pair. Pairs facing away from each other are exactly zero and are
never evaluated; pairs that nothing can block get no rays.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, fields

import numba as _numba
import numpy as np
import scipy.sparse as sp

from ... import _tol
from ..._memory import FILL_PAIRS
from ...options import Options
from ...formfactors import pair_factors
from ._fill_kernel import block_pairs, mirrored, once_factors, parts_to_csr

__all__ = ["FillSettings", "FillStats", "candidate_pairs", "unoccluded_factors", "fill_block", "assemble"]


VISIBILITY_MODES = ("auto", "rays", "exact")
# The fill's blocks aim at this many seconds each (progress), starting from FIRST_BLOCK_PAIRS pairs
# (and never fewer). 4096 until session 23: View3D's hall keeps 453 of its 716 pairs behind 65+
# occluders in its first 10 rows, and the bar sat at 0% for over 20 minutes at the defaults.
BLOCK_SECONDS = 2.0
FIRST_BLOCK_PAIRS = 512
# ... except fills of at most this many pairs, one block: a block costs about 1 ms of setup,
# an eighth of the plates cut 8 x 8 with a blocker (8,385 pairs: 10.0 -> 8.7 ms best of 30), and
# such a fill in two blocks shows one step of progress at most. Thermal models of up to 150
# surfaces are filled at once.
ONE_BLOCK_PAIRS = 12_288

_OPTIONS = Options()  # the defaults


@dataclass(frozen=True)
class FillSettings:
    """The accuracy fields of :class:`radiosity.Options` that the fill reads (part of the cache key).

    One set of defaults: each field's default is ``Options``' (see its docstring for meanings);
    ``solve`` builds these with :meth:`from_options`.
    """

    near_order: int = _OPTIONS.near_order
    far_separation: float = _OPTIONS.far_separation
    visibility_samples: int = _OPTIONS.visibility_samples
    visibility: str = _OPTIONS.visibility
    visibility_max_samples: int = _OPTIONS.visibility_max_samples
    visibility_rtol: float = _OPTIONS.visibility_rtol
    formfactor_rtol: float = _OPTIONS.formfactor_rtol

    @classmethod
    def from_options(cls, options: Options) -> "FillSettings":
        """The fill's fields of ``options``."""
        return cls(**{f.name: getattr(options, f.name) for f in fields(cls)})

    def __post_init__(self):
        if self.visibility not in VISIBILITY_MODES:
            msg = f"visibility must be one of {', '.join(VISIBILITY_MODES)}; got {self.visibility!r}"
            raise ValueError(msg)
        if self.visibility_samples < 1 or self.visibility_max_samples < 1:
            msg = (f"visibility_samples and visibility_max_samples must be >= 1, got "
                   f"{self.visibility_samples} and {self.visibility_max_samples}")
            raise ValueError(msg)
        if not self.visibility_rtol >= 0:
            raise ValueError(f"visibility_rtol must be >= 0, got {self.visibility_rtol}")


@dataclass
class FillStats:
    n_pairs: int = 0
    n_traced_pairs: int = 0  # partly occluded pairs (rays or exact shadows)
    n_blocked_pairs: int = 0  # pairs fully blocked, decided without rays
    n_exact_pairs: int = 0  # partly occluded pairs computed by exact shadows
    n_rays: int = 0
    dropped_mass: float = 0.0
    seconds_formfactors: float = 0.0
    seconds_visibility: float = 0.0


def _circumradius(quads: np.ndarray, centroid: np.ndarray) -> np.ndarray:
    return np.linalg.norm(quads - centroid[:, None, :], axis=2).max(axis=1)


def candidate_pairs(quads: np.ndarray, normals: np.ndarray, centroid: np.ndarray, rows: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i in rows, j) that face each other: some of j is in front of i and vice versa."""
    offset = np.einsum("nc,nc->n", normals, centroid)
    scale = _circumradius(quads, centroid)
    ok = np.empty((len(rows), len(quads)), dtype=bool)
    _facing_loop(quads, normals, offset, scale, rows, ok)
    r, j = np.nonzero(ok)
    return rows[r], j


def facing_pairs(quads: np.ndarray, normals: np.ndarray, centroid: np.ndarray, i: np.ndarray, j: np.ndarray
                 ) -> np.ndarray:
    """(m,) bool: pairs (i[m], j[m]) that face each other by :func:`candidate_pairs`' test."""
    offset = np.einsum("nc,nc->n", normals, centroid)
    ok = np.empty(len(i), dtype=bool)
    _facing_pair_loop(quads, normals, offset, _circumradius(quads, centroid), np.asarray(i, np.int64),
                      np.asarray(j, np.int64), ok)
    return ok


def _facing_pair_loop(quads, normals, offset, scale, i, j, ok):
    """:func:`_facing_loop`'s test for given pairs."""
    for t in _prange(len(i)):
        a, b = i[t], j[t]
        tol = 1e-9 * (scale[a] + scale[b])
        ok[t] = a != b and _some_vertex_in_front(quads, b, normals, offset, a, tol) \
            and _some_vertex_in_front(quads, a, normals, offset, b, tol)


def _facing_loop(quads, normals, offset, scale, rows, ok):
    """:func:`_facing_numpy` as a compiled loop over (row, patch) pairs: the numpy form builds
    two (rows, n, 4) height arrays (0.4 GB and 1 s for the Cornell box's 1,742 patches); the
    loop stops at the first vertex in front and takes 0.05 s."""
    for r in _prange(len(rows)):
        i = rows[r]
        for j in range(len(quads)):
            tol = 1e-9 * (scale[i] + scale[j])
            ok[r, j] = j != i and _some_vertex_in_front(quads, j, normals, offset, i, tol) \
                and _some_vertex_in_front(quads, i, normals, offset, j, tol)


def _some_vertex_in_front(quads, j, normals, offset, i, tol):
    """Whether a vertex of patch j lies more than ``tol`` in front of patch i's plane."""
    for v in range(quads.shape[1]):
        h = normals[i, 0] * quads[j, v, 0] + normals[i, 1] * quads[j, v, 1] + normals[i, 2] * quads[j, v, 2]
        if h - offset[i] > tol:
            return True
    return False


_prange = _numba.prange
_some_vertex_in_front = _numba.njit(cache=True, inline="always")(_some_vertex_in_front)
_facing_loop = _numba.njit(cache=True, parallel=True, error_model="numpy")(_facing_loop)
_facing_pair_loop = _numba.njit(cache=True, parallel=True, error_model="numpy")(_facing_pair_loop)


def _is_near(quads, centroid, i, j, settings: FillSettings) -> np.ndarray:
    """Pairs integrated at Gauss points of the receiver (the others use its centroid)."""
    radius = _circumradius(quads, centroid)
    separation = np.linalg.norm(centroid[i] - centroid[j], axis=1) / (radius[i] + radius[j])
    return separation < settings.far_separation


def unoccluded_factors(quads: np.ndarray, normals: np.ndarray, centroid: np.ndarray, area: np.ndarray,
                       i: np.ndarray, j: np.ndarray, settings: FillSettings) -> np.ndarray:
    """F(i -> j) without occlusion, each pair to ``settings.formfactor_rtol`` (relative)."""
    return pair_factors(quads, normals, centroid, area, i, j, rtol=settings.formfactor_rtol,
                        max_points=_tol.PAIR_MAX_POINTS, mode="fill")


def _apply_visibility(f, quads, centroid, area, i, j, visibility, settings: FillSettings, stats: FillStats,
                      classified: tuple) -> None:
    """Multiply the unoccluded factors f (in place) by each pair's visible fraction.

    ``classified``: (status, rows, occ) of all the pairs from ``visibility.classify``
    (:func:`fill_block` classifies before the factors: blocked pairs need none).
    """
    from ...visibility import MAYBE
    from ...visibility._pairs import _rows_of
    from ...visibility._constants import (AUTO_EXACT_ATOL, AUTO_EXACT_OCCLUDERS, MAX_CELL_OCCLUDERS,
                                          SHADOW_ATOL_SHARE, SHADOW_ATOL_SHARE_TIGHT, SHADOW_CELL_ORDER,
                                          SHADOW_CELLS_BELOW, SHADOW_MAX_DEPTH, SHADOW_PENUMBRA_DEPTH,
                                          SHADOW_PENUMBRA_DEPTH_LOOSE, SHADOW_RTOL_SHARE, SHADOW_TIGHT_MAX_DEPTH)

    nz = np.flatnonzero(f > 0)
    rows, occ = _rows_of(classified[1], classified[2], nz, len(f))
    part = np.flatnonzero(classified[0][nz] == MAYBE)
    if not len(part):
        return
    stats.n_traced_pairs += len(part)
    pi, pj = i[nz[part]], j[nz[part]]
    frac = np.ones(len(part))
    local = np.full(len(nz), -1)
    local[part] = np.arange(len(part))
    pair_of = local[rows]  # partly occluded pair of each (pair, occluder) row
    if settings.visibility == "exact":
        exact = np.ones(len(part), bool)
    elif settings.visibility == "rays":
        exact = np.zeros(len(part), bool)
    else:
        # below draft's tolerance, rays for the small pairs behind many occluders only: where the
        # compiled unions handle every receiver point, exact shadows cost little more and rays'
        # early agreement missed small shadows (in a closed room of 50 boxes at default rows
        # spread 0.99879-1.00155 with rays for F <= 4e-4, 0.99990-1.00015 with exact shadows
        # everywhere, in 1.07x the time)
        few = np.bincount(pair_of, minlength=len(part)) <= AUTO_EXACT_OCCLUDERS
        few &= settings.visibility_rtol < AUTO_EXACT_ATOL
        exact = few | (f[nz[part]] / settings.visibility_max_samples > settings.visibility_rtol)

    def subset(sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The (pair, occluder) rows of the partly occluded pairs ``sel``, renumbered 0..len(sel)-1."""
        return _rows_of(pair_of, occ, sel, len(part))

    if (~exact).any():
        sel = np.flatnonzero(~exact)
        sub_rows, sub_occ = subset(sel)
        frac[sel] = visibility.ray_fraction(pi[sel], pj[sel], settings.visibility_samples,
                                            settings.visibility_max_samples, rows=sub_rows, occ=sub_occ)
    if exact.any():
        stats.n_exact_pairs += int(exact.sum())
        tight = settings.formfactor_rtol < SHADOW_CELLS_BELOW and settings.visibility_rtol < SHADOW_CELLS_BELOW
        cells = exact & (np.bincount(pair_of, minlength=len(part)) <= MAX_CELL_OCCLUDERS) if tight else None
        if cells is not None and cells.any():
            sel = np.flatnonzero(cells)
            # the hidden part over receiver cells cut along the shadow's edges: F = F_unoccluded - hidden
            unocc = f[nz[part[sel]]]
            hidden = visibility.exact_hidden(pi[sel], pj[sel], *subset(sel),
                                             SHADOW_RTOL_SHARE * settings.formfactor_rtol, unocc,
                                             penumbra_depth=SHADOW_PENUMBRA_DEPTH, max_depth=SHADOW_TIGHT_MAX_DEPTH)
            frac[sel] = _seen_fraction(unocc, hidden)
            exact = exact & ~cells
        # the rest: exact shadows on receiver cells refined where the hidden factor varies, far
        # pairs too. Fixed Gauss points smeared a shadow's edge across the receiver: a plate with
        # a centred blocker erred by 2.4e-3 at 4 x 4 points, and in a closed room of boxes at the
        # default preset rows summed to 0.9987-1.0017 (bench/closed_boxes.py, docs/visibility.md).
        if exact.any():
            sel = np.flatnonzero(exact)
            unocc = f[nz[part[sel]]]
            atol = (SHADOW_ATOL_SHARE_TIGHT if tight else SHADOW_ATOL_SHARE) * _shadow_atol(settings)
            sub_rows, sub_occ = subset(sel)
            # integrated over the patch where the shadow is smoother. The receiver's factor is
            # mirrored to the source's row by reciprocity, its error scaled by A_recv / A_src:
            # both directions meet atol when the receiver's target is atol min(1, A_src / A_recv)
            ri, rj = pi[sel], pj[sel]
            flip = visibility.receive_on_source(ri, rj, sub_rows, sub_occ) & (area[ri] > 0)
            recv, src = np.where(flip, rj, ri), np.where(flip, ri, rj)
            target = atol * np.minimum(1.0, area[src] / np.where(area[recv] > 0, area[recv], 1.0))
            penumbra = SHADOW_PENUMBRA_DEPTH if tight else SHADOW_PENUMBRA_DEPTH_LOOSE
            hidden = visibility.adaptive_hidden(recv, src, sub_rows, sub_occ, target, order=SHADOW_CELL_ORDER,
                                                penumbra_depth=penumbra,
                                                max_depth=SHADOW_TIGHT_MAX_DEPTH if tight else SHADOW_MAX_DEPTH)
            ratio = np.where(flip, area[rj] / area[ri], 1.0)  # F(i -> j) = A_j F(j -> i) / A_i
            frac[sel] = _seen_fraction(unocc, hidden * ratio)
    f[nz[part]] *= frac


def _shadow_atol(settings: FillSettings) -> float:
    """Absolute error per partly occluded factor that the adaptive exact shadows aim at.

    ``"auto"`` (the presets) sends a pair to exact shadows because rays would miss
    ``visibility_atol``, the absolute error per factor it promises; ``"exact"`` asks for the
    shadows as exact as the factors, so the tighter of that and ``formfactor_rtol`` (read as
    absolute). With the tighter for every pair, as until 2026-12-03, the Cornell box's fine fill
    (formfactor_rtol 1e-6) took 787 s, not 24 s, for the same object means.
    """
    if settings.visibility == "exact":
        return min(settings.visibility_rtol, settings.formfactor_rtol)
    return settings.visibility_rtol


def _seen_fraction(unocc: np.ndarray, hidden: np.ndarray) -> np.ndarray:
    """The visible fraction (F_unoccluded - hidden) / F_unoccluded, in [0, 1] (1 where F_unoccluded is 0)."""
    seen = np.clip(unocc - hidden, 0.0, unocc)
    return np.where(unocc > 0, seen / np.where(unocc > 0, unocc, 1.0), 1.0)


def _row_blocks(n: int, pairs_per_block: int) -> list[tuple[int, int]]:
    """Row ranges holding about ``pairs_per_block`` pairs (i, j > i) each."""
    upper = np.cumsum(np.arange(n, 0, -1))  # pairs (i, j > i) in rows 0..i
    block = upper // max(1, pairs_per_block)
    edges = np.r_[0, np.flatnonzero(np.diff(block)) + 1, n]
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:]) if b > a]


def fill_block(quads, normals, centroid, area, visibility, settings: FillSettings, start: int, stop: int, *,
               active: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, FillStats]:
    """One block of the fill: the pairs (i, j > i) with i in rows ``start:stop``, and their mirrors.

    Each unordered pair is integrated once, over its smaller patch (form factor and visibility),
    and mirrored by reciprocity, ``F(j -> i) = A_i F(i -> j) / A_j`` (see
    :mod:`radiosity.methods.uniform._fill_kernel`).

    The unit of work of :func:`assemble`, of the Dask tasks (:mod:`radiosity.methods.uniform.cluster`) and of
    the out-of-core writer (:mod:`radiosity.methods.uniform.shards`): a block's result depends only on the
    geometry, the settings and its rows, so however blocks are scheduled, F is the same bit for bit.

    Returns
    -------
    i, j : (k,) int64
        Receiver and source of each kept factor (below ``_tol.DROP_FACTOR`` is dropped).
    v : (k,) float64
        F(i -> j) with occlusion.
    stats : FillStats
        This block's counts and seconds (``n_rays`` included).
    """
    stats = FillStats()
    # one memory layout for the compiled passes: a strided view (a sliced or transposed scene
    # array) would compile a second copy of each of them, 10-40 s on a cold cache
    quads, normals, centroid, area = (np.ascontiguousarray(a, dtype=np.float64)
                                      for a in (quads, normals, centroid, area))
    rays_before = visibility.n_rays if visibility is not None else 0
    rows = np.arange(start, stop)
    if active is not None:
        rows = rows[active[rows]]
    # each unordered pair once, the smaller patch receiving; its mirror by reciprocity (below)
    i, j, order, two = block_pairs(quads, normals, centroid, area, rows, active, settings.formfactor_rtol,
                                   two_area_rtol=settings.formfactor_rtol)
    if not len(i):
        empty = np.zeros(0, np.int64)
        return empty, empty, np.zeros(0), stats
    from ...visibility import FULL

    t0 = time.perf_counter()
    classified = None
    need = slice(None)
    if visibility is not None and not (visibility.cull and visibility.n_occluders == 0):  # else nothing blocks
        # classified before the factors: a pair some occluder hides whole needs none (on the
        # blocked plates cut 8 x 8, 1,936 of the 4,096 pairs)
        classified = visibility.classify(i, j)
        need = np.flatnonzero(classified[0] != FULL)
        stats.n_blocked_pairs += len(i) - len(need)
    f = np.zeros(len(i))
    f[need] = once_factors(quads, normals, centroid, area, i[need], j[need], rtol=settings.formfactor_rtol,
                           max_points=_tol.PAIR_MAX_POINTS, order=order[need], two_area=True, two_order=two[need])
    t1 = time.perf_counter()
    stats.seconds_formfactors += t1 - t0
    if visibility is not None:
        if classified is not None:
            _apply_visibility(f, quads, centroid, area, i, j, visibility, settings, stats, classified)
        for name in ("n_traced_pairs", "n_blocked_pairs", "n_exact_pairs"):  # the mirrors share the status
            setattr(stats, name, 2 * getattr(stats, name))
        stats.seconds_visibility += time.perf_counter() - t1
        stats.n_rays = visibility.n_rays - rays_before
    stats.n_pairs += 2 * len(i)
    i, j, f, dropped = mirrored(area, i, j, f, _tol.DROP_FACTOR)  # F(j -> i) = A_i F(i -> j) / A_j, A_j >= A_i
    stats.dropped_mass += dropped
    return i, j, f, stats


def add_stats(total: FillStats, part: FillStats) -> None:
    """Add one block's statistics to ``total`` (in place)."""
    for name in FillStats.__dataclass_fields__:
        setattr(total, name, getattr(total, name) + getattr(part, name))


def assemble(quads, normals, centroid, area, visibility, settings: FillSettings, progress=None, *,
             active: np.ndarray | None = None, pairs_per_block: int = FILL_PAIRS // 2
             ) -> tuple[sp.csr_matrix, FillStats]:
    """The sparse view-factor matrix F (n, n) with occlusion, and fill statistics.

    Rows are filled in blocks (:func:`fill_block`); a block holds the pairs (i, j > i) of its
    rows and their mirrors (j, i), so each unordered pair is classified for occlusion once.
    Blocks hold up to ``pairs_per_block`` pairs, fewer where pairs are slow: each takes about
    ``BLOCK_SECONDS`` at the rate of the one before, so that ``progress`` moves (View3D's
    398-surface hall, 79,003 pairs behind up to 100 occluders, was one block: 0% until the end).

    ``active`` (n,) bool, default all: pairs with an inactive patch at either end (hidden or
    obstruction patches, whose rows and columns the solver zeroes) are left out of F entirely:
    no form factor, no visibility. Inactive patches still block.
    """
    n = len(quads)
    stats = FillStats()
    parts = []
    upper = np.cumsum(np.arange(n, 0, -1))  # pairs (i, j > i) in rows 0..i
    total = int(upper[-1]) if n else 0
    start, pairs = 0, min(pairs_per_block, FIRST_BLOCK_PAIRS if total > ONE_BLOCK_PAIRS else max(total, 1))
    while start < n:
        before = upper[start - 1] if start else 0
        stop = int(min(n, max(start + 1, np.searchsorted(upper, before + pairs, side="right"))))
        t0 = time.perf_counter()
        i, j, v, block_stats = fill_block(quads, normals, centroid, area, visibility, settings, start, stop,
                                          active=active)
        per_pair = (time.perf_counter() - t0) / max(1, upper[stop - 1] - before)
        # blocks sized to take about BLOCK_SECONDS: F does not depend on them (fill_block)
        pairs = int(np.clip(BLOCK_SECONDS / max(per_pair, 1e-12), FIRST_BLOCK_PAIRS, max(pairs_per_block, 1)))
        add_stats(stats, block_stats)
        parts.append((i, j, v))
        if progress is not None:
            progress(stop - start)
        start = stop
    return coo_parts_to_csr(parts, n), stats


def coo_parts_to_csr(parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]], n: int) -> sp.csr_matrix:
    """The (n, n) CSR matrix of blocks' (i, j, v), in block order (the same order, the same bits)."""
    fast = parts_to_csr(parts, n)
    if fast is not None:
        return fast
    i, j, v = (np.concatenate(p) for p in zip(*parts))
    return sp.csr_matrix((v, (i, j)), shape=(n, n))

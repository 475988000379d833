"""The fill's separated pairs in one compiled pass, each unordered pair once (reciprocity).

:func:`radiosity.formfactors._quadrature.pair_factors` serves any pair, and for a well separated pair (its
a-priori Gauss order p > 0) it costs a sequence of numpy passes around the Lambert kernel: unique
receivers, their Gauss points and repeated normals as arrays, a sort by source, gathers. On the
plates of issue 15 (1,048,576 pairs, all separated) those passes and the kernel's gathers took
about two thirds of the fill. :func:`separated_factors` does the same arithmetic (the receiver's
order-p Gauss points of :func:`radiosity.formfactors._quadrature.split_patch_points`, or its centroid for
p = 1, and Lambert's closed form in the one-source lane loops) in one parallel loop over runs of
pairs sharing a source: each run copies its receivers' points (computed once per block, in a
table) straight into the lanes, or, for a run of two-area pairs whose receivers' points lie side
by side in the table (the fill's receivers j > i come in index order), reads them in place.
Pairs whose source is small enough for an order <= 3 Gauss rule under the same a-priori bound
take the two-area rule instead of Lambert's closed form: Gauss points on both patches and the
point-to-point kernel (:func:`two_area_need`).

:func:`reciprocal_pairs` orients each unordered pair so that the smaller patch receives (its
integral is the cheaper and the better conditioned: rho in the a-priori bound grows as the
receiver shrinks), and the fill mirrors it, F(j -> i) = A_i F(i -> j) / A_j: reciprocity holds
for the exact factors of flat patches, one-sided or clipped, so the mirror has the same relative
error as the computed direction and ``A_i F_ij = A_j F_ji`` holds to rounding.
"""

from __future__ import annotations

import types

import numba as _numba
import numpy as np

from ..._validate import check_rtol
from ...formfactors import _quadrature as quadrature
from ...formfactors._quadrature import _pair_rho
from ...formfactors._lambert import _G_SIZE, _SRC_LANES, _source_block

__all__ = ["block_pairs", "reciprocal_pairs", "mirrored", "rows_to_csr", "parts_to_csr", "once_factors", "raw_ratio", "separated_factors", "MAX_ORDER", "TWO_AREA_MAX_ORDER", "two_area_need"]

_prange = _numba.prange  # the loops below are compiled with parallel=True (see _TwoWays)
MAX_ORDER = max(quadrature._APRIORI_ORDERS)
# Receiver points per task of the kernel: enough lanes for the one-source loops, few enough that
# the (3, n) rows stay in L2 and the tasks balance over the cores.
_TASK_LANES = 4096
_TINY = float(np.finfo(float).tiny)
# Largest source order of the two-area rule (see two_area_need).
TWO_AREA_MAX_ORDER = 3


def _gauss_tables() -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on [0, 1], row p for order p (1..MAX_ORDER)."""
    nodes = np.zeros((MAX_ORDER + 1, MAX_ORDER))
    weights = np.zeros((MAX_ORDER + 1, MAX_ORDER))
    for p in range(1, MAX_ORDER + 1):
        nodes[p, :p], weights[p, :p] = quadrature.gauss_legendre_01(p)
    return nodes, weights


def reciprocal_pairs(area: np.ndarray, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(receiver, source) of each unordered pair {i, j}: the smaller patch receives (j on ties,
    so that pairs listed by i come grouped by source)."""
    swap = area[j] <= area[i]
    return np.where(swap, j, i), np.where(swap, i, j)


def block_pairs(quads: np.ndarray, normals: np.ndarray, centroid: np.ndarray, area: np.ndarray, rows: np.ndarray,
                active: np.ndarray | None, rtol: float, *, two_area_rtol: float | None = None):
    """The unordered pairs {i, j > i}, i in ``rows``, that face each other, oriented by
    :func:`reciprocal_pairs`, with their a-priori Gauss order (0: refine adaptively).

    One compiled pass for what ``assembly.candidate_pairs`` (then ``j > i``, both active) and
    ``quadrature._pair_setup`` do: the same facing test and the same bound, with the bound's
    powers replaced by the radius ratios where they are met (no ``pow`` per pair), and no
    (rows, n) mask to scan. A row meets its partners in chunks of ``_CHUNK`` consecutive
    patches; where bounds over a chunk (its boxes and the ranges of its radii, areas and plane
    offsets) prove that no pair of the chunk faces, or that every one does with one orientation
    and one order, the pairs are written without a test each (:func:`_chunk_rule`): the same
    pairs and orders bit for bit, since the bounds keep margins far above rounding.

    ``two_area_rtol``: also return each pair's two-area source order (:func:`_two_area_order`
    with :func:`two_area_need` of it, 0 for none or for order-0 pairs; what
    :func:`separated_factors` would compute per pair) as a fourth array.
    """
    n = len(quads)
    rows = np.asarray(rows, dtype=np.int64)
    live = np.ones(n, bool) if active is None else np.asarray(active, bool)
    offset = np.einsum("nc,nc->n", normals, centroid)
    radius = quadrature._radius(quads, centroid)
    orders = np.array(quadrature._APRIORI_ORDERS, dtype=np.int64)
    # the bound C rho^(-2p) <= rtol / SAFETY  <=>  rho >= (C SAFETY / rtol)^(1 / 2p)
    need = (quadrature._APRIORI_C * quadrature._APRIORI_SAFETY / rtol) ** (1.0 / (2.0 * orders))
    need_src = two_area_need(two_area_rtol)
    chunks = _chunk_bounds(quads, normals, centroid, area, radius, offset, live, _CHUNK)
    # rounding of a dot product of a unit normal with coordinates stays far below this
    margin = 1e-13 * (float(np.abs(quads).max()) + float(np.abs(offset).max()) + 1.0) if n else 0.0
    # a counting pass (chunk rules, kept per row and chunk, and the facing test of the pairs of
    # undecided chunks), then each row writes its pairs in place: no room for all partners j > i
    # to pack afterwards (that copy cost more than the listing once chunks went whole)
    rules = np.zeros((len(rows), len(chunks[0]), 4), np.int8)
    starts = np.zeros(len(rows) + 1, np.int64)
    _count_pairs(quads, normals, centroid, area, offset, radius, rows, live, orders, need, need_src, margin,
                 *chunks, rules, starts)
    np.cumsum(starts, out=starts)
    rec, src, order = np.empty(starts[-1], np.int64), np.empty(starts[-1], np.int64), np.empty(starts[-1], np.int64)
    two = np.empty(starts[-1] if two_area_rtol is not None else 0, np.int64)
    _list_pairs(quads, normals, centroid, area, offset, radius, rows, live, starts, orders, need, need_src, margin,
                *chunks, rules, rec, src, order, two)
    return (rec, src, order, two) if two_area_rtol is not None else (rec, src, order)


def mirrored(area: np.ndarray, i: np.ndarray, j: np.ndarray, f: np.ndarray, drop: float
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The computed factors F(i -> j) and their mirrors F(j -> i) = A_i F(i -> j) / A_j (0 where
    A_j = 0), those above ``drop`` kept, in one compiled pass.

    The same entries in the same order as concatenating (i, j, f) and (j, i, f A_i / A_j) and
    masking ``> drop`` (test), without the three concatenations, the ratio array and the mask
    (a tenth of the open plates' fill).

    Returns
    -------
    i, j : (k,) int64
        Receiver and source of each kept factor: the computed ones first, then the mirrors.
    v : (k,) float
        The factors.
    dropped : float
        Sum of A_receiver F over the factors left out.
    """
    i, j = np.asarray(i, np.int64), np.asarray(j, np.int64)
    f, area = np.asarray(f, float), np.asarray(area, float)
    # in parallel over fixed spans of _MIRROR_SPAN pairs: each span's kept count, then each
    # span writes from its offset (the same entries in the same places as one serial pass)
    spans = (len(i) + _MIRROR_SPAN - 1) // _MIRROR_SPAN
    kept = np.zeros((2, spans + 1), np.int64)
    _count_kept(area, i, j, f, float(drop), kept)
    np.cumsum(kept[0], out=kept[0])
    np.cumsum(kept[1], out=kept[1])
    kept[1] += kept[0, -1]
    total = int(kept[1, -1])
    out_i, out_j, out_v = np.empty(total, np.int64), np.empty(total, np.int64), np.empty(total)
    _write_mirrored(area, i, j, f, float(drop), kept, out_i, out_j, out_v)
    # the dropped mass, serially in entry order (its rounding as before); none on most scenes
    dropped = _dropped_mass(area, i, j, f, float(drop)) if total < 2 * len(i) else 0.0
    return out_i, out_j, out_v, float(dropped)


# Pairs per span of the parallel mirror (its offsets are per span, fixed: results do not depend
# on the thread count).
_MIRROR_SPAN = 1 << 15


def _mirror_value(area, a, b, fab):
    return fab * (area[a] / area[b]) if area[b] > 0 else 0.0


def _count_kept(area, i, j, f, drop, kept):
    """kept[0, s + 1], kept[1, s + 1]: computed factors and mirrors above ``drop`` in span s."""
    spans = kept.shape[1] - 1
    for s in _prange(spans):
        a, b = 0, 0
        for t in range(s * _MIRROR_SPAN, min(len(i), (s + 1) * _MIRROR_SPAN)):
            a += f[t] > drop
            b += _mirror_value(area, i[t], j[t], f[t]) > drop
        kept[0, s + 1], kept[1, s + 1] = a, b


def _write_mirrored(area, i, j, f, drop, kept, out_i, out_j, out_v):
    """The kept factors, span s's from kept[0, s], their mirrors from kept[1, s]."""
    spans = kept.shape[1] - 1
    for s in _prange(spans):
        k, m = kept[0, s], kept[1, s]
        for t in range(s * _MIRROR_SPAN, min(len(i), (s + 1) * _MIRROR_SPAN)):
            if f[t] > drop:
                out_i[k], out_j[k], out_v[k] = i[t], j[t], f[t]
                k += 1
            v = _mirror_value(area, i[t], j[t], f[t])
            if v > drop:
                out_i[m], out_j[m], out_v[m] = j[t], i[t], v
                m += 1


def _dropped_mass(area, i, j, f, drop):
    """Sum of A_receiver F over the left-out factors: the computed ones, then the mirrors."""
    dropped = 0.0
    for t in range(len(i)):
        if not f[t] > drop:
            dropped += f[t] * area[i[t]]
    for t in range(len(i)):
        v = _mirror_value(area, i[t], j[t], f[t])
        if not v > drop:
            dropped += v * area[j[t]]
    return dropped


def rows_to_csr(i: np.ndarray, j: np.ndarray, v: np.ndarray, n: int):
    """``scipy.sparse.csr_matrix((v, (i, j)), shape=(n, n))`` for entries without duplicates, in
    two compiled passes (a counting scatter by row, a sort of each row's columns) instead of
    scipy's COO checks, conversion and canonicalisation (a quarter of the plates' fill).
    The same matrix, bit for bit (canonical: sorted columns). None if (i, j) repeats, or if
    the matrix would need 64-bit indices: the caller then asks scipy."""
    return parts_to_csr([(i, j, v)], n)


def parts_to_csr(parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]], n: int):
    """:func:`rows_to_csr` of the concatenated parts (i, j, v), without concatenating them: each
    part is counted and scattered in place (the fill's blocks, 48 MB a block on the plates)."""
    import scipy.sparse as sp

    parts = [(np.asarray(i, np.int64), np.asarray(j, np.int64), np.asarray(v, float)) for i, j, v in parts]
    total = sum(len(i) for i, _, _ in parts)
    if total >= 2**31 - 1 or n >= 2**31 - 1:
        return None
    indptr = np.zeros(n + 1, np.int32)
    indices = np.empty(total, np.int32)
    data = np.empty(total)
    for i, _, _ in parts:
        _count_rows(i, indptr)
    _cumulate(indptr)
    fill = indptr[:-1].copy()
    for i, j, v in parts:
        # rows split among the threads, each scanning every entry for its own rows
        spans = _numba.get_num_threads() if len(i) >= PARALLEL_MIN else 1
        _place_rows(i, j, v, fill, indices, data, spans)
    if not _sort_rows(indptr, indices, data):
        return None
    F = sp.csr_matrix((data, indices, indptr), shape=(n, n))
    F.has_sorted_indices = True
    F.has_canonical_format = True
    return F


def _count_rows(i, indptr):
    """indptr[r + 1] += entries of row r in i."""
    for t in range(len(i)):
        indptr[i[t] + 1] += 1


def _cumulate(indptr):
    for r in range(len(indptr) - 1):
        indptr[r + 1] += indptr[r]


def _place_rows(i, j, v, fill, indices, data, spans):
    """Entries grouped by row, in input order within a row: fill[r] is row r's next free slot.
    Rows are cut into ``spans`` ranges, one task each (a task writes only its own rows)."""
    n = len(fill)
    for s in _prange(spans):
        lo, hi = s * n // spans, (s + 1) * n // spans
        for t in range(len(i)):
            r = i[t]
            if lo <= r < hi:
                indices[fill[r]], data[fill[r]] = j[t], v[t]
                fill[r] += 1


def _sort_rows(indptr, indices, data):
    """Sort each row by column; False if a column repeats within a row."""
    ok = np.ones(len(indptr) - 1, np.bool_)
    for r in _prange(len(indptr) - 1):
        lo, hi = indptr[r], indptr[r + 1]
        # the fill's rows mostly come sorted already (pairs listed by row, then their mirrors):
        # one look instead of an argsort (a tenth of the open plates' fill)
        ascending = True
        for t in range(lo + 1, hi):
            if indices[t] <= indices[t - 1]:
                ascending = False
                break
        if ascending:
            continue
        cols = indices[lo:hi]
        by_col = np.argsort(cols)
        indices[lo:hi] = cols[by_col]
        data[lo:hi] = data[lo:hi][by_col]
        for t in range(lo + 1, hi):
            if indices[t] == indices[t - 1]:
                ok[r] = False
    return ok.all()


def _in_front(quads, j, normals, offset, i, tol):
    """Whether a vertex of patch j lies more than ``tol`` in front of patch i's plane (the test
    of ``assembly._some_vertex_in_front``)."""
    for v in range(quads.shape[1]):
        h = normals[i, 0] * quads[j, v, 0] + normals[i, 1] * quads[j, v, 1] + normals[i, 2] * quads[j, v, 2]
        if h - offset[i] > tol:
            return True
    return False


def _facing(quads, normals, offset, radius, i, j):
    tol = 1e-9 * (radius[i] + radius[j])
    return _in_front(quads, j, normals, offset, i, tol) and _in_front(quads, i, normals, offset, j, tol)


def _balanced(t, n):
    """Row of task t: rows from both ends alternately, so that the prange's contiguous chunks
    get equal shares of a triangle's pairs (row i has n - 1 - i partners)."""
    return t // 2 if t % 2 == 0 else n - 1 - t // 2


# Partners per chunk of the pair listing's bounds (see block_pairs).
_CHUNK = 32


def _chunk_bounds(quads, normals, centroid, area, radius, offset, live, size):
    """Per chunk of ``size`` consecutive patches: whether all are live with one normal (bit for
    bit), their vertex box, centroid box, and the ranges of radius, area and plane offset."""
    n = quads.shape[0]
    m = (n + size - 1) // size
    uniform = np.zeros(m, np.bool_)
    vbox, cbox = np.empty((m, 2, 3)), np.empty((m, 2, 3))
    ranges = np.empty((m, 3, 2))  # radius, area, offset: (min, max)
    for c in range(m):
        lo, hi = c * size, min(n, (c + 1) * size)
        ok = True
        for d in range(3):
            vbox[c, 0, d], vbox[c, 1, d] = np.inf, -np.inf
            cbox[c, 0, d], cbox[c, 1, d] = np.inf, -np.inf
        for k in range(3):
            ranges[c, k, 0], ranges[c, k, 1] = np.inf, -np.inf
        for j in range(lo, hi):
            ok = ok and live[j] and normals[j, 0] == normals[lo, 0] and normals[j, 1] == normals[lo, 1] \
                and normals[j, 2] == normals[lo, 2]
            for d in range(3):
                for v in range(quads.shape[1]):
                    vbox[c, 0, d] = min(vbox[c, 0, d], quads[j, v, d])
                    vbox[c, 1, d] = max(vbox[c, 1, d], quads[j, v, d])
                cbox[c, 0, d] = min(cbox[c, 0, d], centroid[j, d])
                cbox[c, 1, d] = max(cbox[c, 1, d], centroid[j, d])
            ranges[c, 0, 0], ranges[c, 0, 1] = min(ranges[c, 0, 0], radius[j]), max(ranges[c, 0, 1], radius[j])
            ranges[c, 1, 0], ranges[c, 1, 1] = min(ranges[c, 1, 0], area[j]), max(ranges[c, 1, 1], area[j])
            ranges[c, 2, 0], ranges[c, 2, 1] = min(ranges[c, 2, 0], offset[j]), max(ranges[c, 2, 1], offset[j])
        uniform[c] = ok
    return uniform, vbox, cbox, ranges


def _box_dot(nx, ny, nz, box):
    """(min, max) of n . x over the box (2, 3)."""
    lo = (nx * (box[0, 0] if nx >= 0 else box[1, 0]) + ny * (box[0, 1] if ny >= 0 else box[1, 1])
          + nz * (box[0, 2] if nz >= 0 else box[1, 2]))
    hi = (nx * (box[1, 0] if nx >= 0 else box[0, 0]) + ny * (box[1, 1] if ny >= 0 else box[0, 1])
          + nz * (box[1, 2] if nz >= 0 else box[0, 2]))
    return lo, hi


def _vertex_dots(quads, i, nx, ny, nz):
    """(min, max) of n . v over patch i's vertices."""
    lo, hi = np.inf, -np.inf
    for v in range(quads.shape[1]):
        h = nx * quads[i, v, 0] + ny * quads[i, v, 1] + nz * quads[i, v, 2]
        lo, hi = min(lo, h), max(hi, h)
    return lo, hi


def _abs_range(lo, hi):
    """(min, max) of |x| over x in [lo, hi]."""
    if lo >= 0.0:
        return lo, hi
    if hi <= 0.0:
        return -hi, -lo
    return 0.0, max(-lo, hi)


def _order_index(rho, need, first):
    """The index q >= first of the order a pair of this rho (not crossing) takes, -1 for none:
    :func:`_apriori_order`'s choice (first 0, ``need`` over _APRIORI_ORDERS) or
    :func:`_two_area_order`'s (first 1, ``need`` from two_area_need)."""
    if not rho > 1.5:
        return -1
    for q in range(first, len(need)):
        if rho >= need[q]:
            return q
    return -1


def _rho_order(d_lo, d_hi, cos_lo, cos_hi, rr_lo, rr_hi, rs_lo, rs_hi, need, first):
    """:func:`_order_index` of every pair with centroid distance in [d_lo, d_hi],
    min(|n_rec . d|, |n_src . d|) in [cos_lo, cos_hi], receiver radius in [rr_lo, rr_hi] and
    source radius in [rs_lo, rs_hi], or -2 if the ranges allow two. rho = (1 - r_src / dist)
    min(|n_rec . d|, |n_src . d|) / r_rec, :func:`_pair_rho`'s; the 1e-9 relative margin is
    far above its rounding."""
    if not (d_lo > rs_hi and rr_lo > _TINY):
        return -2
    lo = (1.0 - rs_hi / d_lo) * cos_lo / rr_hi * (1.0 - 1e-9)
    hi = (1.0 - rs_lo / d_hi) * cos_hi / rr_lo * (1.0 + 1e-9)
    a = _order_index(lo, need, first)
    return a if a == _order_index(hi, need, first) else -2


def _chunk_rule(quads, normals, centroid, area, offset, radius, i, c, orders, need, need_src, margin, vbox, cbox,
                ranges, out):
    """For row i and the whole chunk c (all live, one normal): out = (kind, swap, order, two).
    kind 0: no proof (test each pair); 1: no pair faces; 2: every pair faces, receiver j if
    swap else i, with these orders (order as :func:`_apriori_order`, two as
    :func:`_two_area_order`)."""
    out[0] = 0
    lo0 = c * _CHUNK
    mx, my, mz = normals[lo0, 0], normals[lo0, 1], normals[lo0, 2]  # the chunk's normal
    nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
    r_lo, r_hi = ranges[c, 0, 0], ranges[c, 0, 1]
    # facing (_facing): a vertex of j in front of i's plane, and one of i in front of j's
    fj_lo, fj_hi = _box_dot(nx, ny, nz, vbox[c])
    fi_lo, fi_hi = _vertex_dots(quads, i, mx, my, mz)
    tol_lo, tol_hi = 1e-9 * (radius[i] + r_lo), 1e-9 * (radius[i] + r_hi)
    if fj_hi - offset[i] <= tol_lo - 2.0 * margin or fi_hi - ranges[c, 2, 1] <= tol_lo - 2.0 * margin:
        out[0] = 1  # one of the two tests fails for every pair of the chunk
        return
    if not (fj_lo - offset[i] > tol_hi + 2.0 * margin and fi_hi - ranges[c, 2, 1] > tol_hi + 2.0 * margin):
        return
    # orientation: the smaller patch receives (j on ties)
    if ranges[c, 1, 1] <= area[i]:
        swap = True
    elif ranges[c, 1, 0] > area[i]:
        swap = False
    else:
        return
    # neither end crosses the other's plane: all of j in front of i's plane, all of i in front of j's
    if not (fj_lo - offset[i] > 2.0 * margin and fi_lo - ranges[c, 2, 1] > 2.0 * margin):
        return
    # centroid distances, and |n . d| for both normals
    dlo2, dhi2 = 0.0, 0.0
    for d in range(3):
        a, b = cbox[c, 0, d] - centroid[i, d], cbox[c, 1, d] - centroid[i, d]
        near = 0.0 if a <= 0.0 <= b else min(abs(a), abs(b))
        far = max(abs(a), abs(b))
        dlo2 += near * near
        dhi2 += far * far
    d_lo, d_hi = np.sqrt(dlo2) * (1.0 - 1e-12), np.sqrt(dhi2) * (1.0 + 1e-12)
    ci = nx * centroid[i, 0] + ny * centroid[i, 1] + nz * centroid[i, 2]
    p_lo, p_hi = _box_dot(nx, ny, nz, cbox[c])
    a_lo, a_hi = _abs_range(p_lo - ci - 2.0 * margin, p_hi - ci + 2.0 * margin)
    cj = mx * centroid[i, 0] + my * centroid[i, 1] + mz * centroid[i, 2]
    b_lo, b_hi = _abs_range(ranges[c, 2, 0] - cj - 2.0 * margin, ranges[c, 2, 1] - cj + 2.0 * margin)
    cos_lo, cos_hi = min(a_lo, b_lo), min(a_hi, b_hi)
    ri = radius[i]
    if swap:  # receiver j (radius in [r_lo, r_hi]), source i
        p = _rho_order(d_lo, d_hi, cos_lo, cos_hi, r_lo, r_hi, ri, ri, need, 0)
    else:
        p = _rho_order(d_lo, d_hi, cos_lo, cos_hi, ri, ri, r_lo, r_hi, need, 0)
    if p == -2:
        return
    q = -1
    if p >= 0 and len(need_src) > 1:  # the roles swapped (order-0 pairs get no two-area order)
        if swap:
            q = _rho_order(d_lo, d_hi, cos_lo, cos_hi, ri, ri, r_lo, r_hi, need_src, 1)
        else:
            q = _rho_order(d_lo, d_hi, cos_lo, cos_hi, r_lo, r_hi, ri, ri, need_src, 1)
        if q == -2:
            return
    out[0], out[1] = 2, swap
    out[2] = orders[p] if p >= 0 else 0
    out[3] = q if q >= 0 else 0


def _count_pairs(quads, normals, centroid, area, offset, radius, rows, live, orders, need, need_src, margin,
                 uniform, vbox, cbox, ranges, rules, counts):
    """counts[r + 1]: row rows[r]'s pairs {i, j > i}, live and facing; rules[r, c]: the
    :func:`_chunk_rule` of each whole chunk c after i (kind 0 where none applies)."""
    n = len(quads)
    for s in _prange(len(rows)):
        r = _balanced(s, len(rows))
        i = rows[r]
        counts[r + 1] = 0
        if not live[i]:
            continue
        rule = np.zeros(4, np.int64)
        k = 0
        j = i + 1
        while j < n:
            c = j // _CHUNK
            stop = min(n, (c + 1) * _CHUNK)
            if j == c * _CHUNK and uniform[c]:
                _chunk_rule(quads, normals, centroid, area, offset, radius, i, c, orders, need, need_src, margin,
                            vbox, cbox, ranges, rule)
                for d in range(4):
                    rules[r, c, d] = rule[d]
                if rule[0] != 0:
                    k += stop - j if rule[0] == 2 else 0
                    j = stop
                    continue
            for jj in range(j, stop):
                if live[jj] and _facing(quads, normals, offset, radius, i, jj):
                    k += 1
            j = stop
        counts[r + 1] = k


def _list_pairs(quads, normals, centroid, area, offset, radius, rows, live, starts, orders, need, need_src, margin,
                uniform, vbox, cbox, ranges, rules, rec, src, order, two):
    """The pairs {rows[r], j > rows[r]}, both live and facing each other, oriented, with
    ``quadrature._pair_setup_loop``'s order (0 for receivers crossing the source's plane or
    rho <= 1.5) and, if ``two`` has room, the two-area order: row r's from ``starts[r]`` on.
    Whole chunks go by the rules :func:`_count_pairs` found, the others pair by pair."""
    n = len(quads)
    with_two = len(two) > 0
    for s in _prange(len(rows)):
        r = _balanced(s, len(rows))
        i = rows[r]
        t = starts[r]
        if not live[i]:
            continue
        j = i + 1
        while j < n:
            c = j // _CHUNK
            stop = min(n, (c + 1) * _CHUNK)
            if j == c * _CHUNK and uniform[c] and rules[r, c, 0] != 0:
                if rules[r, c, 0] == 2:
                    for jj in range(j, stop):
                        if rules[r, c, 1]:
                            rec[t], src[t] = jj, i
                        else:
                            rec[t], src[t] = i, jj
                        order[t] = rules[r, c, 2]
                        if with_two:
                            two[t] = rules[r, c, 3]
                        t += 1
                j = stop
                continue
            for jj in range(j, stop):
                if not (live[jj] and _facing(quads, normals, offset, radius, i, jj)):
                    continue
                a, b = (jj, i) if area[jj] <= area[i] else (i, jj)
                rec[t], src[t] = a, b
                order[t] = _apriori_order(quads, normals, centroid, radius, a, b, orders, need)
                if with_two:
                    two[t] = _two_area_order(quads, normals, centroid, radius, a, b, need_src) if order[t] > 0 else 0
                t += 1
            j = stop


def _apriori_order(quads, normals, centroid, radius, a, b, orders, need):
    """``quadrature._pair_setup_loop`` for one pair (receiver a, source b): 0 or the order."""
    rho, crossing = _pair_rho(quads, normals, centroid, radius, centroid, normals, radius, a, b)
    if crossing or not rho > 1.5:
        return 0
    for q in range(len(orders)):
        if rho >= need[q]:
            return orders[q]
    return 0


def once_factors(quads: np.ndarray, normals: np.ndarray, centroid: np.ndarray, area: np.ndarray,
                 rec: np.ndarray, src: np.ndarray, *, rtol: float, max_points: int, mode: str = "fill",
                 order: np.ndarray | None = None, two_area: bool = False,
                 two_order: np.ndarray | None = None) -> np.ndarray:
    """Unoccluded F(rec -> src), each pair to ``rtol``: :func:`radiosity.formfactors._quadrature.pair_factors`'s
    rules, its separated pairs by :func:`separated_factors`, the others (near, touching, crossing
    the source's plane) by ``pair_factors`` itself. ``two_area``: separated pairs whose source
    is small enough take the Gauss rule on the source too (:func:`two_area_need`), within the
    same rtol but not the same numbers. ``two_order``: their two-area orders as
    ``block_pairs(..., two_area_rtol=rtol)`` lists them (else computed per pair)."""
    from ...formfactors._closed_form import _MODES

    check_rtol(rtol)
    rec = np.asarray(rec, dtype=np.int64)
    src = np.asarray(src, dtype=np.int64)
    out = np.empty(len(rec))
    if not len(rec):
        return out
    if order is None:
        radius = quadrature._radius(quads, centroid)
        crossing, order = quadrature._pair_setup(quads, normals, centroid, radius, centroid, normals, radius,
                                                 rec, src, rtol)
        order = np.where(crossing, 0, order)
    lo, hi = (int(order.min()), int(order.max())) if len(order) else (1, 1)
    if lo > 0 and hi * hi <= max_points:  # no gathers for the common case of a scene of separated pairs
        return separated_factors(quads, normals, centroid, area, rec, src, order, _MODES[mode],
                                 raw_below=raw_ratio(rtol), two_area_rtol=rtol if two_area else None,
                                 two_order=two_order if two_area else None)
    fast = (order > 0) & (order * order <= max_points)
    sel = np.flatnonzero(fast)
    out[sel] = separated_factors(quads, normals, centroid, area, rec[sel], src[sel], order[sel], _MODES[mode],
                                 raw_below=raw_ratio(rtol), two_area_rtol=rtol if two_area else None,
                                 two_order=two_order[sel] if two_area and two_order is not None else None)
    rest = np.flatnonzero(~fast)
    if len(rest):
        out[rest], info = quadrature.pair_factors(quads, normals, centroid, area, rec[rest], src[rest], rtol=rtol,
                                                  max_points=max_points, mode=mode, return_info=True)
        # the few pairs the budget stopped short: a floor sliver 2.2 m long touching a cylinder's
        # side along its 2 cm base got 0.0219756 at rtol 1e-6 and 0.0220821 at 1e-8 for
        # 0.0219845 (its row summed to 1 + 8.8e-5); with RETRY_POINTS_FACTOR times the budget,
        # exact
        again = rest[~info["converged"]]
        if len(again):
            out[again] = quadrature.pair_factors(quads, normals, centroid, area, rec[again], src[again], rtol=rtol,
                                                 max_points=RETRY_POINTS_FACTOR * max_points, mode=mode)
    return out


# Times the fill's point budget a near pair that did not converge within it gets again.
RETRY_POINTS_FACTOR = 16


def raw_ratio(rtol: float) -> float:
    """Largest distance/size at which Lambert's raw sum still meets ``rtol`` with room to spare.

    The raw sum adds edge terms of size size/distance whose total is (size/distance)^2, so it
    loses about distance/size of its digits: with four edges, each term good to 2 ulp, its
    relative error stays below 8 u R at R = distance/size. The far form (exact to R = 1e6)
    costs more per lane; the fill takes the raw sum where 8 u R <= rtol / 1000.
    """
    return rtol / (1000.0 * 8.0 * float(np.finfo(float).eps))


def separated_factors(quads: np.ndarray, normals: np.ndarray, centroid: np.ndarray, area: np.ndarray,
                      rec: np.ndarray, src: np.ndarray, order: np.ndarray, mode: int, *,
                      raw_below: float = 0.0, two_area_rtol: float | None = None,
                      two_order: np.ndarray | None = None) -> np.ndarray:
    """F(rec -> src) by the receiver's order-p Gauss rule (the centroid for p = 1), p = ``order``.

    The same rule as :func:`radiosity.formfactors._quadrature.pair_factors` for its separated pairs
    (``order`` from its a-priori bound), without its intermediate arrays.

    Parameters
    ----------
    quads, normals, centroid, area : (n, 4, 3), (n, 3), (n, 3), (n,) float
        Patches (receivers and sources), their unit normals, area centroids and areas.
    rec, src : (m,) int
        Receiver and source of each pair.
    order : (m,) int
        Gauss points per direction on the receiver, 1..MAX_ORDER.
    mode : int
        The Lambert kernel's mode (``formfactors._MODES``).
    raw_below : float, default: 0
        Runs whose pairs all have (centroid distance + receiver radius) / source radius at most
        this take the raw sum (mode "raw": no far form), see :func:`raw_ratio`.
    two_area_rtol : float, optional
        If given, pairs whose source meets the a-priori bound at this rtol with an order-q rule,
        q <= ``TWO_AREA_MAX_ORDER``, take that Gauss rule on the source as well (the two-area
        rule of :func:`two_area_need`) instead of Lambert's closed form.
    two_order : (m,) int, optional
        With ``two_area_rtol``: each pair's source order q (0: Lambert), as
        ``block_pairs(..., two_area_rtol=...)`` lists them; computed per pair if not given.

    Returns
    -------
    (m,) float
        F(rec -> src).
    """
    m = len(rec)
    out = np.empty(m)
    if not m:
        return out
    grouped = _ascending(np.asarray(src))  # the fill's pairs of equal areas come grouped by source
    has_two = two_area_rtol is not None and two_order is not None
    two = np.asarray(two_order if has_two else np.zeros(0), dtype=np.int64)
    if grouped:
        rec_s, src_s, order_s = (np.ascontiguousarray(x, dtype=np.int64) for x in (rec, src, order))
        two_s = np.ascontiguousarray(two)
    else:
        by_source = np.argsort(src, kind="stable")
        rec_s, src_s = rec[by_source].astype(np.int64), src[by_source].astype(np.int64)
        order_s = order[by_source].astype(np.int64)
        two_s = two[by_source] if has_two else two
    starts = _task_starts(src_s, order_s, _TASK_LANES)
    nodes, weights = _gauss_tables()
    sorted_out = out if grouped else np.empty(m)
    quads, normals, centroid, area = (np.ascontiguousarray(x, dtype=float) for x in (quads, normals, centroid, area))
    slot = np.full((len(quads), MAX_ORDER + 1), -1, np.int64)
    total = _table_slots(rec_s, order_s, slot)
    TP, TN, TW = np.empty((3, total)), np.empty((3, total)), np.empty(total)
    _point_table(quads, normals, centroid, area, nodes, weights, slot, TP, TN, TW)
    _separated_kernel(quads, normals, centroid, area, quadrature._radius(quads, centroid), rec_s, src_s, order_s,
                      starts, nodes, weights, mode, float(raw_below), two_area_need(two_area_rtol), has_two, two_s,
                      slot, TP, TN, TW, sorted_out)
    if not grouped:
        out[by_source] = sorted_out
    return out


def two_area_need(rtol: float | None) -> np.ndarray:
    """need[q] (q = 1..TWO_AREA_MAX_ORDER): the smallest rho_src at which an order-q Gauss rule on
    the source meets ``quadrature._APRIORI_C rho^(-2q) <= rtol / quadrature._APRIORI_SAFETY``, the
    receiver's a-priori bound with the roles swapped; [inf] alone (no two-area pairs) for None.

    The two-area rule (the point-to-point kernel cos cos / (pi r^2) at Gauss points of both
    patches, as View3D's double-area integration) adds the source's error to the receiver's, so
    a pair errs by at most twice the bound, 2 rtol / SAFETY. It costs q^2 kernel evaluations
    per receiver point, each far cheaper than Lambert's four edges with their atan2; above
    order 3 (81 evaluations a pair at p = 3) Lambert's closed form is the cheaper.
    """
    need = np.full(1 if rtol is None else TWO_AREA_MAX_ORDER + 1, np.inf)
    if rtol is not None:
        q = np.arange(1, TWO_AREA_MAX_ORDER + 1)
        need[1:] = (quadrature._APRIORI_C * quadrature._APRIORI_SAFETY / rtol) ** (1.0 / (2.0 * q))
    return need


def _ascending(x):
    """Whether x never decreases (one compiled pass, stopping at the first descent)."""
    for t in range(1, len(x)):
        if x[t] < x[t - 1]:
            return False
    return True


def _task_starts(src, order, lanes):
    """Boundaries of tasks: runs of one source, cut after about ``lanes`` receiver points."""
    starts = np.empty(len(src) + 1, np.int64)
    count = 0
    used = 0
    for t in range(len(src)):
        if t == 0 or src[t] != src[t - 1] or used >= lanes:
            starts[count] = t
            count += 1
            used = 0
        used += order[t] * order[t]
    starts[count] = len(src)
    return starts[:count + 1]


def _table_slots(rec, order, slot):
    """slot[r, p]: first column of receiver r's order-p points in the point table (-1: unused);
    returns the table's length. Each receiver's points are computed once there, not once per
    pair (on the plates a receiver meets 1,024 sources)."""
    for t in range(len(rec)):
        slot[rec[t], order[t]] = 0
    total = 0
    for r in range(slot.shape[0]):
        for p in range(1, slot.shape[1]):
            if slot[r, p] == 0:
                slot[r, p] = total
                total += p * p
    return total


def _point_table(quads, normals, centroid, area, nodes, weights, slot, TP, TN, TW):
    """The table of :func:`_table_slots`: each receiver's order-p points, normals and weights."""
    for r in _prange(slot.shape[0]):
        for p in range(1, slot.shape[1]):
            if slot[r, p] >= 0:
                _put_points(quads, normals, centroid, area, r, p, nodes, weights, TP, TN, TW, slot[r, p])


def _copy_points(TP, TN, TW, at, count, PT, NT, W, pos):
    """count table columns from ``at`` into the lanes from ``pos``; returns the next free lane."""
    for c in range(count):
        for d in range(3):
            PT[d, pos + c] = TP[d, at + c]
            NT[d, pos + c] = TN[d, at + c]
        W[pos + c] = TW[at + c]
    return pos + count


def _put_points(quads, normals, centroid, area, r, p, nodes, weights, PT, NT, W, pos):
    """Receiver r's order-p points (``split_patch_points``' map; p = 1: its centroid) into the
    lanes pos.., with their area weights; returns the next free lane."""
    if p == 1:
        for d in range(3):
            PT[d, pos] = centroid[r, d]
            NT[d, pos] = normals[r, d]
        W[pos] = area[r]
        return pos + 1
    a0, a1, a2 = quads[r, 0, 0], quads[r, 0, 1], quads[r, 0, 2]
    ab0, ab1, ab2 = quads[r, 1, 0] - a0, quads[r, 1, 1] - a1, quads[r, 1, 2] - a2
    ad0, ad1, ad2 = quads[r, 3, 0] - a0, quads[r, 3, 1] - a1, quads[r, 3, 2] - a2
    tw0 = a0 - quads[r, 1, 0] + quads[r, 2, 0] - quads[r, 3, 0]
    tw1 = a1 - quads[r, 1, 1] + quads[r, 2, 1] - quads[r, 3, 1]
    tw2 = a2 - quads[r, 1, 2] + quads[r, 2, 2] - quads[r, 3, 2]
    # dx/du x dx/dv = j0 + u ju + v jv (see quadrature._map_square)
    j00, j01, j02 = ab1 * ad2 - ab2 * ad1, ab2 * ad0 - ab0 * ad2, ab0 * ad1 - ab1 * ad0
    ju0, ju1, ju2 = ab1 * tw2 - ab2 * tw1, ab2 * tw0 - ab0 * tw2, ab0 * tw1 - ab1 * tw0
    jv0, jv1, jv2 = tw1 * ad2 - tw2 * ad1, tw2 * ad0 - tw0 * ad2, tw0 * ad1 - tw1 * ad0
    for a in range(p):
        u, wu = nodes[p, a], weights[p, a]
        for b in range(p):
            v, wv = nodes[p, b], weights[p, b]
            PT[0, pos] = a0 + u * ab0 + v * (ad0 + u * tw0)
            PT[1, pos] = a1 + u * ab1 + v * (ad1 + u * tw1)
            PT[2, pos] = a2 + u * ab2 + v * (ad2 + u * tw2)
            for d in range(3):
                NT[d, pos] = normals[r, d]
            x0, x1, x2 = j00 + u * ju0 + v * jv0, j01 + u * ju1 + v * jv1, j02 + u * ju2 + v * jv2
            W[pos] = wu * wv * np.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
            pos += 1
    return pos


def _two_area_order(quads, normals, centroid, radius, a, b, need_src):
    """The source's Gauss order for the two-area rule of pair (receiver a, source b): the
    smallest q whose bound ``_APRIORI_C rho_src^(-2q)`` meets the limit (need_src[q]: the rho it
    takes), with rho_src the receiver's rho with the roles swapped; 0 (Lambert's closed form on
    the source) if none up to len(need_src) - 1 does, or if the source crosses the receiver's
    plane (its integrand would be clipped, not smooth)."""
    rho, crossing = _pair_rho(quads, normals, centroid, radius, centroid, normals, radius, b, a)
    if crossing or not rho > 1.5:
        return 0
    for q in range(1, len(need_src)):
        if rho >= need_src[q]:
            return q
    return 0


def _two_area_lanes(X, Y, Z, NX, NY, NZ, SP, SW, nq, nb0, nb1, nb2, vals):
    """vals[l] = sum_k SW[k] cos_l cos_k / (pi r^2) over the source's nq points SP, for every
    lane l (receiver points X, Y, Z, normals NX, NY, NZ): the point-to-point kernel, no edges
    and no atan2. The inner loop runs over whole 1-D arrays from 0, which LLVM vectorises
    (over (3, n) rows, or from a lane lo > 0, it did not: 4.2 against 0.7 ns an evaluation)."""
    for u in range(len(vals)):
        vals[u] = 0.0
    for k in range(nq):
        y0, y1, y2, wk = SP[0, k], SP[1, k], SP[2, k], SW[k] / np.pi
        for u in range(len(vals)):
            d0, d1, d2 = y0 - X[u], y1 - Y[u], y2 - Z[u]
            r2 = d0 * d0 + d1 * d1 + d2 * d2
            c_rec = NX[u] * d0 + NY[u] * d1 + NZ[u] * d2
            c_src = -(nb0 * d0 + nb1 * d1 + nb2 * d2)
            vals[u] += wk * c_rec * c_src / (r2 * r2)


def _side_by_side(slot, rec, order, t0, t1):
    """Whether pairs t0..t1's receiver points lie in the point table in pair order, one run of
    columns: the fill's receivers j > i come in index order, so for most runs they do."""
    at = slot[rec[t0], order[t0]]
    for t in range(t0, t1):
        if slot[rec[t], order[t]] != at:
            return False
        at += order[t] * order[t]
    return True


def _two_area_in_table(quads, normals, centroid, area, rec, src, order, t0, t1, q_run, nodes, weights, at0,
                       TP, TN, TW, out):
    """out[t0:t1] for a run of two-area pairs whose receiver points lie side by side in the table
    from column at0 (:func:`_side_by_side`): the lanes are the table's own columns, not copies.
    The same arithmetic in the same order as the copying path, so the same numbers bit for bit."""
    b = src[t0]
    n = 0
    for t in range(t0, t1):
        n += order[t] * order[t]
    vals = np.empty(n)
    SP, SN, SW = np.empty((3, q_run * q_run)), np.empty((3, q_run * q_run)), np.empty(q_run * q_run)
    _put_points(quads, normals, centroid, area, b, q_run, nodes, weights, SP, SN, SW, 0)
    _two_area_lanes(TP[0, at0:at0 + n], TP[1, at0:at0 + n], TP[2, at0:at0 + n], TN[0, at0:at0 + n],
                    TN[1, at0:at0 + n], TN[2, at0:at0 + n], SP, SW, q_run * q_run, normals[b, 0], normals[b, 1],
                    normals[b, 2], vals)
    pos = 0
    for t in range(t0, t1):
        acc, wsum = 0.0, 0.0
        for l in range(pos, pos + order[t] * order[t]):
            acc += TW[at0 + l] * vals[l]
            wsum += TW[at0 + l]
        pos += order[t] * order[t]
        out[t] = acc / wsum if wsum > 0.0 else 0.0


def _separated_kernel(quads, normals, centroid, area, radius, rec, src, order, starts, nodes, weights, mode,
                      raw_below, need_src, has_two, two, slot, TP, TN, TW, out):
    """out[t] = F(rec[t] -> src[t]) for pairs sorted by source, one task per run in ``starts``.

    Pairs whose source has a two-area order (:func:`_two_area_order`; none if ``need_src`` has
    one entry) take the Gauss rule on the source too, at their own order; the others Lambert's
    closed form, by the raw sum where the pair's own distance / source size allows
    (``raw_below``). A pair's lanes go with the lanes of the same rule (raw, far form, two-area
    order 1, 2, ...), so its value depends on the pair alone, not on the run it shares: until
    2026-12-06 a run took its largest order and the raw sum only if all its pairs allowed it,
    and the fill's F changed in the 8th digit with the block sizes, which follow the clock.
    ``has_two``: the orders are given in ``two`` (the pair listing's, the same numbers)."""
    k = quads.shape[1]
    max_q = len(need_src) - 1
    for task in _prange(len(starts) - 1):
        t0, t1 = starts[task], starts[task + 1]
        b = src[t0]
        # each pair's rule: -1 raw sum, 0 Lambert's far-capable form, q > 0 two-area order q
        rule = np.zeros(t1 - t0, np.int64)
        lanes = np.zeros(max_q + 2, np.int64)  # lanes per rule, rule r at index r + 1
        for t in range(t0, t1):
            a = rec[t]
            if has_two:
                q = two[t]
            else:
                q = _two_area_order(quads, normals, centroid, radius, a, b, need_src) if max_q > 0 else 0
            if q == 0:
                d0 = centroid[b, 0] - centroid[a, 0]
                d1 = centroid[b, 1] - centroid[a, 1]
                d2 = centroid[b, 2] - centroid[a, 2]
                ratio = (np.sqrt(d0 * d0 + d1 * d1 + d2 * d2) + radius[a]) / max(radius[b], _TINY)
                q = -1 if ratio <= raw_below else 0
            rule[t - t0] = q
            lanes[q + 1] += order[t] * order[t]
        n = 0
        first = np.empty(max_q + 2, np.int64)
        for r in range(max_q + 2):
            first[r] = n
            n += lanes[r]
        only = rule[0]
        for t in range(t0, t1):
            if rule[t - t0] != only:
                only = -2
        if only > 0 and _side_by_side(slot, rec, order, t0, t1):
            _two_area_in_table(quads, normals, centroid, area, rec, src, order, t0, t1, only, nodes, weights,
                               slot[rec[t0], order[t0]], TP, TN, TW, out)
            continue
        PT, NT = np.empty((3, n)), np.empty((3, n))
        W, vals = np.empty(n), np.empty(n)
        pos = first.copy()
        for t in range(t0, t1):
            r = rule[t - t0] + 1
            pos[r] = _copy_points(TP, TN, TW, slot[rec[t], order[t]], order[t] * order[t], PT, NT, W, pos[r])
        for r, lambert_mode in ((0, 1), (1, mode)):  # raw sum, then the mode's form
            if lanes[r] > 0:
                g = np.empty(_G_SIZE)
                w, h, wc = np.empty((k, 3)), np.empty(k), np.empty((2 * k, 3))
                for lo in range(first[r], first[r] + lanes[r], _SRC_LANES):
                    _source_block(PT, NT, lo, min(_SRC_LANES, first[r] + lanes[r] - lo), quads, b, lambert_mode,
                                  vals, g, w, h, wc)
        for q in range(1, max_q + 1):
            if lanes[q + 1] > 0:
                lo, hi = first[q + 1], first[q + 1] + lanes[q + 1]
                SP, SN, SW = np.empty((3, q * q)), np.empty((3, q * q)), np.empty(q * q)
                _put_points(quads, normals, centroid, area, b, q, nodes, weights, SP, SN, SW, 0)
                _two_area_lanes(PT[0, lo:hi], PT[1, lo:hi], PT[2, lo:hi], NT[0, lo:hi], NT[1, lo:hi], NT[2, lo:hi],
                                SP, SW, q * q, normals[b, 0], normals[b, 1], normals[b, 2], vals[lo:hi])
        pos = first.copy()
        for t in range(t0, t1):
            r = rule[t - t0] + 1
            acc, wsum = 0.0, 0.0
            for l in range(pos[r], pos[r] + order[t] * order[t]):
                acc += W[l] * vals[l]
                wsum += W[l]
            pos[r] += order[t] * order[t]
            out[t] = acc / wsum if wsum > 0.0 else 0.0


# Below this many pairs (or entries) a pass runs on one thread: waking the thread pool costs more
# than the pass on a busy machine (35 ms per parallel loop for the 8 x 8 plates' 4,096 pairs).
PARALLEL_MIN = 50_000


class _TwoWays:
    """A compiled loop in a parallel and a serial build, picked per call by ``work(*args)``
    (the pairs or entries it loops over)."""

    def __init__(self, fn, work, **options):
        self.parallel = _numba.njit(cache=True, parallel=True, **options)(fn)
        # a copy under its own name: numba's cache files are named after the function, not its flags
        serial = types.FunctionType(fn.__code__, fn.__globals__, fn.__name__ + "_serial", fn.__defaults__)
        serial.__qualname__ = fn.__qualname__ + "_serial"
        self.serial = _numba.njit(cache=True, **options)(serial)
        self.work = work

    def __call__(self, *args):
        return (self.parallel if self.work(*args) >= PARALLEL_MIN else self.serial)(*args)


# The plain functions above are compiled here (the serial and parallel builds of _TwoWays).
_task_starts = _numba.njit(cache=True)(_task_starts)
_ascending = _numba.njit(cache=True)(_ascending)
_count_rows = _numba.njit(cache=True)(_count_rows)
_cumulate = _numba.njit(cache=True)(_cumulate)
_place_rows = _TwoWays(_place_rows, lambda *a: len(a[0]) if a[6] > 1 else 0)
_mirror_value = _numba.njit(cache=True, inline="always")(_mirror_value)
_count_kept = _TwoWays(_count_kept, lambda *a: len(a[1]))
_write_mirrored = _TwoWays(_write_mirrored, lambda *a: len(a[1]))
_dropped_mass = _numba.njit(cache=True)(_dropped_mass)
_sort_rows = _TwoWays(_sort_rows, lambda indptr, indices, data: len(indices))
_balanced = _numba.njit(cache=True, inline="always")(_balanced)
_in_front = _numba.njit(cache=True, inline="always")(_in_front)
_facing = _numba.njit(cache=True, inline="always")(_facing)
_apriori_order = _numba.njit(cache=True, inline="always", error_model="numpy")(_apriori_order)
_chunk_bounds = _numba.njit(cache=True)(_chunk_bounds)
_box_dot = _numba.njit(cache=True, inline="always")(_box_dot)
_vertex_dots = _numba.njit(cache=True, inline="always")(_vertex_dots)
_abs_range = _numba.njit(cache=True, inline="always")(_abs_range)
_order_index = _numba.njit(cache=True, inline="always")(_order_index)
_rho_order = _numba.njit(cache=True, inline="always", error_model="numpy")(_rho_order)
_chunk_rule = _numba.njit(cache=True, error_model="numpy")(_chunk_rule)
# the work of both listing passes: the pairs {i, j > i} of their rows
_count_pairs = _TwoWays(_count_pairs, lambda *a: len(a[6]) * (len(a[0]) - len(a[6]) // 2), error_model="numpy")
_list_pairs = _TwoWays(_list_pairs, lambda *a: len(a[6]) * (len(a[0]) - len(a[6]) // 2), error_model="numpy")
_put_points = _numba.njit(cache=True, inline="always", error_model="numpy")(_put_points)
_copy_points = _numba.njit(cache=True, inline="always")(_copy_points)
_table_slots = _numba.njit(cache=True)(_table_slots)
_point_table = _TwoWays(_point_table, lambda *a: a[6].shape[0] * 8, error_model="numpy")
_two_area_order = _numba.njit(cache=True, inline="always", error_model="numpy")(_two_area_order)
_two_area_lanes = _numba.njit(cache=True, error_model="numpy")(_two_area_lanes)
_side_by_side = _numba.njit(cache=True)(_side_by_side)
_two_area_in_table = _numba.njit(cache=True, error_model="numpy")(_two_area_in_table)
_separated_kernel = _TwoWays(_separated_kernel, lambda *a: len(a[5]), error_model="numpy")

"""The fill's one-pass pairs (radiosity.methods.uniform._fill_kernel): the same rule as pair_factors, each unordered
pair once with its mirror by reciprocity, the same pair list as candidate_pairs, the same CSR."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import PARALLEL_SQUARES

from radiosity import _tol
from radiosity.methods.uniform._fill_kernel import (block_pairs, mirrored, once_factors, raw_ratio, reciprocal_pairs,
                                                   rows_to_csr, separated_factors)
from radiosity.methods.uniform.assembly import FillSettings, assemble, candidate_pairs
from radiosity.formfactors._closed_form import _MODES
from radiosity.geometry import polygon_normals
from radiosity.formfactors._quadrature import _pair_setup, _radius, centroids_and_areas, pair_factors


def plates(n: int, *, tilt: float = 0.0, upper_n: int | None = None) -> np.ndarray:
    """A unit plate at z = 0 cut n x n facing up, one at z = 1 cut upper_n x upper_n facing down
    (its far edge raised by ``tilt``)."""
    def grid(k, z, down):
        h = 1.0 / k
        a, b = np.meshgrid(np.arange(k) * h, np.arange(k) * h, indexing="ij")
        a, b = a.ravel(), b.ravel()
        sq = np.stack([np.c_[a, b], np.c_[a + h, b], np.c_[a + h, b + h], np.c_[a, b + h]], axis=1)
        zz = np.full(sq.shape[:2] + (1,), z) + (tilt * sq[..., :1] if down else 0.0)
        q = np.concatenate([sq, zz], axis=2)
        return q[:, ::-1] if down else q

    return np.ascontiguousarray(np.concatenate([grid(n, 0.0, False), grid(upper_n or n, 1.0, True)]))


def geometry(quads):
    normals = polygon_normals(quads)
    centroid, area = centroids_and_areas(quads)
    return normals, centroid, area


@pytest.mark.parametrize("rtol", [1e-3, 1e-6])
def test_separated_pairs_match_pair_factors(rtol):
    """The fused kernel evaluates pair_factors' own rule: the same numbers to rounding."""
    quads = plates(4, tilt=0.3, upper_n=3)
    normals, centroid, area = geometry(quads)
    i, j = candidate_pairs(quads, normals, centroid, np.arange(len(quads)))
    radius = _radius(quads, centroid)
    crossing, order = _pair_setup(quads, normals, centroid, radius, centroid, normals, radius, i, j, rtol)
    sel = (order > 0) & ~crossing
    assert sel.sum() > 50
    mine = separated_factors(quads, normals, centroid, area, i[sel], j[sel], order[sel], _MODES["fill"])
    ref = pair_factors(quads, normals, centroid, area, i[sel], j[sel], rtol=rtol, mode="fill")
    np.testing.assert_allclose(mine, ref, rtol=1e-13, atol=0)
    # the raw sum where it keeps its digits (distance / size <= raw_ratio(rtol)): within 8 u R
    raw = separated_factors(quads, normals, centroid, area, i[sel], j[sel], order[sel], _MODES["fill"],
                            raw_below=raw_ratio(rtol))
    np.testing.assert_allclose(raw, ref, rtol=1e-13, atol=0)


def test_raw_sum_only_where_its_digit_loss_is_below_rtol():
    """A 1e-5 source 1 away (distance / size 2.4e5) seen from a unit plate: at rtol 1e-10 the run
    keeps the far form (raw_ratio 56), at 1e-3 it takes the raw sum, whose error 8 u R ~ 4e-10
    is far below rtol."""
    small = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]], float) * 1e-5 + [0.5, 0.5, 1.0]
    quads = np.ascontiguousarray(np.concatenate([plates(1)[:1], small[:, ::-1]]))
    normals, centroid, area = geometry(quads)
    rec, src, order = np.array([0]), np.array([1]), np.array([6])
    far = separated_factors(quads, normals, centroid, area, rec, src, order, _MODES["fill"])
    tight = separated_factors(quads, normals, centroid, area, rec, src, order, _MODES["fill"], raw_below=raw_ratio(1e-10))
    loose = separated_factors(quads, normals, centroid, area, rec, src, order, _MODES["fill"], raw_below=raw_ratio(1e-3))
    assert tight[0] == far[0]
    assert loose[0] != far[0] and abs(loose[0] / far[0] - 1) < 1e-8


def test_block_pairs_are_candidate_pairs_oriented_with_the_same_orders():
    quads = plates(4, tilt=0.3, upper_n=3)
    normals, centroid, area = geometry(quads)
    rows = np.arange(len(quads))
    active = np.ones(len(quads), bool)
    active[5] = False
    rec, src, order = block_pairs(quads, normals, centroid, area, rows, active, 1e-6)
    i, j = candidate_pairs(quads, normals, centroid, rows)
    keep = (j > i) & active[i] & active[j]
    r2, s2 = reciprocal_pairs(area, i[keep], j[keep])
    assert sorted(zip(rec, src)) == sorted(zip(r2, s2))
    assert np.all(area[rec] <= area[src])
    radius = _radius(quads, centroid)
    crossing, ref = _pair_setup(quads, normals, centroid, radius, centroid, normals, radius, rec, src, 1e-6)
    np.testing.assert_array_equal(order, np.where(crossing, 0, ref))


@pytest.mark.parametrize("tilt, upper_n, rtol", [(0.0, 8, 1e-5), (0.3, 6, 1e-6), (0.0, 12, 1e-8), (2.0, 7, 1e-4)])
def test_block_pairs_whole_chunks_give_each_pair_its_own_test_and_orders(tilt, upper_n, rtol):
    """Plates cut into chunks of _CHUNK patches with one normal: rows take whole chunks by their
    bounds (_chunk_rule). The pairs, orientations, orders and two-area orders are those of the
    per-pair tests (candidate_pairs, _pair_setup, the kernel's own two-area choice), and the
    factors the same bit for bit."""
    quads = plates(8, tilt=tilt, upper_n=upper_n)
    normals, centroid, area = geometry(quads)
    rows = np.arange(len(quads))
    active = np.ones(len(quads), bool)
    active[[3, 70]] = False
    for act in (None, active):
        rec, src, order, two = block_pairs(quads, normals, centroid, area, rows, act, rtol, two_area_rtol=rtol)
        i, j = candidate_pairs(quads, normals, centroid, rows)
        keep = (j > i) if act is None else (j > i) & act[i] & act[j]
        r2, s2 = reciprocal_pairs(area, i[keep], j[keep])
        assert sorted(zip(rec.tolist(), src.tolist())) == sorted(zip(r2.tolist(), s2.tolist()))
        radius = _radius(quads, centroid)
        crossing, ref = _pair_setup(quads, normals, centroid, radius, centroid, normals, radius, rec, src, rtol)
        np.testing.assert_array_equal(order, np.where(crossing, 0, ref))
        sel = order > 0
        mine = once_factors(quads, normals, centroid, area, rec, src, rtol=rtol, max_points=_tol.PAIR_MAX_POINTS,
                            order=order, two_area=True, two_order=two)
        per_pair = once_factors(quads, normals, centroid, area, rec, src, rtol=rtol, max_points=_tol.PAIR_MAX_POINTS,
                                order=order, two_area=True)
        np.testing.assert_array_equal(mine, per_pair)
        assert sel.sum() > 1000
        if rtol == 1e-5:  # the plates of bench_fill's kind: every pair two-area
            assert (two[sel] > 0).all()


def test_plates_total_reciprocity_and_mirror():
    """Plates cut 6 and 4: each entry is computed once over the smaller patch, A_i F_ij = A_j F_ji
    to rounding, and the total meets Howell C-11."""
    quads = plates(6, upper_n=4)
    normals, centroid, area = geometry(quads)
    F, stats = assemble(quads, normals, centroid, area, None, FillSettings(formfactor_rtol=1e-6))
    m = 36
    AF = sp.diags(area) @ F
    np.testing.assert_allclose(AF.toarray(), AF.T.toarray(), rtol=1e-14, atol=1e-18)
    total = float(AF[:m, m:].sum())
    assert total == pytest.approx(PARALLEL_SQUARES[1.0], abs=1e-8)
    assert stats.n_pairs == 2 * 36 * 16
    # the computed direction is the small patch's (upper n = 4 has the larger patches)
    i, j = np.arange(3), np.full(3, m + 1)
    np.testing.assert_allclose(F[i, j].A.ravel(), pair_factors(quads, normals, centroid, area, i, j, rtol=1e-6,
                                                                mode="fill"), rtol=1e-12)


def test_once_factors_near_pairs_go_to_pair_factors():
    """Adjacent and touching patches (a folded strip) take pair_factors' adaptive rule."""
    quads = plates(2, tilt=0.0)
    quads[4:] = quads[:4][:, ::-1] @ np.array([[1, 0, 0], [0, 0, 1], [0, 1, 0]])  # a wall at y = 0
    quads = np.ascontiguousarray(quads)
    normals, centroid, area = geometry(quads)
    i, j = candidate_pairs(quads, normals, centroid, np.arange(len(quads)))
    got = once_factors(quads, normals, centroid, area, i, j, rtol=1e-8, max_points=_tol.PAIR_MAX_POINTS)
    ref = pair_factors(quads, normals, centroid, area, i, j, rtol=1e-8, max_points=_tol.PAIR_MAX_POINTS, mode="fill")
    np.testing.assert_allclose(got, ref, rtol=1e-13)


@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 40), density=st.floats(0.0, 1.0), seed=st.integers(0, 2**16),
       shuffle=st.sampled_from(["all", "none", "some rows"]))
def test_rows_to_csr_is_scipys_matrix(n, density, seed, shuffle):
    rng = np.random.default_rng(seed)
    dense = np.where(rng.random((n, n)) < density, rng.normal(size=(n, n)), 0.0)
    i, j = np.nonzero(dense)  # row-major: every row's columns ascending (the sorted rows' shortcut)
    if shuffle == "all":
        perm = rng.permutation(len(i))
    elif shuffle == "none":
        perm = np.arange(len(i))
    else:  # rows whose entries come reversed, among sorted ones
        perm = np.lexsort((np.where(i % 2 == 1, -j, j), i))
    i, j = i[perm].astype(np.int64), j[perm].astype(np.int64)
    v = dense[i, j]
    mine, ref = rows_to_csr(i, j, v, n), sp.csr_matrix((v, (i, j)), shape=(n, n))
    for name in ("indptr", "indices", "data"):
        np.testing.assert_array_equal(getattr(mine, name), getattr(ref, name))
    if len(i):  # a repeated entry: scipy sums, the fast path declines (at the row's end or next to it)
        assert rows_to_csr(np.r_[i, i[:1]], np.r_[j, j[:1]], np.r_[v, v[:1]], n) is None
        assert rows_to_csr(np.r_[i[:1], i], np.r_[j[:1], j], np.r_[v[:1], v], n) is None


@settings(max_examples=25, deadline=None)
def _reference_mirror(area, i, j, f, drop):
    """fill_block's former numpy passes: both directions concatenated, (rows, cols, values, kept > drop)."""
    ratio = np.divide(area[i], area[j], out=np.zeros(len(i)), where=area[j] > 0)
    ri, rj, rv = np.concatenate([i, j]), np.concatenate([j, i]), np.concatenate([f, f * ratio])
    return ri, rj, rv, rv > drop


@given(n=st.integers(1, 30), m=st.integers(0, 200), seed=st.integers(0, 2**16), drop=st.sampled_from([0.0, 1e-3, 0.3]))
def test_mirrored_is_the_concatenated_mirror(n, m, seed, drop):
    rng = np.random.default_rng(seed)
    area = np.where(rng.random(n) < 0.1, 0.0, rng.random(n))
    i, j = rng.integers(0, n, m), rng.integers(0, n, m)
    f = np.where(rng.random(m) < 0.2, 0.0, rng.random(m))
    ri, rj, rv, keep = _reference_mirror(area, i, j, f, drop)
    got_i, got_j, got_v, dropped = mirrored(area, i, j, f, drop)
    np.testing.assert_array_equal(got_i, ri[keep])
    np.testing.assert_array_equal(got_j, rj[keep])
    np.testing.assert_array_equal(got_v, rv[keep])  # bit for bit
    assert got_i.dtype == got_j.dtype == np.int64
    assert dropped == pytest.approx(float((rv[~keep] * area[ri[~keep]]).sum()), rel=1e-12, abs=1e-300)


@pytest.mark.parametrize("drop", [0.0, 0.3])
def test_parallel_mirror_and_csr_match_the_references(drop):
    """Above PARALLEL_MIN the mirror runs over spans of pairs and the CSR scatter over ranges of
    rows, one task each: the same entries in the same order, the same matrix, bit for bit."""
    rng = np.random.default_rng(5)
    n, m = 3000, 150_000
    area = np.where(rng.random(n) < 0.01, 0.0, rng.random(n))
    i, j = rng.integers(0, n, m), rng.integers(0, n, m)
    f = np.where(rng.random(m) < 0.2, 0.0, rng.random(m))
    ri, rj, rv, keep = _reference_mirror(area, i, j, f, drop)
    got_i, got_j, got_v, dropped = mirrored(area, i, j, f, drop)
    for got, ref in ((got_i, ri[keep]), (got_j, rj[keep]), (got_v, rv[keep])):
        np.testing.assert_array_equal(got, ref)
    serial = 0.0
    for a, v in zip(ri[~keep], rv[~keep]):  # the former serial sum, in entry order
        serial += v * area[a]
    assert dropped == serial
    flat = np.unique(ri * n + rj)  # no repeated (i, j): shuffled distinct entries
    flat = flat[rng.permutation(len(flat))]
    ci, cj = flat // n, flat % n
    cv = rng.normal(size=len(flat))
    mine, ref = rows_to_csr(ci, cj, cv, n), sp.csr_matrix((cv, (ci, cj)), shape=(n, n))
    for name in ("indptr", "indices", "data"):
        np.testing.assert_array_equal(getattr(mine, name), getattr(ref, name))


def _facing_random_pairs(m: int, seed: int) -> np.ndarray:
    """(2 m, 4, 3): pairs (2k, 2k + 1) of random parallelograms and triangles (a repeated last
    vertex) facing each other, sizes 0.1..10 and ratios 0.1..10, 1 to 300 sizes apart."""
    rng = np.random.default_rng(seed)
    quads = np.empty((2 * m, 4, 3))
    for k in range(2 * m):
        size = 10 ** rng.uniform(-1, 1)
        centre = np.zeros(3) if k % 2 == 0 else rng.normal(size=3)
        if k % 2:
            centre *= 10 ** rng.uniform(0.5, 3.0) / np.linalg.norm(centre)
        n = rng.normal(size=3)
        t = np.cross(n, rng.normal(size=3))
        t /= np.linalg.norm(t)
        s = np.cross(n / np.linalg.norm(n), t)
        a, b, shear = rng.uniform(0.3, 1.0) * size, rng.uniform(0.3, 1.0) * size, rng.uniform(-0.5, 0.5) * size
        p0 = centre - 0.5 * a * t - 0.5 * b * s
        quads[k] = [p0, p0 + a * t, p0 + a * t + b * s + shear * t, p0 + b * s + shear * t]
        if rng.random() < 0.4:
            quads[k, 3] = quads[k, 2]
    normals = polygon_normals(quads)
    centroid, _ = centroids_and_areas(quads)
    d = centroid[1::2] - centroid[::2]
    triangle = np.all(quads[:, 3] == quads[:, 2], axis=1)
    for k, sign in ((0, 1.0), (1, -1.0)):  # each faces the other: reverse the winding where not
        flip = np.flatnonzero(sign * np.einsum("mc,mc->m", normals[k::2], d) < 0) * 2 + k
        quads[flip] = np.where(triangle[flip, None, None], quads[flip][:, [0, 2, 1, 1]], quads[flip][:, [0, 3, 2, 1]])
    return np.ascontiguousarray(quads)


@pytest.mark.parametrize("rtol", [1e-4, 1e-6])
def test_two_area_rule_meets_rtol(rtol):
    """Gauss points on both patches (the point-to-point kernel) where the source's a-priori
    bound allows: within rtol of the exact factor, on most random separated pairs."""
    quads = _facing_random_pairs(400, seed=3)
    normals, centroid, area = geometry(quads)
    assert np.all(np.einsum("mc,mc->m", normals[::2], centroid[1::2] - centroid[::2]) > 0)
    assert np.all(np.einsum("mc,mc->m", normals[1::2], centroid[1::2] - centroid[::2]) < 0)
    i, j = np.arange(0, len(quads), 2), np.arange(1, len(quads), 2)
    radius = _radius(quads, centroid)
    crossing, order = _pair_setup(quads, normals, centroid, radius, centroid, normals, radius, i, j, rtol)
    sel = (order > 0) & ~crossing
    i, j, order = i[sel], j[sel], order[sel]
    two = separated_factors(quads, normals, centroid, area, i, j, order, _MODES["fill"], two_area_rtol=rtol)
    lambert = separated_factors(quads, normals, centroid, area, i, j, order, _MODES["fill"])
    exact = pair_factors(quads, normals, centroid, area, i, j, rtol=1e-11, mode="fill")
    assert np.all(exact > 0)
    used = two != lambert
    assert used.sum() > 0.5 * len(i)
    assert np.max(np.abs(two - exact) / exact) <= rtol


def test_two_area_lanes_read_in_place_or_copied_alike():
    """Runs whose receivers' points lie side by side in the point table read them in place;
    shuffled receivers (points not side by side) are copied into lanes: the same numbers."""
    quads = plates(8)
    normals, centroid, area = geometry(quads)
    src = np.repeat(np.arange(64), 64)
    rec = np.tile(np.arange(64, 128), 64)  # each source's receivers in index order: in place
    order = np.full(len(rec), 2)
    in_place = separated_factors(quads, normals, centroid, area, rec, src, order, _MODES["fill"], two_area_rtol=1e-5)
    shuffle = np.concatenate([s * 64 + np.random.default_rng(s).permutation(64) for s in range(64)])
    copied = separated_factors(quads, normals, centroid, area, rec[shuffle], src[shuffle], order[shuffle],
                               _MODES["fill"], two_area_rtol=1e-5)
    lambert = separated_factors(quads, normals, centroid, area, rec, src, order, _MODES["fill"])
    assert np.all(in_place != lambert)  # every pair took the two-area rule
    assert np.array_equal(in_place[shuffle], copied)


@pytest.mark.parametrize("rtol, two_area_orders", [(1e-3, 2), (1e-6, 0)])
def test_each_pair_s_factor_is_its_own_whatever_pairs_it_comes_with(rtol, two_area_orders):
    """The fill's blocks follow the clock (``assembly.BLOCK_SECONDS``), so a pair must get the
    same bits alone, in any batch and in any order. A run of pairs facing one source took its
    largest two-area order, and the raw sum only where every pair allowed it: the bundled box's
    F changed in the 8th digit between the first solve of a process and the next."""
    import radiosity

    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"), max_patch_size=0.11)
    quads, normals, centroid, area = scene.patch_quads, scene.patch_normal, scene.patch_centroid, scene.patch_area
    i, j, order, two = block_pairs(quads, normals, centroid, area, np.arange(scene.n_patches), None, rtol,
                                   two_area_rtol=rtol)

    def factors(sel):
        return once_factors(quads, normals, centroid, area, i[sel], j[sel], rtol=rtol, max_points=4096,
                            order=order[sel], two_area=True, two_order=two[sel])

    whole = factors(np.arange(len(i)))
    assert len(np.unique(two[two > 0])) == two_area_orders  # at 1e-3, runs that mix two-area orders
    batches = np.concatenate([factors(np.arange(s, min(len(i), s + 300))) for s in range(0, len(i), 300)])
    assert np.array_equal(batches, whole)
    shuffled = np.random.default_rng(0).permutation(len(i))
    assert np.array_equal(factors(shuffled), whole[shuffled])


@pytest.mark.parametrize("rtol", [1e-4, 1e-6, 1e-8])
def test_a_touching_needle_the_point_budget_stops_short_is_integrated_again(rtol):
    """A floor sliver 2.2 m long touching a cylinder's side along its 2 cm base (a room of the
    session-24 adversarial pass): within the fill's 4,096 points a pair it got 0.0219756 at rtol
    1e-6 and 0.0220821 at 1e-8 for 0.0219844589, and its row summed to 1 + 8.8e-5. Pairs the
    budget stops short are integrated again with a larger one."""
    from radiosity.formfactors._quadrature import pair_factors
    from radiosity.geometry import centroids_and_areas

    sliver = np.array([[3.0, 4.0, 0.0], [2.1, 2.0, 0.0], [2.0898, 1.9224, 0.0], [2.0898, 1.9224, 0.0]])
    side = np.array([[2.0898, 1.9224, 0.0], [2.1, 2.0, 0.0], [2.0898, 1.9224, 1.2], [2.0898, 1.9224, 1.2]])
    quads = np.array([sliver, side])
    normals = polygon_normals(quads)
    centroid, area = centroids_and_areas(quads)
    exact = pair_factors(quads, normals, centroid, area, np.array([0]), np.array([1]), rtol=1e-10)[0]
    f = once_factors(quads, normals, centroid, area, np.array([0]), np.array([1]), rtol=rtol,
                     max_points=_tol.PAIR_MAX_POINTS, order=np.array([0]))
    assert f[0] == pytest.approx(exact, rel=rtol)

"""Visibility: Embree robustness, exact classification, adaptive rays, exact shadows."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import all_pairs, boxes_scene, corner_point_factor, make_vis, rect

pytest.importorskip("embreex")

from radiosity import _tol  # noqa: E402
from radiosity.geometry import centroids_and_areas  # noqa: E402
from radiosity.visibility import FREE, FULL, MAYBE  # noqa: E402
from radiosity.visibility._embree import EmbreeOccluder  # noqa: E402
from radiosity.visibility._occluders import build_occluders, classify_rows, classify_rows_numpy  # noqa: E402


# ---------------------------------------------------------------- Embree: shared edges and vertices
@pytest.mark.parametrize("shift", [0.0, 1e4])
def test_rays_through_shared_edges_and_vertices_are_blocked(shift):
    """A quad cut in a fan of 8 triangles around its centre: aim at every shared edge and vertex."""
    c = np.array([0.5, 0.5, 0.0])
    ring = np.array([[0, 0, 0], [0.5, 0, 0], [1, 0, 0], [1, 0.5, 0], [1, 1, 0], [0.5, 1, 0], [0, 1, 0], [0, 0.5, 0]])
    tris = np.stack([np.stack([c, ring[k], ring[(k + 1) % 8]]) for k in range(8)]) + shift
    occ = EmbreeOccluder(tris)
    t = np.linspace(0, 1, 41)[1:-1, None]
    targets = np.concatenate([c + t * (ring[k] - c) for k in range(8)] + [c[None], ring[1::2]]) + shift
    origins = targets + np.array([0.3, -0.2, 1.0])
    ends = targets - np.array([0.3, -0.2, 1.0])
    assert occ.occluded(origins, ends).all()


def test_rays_leaving_a_surface_near_shared_edges_do_not_self_shadow():
    """Two coplanar triangles and a perpendicular wall: rays from near the shared edges escape."""
    floor = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0]], [[0, 0, 0], [1, 1, 0], [0, 1, 0]]], float)
    wall = np.array([[[0, 0, 0], [0, 1, 0], [0, 1, 1]], [[0, 0, 0], [0, 1, 1], [0, 0, 1]]], float)
    occ = EmbreeOccluder(np.concatenate([floor, wall]))
    off = _tol.RAY_OFFSET_REL * np.sqrt(3)
    rng = np.random.default_rng(1)
    s = rng.uniform(1e-3, 1, 2000)
    near_diag = np.column_stack([s, s + rng.uniform(-1e-3, 1e-3, 2000), np.zeros(2000)])
    origins = near_diag + [0, 0, off]
    ends = np.column_stack([np.full(2000, off), rng.uniform(0, 1, 2000), rng.uniform(1e-3, 1, 2000)])
    assert not occ.occluded(origins, ends).any()


# ---------------------------------------------------------------- classification
def test_classification_kernel_matches_numpy_reference():
    rng = np.random.default_rng(7)
    blockers = [rect(-0.3, 0.3, -0.3, 0.3, 0.0) + rng.normal(0, 0.05, 3) for _ in range(5)]
    occ = build_occluders(np.array(blockers), np.tile([0, 0, 1.0], (5, 1)), np.arange(5), np.ones(5, bool), 2.0)
    t = 4000
    base_i = rect(-0.1, 0.1, -0.1, 0.1, 0)
    vi = base_i + rng.normal(0, 0.5, (t, 1, 3)) * [1, 1, 0] + rng.uniform(-1.5, 1.5, (t, 1, 1)) * [0, 0, 1]
    vj = base_i + rng.normal(0, 0.5, (t, 1, 3)) * [1, 1, 0] + rng.uniform(-1.5, 1.5, (t, 1, 1)) * [0, 0, 1]
    k = rng.integers(0, occ.n_occluders, t)
    a = classify_rows(occ, vi, vj, k, 2.0)
    b = classify_rows_numpy(occ, vi, vj, k, 2.0)
    np.testing.assert_array_equal(a, b)
    assert {FREE, FULL, MAYBE} <= set(np.unique(a).tolist())


def _straddling_rows(rng, t):
    """Occluders in z = 0 and pairs where one patch (a random quad, tilted) crosses that plane
    and the other lies above or below it."""
    blockers = [rect(-0.3, 0.3, -0.3, 0.3, 0.0) + [*rng.normal(0, 0.2, 2), 0] for _ in range(5)]
    occ = build_occluders(np.array(blockers), np.tile([0, 0, 1.0], (5, 1)), np.arange(5), np.ones(5, bool), 2.0)
    base = rect(-0.2, 0.2, -0.2, 0.2, 0)
    tilt = rng.normal(0, 1.0, (t, 2))
    cut = base + rng.normal(0, 0.6, (t, 1, 3)) * [1, 1, 0.2]
    cut[..., 2] += tilt @ base[:, :2].T  # a tilted plane through z near 0
    side = rng.choice([-1.0, 1.0], (t, 1, 1))
    whole = base + rng.normal(0, 0.6, (t, 1, 3)) * [1, 1, 0] + side * [0, 0, 1] * rng.uniform(0.05, 1.5, (t, 1, 1))
    swap = rng.random(t) < 0.5
    vi = np.where(swap[:, None, None], whole, cut)
    vj = np.where(swap[:, None, None], cut, whole)
    return occ, vi, vj, rng.integers(0, occ.n_occluders, t)


def test_classification_cuts_a_patch_that_straddles_the_occluder_plane():
    """A patch crossing an occluder's plane sends segments across it from its far part only:
    FREE where those miss the occluder (it was always MAYBE), never FULL; kernel = reference,
    and no segment between dense points of a FREE pair meets the occluder."""
    rng = np.random.default_rng(11)
    occ, vi, vj, k = _straddling_rows(rng, 3000)
    straddles = [(np.ptp(np.sign(v[..., 2]), axis=1) > 0) for v in (vi, vj)]
    one = straddles[0] ^ straddles[1]
    assert one.mean() > 0.9
    a = classify_rows(occ, vi, vj, k, 2.0)
    np.testing.assert_array_equal(a, classify_rows_numpy(occ, vi, vj, k, 2.0))
    assert FULL not in a[one].tolist() and 0.2 < (a[one] == FREE).mean() < 0.95
    w = rng.dirichlet(np.ones(4), 400)  # points inside each quad's hull
    free = np.flatnonzero(a == FREE)
    for t in free[:300]:
        p, q = w @ vi[t], w[rng.permutation(400)] @ vj[t]
        cross = (p[:, 2] > 0) != (q[:, 2] > 0)
        x = p + (p[:, 2] / (p[:, 2] - q[:, 2]))[:, None] * (q - p)
        lo, hi = occ.polys[k[t]].min(axis=0), occ.polys[k[t]].max(axis=0)
        inside = (x[:, :2] >= lo[:2]).all(axis=1) & (x[:, :2] <= hi[:2]).all(axis=1)
        assert not (cross & inside).any()


def test_classification_of_plates_and_blocker():
    low = [rect(0, 0.3, 0, 0.3, 0), rect(0.5, 1, 0.5, 1, 0), rect(0.4, 0.6, 0.4, 0.6, 0)]
    up = [rect(0.4, 0.6, 0.4, 0.6, 1, down=True), rect(0, 0.1, 0, 0.1, 1, down=True)]
    blocker = rect(0.25, 0.75, 0.25, 0.75, 0.5)
    vis = make_vis(low + up + [blocker])
    status, _, _ = vis.classify(np.array([2, 0, 0, 1]), np.array([3, 3, 4, 4]))
    # centre-centre: full; corner-centre: partial; corner-corner: free (misses the blocker);
    # the far corner to the corner: every segment crosses the blocker, those from the low
    # patch's corner (0.5, 0.5) to the high one's (0, 0) at its corner (0.25, 0.25): a set of
    # measure zero touches its edge, so the pair is hidden (touching is not covering only where
    # the segments pass outside)
    np.testing.assert_array_equal(status, [FULL, MAYBE, FREE, FULL])


# ---------------------------------------------------------------- exact shadows at a point
SOURCE = rect(-1, 1, -1, 1, 2, down=True)
FLOOR = rect(-1, 1, -1, 1, 0)  # keeps the receiver point inside the scene's hull
ORIGIN = np.zeros((1, 3))
UP = np.array([[0, 0, 1.0]])


def test_point_fraction_exact_quarter_shadow():
    """A blocker at mid-height hiding exactly one quadrant of the source from the origin."""
    vis = make_vis([SOURCE, FLOOR, rect(0, 0.5, 0, 0.5, 1)])
    exact = vis.point_fraction(ORIGIN, UP, np.array([0]), exact=True)
    assert exact[0] == pytest.approx(0.75, abs=1e-12)
    rays = make_vis([SOURCE, FLOOR, rect(0, 0.5, 0, 0.5, 1)], samples=16).point_fraction(ORIGIN, UP, np.array([0]))
    assert rays[0] == pytest.approx(0.75, abs=0.03)


def test_point_fraction_exact_union_of_overlapping_occluders_with_a_hole():
    """Four overlapping bars (two heights) whose shadows form a square ring on the source."""
    bars = [rect(-0.4, 0.4, -0.4, -0.25, 1), rect(-0.4, 0.4, 0.25, 0.4, 1),
            rect(-0.6, -0.375, -0.6, 0.6, 1.5), rect(0.375, 0.6, -0.6, 0.6, 1.5)]
    vis = make_vis([SOURCE, FLOOR] + bars)
    full = 4 * corner_point_factor(1, 1, 2)
    ring = 4 * corner_point_factor(0.8, 0.8, 2) - 4 * corner_point_factor(0.5, 0.5, 2)
    exact = vis.point_fraction(ORIGIN, UP, np.array([0]), exact=True)
    assert exact[0] == pytest.approx(1 - ring / full, abs=1e-12)


def test_horizon_straddling_source_rays_aim_only_at_the_visible_part():
    """The source reaches below the receiver's plane; an occluder hides only that part."""
    receiver = rect(0, 1, 0, 1, 0)
    source = np.array([[2, 0, -1], [2, 1, -1], [2, 1, 1], [2, 0, 1]], float)[::-1].copy()  # faces -x
    below = np.array([[1.5, -1, -1], [1.5, 2, -1], [1.5, 2, -0.01], [1.5, -1, -0.01]], float)
    quads = [receiver, source, below]
    for exact in (False, True):
        vis = make_vis(quads, samples=3, max_samples=6)
        assert vis.fraction(np.array([0]), np.array([1]), exact=exact)[0] == pytest.approx(1.0, abs=1e-12)
    points = np.array([[0.5, 0.5, 0.0], [0.1, 0.9, 0.0]])
    normals = np.tile([0, 0, 1.0], (2, 1))
    for exact in (False, True):
        f = make_vis(quads).point_fraction(points, normals, np.array([1, 1]), exact=exact)
        np.testing.assert_allclose(f, 1.0, atol=1e-12)


@pytest.mark.parametrize("cull", [True, False])
def test_a_pair_whose_rays_carry_no_weight_is_not_seen_through_a_wall(cull):
    """Only the top 1e-3 of the source rises above the receiver's plane, so no sample pair
    carries weight; a wall hides everything. Such pairs once counted as unblocked (a roof
    piece of View3D's hall saw a wall of the next room: F = 2.5e-6 where 0 is exact)."""
    receiver = rect(0, 1, 0, 1, 0)
    source = np.array([[3, 0, -0.999], [3, 1, -0.999], [3, 1, 0.001], [3, 0, 0.001]], float)[::-1].copy()
    # the wall leaves segments to the source's part below the receiver's plane unblocked: the
    # pair is undecided by its vertices, though every segment that carries light is blocked
    wall = np.array([[1.5, -5, -0.3], [1.5, 6, -0.3], [1.5, 6, 5], [1.5, -5, 5]], float)
    vis = make_vis([receiver, source, wall], samples=2, max_samples=4, cull=cull)
    assert vis.classify(np.array([0]), np.array([1]))[0][0] == MAYBE
    assert vis.ray_fraction(np.array([0, 1]), np.array([1, 0]))[0] == 0.0
    assert vis.ray_fraction(np.array([0, 1]), np.array([1, 0]))[1] == 0.0
    open_vis = make_vis([receiver, source], samples=2, max_samples=4, cull=cull)
    # nothing in the way: the same blind rays fall back to exact shadows, which find no shadow
    np.testing.assert_array_equal(open_vis.ray_fraction(np.array([0, 1]), np.array([1, 0])), 1.0)
    if cull:  # blind=False leaves them to the caller (the hierarchy resolves them once)
        i, j = np.array([0, 1]), np.array([1, 0])
        status, rows, occ = vis.classify(i, j)
        assert np.isnan(vis.ray_fraction(i, j, rows=rows, occ=occ, blind=False)).all()
        np.testing.assert_array_equal(vis.blind_fraction(i, j, rows, occ), 0.0)
        np.testing.assert_array_equal(vis.blind_fraction(i, j, rows, occ, orders=(4,)), 0.0)


def test_adaptive_rays_refine_only_partial_pairs():
    low = [rect(0.45, 0.55, 0.45, 0.55, 0), rect(0.2, 0.3, 0.45, 0.55, 0)]
    up = [rect(0.45, 0.55, 0.45, 0.55, 1, down=True)]
    blocker = rect(0.5, 0.75, 0.25, 0.75, 0.5)  # its edge x = 0.5 halves the centre pair
    vis = make_vis(low + up + [blocker], samples=2, max_samples=8)
    f = vis.fraction(np.array([0]), np.array([2]))
    assert vis.n_rays == 2**4 + 8**4
    assert f[0] == pytest.approx(0.5, abs=0.05)
    exact = vis.fraction(np.array([0]), np.array([2]), exact=True, order=6)
    assert exact[0] == pytest.approx(0.5, abs=1e-9)  # symmetric about the edge


# ---------------------------------------------------------------- compiled kernels vs references
def test_fused_classification_matches_numpy_reference():
    """The compiled walk against the box-only numpy reference: the same FULL pairs, and where
    they differ only occluders no segment meets are dropped (the walk's hull)."""
    quads, groups = boxes_scene()
    vis = make_vis(quads, groups)
    i, j = all_pairs(len(quads))
    status, rows, occ = vis.classify(i, j)
    assert {FREE, FULL, MAYBE} <= set(status.tolist())
    _assert_tightens_the_box_reference(vis, quads, i, j, status, rows, occ)
    # the classification is a property of the segments between two patches: symmetric
    back, _, _ = vis.classify(j, i)
    np.testing.assert_array_equal(back, status)


def _segments_meet_quad(p, q, quad):
    """(m,) bool: segment p[m]-q[m] crosses the planar convex quad."""
    n = np.cross(quad[1] - quad[0], quad[2] - quad[0])
    n /= np.linalg.norm(n)
    sp, sq = (p - quad[0]) @ n, (q - quad[0]) @ n
    cross = sp * sq < 0
    x = p + (sp / np.where(cross, sp - sq, 1.0))[:, None] * (q - p)
    inside = np.ones(len(p), bool)
    for e in range(4):
        a, b = quad[e], quad[(e + 1) % 4]
        inside &= np.einsum("mc,c->m", np.cross(b - a, x - a), n) >= 0
    return cross & inside


def _assert_tightens_the_box_reference(vis, quads, i, j, status, rows, occ, seed=5):
    """The walk's status and occluders only tighten the box-only reference's, FULL is the same,
    and no dense segment between the two patches meets an occluder the walk dropped. Returns
    the dropped (pair, occluder) rows."""
    rng = np.random.default_rng(seed)
    ref_status, ref_rows, ref_occ = vis._classify(quads[i], quads[j], np.minimum(vis._lo[i], vis._lo[j]),
                                                  np.maximum(vis._hi[i], vis._hi[j]))
    np.testing.assert_array_equal(status == FULL, ref_status == FULL)
    assert not ((ref_status == FREE) & (status != FREE)).any()
    got = set(zip(rows.tolist(), occ.tolist()))
    ref = set(zip(ref_rows[ref_status[ref_rows] == MAYBE].tolist(), ref_occ[ref_status[ref_rows] == MAYBE].tolist()))
    assert got <= ref
    dropped = sorted(ref - got)
    wts = rng.dirichlet(np.ones(4), 300)
    for r, k in dropped[:400]:
        p, q = wts @ quads[i[r]], wts[rng.permutation(300)] @ quads[j[r]]
        assert not _segments_meet_quad(p, q, quads[k]).any()
    return dropped, ref_status


def test_walk_bounded_by_the_pair_hull_drops_only_occluders_no_segment_meets():
    """Pairs whose box holds occluders walk the BVH within the faces of their hull too (after
    HULL_AFTER occluders): against the box-only reference the status and occluders only
    tighten, FULL never changes, and no dense segment meets an occluder dropped."""
    rng = np.random.default_rng(5)
    centres = rng.uniform(0, 1, (500, 3))
    u = rng.normal(size=(500, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    w = np.cross(u, rng.normal(size=(500, 3)))
    w /= np.linalg.norm(w, axis=1)[:, None]
    v = np.cross(u, w)
    half = rng.uniform(0.01, 0.04, (500, 1))
    quads = np.stack([centres + half * (sa * w + sb * v) for sa, sb in ((-1, -1), (1, -1), (1, 1), (-1, 1))], axis=1)
    vis = make_vis(quads)
    i, j = rng.integers(0, 500, (2, 4000))
    keep = i != j
    i, j = i[keep], j[keep]
    status, rows, occ = vis.classify(i, j)
    dropped, ref_status = _assert_tightens_the_box_reference(vis, quads, i, j, status, rows, occ)
    assert len(dropped) > 100 and (status == FREE).sum() > (ref_status == FREE).sum()  # the hull did cut
    back, _, _ = vis.classify(j, i)
    np.testing.assert_array_equal(back, status)


def test_runs_of_pairs_classified_whole_match_pairs_one_by_one():
    """Runs of pairs sharing a receiver or a source are classified as a whole first
    (``_exact_kernel._classify_set``); shuffled, no run forms and every pair is walked alone:
    the same status and the same occluders (in the same order) for every pair."""
    quads, groups = boxes_scene()
    vis = make_vis(quads, groups)
    i, j = all_pairs(len(quads))
    perm = np.random.default_rng(3).permutation(len(i))
    where = np.argsort(perm)  # pair r's position among the shuffled pairs
    for a, b in ((i, j), (j, i)):  # runs of one receiver, then runs of one source
        status, rows, occ = vis._classify_pairs(quads, a, quads, b)
        s2, rows2, occ2 = vis._classify_pairs(quads, a[perm], quads, b[perm])
        np.testing.assert_array_equal(s2, status[perm])
        s3, rows3, occ3 = vis._classify_pairs(quads, a, quads, b, runs=False)  # no runs at all
        np.testing.assert_array_equal(s3, status)
        np.testing.assert_array_equal(rows3, rows)
        np.testing.assert_array_equal(occ3, occ)
        assert list(zip(perm[rows2].tolist(), occ2.tolist())) == \
            sorted(zip(rows.tolist(), occ.tolist()), key=lambda r: where[r[0]])
        assert {FREE, FULL, MAYBE} <= set(status.tolist())


def test_runs_that_stay_undecided_are_given_up_with_the_same_results():
    """The blocked plates cut 8 x 8 (a blocker between them casting shadows that straddle most
    runs of one receiver): a block of pairs stops testing runs as a whole once most tests stay
    undecided (``_exact_kernel._grouping_pays``), and every pair still gets what its own walk
    gives, in the same order."""
    h = 1.0 / 8
    a, b = (g.ravel() * h for g in np.meshgrid(np.arange(8), np.arange(8), indexing="ij"))
    square = np.stack([np.column_stack([a, b]), np.column_stack([a + h, b]), np.column_stack([a + h, b + h]),
                       np.column_stack([a, b + h])], axis=1)
    low = np.concatenate([square, np.zeros((64, 4, 1))], axis=2)
    up = np.concatenate([square, np.ones((64, 4, 1))], axis=2)[:, ::-1]
    blocker = np.array([[[0.25, 0.25, 0.5], [0.75, 0.25, 0.5], [0.75, 0.75, 0.5], [0.25, 0.75, 0.5]]])
    quads = np.concatenate([low, up, blocker])
    vis = make_vis(quads, np.arange(len(quads)))
    i, j = np.repeat(np.arange(64), 64), np.tile(np.arange(64, 128), 64)  # runs of one receiver
    status, rows, occ = vis._classify_pairs(quads, i, quads, j)
    alone = vis._classify_pairs(quads, i, quads, j, runs=False)
    for got, want in zip((status, rows, occ), alone):
        np.testing.assert_array_equal(got, want)
    assert np.bincount(status).tolist() == [1392, 1936, 768]  # free, full, maybe (bench_fill's counts)


def test_culling_behind_either_plane_drops_exactly_the_occluders_behind():
    """``cull_behind`` (the hierarchy's elements) leaves out of the classification every occluder
    with no vertex in front of the receiver's plane or of the source's, and nothing else: a
    box's faces touching one of its faces are no longer possible occluders of that face's pairs.
    Runs of pairs classified as a whole still match the pairs one by one. Pairs that face each
    other only: an occluder on a patch's plane, edge-on, can hide the patch from points behind
    its plane, which see nothing of it anyway."""
    quads, groups = boxes_scene()
    vis = make_vis(quads, groups)
    vis.closed = False  # compare with the classification alone
    i, j = all_pairs(len(quads))
    i, j = _facing(quads, vis.normals, i, j)
    ref_status, ref_rows, ref_occ = vis.classify(i, j)
    vis.cull_behind = True
    status, rows, occ = vis.classify(i, j)

    polys = vis.occluders.polys[ref_occ]
    tol = 1e-9 * vis.scale

    def in_front(patch):
        return np.einsum("tkc,tc->tk", polys - quads[patch[ref_rows], 0][:, None, :], vis.normals[patch[ref_rows]])

    keep = (in_front(i).max(axis=1) > tol) & (in_front(j).max(axis=1) > tol)
    assert 0 < (~keep).sum() and keep.sum() > 0  # some touch, some do not
    assert sorted(zip(rows.tolist(), occ.tolist())) == sorted(zip(ref_rows[keep].tolist(), ref_occ[keep].tolist()))
    left = np.bincount(ref_rows[keep], minlength=len(i))
    expected = np.where(ref_status == FULL, FULL, np.where(left > 0, MAYBE, FREE))
    np.testing.assert_array_equal(status, expected)
    perm = np.random.default_rng(4).permutation(len(i))
    shuffled, _, _ = vis._classify_pairs(quads, i[perm], quads, j[perm], vis.normals)
    np.testing.assert_array_equal(shuffled, status[perm])


def _facing(quads, normals, i, j):
    """The pairs (i, j) each of which has a vertex in front of the other's plane."""
    def ahead(a, b):
        return (np.einsum("tvc,tc->tv", quads[a] - quads[b, :1], normals[b]) > 1e-9).any(axis=1)

    keep = ahead(i, j) & ahead(j, i)
    return i[keep], j[keep]


def test_classification_against_listed_candidates_matches_the_walk():
    """``classify_listed`` (the hierarchy's children, against their parent's undecided
    occluders) gives the BVH walk's status and occluders when the candidates hold every
    occluder the walk can reach: here all of them, with and without ``cull_behind``; a pair
    whose candidates miss its only blocker is free, as the list says."""
    quads, groups = boxes_scene()
    vis = make_vis(quads, groups)
    vis.closed = False
    vis.hull_always = True  # as the hierarchy's views: every undecided occluder against the hull
    i, j = all_pairs(len(quads))
    every = np.arange(vis.occluders.n_occluders)
    starts = np.arange(len(i) + 1) * len(every)
    for behind in (False, True):
        vis.cull_behind = behind
        walk = vis.classify(i, j, runs=False)
        listed = vis.classify_listed(i, j, starts, np.tile(every, len(i)))
        np.testing.assert_array_equal(listed[0], walk[0])
        assert sorted(zip(*(a.tolist() for a in listed[1:]))) == sorted(zip(*(a.tolist() for a in walk[1:])))
        assert {FREE, FULL, MAYBE} <= set(walk[0].tolist())
    blocked = np.flatnonzero(walk[0] == FULL)[:5]
    none = vis.classify_listed(i[blocked], j[blocked], np.zeros(len(blocked) + 1, np.int64), np.zeros(0, np.int64))
    assert (none[0] == FREE).all()


def test_occluder_mask_kernel_matches_numpy_reference():
    """The compiled on-facet test of occluder_mask gives the numpy form's mask."""
    from scipy.spatial import ConvexHull

    from radiosity.visibility._exact_kernel import on_facet_planes
    from radiosity.visibility._pairs import _nearest_planes, _on_facet_planes_numpy

    quads, _ = boxes_scene()
    scale = float(np.linalg.norm(np.ptp(quads.reshape(-1, 3), axis=0)))
    planes = ConvexHull(quads.reshape(-1, 3)).equations
    cand = _nearest_planes(quads, planes, scale)
    ref = _on_facet_planes_numpy(quads, planes, cand, 1e-7 * scale)
    np.testing.assert_array_equal(on_facet_planes(quads, planes, cand.astype(np.int64), 1e-7 * scale), ref)
    assert 0 < ref.sum() < len(quads)  # floor and ceiling on the hull, the boxes not


def test_segment_rays_match_embree_and_the_numpy_reference():
    """Rays tested against each pair's own occluders (float64) = Embree against every patch."""
    quads, groups = boxes_scene()
    vis = make_vis(quads, groups, samples=3, max_samples=5)
    i, j = all_pairs(len(quads))
    status, rows, occ = vis.classify(i, j)
    part = np.flatnonzero(status == MAYBE)
    local = np.full(len(i), -1)
    local[part] = np.arange(len(part))
    ii, jj = i[part], j[part]
    segments = vis.ray_fraction(ii, jj, rows=local[rows], occ=occ)
    assert vis.ray_fraction(ii, jj) == pytest.approx(segments, abs=0)  # classifies by itself
    key = ii.astype(np.uint64) * np.uint64(len(quads)) + jj.astype(np.uint64)
    xs, wx = stratified_points_reference(quads[ii], 3, key, 1)
    embree, agree = vis._trace(xs, wx, vis.normals[ii], jj, 3, key)
    reference, ref_agree = vis._trace_numpy(xs, wx, vis.normals[ii], jj, 3, key)
    np.testing.assert_allclose(embree, reference, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(agree, ref_agree)
    from radiosity.visibility._pairs import _occluder_lists

    seg, seg_agree = vis._trace(xs, wx, vis.normals[ii], jj, 3, key, _occluder_lists(local[rows], occ, len(ii)))
    assert 0 < np.nanmean(seg) < 1 and not agree.all()
    np.testing.assert_allclose(seg, embree, atol=1e-12)  # jittered rays miss edges: no disagreement
    np.testing.assert_array_equal(seg_agree, agree)
    # rows that read their pair's list through ``owner`` (no copy) get what the copied lists give
    pick = np.random.default_rng(7).permutation(len(ii))[: len(ii) // 2]
    starts, occ_lists = _occluder_lists(local[rows], occ, len(ii))
    owned, owned_agree = vis._trace(xs[pick], wx[pick], vis.normals[ii[pick]], jj[pick], 3, key[pick],
                                    (starts, occ_lists, pick))
    np.testing.assert_array_equal(owned, seg[pick])
    np.testing.assert_array_equal(owned_agree, seg_agree[pick])


def stratified_points_reference(quads, samples, key, salt):
    from radiosity.visibility._pairs import stratified_points
    from radiosity.visibility._ray_kernel import stratified_points as compiled

    pts, w = stratified_points(quads, samples, key, salt)
    cpts, cw = compiled(quads, np.arange(len(quads)), samples, key, salt)
    np.testing.assert_array_equal(cpts, pts)
    np.testing.assert_array_equal(cw, w)
    return pts, w


@pytest.mark.parametrize("max_union", [10, 1])
def test_union_by_inclusion_exclusion_matches_shapely(monkeypatch, max_union):
    """Several overlapping occluders at one point: compiled union (or the shapely fallback)."""
    from radiosity.visibility import _exact

    monkeypatch.setattr(_exact, "MAX_UNION", max_union)
    rng = np.random.default_rng(3)
    n_groups, per = 40, 5
    x = np.repeat(rng.uniform(-0.5, 0.5, (n_groups, 3)) * [1, 1, 0], per, axis=0)
    nx = np.tile([0, 0, 1.0], (n_groups * per, 1))
    source = np.repeat(SOURCE[None], n_groups * per, axis=0)
    sn = np.tile([0, 0, -1.0], (n_groups * per, 1))
    occ = np.array([rect(-r, r, -r, r, 0) + [cx, cy, h] for cx, cy, r, h in
                    zip(*rng.uniform([-0.8, -0.8, 0.1, 0.3], [0.8, 0.8, 0.5, 1.7], (n_groups * per, 4)).T)])
    on = np.tile([0, 0, 1.0], (n_groups * per, 1))
    group = np.repeat(np.arange(n_groups), per)
    got = _exact.hidden_factors(x, nx, group, source, sn, occ, on, 1e-9)
    ref = _exact._hidden_factors_shapely(x, nx, group, source, sn, occ, on, 1e-9)
    assert (ref > 0).all()
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-14)


def test_exact_fraction_falls_back_to_shapely_unions(monkeypatch):
    import radiosity.visibility._exact as exact
    import radiosity.visibility._pairs as pairs

    quads, groups = boxes_scene()
    i, j = all_pairs(len(quads))
    compiled = make_vis(quads, groups).fraction(i, j, exact=True, order=3)
    monkeypatch.setattr(pairs, "MAX_UNION", 1)
    monkeypatch.setattr(exact, "MAX_UNION", 1)  # else the group kernel unites them itself
    united = []  # rows that reached the shapely union: the path this test is named for
    real = exact.union_factors
    monkeypatch.setattr(exact, "union_factors", lambda x, *a, **k: united.append(len(x)) or real(x, *a, **k))
    fallback = make_vis(quads, groups).fraction(i, j, exact=True, order=3)
    assert sum(united) > 100
    assert 0 < compiled.mean() < 1
    np.testing.assert_allclose(fallback, compiled, rtol=1e-9, atol=1e-12)


def test_exact_fraction_of_a_few_pairs_costs_memory_for_those_pairs_only():
    """Exact shadows of two pairs in a scene of 20,000 patches: the Gauss points of the two
    receivers, not of every patch. Each call placed order**2 points on every patch: the blind
    pairs' order-16 rule took a terrain of a million triangles to 19 GB."""
    import tracemalloc

    quads, groups = boxes_scene()
    far = np.array([rect(0, 0.01, 0, 0.01, 0)]) + np.column_stack([np.arange(20_000) * 0.02, np.full(20_000, 50.0),
                                                                  np.zeros(20_000)])[:, None, :]
    vis = make_vis(np.concatenate([quads, far]), np.r_[groups, np.arange(20_000) + groups.max() + 1])
    i, j = all_pairs(len(quads))
    status, rows, occ = vis.classify(i, j)
    alone = make_vis(quads, groups)
    maybe = np.flatnonzero(status == MAYBE)
    coarse = alone.exact_fraction(i, j, rows, occ, 3)
    part = maybe[(coarse[maybe] > 0) & (coarse[maybe] < 1)][:2]  # two partly hidden pairs
    keep = np.isin(rows, part)
    rows = np.searchsorted(part, rows[keep])
    expected = alone.exact_fraction(i[part], j[part], rows, occ[keep], 16)
    tracemalloc.start()
    got = vis.exact_fraction(i[part], j[part], rows, occ[keep], 16)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 5e6  # every patch's points: 20,006 x 256 x 3 doubles, 123 MB
    np.testing.assert_array_equal(got, expected)
    assert ((0 < got) & (got < 1)).all()


def _random_quad(rng, center, size):
    """A random planar convex quad (a rotated, sheared rectangle) around center."""
    basis, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    u, v = basis[:, 0] * size * rng.uniform(0.2, 1), basis[:, 1] * size * rng.uniform(0.2, 1)
    v = v + rng.uniform(-0.5, 0.5) * u
    return np.array([center - u - v, center + u - v, center + u + v, center - u + v])


def _normal(quad):
    n = np.cross(quad[2] - quad[0], quad[3] - quad[1])
    return n / np.linalg.norm(n)


@pytest.mark.parametrize("seed", range(4))
def test_occluders_outside_the_cone_are_skipped_without_changing_the_factor(seed):
    """``_point_hidden`` skips occluders wholly outside one plane of the cone from x over the
    source. One occluder per point: the kernel (with the test) equals the clipped polygon's
    factor (``hidden_rows``, without it), for random quads anywhere, including occluders whose
    edge lies in a cone plane and occluders across x's own plane."""
    from radiosity.visibility._exact import hidden_factors
    from radiosity.visibility._exact_kernel import hidden_rows

    rng = np.random.default_rng(seed)
    n = 400
    source = np.array([_random_quad(rng, rng.uniform(-1, 1, 3), 1.0) for _ in range(n)])
    sn = np.array([_normal(q) for q in source])
    x = rng.uniform(-2, 2, (n, 3))
    nx = rng.normal(size=(n, 3))
    nx /= np.linalg.norm(nx, axis=1)[:, None]
    t = rng.uniform(0.05, 0.95, (n, 1))
    occluder = np.array([_random_quad(rng, c, rng.uniform(0.05, 1.0)) for c in x + t * (source.mean(axis=1) - x)])
    # a quarter of them with an edge along the ray from x to a source vertex (in a cone plane)
    edge = slice(0, n // 4)
    occluder[edge, 0] = x[edge] + t[edge] * (source[edge, 0] - x[edge])
    occluder[edge, 1] = x[edge] + t[edge] * (source[edge, 1] - x[edge])
    on = np.array([_normal(q) for q in occluder])
    got = hidden_factors(x, nx, np.arange(n), source, sn, occluder, on, 1e-9)
    want, _, _ = hidden_rows(x, nx, source, sn, occluder, on, 1e-9, False)
    want = np.maximum(want, 0.0)  # a point's hidden factor counts only what it sees
    assert n // 4 < (want > 0).sum() < n - n // 10  # the draw hides something often, not always
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)


def test_a_wall_of_two_surfaces_hides_what_it_hides_as_one():
    """Coplanar occluders of different objects that tile a convex polygon are merged, so a pair
    behind the whole wall is hidden by one occluder (in View3D's 398-surface hall a floor piece
    behind a wall of two surfaces leaked 4.4e-6 of its 3.7e-5 through the seam, in 103 s). An
    L of three pieces merges only where two tile a rectangle, and a merged polygon of several
    objects takes no part in closed-object culling (front 0)."""
    lower = np.array([[0, 0, 0], [2, 0, 0], [2, 0, 1], [0, 0, 1]], float)  # the wall y = 0, two pieces
    upper = np.array([[0, 0, 1], [2, 0, 1], [2, 0, 2], [0, 0, 2]], float)
    floor = rect(0.5, 1.5, -2, -1, 0)
    beyond = np.array([[0.5, 1.5, 0.5], [1.5, 1.5, 0.5], [1.5, 1.5, 1.2], [0.5, 1.5, 1.2]], float)[::-1].copy()
    vis = make_vis([lower, upper, floor, beyond])
    assert vis.occluders.n_occluders == 1 and vis.occluders.front.tolist() == [0]
    status, _, _ = vis.classify(np.array([2]), np.array([3]))
    assert status.tolist() == [FULL]
    corner = np.array([[2, 0, 0], [3, 0, 0], [3, 0, 1], [2, 0, 1]], float)  # lower + corner tile 3 x 1
    vis = make_vis([lower, upper, corner, floor, beyond])
    assert vis.occluders.n_occluders == 2


def _boxes_partly_occluded(step: int):
    """The boxes scene's Visibility and the arguments of ``adaptive_hidden`` (receivers,
    sources, occluder rows, tolerance 1e-6) for every ``step``-th partly occluded facing pair."""
    quads, groups = boxes_scene()
    vis = make_vis(quads, groups)
    i, j = all_pairs(len(quads))
    i, j = _facing(quads, vis.normals, i, j)
    status, rows, occ = vis.classify(i, j)
    part = np.flatnonzero(status == MAYBE)[::step]
    local = np.full(len(i), -1)
    local[part] = np.arange(len(part))
    keep = local[rows] >= 0
    return vis, (i[part], j[part], local[rows[keep]], occ[keep], 1e-6)


def test_squares_own_occluders_change_nothing_but_the_work(monkeypatch):
    """Each adaptive square keeps only the occluders of its parent that reach it (or one that
    hides it all): the hidden factors are those of squares that test every occluder of the
    pair, to rounding, on the boxes scene's partly occluded pairs."""
    from radiosity.visibility._pairs import Visibility

    vis, args = _boxes_partly_occluded(7)
    own = vis.adaptive_hidden(*args, penumbra_depth=2, max_depth=3)
    whole = Visibility._square_occluders

    def every_occluder(self, i, j, lists, pair, corner, size):
        return lists, whole(self, i, j, lists, pair, corner, size)[1]

    monkeypatch.setattr(Visibility, "_square_occluders", every_occluder)
    reference = vis.adaptive_hidden(*args, penumbra_depth=2, max_depth=3)
    assert len(args[0]) > 50 and reference.max() > 0
    np.testing.assert_allclose(own, reference, rtol=1e-12, atol=1e-15)


def _staggered_slats(gap_at: float):
    """A unit source (z = 0, facing up), a receiver above it (z = 2, facing down) and two
    slats at different heights that overlap as seen from a receiver square over x in
    [0.4, 0.6] when the upper one starts at x = 0.4, and leave it a gap when it starts at 0.7."""
    source = rect(0, 1, 0, 1, 0)
    receiver = rect(0, 1, 0, 1, 2, down=True)
    lower = rect(-1, 0.6, -1, 2, 1, down=True)
    upper = rect(gap_at, 2, -1, 2, 1.3, down=True)
    return [source, receiver, lower, upper]


@pytest.mark.parametrize("gap_at, covered", [(0.4, True), (0.7, False)])
def test_occluders_that_hide_a_square_only_together_cover_it(gap_at, covered):
    """Two slats at different heights, neither of which hides a receiver square alone, hide it
    together: the intersection over the square's corners of each one's hidden polygon on the
    source is hidden from all of the square (its points' segments to a source point that
    meet a convex occluder form a convex set), and the union of those covers the source.
    Moved apart, they leave a gap and the square is not covered."""
    from radiosity.visibility._exact_kernel import covered_squares

    quads = _staggered_slats(gap_at)
    vis = make_vis(quads)
    o = vis.occluders
    slats = [int(np.argmin(np.abs(o.center[:, 2] - z))) for z in (1.0, 1.3)]
    square = np.array([[[0.4, 0.4, 2.0], [0.6, 0.4, 2.0], [0.6, 0.6, 2.0], [0.4, 0.6, 2.0]]])
    down, up = np.array([[0.0, 0.0, -1.0]]), np.array([[0.0, 0.0, 1.0]])
    source = np.asarray(quads[0])[None]

    def cover(occ):
        occ = np.asarray(occ, np.int64)
        return bool(covered_squares(square, square.mean(axis=1), down, source, up, np.array([0, len(occ)]), occ,
                                    o.polys, o.normal, 1e-12, 64)[0])

    assert cover(slats) is covered
    assert not cover(slats[:1]) and not cover(slats[1:])


def test_squares_covered_together_change_nothing_but_the_work(monkeypatch):
    """Squares that two slats hide together stop splitting; the hidden factor is the one of
    squares split to the deepest level wherever no single occluder hides them, within the
    quadrature error of the unoccluded factor on the squares that stop (the tolerance, 1e-6)."""
    from radiosity.visibility._pairs import Visibility

    vis = make_vis(_staggered_slats(0.4))
    i, j = np.array([1]), np.array([0])
    status, rows, occ = vis.classify(i, j)
    assert status.tolist() == [MAYBE]
    fused = vis.adaptive_hidden(i, j, rows, occ, 1e-6, penumbra_depth=4, max_depth=5)
    fused_rows = vis.n_exact_rows
    monkeypatch.setattr(Visibility, "_squares_covered", lambda self, i, j, lists, cells, *a: np.zeros(len(cells), bool))
    vis.n_exact_rows = 0
    split = vis.adaptive_hidden(i, j, rows, occ, 1e-6, penumbra_depth=4, max_depth=5)
    np.testing.assert_allclose(fused, split, rtol=0, atol=1e-7)
    assert 0 < fused[0] < 1 and fused_rows < vis.n_exact_rows / 2


@pytest.mark.parametrize("penumbra_depth", [0, 4])
def test_a_receiver_the_slats_hide_together_gets_nothing(penumbra_depth):
    """The two staggered slats together hide the whole source from the whole receiver: the
    hidden part is the pair's unoccluded factor (area kernel, 1e-10) within the tolerance, with
    or without the penumbra levels, since the squares they cover take that factor exactly."""
    from radiosity.formfactors import pair_factors

    quads = np.asarray(_staggered_slats(0.4), float)
    vis = make_vis(quads)
    i, j = np.array([1]), np.array([0])
    status, rows, occ = vis.classify(i, j)
    assert status.tolist() == [MAYBE]
    centroid, area = centroids_and_areas(quads)
    unoccluded = pair_factors(quads, vis.normals, centroid, area, i, j, rtol=1e-10)[0]
    hidden = vis.adaptive_hidden(i, j, rows, occ, 1e-6, penumbra_depth=penumbra_depth, max_depth=5)[0]
    assert abs(unoccluded - hidden) <= 1e-6 * unoccluded


def test_squares_in_chunks_of_pairs_give_the_same_bits(monkeypatch):
    """The adaptive squares run over chunks of pairs (memory: every square carries its pair's
    occluder list); a pair's squares do not depend on the others', so any chunking gives the
    same hidden factors bit for bit."""
    from radiosity.visibility import _pairs

    vis, args = _boxes_partly_occluded(5)
    whole = vis.adaptive_hidden(*args, penumbra_depth=2, max_depth=3)
    monkeypatch.setattr(_pairs, "CHUNK_SQUARE_PAIRS", 7)
    chunked = vis.adaptive_hidden(*args, penumbra_depth=2, max_depth=3)
    assert len(args[0]) > 50 and whole.max() > 0
    assert whole.tobytes() == chunked.tobytes()


@pytest.mark.parametrize("threshold", [0, 20])
def test_pairs_with_long_occluder_lists_trace_through_embree_with_the_same_fractions(monkeypatch, threshold):
    """Two plates cut 6 x 6 with a 320-triangle icosphere between them: up to 37 undecided
    occluders a pair. Tracing the pairs with more than ``threshold`` of them through Embree
    (``RAY_LIST_EMBREE``) gives the fractions of the compiled loop over each pair's list, and
    a segment that crosses the sphere is blocked either way."""
    import trimesh

    from radiosity.visibility import Visibility, _pairs

    n = 6
    edges = np.linspace(0.0, 2.0, n + 1)
    plates = [rect(edges[a], edges[a + 1], edges[b], edges[b + 1], z, down=down)
              for z, down in ((0.0, False), (2.0, True)) for a in range(n) for b in range(n)]
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=0.5)
    sphere.apply_translation([1.0, 1.0, 1.0])
    tris = sphere.vertices[sphere.faces]
    quads = np.concatenate([np.array(plates), np.concatenate([tris, tris[:, 2:3]], axis=1)])
    normals = np.cross(quads[:, 1] - quads[:, 0], quads[:, 2] - quads[:, 0])
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    groups = np.r_[np.zeros(2 * n * n, int), np.ones(len(tris), int)]
    i, j = (g.ravel() for g in np.meshgrid(np.arange(n * n), np.arange(n * n, 2 * n * n), indexing="ij"))
    vis = Visibility(quads, normals, groups, 3.0, samples=2, max_samples=4)
    status, rows, occ = vis.classify(i, j)
    assert np.bincount(rows, minlength=len(i)).max() > 20 >= threshold
    looped = vis.ray_fraction(i, j, 4, 4, rows=rows, occ=occ)
    monkeypatch.setattr(_pairs, "RAY_LIST_EMBREE", threshold)
    traced = vis.ray_fraction(i, j, 4, 4, rows=rows, occ=occ)
    np.testing.assert_allclose(traced, looped, atol=1e-12)
    middle = [a * n + b for a in (2, 3) for b in (2, 3)]  # under the sphere
    centre = np.isin(i, middle) & (j == i + n * n)  # straight up through it
    assert centre.sum() == 4 and np.all(traced[centre] < 0.5)


def test_a_capped_walk_keeps_the_first_undecided_occluders_and_says_so():
    """``Visibility.list_cap``: a pair's walk stops at that many undecided occluders. Its list
    is then the first of the full walk's, exactly ``list_cap`` long, also where closed-object
    culling would drop some (the length is what tells the hierarchy the list may be cut short);
    every other pair is as without the cap."""
    from helpers import cube_room_scene
    from radiosity.visibility import Visibility

    scene = cube_room_scene(20)
    i, j = all_pairs(scene.n_patches)
    cap = 40
    for closed in (False, True):
        vis = Visibility(scene.patch_quads, scene.patch_normal, scene.patch_object, scene.scale, closed=closed)
        full = vis.classify(i, j)
        vis.list_cap = cap
        capped = vis.classify(i, j)
        n_full = np.bincount(full[1], minlength=len(i))
        n_capped = np.bincount(capped[1], minlength=len(i))
        cut = n_capped == cap
        assert cut.any() and (~cut & (full[0] == MAYBE)).any() and n_capped.max() == cap
        assert np.all(capped[0][cut] == MAYBE)
        np.testing.assert_array_equal(full[0][~cut], capped[0][~cut])
        np.testing.assert_array_equal(n_full[~cut], n_capped[~cut])
        if not closed:  # the raw walk: the first cap of its occluders, and only pairs with as many
            np.testing.assert_array_equal(cut, n_full >= cap)
            for p in np.flatnonzero(cut)[:20]:
                np.testing.assert_array_equal(capped[2][capped[1] == p], full[2][full[1] == p][:cap])

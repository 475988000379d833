"""Hierarchical radiosity (issue 14): quadtrees, refinement, push-pull, agreement with uniform."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import radiosity
from radiosity.methods.hierarchical import build_hierarchy
from radiosity.methods.hierarchical._hierarchy import _solve_channel
from radiosity.methods.hierarchical._elements import Elements, split_quads
from radiosity.options import Options
from radiosity.geometry import centroids_and_areas

from helpers import all_pairs, axis_box, boxes_scene, cube_room_scene, make_vis, rect, write_obj

REFERENCE = Path(__file__).parent / "data" / "cornell_uniform_default.json"


@pytest.fixture(scope="module")
def furnace(tmp_path_factory):
    """A closed room with a floating block and a floating slab: every face emits 1, reflects 0.5."""
    path = write_obj(tmp_path_factory.mktemp("furnace") / "furnace.obj",
                     {"room": axis_box([0, 0, 0], [1, 1, 1], inward=True),
                      "block": axis_box([0.3, 0.35, 0.3], [0.65, 0.7, 0.6], inward=False),
                      "slab": axis_box([0.1, 0.1, 0.1], [0.9, 0.2, 0.3], inward=False)})
    with pytest.warns(radiosity.RadiosityWarning):  # its MTL emits nothing: the materials come next
        scene = radiosity.load_scene(path)
    return scene.with_materials(reflectance=0.5, emission=1.0)


def solve_h(scene, preset="draft", **kw):
    return radiosity.solve(scene, method="hierarchical", preset=preset, cache=False, **kw)


# ---------------------------------------------------------------------------------- quadtrees
@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-1, 1), min_size=9, max_size=9), st.booleans())
def test_children_tile_their_parent(coords, triangle):
    """Four children per element, same winding, areas summing to the parent's."""
    a, b, c = np.asarray(coords).reshape(3, 3)
    if np.linalg.norm(np.cross(b - a, c - a)) < 1e-3:
        return
    quad = np.array([a, b, c, c]) if triangle else np.array([a, b, c, a + c - b])  # a parallelogram
    children = split_quads(quad[None])[0]
    _, area = centroids_and_areas(quad[None])
    _, child_area = centroids_and_areas(children)
    assert child_area.sum() == pytest.approx(area[0], rel=1e-12)
    normal = np.cross(quad[1] - quad[0], quad[2] - quad[0])
    for child in children:
        assert np.cross(child[1] - child[0], child[2] - child[0]) @ normal > 0


def test_elements_stop_at_the_minimum_size():
    quad = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]], float)
    el = Elements(quad, np.array([[0, 0, 1.0]]), min_size=0.2)
    while el.splittable[el.leaves()].any():
        el.split(el.leaves()[el.splittable[el.leaves()]])
    leaves = el.leaves()
    assert len(leaves) == 16  # edges 1 -> 0.5 -> 0.25; 0.125 would be below 0.2
    assert el.area[leaves].sum() == pytest.approx(1.0)
    rows, elements = el.ancestry(leaves)
    assert np.bincount(rows).tolist() == [3] * 16  # each leaf, its parent and the root


# ---------------------------------------------------------------------------------- physics
def test_furnace_identity_through_occlusion(furnace):
    """Every surface emits E and reflects rho in a closed scene: B = E / (1 - rho) on every leaf.

    Measured at this tolerance: worst leaf 1.4% off, mean 0.2% (the issue's target is 1%; the
    error of a leaf adds up the errors of all its ancestors' links, see docs/hierarchical.md).
    """
    solution = solve_h(furnace, link_tolerance=1e-3, min_element_rel=1 / 10)
    B = solution.radiosity
    assert len(B) > furnace.n_patches  # it refined
    print("furnace: worst leaf", np.abs(B / 2.0 - 1.0).max(), "mean", np.abs(B / 2.0 - 1.0).mean())
    assert np.abs(B / 2.0 - 1.0).max() < 0.02
    assert np.abs(B / 2.0 - 1.0).mean() < 0.004


def test_furnace_identity_in_a_room_of_cubes():
    """A closed room holding eight small floating cubes, every face emitting 1 and reflecting
    0.5: B = 2 on every leaf within 1% at draft, link_tolerance=1e-2 (measured: worst leaf
    0.61%, mean -0.11%; 1.1% / +0.15% before links that cannot split were settled in every pass,
    settled partly visible links got exact shadows in every preset and a near-source bound
    pushed a wall's links to small cubes before it down the wall's quadtree)."""
    from helpers import cube_room_scene

    solution = solve_h(cube_room_scene(8), link_tolerance=1e-2, min_element_rel=1 / 10)
    error = solution.radiosity / 2.0 - 1.0
    assert solution.scene.n_patches > 54  # the walls refined
    assert np.abs(error).max() < 1e-2
    assert abs(error.mean()) < 3e-3


def test_push_pull_conserves_power(furnace):
    """Power gathered at every level (A_e H_e) equals the power pushed onto the leaves (before
    rows past 1 are scaled down): the links' variation across their receivers, which G gathers
    in rows after the elements', moves power between the leaves below a receiver and adds none."""
    hier = build_hierarchy(furnace, Options.from_preset("draft", link_tolerance=1e-2, min_element_rel=1 / 10))
    hier.refine()
    B, K, leaves, _ = hier.solve(1e-10)
    assert K.gather.variation is not None
    gathered = hier.el.area[:, None] * (K.gather @ (K.pull @ B))[:len(hier.el)]
    pushed = hier.el.area[leaves, None] * (K.push @ (K.gather @ (K.pull @ B)))
    np.testing.assert_allclose(pushed.sum(axis=0), gathered.sum(axis=0), rtol=1e-12)
    np.testing.assert_allclose(K.pull @ np.ones(len(leaves)), 1.0, rtol=1e-12)  # pull is an area mean


@pytest.fixture(scope="module")
def cornell():
    """The bundled box, hierarchical at a coarse tolerance (the fastest setting that agrees to 3%)."""
    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    return scene, solve_h(scene, link_tolerance=3e-2, min_element_rel=1 / 25)


def test_agrees_with_uniform_on_the_cornell_box(cornell):
    """Object means within 3% of the uniform default solve (measured: 2.2% at this tolerance)."""
    reference = json.loads(REFERENCE.read_text())["objects"]
    means = cornell[1].object_radiosity()
    for name, value in reference.items():
        np.testing.assert_allclose(means[name], value, rtol=0.03, err_msg=name)


def test_source_shares_take_the_bias_out_of_the_cornell_box_at_draft():
    """Every object mean within 0.8% of the uniform default solve at draft, 2.4 cm elements:
    before a link gathered by its source's children's shares, every object came out dark and
    the ceiling by 1.7% (it sees the walls' upper parts best, brighter than their means)."""
    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    means = solve_h(scene, min_element_size=0.024).object_radiosity()
    for name, value in json.loads(REFERENCE.read_text())["objects"].items():
        np.testing.assert_allclose(means[name], value, rtol=0.008, err_msg=name)


def test_links_keep_their_undecided_occluders_across_passes_for_their_children():
    """After a pass, each partly visible link that can still split keeps the occluders its
    classification left undecided, and the links that cannot split keep none. In the next pass
    its children are classified against that list instead of walking the occluders' BVH
    (the 100-cube room: 27 -> 18.5 s), and decide as the walk does."""
    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    hier = build_hierarchy(scene, Options.from_preset("draft", min_element_rel=1 / 20))
    hier.refine()
    hier.solve(1e-10)
    links, el = hier.links, hier.el
    can = el.splittable[links.r] | el.splittable[links.s]
    listed = links.occluders.count > 0
    np.testing.assert_array_equal(listed, links.partial & can)
    assert listed.sum() > 100 and (links.partial & ~can).any()
    ask = links.take(listed)
    r, s, parent = hier._expand(ask)
    walked = hier.vis.fractions_undecided(el, r, s, children=True)
    inherited = hier.vis.fractions_undecided(el, r, s, children=True, candidates=ask.occluders.of(parent))
    for a, b in zip(walked, inherited):
        np.testing.assert_array_equal(a, b)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 30), st.integers(0, 6), st.booleans(), st.booleans()), min_size=1, max_size=4),
       st.integers(0, 2**32 - 1))
def test_gathered_links_are_the_masked_parts_joined_with_their_occluder_lists(shapes, seed):
    """``Links.gather`` (one copy by index, as a pass joins its kept links) gives what taking
    each part by its mask and concatenating gives, occluder lists and their dtypes included,
    for empty parts, empty masks, unmasked parts and parts whose lists mix int16 and int32."""
    from radiosity.methods.hierarchical._hierarchy import Links, Undecided

    rng = np.random.default_rng(seed)
    parts = []
    for n, most, masked, wide in shapes:
        count = rng.integers(0, most + 1, n)
        top = 40_000 if wide else 300
        fields = [rng.integers(0, 99, n), rng.integers(0, 99, n)] + [rng.random(n) for _ in range(4)]
        fields += [rng.random(n) < 0.5, rng.random(n) < 0.5, rng.integers(-127, 128, (n, 9)).astype(np.int8),
                   rng.random(n).astype(np.float32)]
        links = Links(*fields, occluders=Undecided(count, rng.integers(0, top, int(count.sum())), rng.random(n) < 0.3))
        parts.append((links, rng.random(n) < 0.6 if masked else None))
    got = Links.gather(parts)
    names = [f for f in Links.__dataclass_fields__ if f != "occluders"]

    def by_mask(links, m):  # the reference: boolean masks and np.concatenate
        return links if m is None else Links(*(getattr(links, f)[m] for f in names),
                                             occluders=links.occluders.take(m))

    kept = [by_mask(p, m) for p, m in parts]
    want = Links(*(np.concatenate([getattr(k, f) for k in kept]) for f in names),
                 occluders=Undecided(np.concatenate([k.occluders.count for k in kept]),
                                     np.concatenate([k.occluders.occ for k in kept]),
                                     np.concatenate([k.occluders.cut for k in kept])))
    for f in names:
        np.testing.assert_array_equal(getattr(got, f), getattr(want, f), err_msg=f)
        assert getattr(got, f).dtype == getattr(want, f).dtype, f
    np.testing.assert_array_equal(got.occluders.count, want.occluders.count)
    np.testing.assert_array_equal(got.occluders.occ, want.occluders.occ)
    np.testing.assert_array_equal(got.occluders.cut, want.occluders.cut)
    assert got.occluders.occ.dtype == want.occluders.occ.dtype


def test_rays_alone_give_the_classified_pairs_their_visibility_and_doubt():
    """``ElementVisibility.by_rays`` (the cluster links' representative pairs: Embree rays,
    no BVH walk) gives every pair the fraction its first samples**4 rays give against the
    classification's own occluder lists, 1 and certain for pairs nothing can block, 0 and
    partly visible for pairs an occluder hides whole, and "partly visible" to every undecided
    pair whose rays disagree."""
    from radiosity.methods.hierarchical._elements import Elements
    from radiosity.methods.hierarchical._links import ElementVisibility
    from radiosity.visibility._occluders import FREE, FULL, MAYBE
    from radiosity.visibility._pairs import _rows_of

    quads, groups = boxes_scene()
    vis = make_vis(quads, groups, samples=2, max_samples=3)
    el = Elements(quads, vis.normals, min_size=0.01)
    i, j = all_pairs(len(quads))
    ev = ElementVisibility(vis)
    visible, partial = ev.by_rays(el, i, j)
    view = ev._over(el)
    status, rows, occ = view.classify(i, j)
    seen = ~np.isnan(view._patch_rays(i, j, 2, i.astype(np.uint64) * np.uint64(len(el)) + j.astype(np.uint64), 1)[0])
    free, full, maybe = (status == k for k in (FREE, FULL, MAYBE))
    assert free.sum() > 50 and full.sum() > 5 and maybe.sum() > 50
    np.testing.assert_array_equal(visible[free & seen], 1.0)
    assert not partial[free & seen].any()
    np.testing.assert_array_equal(visible[full & seen], 0.0)
    assert partial[full & seen].all()
    part = np.flatnonzero(maybe & seen)
    sub_rows, sub_occ = _rows_of(rows, occ, part, len(i))
    segments = view.ray_fraction(i[part], j[part], 2, 2, rows=sub_rows, occ=sub_occ)
    np.testing.assert_allclose(visible[part], segments, atol=1e-12)
    mixed = (segments > 0) & (segments < 1)
    assert mixed.sum() > 20 and partial[part[mixed]].all()


def test_source_shares_are_each_childs_part_of_the_factor_from_the_receivers_centroid():
    """A link whose source has children gathers from each by Lambert's factor from the
    receiver's centroid to it over their sum; G holds the link's value and those four shares,
    and its row sums (what the receiver gathers from a uniform source) do not change."""
    from radiosity.methods.hierarchical._links import source_shares

    scene = radiosity.load_scene(radiosity.bundled_scene("cornell_box"))
    hier = build_hierarchy(scene, Options.from_preset("draft", min_element_rel=1 / 10))
    hier.refine()
    hier.solve(1e-10)
    hier.refine()
    _, K, _, _ = hier.solve(1e-10)
    links, el = hier.links, hier.el
    split = np.flatnonzero(el.first_child[links.s] >= 0)
    assert len(split) > 100
    pick = split[:: len(split) // 40]
    shares = source_shares(el, links.r[pick], links.s[pick])
    built = K.gather.parts[0]  # the shares G was built with, one row per link of ``split``
    np.testing.assert_allclose(built.shares[np.searchsorted(split, pick)], shares, rtol=1e-6)
    np.testing.assert_allclose(shares.sum(axis=1), 1.0, rtol=1e-12)
    for k, (r, s) in enumerate(zip(links.r[pick], links.s[pick])):
        quads = el.quads[el.first_child[s] + np.arange(4)]
        factor = radiosity.point_to_polygons(el.centroid[r][None], el.normal[r][None], quads)[0]
        np.testing.assert_allclose(shares[k], factor / factor.sum(), rtol=1e-9, atol=1e-12)
    rows = np.bincount(links.r, weights=links.factor * links.visible, minlength=len(el))
    np.testing.assert_allclose((K.gather @ np.ones(len(el)))[:len(el)], rows, rtol=1e-6, atol=1e-15)


def test_energy_balance_and_summary(cornell):
    solution = cornell[1]
    e = {k: np.array(v) for k, v in solution.energy.items()}
    np.testing.assert_allclose(e["absorbed"] + e["escaped"], e["emitted"], rtol=1e-8)
    summary = solution.summary()
    assert summary["method"] == "hierarchical"
    assert summary["hierarchy"]["links"] == solution.F.nnz > 0
    assert summary["hierarchy"]["leaves"] == solution.scene.n_patches
    assert summary["hierarchy"]["converged"]
    json.dumps(summary)


def test_leaves_are_patches_of_their_objects(cornell):
    """The leaf mesh tiles the input: per object the same area, each leaf inside its face's object."""
    scene, solution = cornell
    for index in range(len(scene.objects)):
        a = scene.patch_area[scene.patch_object == index].sum()
        b = solution.scene.patch_area[solution.scene.patch_object == index].sum()
        assert b == pytest.approx(a, rel=1e-9)


def test_cli_method_hierarchical(tmp_path):
    from radiosity.cli import main

    out = tmp_path / "out"
    code = main(["solve", str(radiosity.bundled_scene("unit_cube")), "--method", "hierarchical", "--preset", "draft",
                 "--no-picture", "--no-cache", "--link-tolerance", "0.05", "--leaf-tolerance", "0", "-o", str(out)])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["method"] == "hierarchical"
    assert summary["solver_options"]["method"] == "hierarchical"
    assert summary["solver_options"]["link_tolerance"] == 0.05
    assert summary["solver_options"]["leaf_tolerance"] == 0.0
    assert summary["hierarchy"]["leaves"] == summary["patches"]
    assert main(["solve", str(radiosity.bundled_scene("unit_cube")), "--method", "hierarchical",
                 "--link-tolerance", "0", "-o", str(out)]) == 2
    assert main(["solve", str(radiosity.bundled_scene("unit_cube")), "--method", "hierarchical",
                 "--leaf-tolerance", "-1", "-o", str(out)]) == 2


def test_links_grow_slower_than_the_leaves(furnace):
    """Halving the minimum size: 4x the leaves where needed, links ~linear in them (never n^2)."""
    coarse = solve_h(furnace, link_tolerance=3e-2, min_element_rel=1 / 10).fill
    fine = solve_h(furnace, link_tolerance=3e-2, min_element_rel=1 / 20).fill
    leaves, links = fine.leaves / coarse.leaves, fine.links / coarse.links
    print("leaves x", leaves, "links x", links)
    assert leaves > 2.0
    assert links < 1.5 * leaves  # a full matrix would grow as leaves**2


def test_refinement_is_deterministic(furnace):
    a = solve_h(furnace, link_tolerance=5e-2, min_element_rel=1 / 10)
    b = solve_h(furnace, link_tolerance=5e-2, min_element_rel=1 / 10)
    np.testing.assert_array_equal(a.scene.patch_quads, b.scene.patch_quads)
    np.testing.assert_array_equal(a.radiosity, b.radiosity)


# ---------------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("bad", [{"link_tolerance": 0.0}, {"link_tolerance": -1e-3},
                                 {"link_tolerance": float("nan")}, {"leaf_tolerance": -1e-2},
                                 {"leaf_tolerance": float("inf")}, {"min_element_size": 10.0},
                                 {"min_element_size": 0.0}])
def test_bad_knobs_are_refused(bad):
    scene = radiosity.load_scene(radiosity.bundled_scene("unit_cube"))
    name = next(iter(bad))
    with pytest.raises(ValueError, match=name):
        solve_h(scene, **bad)


def test_progress_bar_runs(capsys):
    scene = radiosity.load_scene(radiosity.bundled_scene("unit_cube"))
    solution = solve_h(scene, link_tolerance=5e-2, progress=True)
    assert solution.fill.links_evaluated > 0
    assert "hierarchy" in capsys.readouterr().err


def test_unknown_method_is_refused():
    scene = radiosity.load_scene(radiosity.bundled_scene("unit_cube"))
    with pytest.raises(TypeError, match="unknown method 'radial'"):
        radiosity.solve(scene, method="radial", cache=False)


# ---------------------------------------------------------------------------------- clustering
@pytest.fixture
def clustered(monkeypatch):
    """Cluster even small scenes (the solve clusters from CLUSTER_MIN_ROOTS input patches on)."""
    import radiosity.methods.hierarchical._hierarchy as hierarchy

    monkeypatch.setattr(hierarchy, "CLUSTER_MIN_ROOTS", 1)


def test_cluster_tree_bounds_its_patches():
    """Every node's sphere holds its patches' vertices; areas add up; children split the parent."""
    from helpers import cube_room_scene
    from radiosity.methods.hierarchical._clusters import ClusterTree

    scene = cube_room_scene(20)
    tree = ClusterTree(np.arange(scene.n_patches), scene.patch_quads, scene.patch_normal, scene.patch_area,
                       scene.reflectance)
    assert len(tree.internal) == scene.n_patches - 1 and sorted(tree.order) == list(range(scene.n_patches))
    for k in range(len(tree)):
        members = tree.order[tree.lo[k]:tree.hi[k]]
        far = np.linalg.norm(scene.patch_quads[members] - tree.centre[k], axis=2).max()
        assert far <= tree.radius[k] * (1 + 1e-12)
        assert np.isclose(tree.area[k], scene.patch_area[members].sum())
        cos = scene.patch_normal[members] @ tree.axis[k]
        assert np.all(np.arccos(np.clip(cos, -1, 1)) <= tree.cone[k] + 1e-9)


def test_clustered_furnace_sphere_links_grow_linearly(clustered):
    """A closed sphere of n triangles, all emitting 1 and reflecting 0.5: B = 2 on every leaf
    within the link tolerance (measured: 0.9% at 3e-2), from O(n) links: 4x the faces, fewer
    links per face (measured 3.6x the links, where all pairs would grow 16x)."""
    from helpers import sphere_scene

    tol = 3e-2
    runs = [solve_h(sphere_scene(m), link_tolerance=tol) for m in (4, 8)]
    for solution in runs:
        B = solution.radiosity
        h = solution.summary()["hierarchy"]
        assert h["cluster_links"] > 0 and h["converged"]
        n = solution.scene.n_patches
        assert h["initial_links"] < 0.5 * n * n  # not every facing pair
        assert np.abs(B / 2.0 - 1.0).max() < tol
    small, large = (s.summary()["hierarchy"]["links"] / s.scene.n_patches for s in runs)
    assert large < small


# ---------------------------------------------------------------------------------- method="auto"
def test_auto_takes_the_hierarchy_past_the_pair_budget(furnace, monkeypatch):
    """auto: uniform under AUTO_MAX_PAIRS (the default, and the summary says uniform), the
    hierarchy above it (with a note why); --method uniform overrides the choice."""
    import importlib

    solve_module = importlib.import_module("radiosity.solve")  # radiosity.solve is the function
    assert Options().method == "auto"
    knobs = dict(preset="draft", cache=False, link_tolerance=5e-2, min_element_rel=1 / 10)
    small = radiosity.solve(furnace, **knobs)
    assert small.summary()["method"] == "uniform"
    monkeypatch.setattr(solve_module, "AUTO_MAX_PAIRS", 10)
    chosen = radiosity.solve(furnace, **knobs)
    summary = chosen.summary()
    assert summary["method"] == "hierarchical" and summary["hierarchy"]["links"] > 0
    assert any(n.startswith("method auto: hierarchical") for n in summary["notes"])
    forced = radiosity.solve(furnace, method="uniform", **knobs)
    assert forced.summary()["method"] == "uniform"
    np.testing.assert_allclose(chosen.object_radiosity()["room"], forced.object_radiosity()["room"], rtol=0.05)


def test_auto_takes_the_hierarchy_when_a_sample_says_the_fill_is_slow(monkeypatch):
    """auto samples the fill's pairs once a scene has AUTO_SAMPLE_MIN active patches: the
    hierarchy, with the estimate in its note, when the sampled fill is over AUTO_MAX_FILL_SECONDS."""
    import importlib

    solve_module = importlib.import_module("radiosity.solve")
    scene = cube_room_scene(8)
    knobs = dict(preset="draft", cache=False, link_tolerance=5e-2, min_element_rel=1 / 5)
    monkeypatch.setattr(solve_module, "AUTO_SAMPLE_MIN", 10)
    assert radiosity.solve(scene, **knobs).summary()["method"] == "uniform"  # about a second
    monkeypatch.setattr(solve_module, "AUTO_MAX_FILL_SECONDS", 1e-3)
    summary = radiosity.solve(scene, **knobs).summary()
    assert summary["method"] == "hierarchical"
    note = next(n for n in summary["notes"] if n.startswith("method auto: hierarchical"))
    assert "would take about" in note and "sampled pairs" in note and "partly occluded" in note


def test_auto_times_the_fill_before_it_believes_a_slow_estimate(monkeypatch):
    """A fill the pair model calls slow is timed on a random sample of its rows first
    (``estimate.time_fill``): the small room's fill, whatever the model says, takes seconds,
    so auto stays uniform. The rows' projection is unbiased: row r holds the pairs (r, j > r),
    so the rows timed stand for all of them."""
    import importlib

    from radiosity.methods.uniform import estimate

    solve_module = importlib.import_module("radiosity.solve")
    scene = cube_room_scene(8)
    knobs = dict(preset="draft", cache=False, link_tolerance=5e-2, min_element_rel=1 / 5)
    monkeypatch.setattr(solve_module, "AUTO_SAMPLE_MIN", 10)
    monkeypatch.setattr(estimate, "SECONDS_PER_PAIR", {"rays": 1.0, "exact": 1.0})  # the model: days
    assert radiosity.solve(scene, **knobs).summary()["method"] == "uniform"
    cut = radiosity.solve(scene, method="uniform", **knobs).scene
    vis = make_vis(cut.patch_quads, cut.patch_object)
    settings = solve_module._fill_settings(Options.from_preset("draft"))
    active = ~cut.patch_inactive
    timing = estimate.time_fill(cut.patch_quads, cut.patch_normal, cut.patch_centroid, cut.patch_area, vis, settings,
                                active, share=1.0, budget=np.inf)
    assert timing.rows == active.sum() - 1 and timing.share == pytest.approx(1 - 1 / active.sum())
    assert 0 < timing.seconds < 600 and "random rows" in timing.describe()


def test_fill_estimate_counts_the_facing_pairs_of_open_plates():
    """Two facing plates cut n x n, nothing between: half the ordered pairs face (plate to
    plate), none is partly occluded; the sample is seeded, so the estimate repeats."""
    from radiosity.methods.uniform.assembly import FillSettings
    from radiosity.methods.uniform.estimate import estimate_fill

    n = 6
    cells = [(x, x + 1 / n, y, y + 1 / n) for x in np.arange(n) / n for y in np.arange(n) / n]
    quads = np.array([rect(*c, 0.0) for c in cells] + [rect(*c, 1.0, down=True) for c in cells])
    vis = make_vis(quads)
    centroid = quads.mean(axis=1)
    first = estimate_fill(quads, vis.normals, centroid, vis, FillSettings(), np.ones(len(quads), bool))
    assert first.partial_pairs == 0 and first.occluders_squared == 0
    assert first.facing_pairs == pytest.approx(n ** 4, rel=0.03)
    assert first == estimate_fill(quads, vis.normals, centroid, vis, FillSettings(), np.ones(len(quads), bool))
    assert first.seconds > 0 and "0% of" in first.describe()


def test_a_cabinet_1_cm_from_a_wall_lights_the_wall_behind_it(tmp_path):
    """A furnace room with a cabinet (triangle faces, as exporters write boxes) 1 cm from a
    wall: the wall behind it sees the cabinet's back and nothing else, so it must gather as
    much as anywhere (B = 2). The 3x3 points of a big triangle of the cabinet's back missed the
    wall element over its apex (0.0005 for 0.028) and the link met eps: -44% behind the
    cabinet, -50% on a shelf's back in the generated furnished room. Sources closer than
    NEAR_GAP receiver radii now take the near bound: -1.6% (for the room's other leaves see the
    test below)."""
    tris = [t for q in axis_box([0.5, 0.0, 3.65], [2.0, 1.8, 3.99], inward=False) for t in (q[[0, 1, 2]], q[[0, 2, 3]])]
    path = write_obj(tmp_path / "gap.obj", {"room": axis_box([0, 0, 0], [6, 3, 4], inward=True), "cabinet": tris})
    with pytest.warns(radiosity.RadiosityWarning):
        scene = radiosity.load_scene(path).with_materials(reflectance=0.5, emission=1.0)
    s = radiosity.solve(scene, method="hierarchical", preset="draft", cache=False)
    centre = s.scene.patch_quads.mean(axis=1)
    room = np.asarray(s.scene.objects)[s.scene.patch_object] == "room"
    behind = room & (centre[:, 2] > 3.995) & (centre[:, 0] > 0.5) & (centre[:, 0] < 2.0) & (centre[:, 1] < 1.8)
    assert behind.sum() > 50
    assert (s.radiosity[behind] / 2 - 1).min() > -0.05


def test_furnace_box_near_a_wall_at_the_draft_element_size(tmp_path):
    """A furnace room with a cabinet 10 cm from a wall, at draft (elements down to 1/50 of the
    diagonal): B = E / (1 - rho) within 2% on every leaf at draft's own leaf_tolerance, within
    1.5% at 1e-2. Measured 2026-12-06: -2.7% / +2.7%, and -0.95% / +0.72% at 1e-2; since the
    quadratic push (session 40) -0.91% / +1.47% and -0.79% / +1.40%: the worst leaf at 1e-2, a
    1.6 cm floor strip in the gap by the cabinet's end, gets +4.6% from its links' means (its
    2 x 0.125 m ancestor's links, which the old leaf test split at 1e-2 and the new one leaves
    to the quadratic) and -1.8% from the quadratic. Before the links' visibility was measured at
    each receiver point (RECEIVER_VISIBILITY), -20% / +11% and -7.6% / +5.9%: the wall
    elements behind the cabinet got the far room's light through the mean visibility of
    elements that straddle the cabinet's shadow."""
    path = write_obj(tmp_path / "gap.obj", {"room": axis_box([0, 0, 0], [6, 3, 4], inward=True),
                                            "cabinet": axis_box([0.5, 0.0, 3.65], [2.0, 1.8, 3.9], inward=False)})
    with pytest.warns(radiosity.RadiosityWarning):
        scene = radiosity.load_scene(path).with_materials(reflectance=0.5, emission=1.0)
    for leaf_tolerance, bound in ((Options.from_preset("draft").leaf_tolerance, 0.02), (1e-2, 0.015)):
        s = radiosity.solve(scene, method="hierarchical", preset="draft", min_element_rel=1 / 50, cache=False,
                            leaf_tolerance=leaf_tolerance)
        error = s.radiosity[~s.scene.patch_hidden] / 2 - 1
        assert np.abs(error).max() < bound, leaf_tolerance


@pytest.mark.slow
def test_furnace_room_of_100_cubes_at_the_draft_element_size():
    """The 100-cube furnace room at draft itself (elements down to 1/50, cube faces split once):
    worst leaf within 1.6%, mean within 0.1% (measured 2026-12-06: -1.23% / +1.06%, mean
    -0.06%). Before, -2.80% / +2.13% and mean -0.14%: a cube face's leaves got its links' mean
    visibility (RECEIVER_VISIBILITY), and undecided pairs whose 16 rays all agreed undercounted
    the gaps between cubes (RETRACE_UNANIMOUS)."""
    solution = solve_h(cube_room_scene(100), link_tolerance=1e-2)
    error = solution.radiosity / 2.0 - 1.0
    assert np.abs(error).max() < 0.016
    assert abs(error.mean()) < 1e-3


@pytest.mark.parametrize("measured", [True, False])
def test_a_partly_visible_link_measures_its_visibility_at_each_receiver_point(monkeypatch, measured):
    """A floor under a light, its left 40% shadowed by a plate 5 cm above it. The floor's link
    to the light is partly visible (V about 0.6 over the floor), but its Gauss points under the
    plate see none of the light. What the receiver's variation test sums at each point is F V
    there less its mean: negative under the plate, positive beside it. Taking the link's mean V
    instead, the leaves under the plate would get the light the plate hides."""
    from radiosity.formfactors import patch_points
    from radiosity.methods.hierarchical import _hierarchy

    monkeypatch.setattr(_hierarchy, "RECEIVER_VISIBILITY", measured)
    # this root link is over eps and would split: measured all the same (SKIP_DOOMED off)
    monkeypatch.setattr(_hierarchy, "SKIP_DOOMED", False)
    quads = np.array([rect(0, 1, 0, 1, 0), rect(0, 1, 0, 1, 1, down=True), rect(-0.2, 0.4, -0.2, 1.2, 0.05, down=True)])
    n = len(quads)
    scene = radiosity.Scene(objects=["floor", "light", "plate"], patch_quads=quads, patch_object=np.arange(n),
                            patch_face=np.arange(n), reflectance=np.full((n, 3), 0.5),
                            emission=np.array([[0.0] * 3, [1.0] * 3, [0.0] * 3]))
    hier = build_hierarchy(scene, Options.from_preset("draft"))
    links = hier._evaluate(np.array([0]), np.array([1]))
    assert links.partial[0] and 0.4 < links.visible[0] < 0.8
    deviation = links.shape[0] * links.shape_scale[0] / 127
    x = patch_points(quads[:1], 3)[0][0, :, 0]
    shadowed, lit = x < 0.3, x > 0.5
    if measured:
        assert np.all(deviation[shadowed] < -0.5 * links.factor[0] * links.visible[0])
        assert np.all(deviation[lit] > 0)
    else:  # the factor's deviation alone is symmetric about the floor's middle
        np.testing.assert_allclose(np.sort(deviation[shadowed]), np.sort(deviation[lit]), atol=1e-3 * links.factor[0])


def test_leaf_tolerance_bounds_what_the_levels_push_onto_the_leaves(tmp_path, monkeypatch):
    """The room of the test above at draft: each link meets eps, but a wall element's links to
    the far room all lean the same way across it. Pushing each receiver's mean alone, with no
    leaf tolerance, the mean |error| of the leaves is about 3.9% (worst 28%); splitting the
    elements whose links, summed at their points, stray past leaf_tolerance took it to 0.47%
    (2026-12-05). The quadratic push carries most of that variation to the leaves by itself
    (0.19%, worst 4.2%), and the leaf tolerance, now applied to what the quadratic leaves out,
    takes the rest (measured 0.08%, worst 1.5%, in three quarters of the links the old test
    made)."""
    from radiosity.methods.hierarchical import _hierarchy

    path = write_obj(tmp_path / "gap.obj", {"room": axis_box([0, 0, 0], [6, 3, 4], inward=True),
                                            "cabinet": axis_box([0.5, 0.0, 3.65], [2.0, 1.8, 3.9], inward=False)})
    with pytest.warns(radiosity.RadiosityWarning):
        scene = radiosity.load_scene(path).with_materials(reflectance=0.5, emission=1.0)

    def errors(**kw):
        s = radiosity.solve(scene, method="hierarchical", preset="draft", cache=False, **kw)
        return np.abs(s.radiosity[~s.scene.patch_hidden] / 2 - 1)

    on = errors()
    assert on.mean() < 3e-3 and on.max() < 3e-2
    assert errors(leaf_tolerance=0.0).mean() < 5e-3
    monkeypatch.setattr(_hierarchy, "QUADRATIC_PUSH", False)
    assert errors(leaf_tolerance=0.0).mean() > 3e-2


def test_a_small_source_touching_a_long_receiver_bounds_its_spread():
    """A 6 m x 1 cm floor strip at the foot of a wall (imprinting leaves such strips between a
    shelf and the wall): its 3x3 points are metres from a 0.2 m wall element at one end, yet the
    strip's end sees half of it. The strips of the generated furnished room got 0.006 of the
    wall for 0.5 (-30%). Touching small sources now bound the spread by 1, so r splits."""
    from radiosity.methods.hierarchical._hierarchy import TOUCHING_BOUND, _near_bound
    from radiosity.methods.hierarchical._links import link_factors

    strip = [[0, 0, 4.0], [0, 0, 3.99], [6, 0, 3.99], [6, 0, 4.0]]
    wall = [[5.8, 0, 4.0], [5.8, 0.2, 4.0], [6.0, 0.2, 4.0], [6.0, 0, 4.0]]
    apart = [[5.8, 0.5, 4.0], [5.8, 0.7, 4.0], [6.0, 0.7, 4.0], [6.0, 0.5, 4.0]]
    el = Elements(np.array([strip, wall, apart], float), np.array([[0, 1.0, 0], [0, 0, -1.0], [0, 0, -1.0]]), 0.05)
    r, s = np.array([0, 0]), np.array([1, 2])
    factor, spread = link_factors(el, r, s)
    assert spread[0] < 0.05  # the points do not see what the strip's end sees
    bound = _near_bound(el, r, s, near_only=True)
    assert bound[0] == TOUCHING_BOUND == 1.0
    assert bound[1] < 1.0  # not touching: the sphere bound as before


def test_a_grey_channel_is_solved_once(furnace):
    """Channels with the same reflectance and emission are one system: solved once, copied
    (0 iterations), the same radiosities as when solved on their own."""
    hier = build_hierarchy(furnace, Options.from_preset("draft", link_tolerance=1e-2, min_element_rel=1 / 10))
    hier.refine()
    start = hier.B.copy()
    B, K, leaves, report = hier.solve(1e-10)
    assert report.iterations[0] > 0 and report.iterations[1:] == [0, 0]
    np.testing.assert_array_equal(B[:, 1], B[:, 0])
    root = hier.el.root[leaves]
    alone, *_ = _solve_channel(K, hier.rho[root][:, 2], hier.emission[root][:, 2], start[leaves][:, 2], 1e-10)
    np.testing.assert_array_equal(B[:, 2], alone)


def test_push_pull_conserves_power_through_clusters(furnace):
    """With clusters, power gathered by elements and clusters (A H) equals the power pushed onto
    the leaves; a cluster pulls the area mean of its leaves."""
    hier = build_hierarchy(furnace, Options.from_preset("draft", link_tolerance=1e-2, min_element_rel=1 / 10),
                           clusters=True)
    hier.refine()
    B, K, leaves, _ = hier.solve(1e-10)
    assert len(hier.cluster_r) > 0
    area = np.concatenate([hier.el.area, hier.tree.area[hier.tree.internal]])
    gathered = area[:, None] * (K.gather @ (K.pull @ B))[:len(area)]
    pushed = hier.el.area[leaves, None] * (K.push @ (K.gather @ (K.pull @ B)))
    np.testing.assert_allclose(pushed.sum(axis=0), gathered.sum(axis=0), rtol=1e-12)
    np.testing.assert_allclose(K.pull @ np.ones(len(leaves)), 1.0, rtol=1e-12)


def test_oriented_cluster_links_gather_as_their_matrix_entries_would():
    """G keeps its oriented cluster links link by link (a value per patch of the receiver, no
    indices), and its element links to sources with children as a value and four shares each;
    G @ x and G.T @ y equal those of the sparse matrix with one entry per link and patch (and
    child): the form they replaced, whose build was the 1M-face sphere's peak."""
    import scipy.sparse as sp

    from radiosity.methods.hierarchical._hierarchy import ORIENT_CONE

    scene = cube_room_scene(30)
    hier = build_hierarchy(scene, Options.from_preset("draft", link_tolerance=1e-2, min_element_rel=1 / 10),
                           clusters=True)
    hier.refine()
    _, K, _, _ = hier.solve(1e-10)
    tree, G = hier.tree, K.gather
    oriented = (tree.patch[hier.cluster_r] < 0) & (tree.cone[hier.cluster_r] > ORIENT_CONE)
    assert oriented.sum() > 20
    r, s = hier.cluster_r[oriented], hier.cluster_s[oriented]
    link, patch, share = tree.oriented_shares(r, s)
    column = np.where(tree.patch >= 0, tree.patch, len(hier.el) + tree.column)
    entries = sp.csr_matrix((hier.cluster_factor[oriented][link] * share, (patch, column[s][link])), shape=G.shape)
    children = G.parts[0]  # links gathering from their source's children, four entries each
    assert len(children.r) > 20
    child_entries = sp.csr_matrix(((children.value[:, None] * children.shares).ravel(),
                                   (np.repeat(children.r, 4), (children.first[:, None] + np.arange(4)).ravel())),
                                  shape=G.shape)
    # the links' point deviations: 9 rows per receiver after the matrix's, one entry per link and point
    v = G.variation
    receiver = np.repeat(np.arange(len(v.indptr) - 1), np.diff(v.indptr))
    deviations = sp.csr_matrix(((v.codes * v.scale[:, None].astype(float)).ravel(),
                                ((9 * receiver[:, None] + np.arange(9)).ravel(), np.repeat(v.column, 9))),
                               shape=(v.n_out, G.shape[1]))
    matrix = sp.vstack([G.matrix, sp.csr_matrix((v.n_out, G.shape[1]))])
    full = matrix + entries + child_entries + sp.vstack([sp.csr_matrix(G.matrix.shape), deviations])
    rng = np.random.default_rng(2)
    x, y = rng.random(G.shape[1]), rng.random(G.shape[0])
    np.testing.assert_allclose(G @ x, full @ x, rtol=1e-12)
    np.testing.assert_allclose(G.T @ y, full.T @ y, rtol=1e-12)
    np.testing.assert_allclose(G @ np.c_[x, 2 * x], full @ np.c_[x, 2 * x], rtol=1e-12)


def test_cluster_visibility_is_the_same_in_chunks_of_links(monkeypatch):
    """Cluster links' visibility goes through the links in chunks (all at once, the 1,000-cube
    room's closed-room cull peaked at 4.8 GB): the same fractions in chunks of 7 as in one."""
    from radiosity.methods.hierarchical import _hierarchy

    hier = build_hierarchy(cube_room_scene(30), Options.from_preset("draft", link_tolerance=1e-2,
                                                                    min_element_rel=1 / 10), clusters=True)
    hier.refine()
    r, s = hier.cluster_r, hier.cluster_s
    whole = hier._cluster_visibility(r, s)
    monkeypatch.setattr(_hierarchy, "CHUNK_LINKS", 7)
    chunked = hier._cluster_visibility(r, s)
    np.testing.assert_array_equal(chunked[0], whole[0])
    np.testing.assert_array_equal(chunked[1], whole[1])
    assert len(r) > 100 and whole[1].any() and (whole[0] < 1).any()


def test_the_solves_that_steer_refinement_see_no_more_than_a_hemisphere(clustered):
    """After the first pass (only emitters' links refined, here one cube's) the other cluster
    links are coarse: leaf rows of K summed to up to 14 in a furnished room, and the solve that
    steered the next pass doubled its light. Those solves scale rows past 1 down to 1 (so
    B <= max E / (1 - rho) = 2); the answer's operator is not scaled."""
    from helpers import cube_room_scene

    scene = cube_room_scene(30, emission=0.0).object_material("cube0", emission=1.0)
    hier = build_hierarchy(scene, Options.from_preset("draft", link_tolerance=1e-2, min_element_rel=1 / 10),
                           clusters=True)
    hier.refine()
    B, K, leaves, _ = hier.solve(1e-10, clamp=True)
    unscaled = K.push @ (K.gather @ (K.pull @ np.ones(len(leaves))))
    assert unscaled.max() > 1.05  # the coarse links do sum past 1 here
    assert hier.stats.rows_over_one == int((unscaled > 1).sum())
    np.testing.assert_array_less(K @ np.ones(len(leaves)), 1.0 + 1e-12)
    assert B.max() <= 2.0 + 1e-8
    assert solve_h(scene, link_tolerance=1e-2, min_element_rel=1 / 10).F.row_scale is None


def test_the_memory_estimate_counts_cluster_links_and_refuses_what_will_not_fit(furnace, monkeypatch):
    """Every estimate before a refinement step counts the cluster links too (on the 100k-face
    sphere they were 4.9 M of 5.0 M links, and the estimate a ninth of the peak without them),
    and a budget below it is refused with the estimate, naming the links."""
    from radiosity import _memory
    from radiosity.methods.hierarchical._hierarchy import CLUSTER_LINK_PEAK_BYTES

    hier = build_hierarchy(furnace, Options.from_preset("draft", link_tolerance=1e-2, min_element_rel=1 / 10),
                           clusters=True)
    seen = []
    check = _memory.check
    monkeypatch.setattr(_memory, "check", lambda what, estimate, knob, **kw: (
        seen.append((len(hier.cluster_r), estimate)), check(what, estimate, knob, **kw))[1])
    hier.refine()
    assert seen and all(estimate >= n_cluster * CLUSTER_LINK_PEAK_BYTES for n_cluster, estimate in seen)
    assert max(n for n, _ in seen) > 0
    monkeypatch.setattr(_memory, "check", check)
    monkeypatch.setenv(_memory.ENV_BUDGET, "200K")
    with pytest.raises(radiosity.MemoryBudgetError, match="links"):
        solve_h(furnace, link_tolerance=1e-2, min_element_rel=1 / 10)


def _tree_of(scene_of: str):
    from helpers import sphere_scene
    from radiosity.methods.hierarchical._clusters import ClusterTree

    scene = cube_room_scene(20) if scene_of == "cubes" else sphere_scene(8)
    return scene, ClusterTree(np.arange(scene.n_patches), scene.patch_quads, scene.patch_normal, scene.patch_area,
                              scene.reflectance)


def _projected_sum(scene, tree, k, u):
    """sum over node k's patches of A_i max(0, n_i . u), patch by patch."""
    members = tree.order[tree.lo[k]:tree.hi[k]]
    return float(scene.patch_area[members] @ np.maximum(scene.patch_normal[members] @ u, 0.0))


@pytest.mark.parametrize("scene_of", ["cubes", "sphere"])
def test_projected_area_of_a_node_is_the_sum_over_its_patches(scene_of):
    """P(u) = sum A_i max(0, n_i . u): from the area vector where the node's normal cone is on
    one side of u's plane, patch by patch where it straddles; both agree with the plain sum."""
    from radiosity.methods.hierarchical._clusters_kernel import _projected

    scene, tree = _tree_of(scene_of)
    rng = np.random.default_rng(5)
    nodes = rng.integers(0, len(tree), 1000)
    u = rng.normal(size=(1000, 3))
    u[:300] = tree.axis[nodes[:300]] + 0.3 * u[:300]  # many cones wholly in front of u
    u /= np.linalg.norm(u, axis=1)[:, None]
    u[-1] = 0.0
    _, _, lo, hi, order, normals, areas, _, axis, cone = tree._kernel_tree()
    got = [_projected(k, *v, lo, hi, order, normals, areas, axis, cone, tree.area_vector) for k, v in zip(nodes, u)]
    np.testing.assert_allclose(got, [_projected_sum(scene, tree, k, v) for k, v in zip(nodes, u)],
                               rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("scene_of", ["cubes", "sphere"])
def test_cluster_estimates_sum_over_the_node_pairs_two_levels_down(scene_of):
    """F_rs = sum_ab A_a F_ab / A_r over the nodes a, b ESTIMATE_DEPTH levels below r and s
    (a patch node its own child), F_ab = P_a(u) P_b(-u) / (pi d^2 A_a) from centre to centre."""
    from radiosity.methods.hierarchical._clusters import ESTIMATE_DEPTH

    scene, tree = _tree_of(scene_of)
    rng = np.random.default_rng(3)
    r, s = rng.choice(tree.internal, 200), rng.integers(0, len(tree), 200)
    expected = []
    for k, source in zip(r, s):
        ends = [[k], [source]]
        for _ in range(ESTIMATE_DEPTH):
            ends = [[c for x in end for c in (tree.child[x] if tree.patch[x] < 0 else [x])] for end in ends]
        total = 0.0
        for a in ends[0]:
            for b in ends[1]:
                u = tree.centre[b] - tree.centre[a]
                d2 = u @ u
                if d2 > 0:
                    u = u / np.sqrt(d2)
                    power = _projected_sum(scene, tree, a, u) * _projected_sum(scene, tree, b, -u) / (np.pi * d2)
                    total += tree.area[a] * min(power / tree.area[a], 1.0)
        expected.append(min(total / tree.area[k], 1.0))
    got = tree.estimates(r, s)
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-300)
    assert (got > 0).sum() > 50


def _reference_bound(tree, r, s, B):
    """ClusterTree.bound written out in numpy (the form the numba kernel replaced)."""
    angle = lambda a, b: np.arccos(np.clip(np.einsum("mc,mc->m", a, b), -1, 1))  # noqa: E731
    w = tree.centre[s] - tree.centre[r]
    dist = np.linalg.norm(w, axis=1)
    gap = dist - tree.radius[r] - tree.radius[s]
    w = w / np.where(dist > 0, dist, 1.0)[:, None]
    spread = np.arcsin(np.clip((tree.radius[r] + tree.radius[s]) / np.where(gap > 0, dist, 1.0), 0, 1))
    cos_r = np.cos(np.clip(angle(tree.axis[r], w) - tree.cone[r] - spread, 0, np.pi / 2))
    cos_s = np.cos(np.clip(angle(tree.axis[s], -w) - tree.cone[s] - spread, 0, np.pi / 2))
    safe_gap = np.where(gap > 0, gap, 1.0)
    factor = np.where(gap > 0, np.minimum(1, tree.area[s] * cos_r * cos_s / (np.pi * safe_gap ** 2)), 1)
    wo = angle(tree.axis[r], tree.axis[s]) + tree.cone[r] + tree.cone[s]
    return (tree.rho[r] * B[s]).max(axis=1) * np.minimum(factor, np.where(wo < np.pi / 2, np.sin(wo) ** 2, 1.0))


@pytest.mark.parametrize("scene_of", ["cubes", "sphere"])
def test_cluster_link_kernels_agree_with_their_definitions(scene_of):
    """The numba kernels of the cluster links against their definitions written out: bounds
    (numpy), the patch facing a point most, and each receiver patch's share (Python loops)."""
    from radiosity.methods.hierarchical._clusters import ESTIMATE_DEPTH

    scene, tree = _tree_of(scene_of)
    rng = np.random.default_rng(11)
    r, s = rng.choice(tree.internal, 400), rng.integers(0, len(tree), 400)
    B = rng.random((len(tree), 3))
    np.testing.assert_allclose(tree.bound(r, s, B), _reference_bound(tree, r, s, B), rtol=1e-9, atol=1e-300)
    members = lambda k: tree.order[tree.lo[k]:tree.hi[k]]  # noqa: E731
    toward = tree.centre[s]
    picked = tree.facing_patch(r, toward)
    for k, point, pick in zip(r, toward, picked):
        score = [scene.patch_area[i] * scene.patch_normal[i] @ (point - tree.centre[k]) for i in members(k)]
        assert pick == (members(k)[::-1][np.argmax(score[::-1])] if max(score) > 0 else members(k)[len(score) // 2])
    link, patch, share = tree.oriented_shares(r[:60], s[:60])
    for j, (k, source) in enumerate(zip(r[:60], s[:60])):
        below = [source]
        for _ in range(ESTIMATE_DEPTH):
            below = [c for b in below for c in (tree.child[b] if tree.patch[b] < 0 else [b])]
        weight = []
        for i in members(k):
            total = 0.0
            for b in below:
                u = tree.centre[b] - tree.centre[k]
                power = _projected_sum(scene, tree, b, -u / max(np.linalg.norm(u), 1e-300))
                w = tree.centre[b] - tree.centroids[i]  # the quad's vertex mean
                if w @ w > 0:  # b is not patch i itself
                    total += power * max(0.0, scene.patch_normal[i] @ w) / np.linalg.norm(w) ** 3
            weight.append(total)
        weight = np.array(weight)
        mean = weight @ scene.patch_area[members(k)] / tree.area[k]
        np.testing.assert_array_equal(patch[link == j], members(k))
        np.testing.assert_allclose(share[link == j], weight / mean if mean > 0 else 1.0, rtol=1e-9)


def test_a_cluster_shares_a_link_by_how_its_patches_face_the_source():
    """A cube's faces as one cluster, lit from +x: the +x face takes the whole share (its area
    mean over the cube is 1, so the link keeps its power), the faces turned away none; the
    patch facing a point most is the one the cluster's visibility is taken from."""
    from radiosity.methods.hierarchical._clusters import ClusterTree

    quads = np.array(axis_box([0, 0, 0], [1, 1, 1], inward=False) + axis_box([5, 0, 0], [6, 1, 1], inward=False))
    normals = np.cross(quads[:, 1] - quads[:, 0], quads[:, 3] - quads[:, 0])
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    areas = np.ones(12)
    tree = ClusterTree(np.arange(12), quads, normals, areas, np.full((12, 3), 0.5))
    cube = next(k for k in tree.internal if set(tree.order[tree.lo[k]:tree.hi[k]]) == set(range(6)))
    other = next(k for k in tree.internal if set(tree.order[tree.lo[k]:tree.hi[k]]) == set(range(6, 12)))
    _, patch, share = tree.oriented_shares(np.array([cube]), np.array([other]))
    plus_x = int(np.argmax(normals[:6, 0]))
    assert np.isclose((share * areas[patch]).sum() / 6.0, 1.0)
    assert share[patch == plus_x] == pytest.approx(6.0, rel=1e-2)  # nearly all of it: the others graze
    assert (share[normals[patch, 0] < -0.5] == 0).all()
    assert tree.facing_patch(np.array([cube]), np.array([[5.5, 0.5, 0.5]]))[0] == plus_x


def test_clustered_furnace_room_of_100_cubes():
    """The clustering case through heavy occlusion: a closed room holding 100 floating cubes
    (606 faces, so the solve clusters), every face E = 1, rho = 0.5, B = 2 on every leaf.
    Measured at draft, 1e-2, min size 1/10: worst leaf -0.7% / +0.6%, mean -0.1%. Before
    2026-12-05 -3.6% / +4.9%: cluster links took the visibility of two patches turned away
    from each other and spread their estimate evenly over the cube faces they reached, and a
    wall's hundreds of links to small cubes each met eps while their sum did not."""
    from helpers import cube_room_scene

    solution = solve_h(cube_room_scene(100), link_tolerance=1e-2, min_element_rel=1 / 10)
    assert solution.summary()["hierarchy"]["cluster_links"] > 0
    error = solution.radiosity / 2.0 - 1.0
    assert np.abs(error).max() < 0.015
    assert abs(error.mean()) < 3e-3


def _furnace_sphere_room(tmp_path, subdivisions: int, radius: float):
    """A closed 2 m furnace room (every face emits 1 and reflects 0.5: B = 2) holding an
    icosphere of the given radius, 0.6 m off the floor."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    sphere.apply_translation([1.0, 1.0, 0.6])
    path = write_obj(tmp_path / "sphere_room.obj", {"room": axis_box([0, 0, 0], [2, 2, 2], inward=True),
                                                    "sphere": list(sphere.vertices[sphere.faces])})
    with pytest.warns(radiosity.RadiosityWarning, match="no face emits"):
        return radiosity.load_scene(path).with_materials(reflectance=0.5, emission=1.0)


def test_the_floor_under_a_cylinder_1_cm_above_it_sees_the_whole_base(tmp_path):
    """A 128-sided cylinder (its base a fan of thin wedges) standing 1 cm above the floor of a
    6 x 6 x 2 m furnace room, at draft: the floor leaves under the base are within 2% of
    B = 2. Their 3x3 points missed the peak of each wedge's apex (0.0034 for 0.0133) and the
    leaves cannot split to take the near bound: -6.2% before such links took the adaptive
    quadrature's factor (EXACT_NEAR_LEAVES)."""
    import trimesh

    cylinder = trimesh.creation.cylinder(radius=0.4, height=1.0, sections=128)
    cylinder.apply_translation([1.0, 1.0, 0.51])
    path = write_obj(tmp_path / "cylinder_room.obj", {"room": axis_box([0, 0, 0], [6, 6, 2], inward=True),
                                                      "cylinder": list(cylinder.vertices[cylinder.faces])})
    with pytest.warns(radiosity.RadiosityWarning, match="no face emits"):
        scene = radiosity.load_scene(path).with_materials(reflectance=0.5, emission=1.0)
    solution = solve_h(scene)
    error = solution.radiosity[:, 0] / 2.0 - 1.0
    centre = solution.scene.patch_quads.mean(axis=1)
    under = (np.hypot(centre[:, 0] - 1.0, centre[:, 1] - 1.0) < 0.4) & (centre[:, 2] < 1e-6)
    assert under.sum() >= 8
    assert np.abs(error[under]).max() < 0.02
    assert solution.summary()["hierarchy"]["exact_near_links"] > 0


@pytest.mark.slow
def test_a_tessellated_sphere_gathers_through_mixed_links(tmp_path, monkeypatch):
    """A furnace room holding an icosphere of 1,280 triangles, at draft: room elements gather
    from the sphere's clusters through element <- cluster links instead of one link per
    triangle, with B = E / (1 - rho) on every leaf still within 1.5% (measured 2026-12-07:
    370,689 links, -1.08% / +1.05%, mean -0.01%; without mixed links 814,066 links, -0.47% /
    +0.53%). Room elements had a link to each triangle: the 5,120-triangle sphere's room
    (3 x 2 x 2 m) took 6.3 M links and 43 s, 0.9 M and 26 s with them."""
    from radiosity.methods.hierarchical import _hierarchy

    scene = _furnace_sphere_room(tmp_path, 3, 0.4)
    mixed = solve_h(scene)
    error = mixed.radiosity / 2.0 - 1.0
    assert np.abs(error).max() < 0.015 and abs(error.mean()) < 1e-3
    assert mixed.summary()["hierarchy"]["mixed_links"] > 10_000
    monkeypatch.setattr(_hierarchy, "MIXED_LINKS", False)
    single = solve_h(scene)
    assert mixed.summary()["hierarchy"]["links"] < 0.6 * single.summary()["hierarchy"]["links"]


@settings(max_examples=25, deadline=None)
@given(st.floats(4.0, 40.0), st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(0.0, 1.2))
def test_element_estimates_of_a_far_cluster_are_lamberts_factors(height, dx, dy, tilt):
    """A mixed link's estimate from a point to a flat cluster (8 x 8 squares of 0.1 m) a few to
    tens of its sizes away matches the sum of the exact point-to-square factors within 2%
    (the isotropic estimate is exact for a point source; the cluster's nodes two levels down
    are 0.2 m across), and the bound is above both."""
    from radiosity.formfactors import point_to_polygons
    from radiosity.methods.hierarchical._clusters import ClusterTree

    squares = np.array([rect(0.1 * i, 0.1 * i + 0.1, 0.1 * j, 0.1 * j + 0.1, 0.0) for i in range(8) for j in range(8)])
    normals = np.tile([0.0, 0.0, 1.0], (64, 1))
    areas = np.full(64, 0.01)
    tree = ClusterTree(np.arange(64), squares, normals, areas, np.full((64, 3), 0.5))
    point = np.array([[0.4 + dx * height, 0.4 + dy * height, height]])
    toward = np.array([0.4, 0.4, 0.0]) - point[0]
    normal = toward / np.linalg.norm(toward)
    normal = normal + tilt * np.cross(normal, [1.0, 0.0, 0.0])  # up to about 50 degrees off the cluster
    normal = (normal / np.linalg.norm(normal))[None]
    exact = point_to_polygons(point, normal, squares).sum()
    estimate = tree.element_estimates(point, normal, np.array([0]))[0]
    assert estimate == pytest.approx(exact, rel=0.02, abs=1e-9)
    bound = tree.element_bound(point, np.zeros(1), normal, np.full((1, 3), 1.0), np.array([0]), np.ones((len(tree), 3)))
    assert bound[0] >= max(exact, estimate) * (1 - 1e-9)


def test_element_estimates_of_sphere_clusters_seen_at_their_rim():
    """A point a few node sizes from a cluster of a sphere's triangles, 60-110 degrees off the
    cluster's axis (the horizon straddles the node): the estimate is the sum of the exact
    factors to the triangles that face the point within 3%. From each node's centre, which
    lies inside the sphere, every triangle leans toward the point: that was 26% off here and
    doubled a reverse link's factor at a sphere's rim."""
    from helpers import sphere_scene

    from radiosity.formfactors import point_to_polygons

    from radiosity.methods.hierarchical._clusters import ClusterTree

    scene = sphere_scene(8)
    tree = ClusterTree(np.arange(scene.n_patches), scene.patch_quads, scene.patch_normal, scene.patch_area,
                       scene.reflectance)
    rng = np.random.default_rng(1)
    nodes = tree.internal[(tree.hi - tree.lo)[tree.internal] >= 16]
    exact, estimate = [], []
    for k in rng.choice(nodes, 200):
        side = np.cross(tree.axis[k], rng.normal(size=3))
        angle = np.radians(rng.uniform(60.0, 110.0))
        u = np.cos(angle) * tree.axis[k] + np.sin(angle) * side / np.linalg.norm(side)
        point = tree.centre[k] + rng.uniform(2.0, 6.0) * u
        members = tree.order[tree.lo[k]:tree.hi[k]]
        facing = ((point - tree.centroids[members]) * scene.patch_normal[members]).sum(axis=1) > 0
        exact.append(point_to_polygons(point[None], -u[None], scene.patch_quads[members][facing]).sum())
        estimate.append(tree.element_estimates(point[None], -u[None], np.array([k]))[0])
    exact, estimate = np.array(exact), np.array(estimate)
    seen = exact > 1e-4 * exact.max()
    assert seen.sum() > 150
    np.testing.assert_allclose(estimate[seen], exact[seen], rtol=0.03)
    assert np.abs(estimate - exact).max() < 1e-3


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_spread_links_on_threads_adds_what_one_pass_adds(threads):
    """The oriented cluster links' part of G @ x, each thread spreading a run of links into
    its own copy of y: the same sums as adding link by link (to rounding), whatever the runs."""
    from radiosity.methods.hierarchical._clusters_kernel import PARALLEL_VALUES, spread_links

    rng = np.random.default_rng(4)
    n, nodes, links = 5_000, 400, 6_000
    order = rng.permutation(n)
    lo = rng.integers(0, n - 100, nodes)
    hi = lo + rng.integers(1, 100, nodes)
    r, column = rng.integers(0, nodes, links), rng.integers(0, n, links)
    members = hi[r] - lo[r]
    start = np.cumsum(members) - members
    value = rng.random(int(members.sum()))
    assert len(value) > 3 * PARALLEL_VALUES
    x = rng.random(n)
    x[::7] = 0.0
    expected = rng.random(n)
    y = expected.copy()
    for k in range(links):
        np.add.at(expected, order[lo[r[k]]:hi[r[k]]], value[start[k]:start[k] + members[k]] * x[column[k]])
    spread_links(r, column, lo, hi, order, start, value, x, y, threads)
    np.testing.assert_allclose(y, expected, rtol=1e-12)


def test_links_about_to_split_skip_their_rays_with_the_same_result(monkeypatch):
    """New links that split if partly visible, whatever the fraction, take no rays
    (SKIP_DOOMED): a furnace room of 20 cubes gives the same leaves and radiosities bit for
    bit, with fewer pairs traced."""
    from radiosity.methods.hierarchical import _hierarchy

    scene = cube_room_scene(20)
    skipped = solve_h(scene)
    monkeypatch.setattr(_hierarchy, "SKIP_DOOMED", False)
    traced = solve_h(scene)
    np.testing.assert_array_equal(skipped.radiosity, traced.radiosity)
    assert skipped.summary()["hierarchy"]["links"] == traced.summary()["hierarchy"]["links"]
    assert skipped.summary()["hierarchy"]["pairs_traced"] < traced.summary()["hierarchy"]["pairs_traced"]


def test_inherited_candidates_are_classified_in_bounded_runs(monkeypatch):
    """Children of partly visible links are classified against their parents' lists in runs of
    at most CHUNK_CANDIDATES entries (100,000 children behind thousands of triangles each
    outgrew the machine at once): runs of 50 give an 8-cube room bit for bit. The lists the
    children keep are counted against the budget as they grow, not at the next level only."""
    from radiosity import _memory
    from radiosity.methods.hierarchical import _hierarchy

    scene = cube_room_scene(8)
    whole = solve_h(scene)
    monkeypatch.setattr(_hierarchy, "CHUNK_CANDIDATES", 50)
    seen, grown = [], [0]
    check_memory, check = _hierarchy.Hierarchy._check_memory, _memory.check

    def recording(self, extra_links, extra_bytes=0, grown_bytes=0):
        grown[0] = grown_bytes
        return check_memory(self, extra_links, extra_bytes, grown_bytes)

    monkeypatch.setattr(_hierarchy.Hierarchy, "_check_memory", recording)
    monkeypatch.setattr(_memory, "check", lambda what, estimate, knob, **kw: (
        seen.append((grown[0], estimate)), check(what, estimate, knob, **kw))[1])
    runs = solve_h(scene)
    np.testing.assert_array_equal(whole.radiosity, runs.radiosity)
    assert whole.summary()["hierarchy"]["links"] == runs.summary()["hierarchy"]["links"]
    before = max(estimate for g, estimate in seen if g == 0)
    while_growing = max(estimate for g, estimate in seen if g > 0)
    assert while_growing > before  # the growth is what a budget between the two refuses
    monkeypatch.setenv(_memory.ENV_BUDGET, str((before + while_growing) // 2))
    with pytest.raises(radiosity.MemoryBudgetError, match="links"):
        solve_h(scene)
    # a room with one cube keeps short lists: it is not charged a run of candidates it will not have
    monkeypatch.delenv(_memory.ENV_BUDGET)
    monkeypatch.setattr(_hierarchy, "CHUNK_CANDIDATES", 8_000_000)
    seen.clear()
    solve_h(cube_room_scene(1))
    assert max(estimate for _, estimate in seen) < 8_000_000 * _hierarchy.CANDIDATE_BYTES


def test_children_of_a_list_cut_short_inherit_it_and_trace_through_embree(monkeypatch):
    """A walk stops at LIST_CAP undecided occluders (a room element behind a tessellated sphere
    collected thousands); the children of such a link are classified against the short list
    (for an occluder hiding one wholly), the others are partly visible with their lists marked
    cut, and their rays go through Embree. Capped at 65 (past RAY_LIST_EMBREE and
    MAX_BLIND_OCCLUDERS, which the cap relies on), the 20-cube furnace room takes that path and
    stays within the furnace identity and near the radiosities with no cap."""
    from radiosity.methods.hierarchical import _links
    from radiosity.visibility._constants import RAY_LIST_EMBREE

    assert _links.LIST_CAP > max(RAY_LIST_EMBREE, _links.MAX_BLIND_OCCLUDERS)
    scene = cube_room_scene(20)
    monkeypatch.setattr(_links, "LIST_CAP", 0)
    whole = solve_h(scene)
    calls = []
    plain = _links.ElementVisibility.fractions_undecided

    def counted(self, el, r, s, **kw):
        calls.append(len(r) if kw.get("incomplete") else 0)
        return plain(self, el, r, s, **kw)

    monkeypatch.setattr(_links.ElementVisibility, "fractions_undecided", counted)
    monkeypatch.setattr(_links, "LIST_CAP", max(RAY_LIST_EMBREE, _links.MAX_BLIND_OCCLUDERS) + 1)
    capped = solve_h(scene)
    assert sum(calls) > 1000
    np.testing.assert_allclose(capped.radiosity, whole.radiosity, rtol=1e-3, atol=0)
    assert np.abs(capped.radiosity / 2.0 - 1.0).max() < 0.016


def test_pairs_classified_against_a_cut_list_keep_what_it_decides_and_walk_where_it_says_nothing():
    """``fractions_undecided(..., incomplete=True)``: the candidates are not all of the pairs'
    occluders. A pair a candidate hides wholly is hidden (-1); a pair a candidate leaves
    undecided is partly visible, its list marked cut and its rays traced through Embree (the
    same fractions as the segment tests against the walk's own lists), unless they are all
    blocked and a walk finds it hidden; a pair no candidate touches walks the BVH, so with no
    candidates at all the answers are the walk's."""
    from radiosity.methods.hierarchical._elements import Elements
    from radiosity.methods.hierarchical._links import ElementVisibility
    from radiosity.visibility._occluders import FREE, FULL, MAYBE
    from radiosity.visibility._pairs import _rows_of

    quads, groups = boxes_scene()
    vis = make_vis(quads, groups, samples=2, max_samples=3)
    el = Elements(quads, vis.normals, min_size=0.01)
    i, j = all_pairs(len(quads))
    ev = ElementVisibility(vis)
    view = ev._over(el)
    status, rows, occ = view.classify(i, j)
    free, full, maybe = (status == k for k in (FREE, FULL, MAYBE))
    assert free.sum() > 50 and full.sum() > 5 and maybe.sum() > 50
    n_occ = view.occluders.n_occluders
    every = (np.arange(len(i) + 1) * n_occ, np.tile(np.arange(n_occ), len(i)))
    visible, partial, _, _, cut = ev.fractions_undecided(el, i, j, children=True, candidates=every,
                                                         incomplete=True)
    np.testing.assert_array_equal(visible == -1.0, full)
    np.testing.assert_array_equal(partial, maybe)
    np.testing.assert_array_equal(cut, maybe)
    np.testing.assert_array_equal(visible[free], 1.0)
    key = i.astype(np.uint64) * np.uint64(len(el)) + j.astype(np.uint64)
    rays = view._patch_rays(i, j, 3, key, 1)[0]
    seen = maybe & ~np.isnan(rays)
    np.testing.assert_array_equal(visible[seen], rays[seen])
    np.testing.assert_array_equal(visible[maybe & np.isnan(rays)], 0.5)
    part = np.flatnonzero(seen)
    sub_rows, sub_occ = _rows_of(rows, occ, part, len(i))
    segments = view.ray_fraction(i[part], j[part], 3, 3, rows=sub_rows, occ=sub_occ)
    np.testing.assert_allclose(visible[part], segments, atol=1e-12)
    assert ((segments > 0) & (segments < 1)).sum() > 20
    # lists without the occluders that hide a pair alone: the pairs the walk finds hidden are
    # found hidden all the same (their rays all blocked, they walk)
    single = (np.arange(len(i) * n_occ + 1), np.tile(np.arange(n_occ), len(i)))
    alone_full = view.classify_listed(np.repeat(i, n_occ), np.repeat(j, n_occ), *single)[0] == FULL
    others = np.tile(np.arange(n_occ), len(i))[~alone_full]
    short = (np.concatenate([[0], np.cumsum(n_occ - alone_full.reshape(len(i), -1).sum(axis=1))]), others)
    visible, partial, _, _, cut = ev.fractions_undecided(el, i, j, children=True, candidates=short, incomplete=True)
    assert (full & cut).sum() > 5  # hidden only by occluders off their lists
    np.testing.assert_array_equal(visible == -1.0, full)
    np.testing.assert_array_equal(partial, maybe)
    none = (np.zeros(len(i) + 1, np.int64), np.zeros(0, np.int64))
    walked = ev.fractions_undecided(el, i, j, children=True)
    alone = ev.fractions_undecided(el, i, j, children=True, candidates=none, incomplete=True)
    for a, b in zip(walked, alone):
        np.testing.assert_array_equal(a, b)


# ------------------------------------------------------------------------ convex objects
def _as_quads(mesh) -> np.ndarray:
    tris = mesh.vertices[mesh.faces]
    return np.concatenate([tris, tris[:, 2:3]], axis=1)


def _rotation(angles) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("xyz", angles).as_matrix()


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.floats(-3.0, 3.0), st.floats(-3.0, 3.0), st.floats(-3.0, 3.0),
       st.sampled_from([1e-4, 1.0, 1e4]), st.sampled_from([0.0, 1e5]))
def test_the_hull_of_random_points_is_convex_and_stays_so_moved_or_scaled(seed, ax, ay, az, scale, offset):
    """The convex hull of random points is a convex group wherever it is put and at any size;
    turned inside out it is not, nor is it with one vertex pushed in."""
    import trimesh

    from radiosity.geometry import convex_groups, polygon_normals

    rng = np.random.default_rng(seed)
    hull = trimesh.convex.convex_hull(rng.normal(size=(40, 3)))
    quads = _as_quads(hull) @ _rotation([ax, ay, az]).T * scale + offset
    one = np.zeros(len(quads), np.int64)
    assert convex_groups(quads, polygon_normals(quads), one).tolist() == [True]
    inside_out = quads[:, ::-1]
    assert convex_groups(inside_out, polygon_normals(inside_out), one).tolist() == [False]
    vertices = hull.vertices.copy()
    vertices[hull.faces[0, 0]] = 0.5 * vertices[hull.faces[0, 0]] + 0.5 * vertices.mean(axis=0)
    dented = _as_quads(trimesh.Trimesh(vertices, hull.faces, process=False))
    dented = dented @ _rotation([ax, ay, az]).T * scale + offset
    assert convex_groups(dented, polygon_normals(dented), one).tolist() == [False]


def test_convex_groups_of_sheets_folds_and_furniture():
    """A flat sheet of many quads, a fold opening outward (a roof ridge) and a box are convex
    groups; a fold opening inward (two quads that face each other, also behind a patch of no
    area, which has no plane to be flat in), a table of five boxes and a closed room seen from
    inside are not. Each group is judged alone."""
    from radiosity.geometry import convex_groups, polygon_normals

    sheet = [rect(0.1 * i, 0.1 * i + 0.1, 0.1 * j, 0.1 * j + 0.1, 0.0) for i in range(5) for j in range(5)]
    ridge = [np.array([[0, 0, 0], [1, 0, 1], [1, 1, 1], [0, 1, 0]]),
             np.array([[1, 0, 1], [2, 0, 0], [2, 1, 0], [1, 1, 1]])]
    valley = [q[::-1] for q in ridge]
    table = axis_box([0, 0, 0.7], [1, 1, 0.75], inward=False)
    for x in (0, 0.95):
        for y in (0, 0.95):
            table += axis_box([x, y, 0], [x + 0.05, y + 0.05, 0.7], inward=False)
    groups = {"sheet": sheet, "ridge": ridge, "valley": valley, "box": axis_box([0, 0, 0], [1, 2, 3], inward=False),
              "table": table, "room": axis_box([0, 0, 0], [3, 3, 3], inward=True),
              "valley behind a degenerate patch": [np.zeros((4, 3))] + valley}
    quads = np.array([np.asarray(q, float) for qs in groups.values() for q in qs])
    ids = np.repeat(np.arange(len(groups)), [len(qs) for qs in groups.values()])
    convex = convex_groups(quads, polygon_normals(quads), ids)
    assert dict(zip(groups, convex.tolist())) == {"sheet": True, "ridge": True, "valley": False, "box": True,
                                                  "table": False, "room": False,
                                                  "valley behind a degenerate patch": False}


def test_links_inside_a_convex_object_are_dropped_with_the_same_result(tmp_path, monkeypatch):
    """A furnace room holding an icosphere of 320 triangles, at draft: the cluster links
    between parts of the sphere (none of its triangles sees another) are dropped, and the
    radiosities stay the same bit for bit. A 20,480-triangle sphere in a 4 x 3 x 2.5 m room kept
    1.2 M such links of 2.4 M; without them its refinement took 34 s instead of 55 s."""
    from radiosity.methods.hierarchical import _clusters, _hierarchy

    monkeypatch.setattr(_hierarchy, "CLUSTER_MIN_ROOTS", 100)
    scene = _furnace_sphere_room(tmp_path, 2, 0.4)
    dropped = solve_h(scene)
    monkeypatch.setattr(_clusters, "DROP_CONVEX", False)
    kept = solve_h(scene)
    np.testing.assert_array_equal(dropped.radiosity, kept.radiosity)
    links = [s.summary()["hierarchy"]["cluster_links"] for s in (dropped, kept)]
    assert links[0] < 0.5 * links[1]


# ------------------------------------------------------------------- reverse mixed links
def test_each_patch_of_a_reverse_link_takes_its_own_visibility(tmp_path, monkeypatch):
    """A furnace room holding a 1,280-triangle sphere (1.5 cm triangles, reverse mixed links)
    with a 0.4 m plate 5 cm to its side, at draft: the sphere's triangles behind the plate see
    the plate, not the walls, and every sphere leaf is within 1.5% of B = 2. When a reverse
    link's visibility came from the one patch of its cluster that faces the element most, the
    walls' light reached the hidden triangles too: -3.7% / +4.4% (REVERSE_PATCH_VISIBILITY)."""
    import trimesh

    from radiosity.methods.hierarchical import _hierarchy

    monkeypatch.setattr(_hierarchy, "CLUSTER_MIN_ROOTS", 100)
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
    sphere.apply_translation([1.0, 1.0, 0.6])
    plate = rect(0.8, 1.2, 0.45, 0.85, 0.0)[:, [2, 0, 1]] + [1.15, 0.0, 0.0]  # the plane x = 1.15
    path = write_obj(tmp_path / "plate_room.obj", {"room": axis_box([0, 0, 0], [2, 2, 2], inward=True),
                                                   "sphere": list(sphere.vertices[sphere.faces]),
                                                   "plate": [plate, plate[::-1]]})
    with pytest.warns(radiosity.RadiosityWarning, match="no face emits"):
        scene = radiosity.load_scene(path).with_materials(reflectance=0.5, emission=1.0)
    solution = solve_h(scene)
    assert solution.summary()["hierarchy"]["reverse_mixed_links"] > 1000
    error = solution.radiosity[:, 0] / 2.0 - 1.0
    on_sphere = solution.scene.patch_object == solution.scene.objects.index("sphere")
    assert np.abs(error[on_sphere]).max() < 0.015
    assert np.abs(error).max() < 0.015


@settings(max_examples=25, deadline=None)
@given(st.floats(0.3, 20.0), st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(0.0, 1.2),
       st.floats(0.05, 2.0))
def test_a_cluster_gathering_from_an_element_is_bounded_and_shares_by_facing(height, dx, dy, tilt, size):
    """A flat cluster (8 x 8 squares of 0.1 m) gathering from a square element above it: the
    reverse mixed link's bound is above the exact factor from every square's centroid to the
    element, and the oriented shares keep the cluster's area mean at the link's factor, the
    squares that see a far element more getting more."""
    from radiosity.formfactors import point_to_polygons
    from radiosity.methods.hierarchical._clusters import ClusterTree

    squares = np.array([rect(0.1 * i, 0.1 * i + 0.1, 0.1 * j, 0.1 * j + 0.1, 0.0) for i in range(8) for j in range(8)])
    normals = np.tile([0.0, 0.0, 1.0], (64, 1))
    tree = ClusterTree(np.arange(64), squares, normals, np.full(64, 0.01), np.full((64, 3), 0.5))
    centre = np.array([0.4 + dx * height, 0.4 + dy * height, height])
    down = np.array([0.4, 0.4, 0.0]) - centre
    normal = down / np.linalg.norm(down)
    normal = normal + tilt * np.cross(normal, [1.0, 0.0, 0.0])
    normal /= np.linalg.norm(normal)
    u = np.cross(normal, [0.0, 1.0, 0.0] if abs(normal[1]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    half = size / 2
    element = centre + half * np.array([-u - v, u - v, u + v, -u + v])  # wound about +normal
    if np.dot(np.cross(element[1] - element[0], element[2] - element[0]), normal) < 0:
        element = element[::-1]
    exact = point_to_polygons(squares.mean(axis=1), normals, element[None]).reshape(64)
    bound = tree.element_source_bound(np.array([0]), centre[None], np.array([half * np.sqrt(2)]), normal[None],
                                      np.array([size * size]), np.ones((1, 3)))
    assert bound[0] * 2.0 >= exact.max() * (1 - 1e-9)  # the node's reflectance bound is 0.5
    start, share = tree.point_shares(np.array([0]), centre[None], normal[None], np.array([0.3]))
    assert start.tolist() == [0]
    assert np.mean(share) == pytest.approx(0.3, rel=1e-9)
    facing = exact > 0.1 * exact.max()
    if facing.sum() > 1 and exact.max() > 0 and height > 2 * size:  # the element about a point
        members = tree.order[:64]
        got = share[np.argsort(members)]
        pick = np.flatnonzero(facing)
        assert np.corrcoef(got[pick], exact[pick])[0, 1] > 0.9


def test_a_finely_tessellated_sphere_gathers_from_room_elements_through_reverse_mixed_links(tmp_path, monkeypatch):
    """A furnace room holding an icosphere of 1,280 triangles of 1.5 cm, under a fifth of the
    draft elements' 6.9 cm, at draft: the sphere's clusters gather from room elements
    through cluster <- element links instead of a link from each triangle, with B = E / (1 -
    rho) on every leaf within 1.5% still, and fewer links in all."""
    from radiosity.methods.hierarchical import _hierarchy

    monkeypatch.setattr(_hierarchy, "CLUSTER_MIN_ROOTS", 100)
    scene = _furnace_sphere_room(tmp_path, 3, 0.1)
    reverse = solve_h(scene)
    error = reverse.radiosity / 2.0 - 1.0
    assert np.abs(error).max() < 0.015 and abs(error.mean()) < 1e-3
    stats = reverse.summary()["hierarchy"]
    assert stats["reverse_mixed_links"] > 1000
    monkeypatch.setattr(_hierarchy, "REVERSE_MIXED", False)
    single = solve_h(scene).summary()["hierarchy"]
    assert single["reverse_mixed_links"] == 0
    assert stats["links"] < 0.95 * single["links"]


@settings(max_examples=40, deadline=None)
@given(corners=st.lists(st.floats(-0.3, 0.3), min_size=8, max_size=8),
       coefficients=st.lists(st.floats(-1.0, 1.0), min_size=5, max_size=5),
       triangle=st.booleans(), depth=st.integers(1, 3))
def test_the_push_carries_a_quadratic_onto_the_leaves_exactly(corners, coefficients, triangle, depth):
    """A receiver's point deviations sampled from a zero-mean quadratic in its plane reach each
    leaf below it as that quadratic's mean over the leaf (against a 10 x 10 Gauss rule), and the
    leaves' area-weighted sum of them is 0: the push moves power between leaves and adds none.
    Any convex quad or triangle, split 1-3 levels."""
    from radiosity.formfactors import patch_points
    from radiosity.methods.hierarchical._variation import variation_push

    jitter = np.array(corners).reshape(4, 2)
    square = np.array([[0, 0], [2, 0], [2, 1], [0, 1]], float) + jitter
    if triangle:
        square[3] = square[2]
    quad = np.c_[square, np.zeros(4)]
    _, area = centroids_and_areas(quad[None])
    if area[0] < 0.2:  # jitter can fold the quad; those are no element
        return
    el = Elements(quad[None], np.array([[0, 0, 1.0]]), 1e-3)
    for _ in range(depth):
        el.split(el.leaves())
    leaves = el.leaves()

    def f(p):
        x, y = p[..., 0] - 0.7, p[..., 1] - 0.4
        return np.stack([x, y, x * x, x * y, y * y], axis=-1) @ np.array(coefficients)

    points, weights = patch_points(el.quads[[0]], 3)
    values = f(points[0])
    deviations = values - (weights[0] @ values) / weights[0].sum()
    pushed = variation_push(el, np.array([0]), leaves) @ deviations
    fine, fine_weights = patch_points(el.quads[leaves], 10)
    exact = (f(fine) * fine_weights).sum(axis=1) / fine_weights.sum(axis=1) - (weights[0] @ values) / weights[0].sum()
    np.testing.assert_allclose(pushed, exact, atol=1e-10)
    assert abs(el.area[leaves] @ pushed) < 1e-12


def test_an_empty_room_meets_the_furnace_identity_at_draft(tmp_path, monkeypatch):
    """A closed, empty 6 x 3 x 5 m room, every face emitting 1 and reflecting 0.5: B = 2 on every
    leaf within 0.5% at draft. Each leaf used to get its ancestors' mean factors, which all
    lean one way: an interior wall leaf gathered 0.960 of its row and one at the floor 1.046
    (B -2.0% / +2.4%); the links' variation across their receivers now reaches the leaves as
    a quadratic (measured: within 0.14%, in 183 k links where the old split test made 288 k)."""
    from radiosity.methods.hierarchical import _hierarchy

    path = write_obj(tmp_path / "empty.obj", {"room": axis_box([0, 0, 0], [6, 3, 5], inward=True)})
    with pytest.warns(radiosity.RadiosityWarning):
        scene = radiosity.load_scene(path).with_materials(reflectance=0.5, emission=1.0)
    assert np.abs(solve_h(scene).radiosity / 2.0 - 1.0).max() < 5e-3
    monkeypatch.setattr(_hierarchy, "QUADRATIC_PUSH", False)
    assert np.abs(solve_h(scene).radiosity / 2.0 - 1.0).max() > 1.5e-2


def test_the_quadratic_push_is_the_same_in_chunks(furnace, monkeypatch):
    """The push's fits and leaf means go through the receivers in chunks (all at once they took
    0.5 kB a receiver): the same matrix in chunks of 7 as in one."""
    from radiosity.methods.hierarchical import _variation

    hier = build_hierarchy(furnace, Options.from_preset("draft", link_tolerance=1e-2, min_element_rel=1 / 10))
    hier.refine()
    leaves = hier.el.leaves()
    receivers = np.unique(hier.links.r[hier.el.first_child[hier.links.r] >= 0])
    assert len(receivers) > 20
    whole = _variation.variation_push(hier.el, receivers, leaves)
    monkeypatch.setattr(_variation, "CHUNK_PAIRS", 7)
    chunked = _variation.variation_push(hier.el, receivers, leaves)
    assert abs(whole - chunked).max() < 1e-12 and whole.nnz == chunked.nnz > 0

"""Imprinting contacts (radiosity/imprint.py) and its place in load_scene / resubdivided."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import shapely

import radiosity
from radiosity.imprint import CONTACT_REL, convex_pieces, imprint_faces, subdivide_imprinted
from radiosity.io.obj import read_obj
from radiosity.geometry import centroids_and_areas

from helpers import polygon_area, write_obj

CORNELL = radiosity.bundled_scene("cornell_box")


def _load(**options):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", radiosity.RadiosityWarning)
        return radiosity.load_scene(CORNELL, **options)


def _xz(points: np.ndarray) -> np.ndarray:
    return points[..., [0, 2]]


def _footprints() -> dict[str, shapely.Polygon]:
    """The blocks' footprints and the light's outline, in the floor/ceiling (x, z) plane."""
    data = read_obj(CORNELL)
    out = {}
    for name in ("short_block", "tall_block", "light"):
        face = data.faces[int(np.flatnonzero(data.face_object == data.objects.index(name))[0])]
        out[name] = shapely.Polygon(_xz(data.vertices[face]))  # top face / light: same outline
    return out


def _object_patches(scene, name):
    return scene.patch_object == scene.objects.index(name)


# ----------------------------------------------------------------------------- Cornell box
def test_cornell_contacts_found():
    data = read_obj(CORNELL)
    cut = imprint_faces(data.vertices, data.faces, data.face_object)
    found = {(data.objects[data.face_object[c.face]], data.objects[c.other_object], c.kind, c.hidden)
             for c in cut.contacts}
    assert found == {("floor", "short_block", "footprint", True), ("floor", "tall_block", "footprint", True),
                     ("ceiling", "light", "overlap", True)}
    prints = _footprints()
    for contact in cut.contacts:
        name = data.objects[contact.other_object]
        assert contact.area == pytest.approx(prints[name].area, rel=1e-9)


@pytest.mark.parametrize("size", [None, 0.05])
def test_hidden_regions_are_exactly_the_footprints(size):
    scene = _load(max_patch_size=size)
    prints = _footprints()
    quads, hidden, area = scene.patch_quads, scene.patch_hidden, scene.patch_area
    for surface, covers in (("floor", ("short_block", "tall_block")), ("ceiling", ("light",))):
        mask = _object_patches(scene, surface)
        union = shapely.unary_union([prints[c] for c in covers])
        assert area[mask & hidden].sum() == pytest.approx(union.area, rel=1e-9)
        centroids = shapely.points(_xz(scene.patch_centroid[mask]))
        assert (shapely.contains(union, centroids) == hidden[mask]).all()
        for name in covers:  # each footprint is its own region
            inside = mask & hidden & shapely.contains(prints[name], shapely.points(_xz(scene.patch_centroid)))
            assert area[inside].sum() == pytest.approx(prints[name].area, rel=1e-9)
    assert not hidden[~(_object_patches(scene, "floor") | _object_patches(scene, "ceiling"))].any()
    assert quads.shape[0] == len(hidden)


def test_no_patch_crosses_an_imprinted_edge():
    scene = _load(max_patch_size=0.04)
    prints = _footprints()
    for surface, covers in (("floor", ("short_block", "tall_block")), ("ceiling", ("light",))):
        mask = _object_patches(scene, surface)
        polys = shapely.polygons(_xz(scene.patch_quads[mask]))
        for name in covers:
            overlap = shapely.area(shapely.intersection(polys, prints[name]))
            patch = shapely.area(polys)
            straddles = (overlap > 1e-9 * patch) & (overlap < (1 - 1e-9) * patch)
            assert not straddles.any()


@pytest.mark.parametrize("size", [0.08, 0.03])
def test_max_patch_size_respected_after_imprinting(size):
    for scene in (_load(max_patch_size=size), _load().resubdivided(size)):
        quads = scene.patch_quads
        assert np.linalg.norm(np.roll(quads, -1, axis=1) - quads, axis=2).max() <= size * (1 + 1e-9)


def test_area_conserved_per_face():
    data = read_obj(CORNELL)
    for scene in (_load(), _load(max_patch_size=0.05), _load().resubdivided(0.03)):
        totals = np.bincount(scene.patch_face, weights=scene.patch_area, minlength=len(data.faces))
        for index, face in enumerate(data.faces):
            poly = data.vertices[face]
            expected = polygon_area(poly)
            if data.objects[data.face_object[index]] == "red_wall":  # non-planar: its fan triangles
                expected = polygon_area(poly[[0, 1, 2]]) + polygon_area(poly[[0, 2, 3]])
            assert totals[index] == pytest.approx(expected, rel=1e-9)


def test_hidden_flags_follow_parents_when_resubdividing():
    scene = _load()
    finer = scene.resubdivided(0.03)
    assert finer.patch_hidden.sum() > scene.patch_hidden.sum()
    # every fine patch lies inside a coarse patch with the same flag
    coarse = shapely.polygons(_xz(scene.patch_quads))
    points = shapely.points(_xz(finer.patch_centroid))
    for flag in (True, False):
        region = shapely.unary_union(coarse[(scene.patch_hidden == flag) & _object_patches(scene, "floor")])
        floor = _object_patches(finer, "floor")
        assert (shapely.contains(region, points[floor & (finer.patch_hidden == flag)])).all()


def test_imprint_off_keeps_plain_subdivision():
    plain = _load(imprint=False)
    assert not plain.patch_hidden.any()
    assert plain.n_patches < _load().n_patches
    assert "imprint" in radiosity.scene.LOAD_OPTIONS


@pytest.fixture(scope="module")
def draft_solution():
    return radiosity.solve(_load(), preset="draft", cache=False)


def test_covered_regions_receive_nothing(draft_solution):
    scene = draft_solution.scene
    hidden = scene.patch_hidden
    assert hidden[_object_patches(scene, "floor")].any() and hidden[_object_patches(scene, "ceiling")].any()
    irradiance = draft_solution.patch_irradiance
    assert np.abs(irradiance[hidden]).max() <= 1e-12 * np.abs(irradiance).max()
    assert np.allclose(draft_solution.radiosity[hidden], scene.emission[hidden])
    lit = _object_patches(scene, "floor") & ~hidden
    assert (irradiance[lit] > 0).all()


def test_object_radiosity_averages_over_hidden_regions_too(draft_solution):
    scene, b = draft_solution.scene, draft_solution.radiosity
    means = draft_solution.object_radiosity()
    for name in ("floor", "ceiling"):
        mask = _object_patches(scene, name)
        whole = (scene.patch_area[mask, None] * b[mask]).sum(axis=0) / scene.patch_area[mask].sum()
        assert np.allclose(means[name], whole, rtol=1e-12)
        visible = mask & ~scene.patch_hidden
        lit = (scene.patch_area[visible, None] * b[visible]).sum(axis=0) / scene.patch_area[visible].sum()
        assert (means[name] < lit).all()  # the dark footprints pull the mean down


def test_covered_regions_of_a_closed_furnace_send_nothing_out(tmp_path):
    """A closed furnace room (every surface E = 1, rho = 0.5) with a block standing on its floor:
    the floor under the block is hidden and keeps B = E, but it is not there for the room, so
    its emission is neither emitted nor escaped. Counted, it went to "escaped": a closed room
    reported 4.96 W of 206.4 W escaping, the covered area's emission."""
    from helpers import axis_box

    furnace = {"furnace": ((0.5, 0.5, 0.5), (1.0, 1.0, 1.0))}
    room = write_obj(tmp_path / "room.obj", {"room": axis_box((0, 0, 0), (2, 2, 2), inward=True),
                                             "block": axis_box((0.6, 0, 0.6), (1.4, 0.5, 1.4), inward=False)},
                     furnace)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", radiosity.RadiosityWarning)
        solution = radiosity.solve(radiosity.load_scene(room), preset="draft", cache=False)
    scene = solution.scene
    assert scene.patch_area[scene.patch_hidden].sum() == pytest.approx(2 * 0.8 * 0.8)  # floor and block bottom
    energy = {k: np.asarray(v) for k, v in solution.energy.items()}
    present = ~scene.patch_hidden
    assert energy["emitted"] == pytest.approx(np.pi * scene.patch_area[present].sum(), rel=1e-12)
    assert np.abs(energy["escaped"]).max() <= 1e-2 * energy["emitted"].max()


# ----------------------------------------------------------------------------- small scenes
FLOOR = np.array([[0, 0, 0], [0, 0, 2], [2, 0, 2], [2, 0, 0]], float)  # y = 0, normal +y


def _box(lo, hi, *, bottom=False, top=True):
    """Axis-aligned box faces, normals outward."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    faces = [np.array(f, float) for f in (
        [[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0]],  # -z
        [[x1, y0, z1], [x0, y0, z1], [x0, y1, z1], [x1, y1, z1]],  # +z
        [[x0, y0, z1], [x0, y0, z0], [x0, y1, z0], [x0, y1, z1]],  # -x
        [[x1, y0, z0], [x1, y0, z1], [x1, y1, z1], [x1, y1, z0]],  # +x
    )]
    if top:
        faces.append(np.array([[x0, y1, z0], [x1, y1, z0], [x1, y1, z1], [x0, y1, z1]], float)[::-1].copy())
    if bottom:
        faces.append(np.array([[x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1]], float))
    return faces


def _imprint(objects: dict[str, list[np.ndarray]]):
    polys = [p for ps in objects.values() for p in ps]
    owner = np.repeat(np.arange(len(objects)), [len(ps) for ps in objects.values()])
    vertices = np.concatenate(polys)
    faces = list(np.split(np.arange(len(vertices)), np.cumsum([len(p) for p in polys])[:-1]))
    return imprint_faces(vertices, faces, owner, scale=2.0), vertices, faces


def _hidden_area(cut, face: int) -> float:
    mask = (cut.piece_face == face) & cut.piece_hidden
    return sum(polygon_area(cut.vertices[p]) for p, m in zip(cut.pieces, mask) if m)


def test_box_without_bottom_hides_its_footprint():
    cut, _, _ = _imprint({"floor": [FLOOR], "box": _box((0.5, 0, 0.5), (1.0, 0.4, 1.2))})
    assert _hidden_area(cut, 0) == pytest.approx(0.5 * 0.7, rel=1e-12)
    assert [(c.kind, c.hidden) for c in cut.contacts] == [("footprint", True)]


def test_box_with_bottom_hides_both_sides():
    cut, _, _ = _imprint({"floor": [FLOOR], "box": _box((0.5, 0, 0.5), (1.0, 0.4, 1.2), bottom=True)})
    assert _hidden_area(cut, 0) == pytest.approx(0.35, rel=1e-12)
    assert _hidden_area(cut, 6) == pytest.approx(0.35, rel=1e-12)  # the box's bottom face


def test_open_tube_is_cut_but_not_hidden():
    cut, _, _ = _imprint({"floor": [FLOOR], "tube": _box((0.5, 0, 0.5), (1.0, 0.4, 1.2), top=False)})
    assert _hidden_area(cut, 0) == 0.0
    assert [(c.kind, c.hidden) for c in cut.contacts] == [("footprint", False)]
    assert (cut.piece_face == 0).sum() > 1


def test_box_overhanging_the_floor_edge():
    cut, _, _ = _imprint({"floor": [FLOOR], "box": _box((1.5, 0, 0.5), (2.5, 0.4, 1.0))})
    assert _hidden_area(cut, 0) == pytest.approx(0.5 * 0.5, rel=1e-12)


def test_picture_on_a_wall_hides_the_wall_behind_it():
    wall = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]], float)  # normal +z
    picture = np.array([[0.5, 0.5, 0], [1.0, 0.5, 0], [1.0, 1.2, 0], [0.5, 1.2, 0]], float)
    cut, _, _ = _imprint({"wall": [wall], "picture": [picture]})
    assert _hidden_area(cut, 0) == pytest.approx(0.35, rel=1e-12)
    assert _hidden_area(cut, 1) == 0.0
    assert (cut.piece_face == 1).sum() == 1  # the picture itself is not cut


def test_light_just_under_a_ceiling():
    ceiling = FLOOR[::-1] + [0, 1, 0]  # y = 1, normal -y
    light = np.array([[0.5, 0, 0.5], [1.0, 0, 0.5], [1.0, 0, 1.0], [0.5, 0, 1.0]], float)
    light[:, 1] = 1 - 0.25 * CONTACT_REL * 2.0  # a quarter of the tolerance below
    cut, _, _ = _imprint({"ceiling": [ceiling], "light": [light]})
    assert _hidden_area(cut, 0) == pytest.approx(0.25, rel=1e-9)
    assert _hidden_area(cut, 1) == 0.0


def test_no_contact_beyond_the_tolerance_or_within_one_object():
    ceiling = FLOOR[::-1] + [0, 1, 0]
    light = np.array([[0.5, 0, 0.5], [1.0, 0, 0.5], [1.0, 0, 1.0], [0.5, 0, 1.0]], float)
    light[:, 1] = 1 - 3 * CONTACT_REL * 2.0
    cut, _, _ = _imprint({"ceiling": [ceiling], "light": [light]})
    assert not cut.contacts and len(cut.pieces) == 2
    cut, _, _ = _imprint({"room": [FLOOR, *_box((0.5, 0, 0.5), (1.0, 0.4, 1.2))]})
    assert not cut.contacts


def test_pieces_are_convex_planar_and_keep_the_winding():
    cut, vertices, faces = _imprint({"floor": [FLOOR], "a": _box((0.2, 0, 0.2), (0.7, 0.3, 0.6)),
                                     "b": _box((1.1, 0, 0.9), (1.6, 0.5, 1.7))})
    for piece, face in zip(cut.pieces, cut.piece_face):
        poly = cut.vertices[piece]
        assert len(poly) in (3, 4)
        normal = np.cross(poly[1] - poly[0], poly[2] - poly[0])
        ref = np.cross(vertices[faces[face]][1] - vertices[faces[face]][0],
                       vertices[faces[face]][2] - vertices[faces[face]][0])
        assert normal @ ref > 0
    floor_area = sum(polygon_area(cut.vertices[p]) for p, f in zip(cut.pieces, cut.piece_face) if f == 0)
    assert floor_area == pytest.approx(4.0, rel=1e-12)


def test_convex_pieces_of_a_polygon_with_holes():
    outer = shapely.box(0, 0, 3, 2)
    holes = shapely.union(shapely.box(0.5, 0.5, 1.0, 1.5), shapely.Polygon([(2, 0.4), (2.6, 1), (2, 1.6), (1.6, 1)]))
    region = outer.difference(holes)
    pieces = convex_pieces(region)
    assert sum(shapely.Polygon(p).area for p in pieces) == pytest.approx(region.area, rel=1e-12)
    for p in pieces:
        assert len(p) in (3, 4)
        assert shapely.Polygon(p).convex_hull.area == pytest.approx(shapely.Polygon(p).area, rel=1e-12)
        assert shapely.Polygon(p).exterior.is_ccw


@pytest.mark.filterwarnings("ignore::radiosity.RadiosityWarning")
def test_load_scene_imprints_obj_files(tmp_path):
    path = write_obj(tmp_path / "box.obj", {"floor": [FLOOR], "box": _box((0.5, 0, 0.5), (1.0, 0.4, 1.2))})
    scene = radiosity.load_scene(path, units="m")
    assert scene.patch_area[scene.patch_hidden].sum() == pytest.approx(0.35, rel=1e-12)
    plain = radiosity.load_scene(path, units="m", imprint=False)
    assert not plain.patch_hidden.any()
    patches, report, cut = subdivide_imprinted(*_imprint({"floor": [FLOOR]})[1:], np.zeros(1, int), 0.5)
    assert patches.n_patches == 16 and not report.nonplanar
    _, areas = centroids_and_areas(patches.quads)
    assert areas.sum() == pytest.approx(4.0)


def test_nonplanar_red_wall_cut_the_same_way_on_load_and_resubdivision():
    """The red wall (non-planar) arrives in a coarse scene as its two fan triangles;
    resubdividing must cut it as the folded quad, like loading at that size does."""
    direct, again = _load(max_patch_size=0.05), _load().resubdivided(0.05)
    wall = [s.objects.index("red_wall") for s in (direct, again)]
    a = direct.patch_quads[direct.patch_object == wall[0]]
    b = again.patch_quads[again.patch_object == wall[1]]
    # 12 x 12 grid (0.5592 m / 0.05); the 12 cells on the fold (0.065 m long) cut in four
    assert len(a) == len(b) == 12 * 12 + 3 * 12
    np.testing.assert_allclose(np.sort(a.reshape(-1, 3), axis=0), np.sort(b.reshape(-1, 3), axis=0), atol=1e-12)


def test_a_partition_standing_on_the_floor_cuts_it_along_its_foot():
    """A two-sided panel on the floor: its foot closes no loop, but light jumps across it, and a
    floor patch straddling it averaged both sides (a factor to the wall beside it 3.6e-4 off
    in tests/helpers.office_scene). The floor is cut along the foot's line, nothing is hidden."""
    panel = np.array([[1.0, 0, 0.5], [1.0, 0.8, 0.5], [1.0, 0.8, 1.5], [1.0, 0, 1.5]])
    cut, _, _ = _imprint({"floor": [FLOOR], "panel": [panel, panel[::-1].copy()]})
    assert not cut.piece_hidden.any() and cut.contacts == []
    floor = [cut.vertices[p] for p, f in zip(cut.pieces, cut.piece_face) if f == 0]
    assert len(floor) > 1
    for piece in floor:  # every piece on one side of the foot's line
        assert piece[:, 0].max() <= 1.0 + 1e-12 or piece[:, 0].min() >= 1.0 - 1e-12
    assert sum(polygon_area(p) for p in floor) == pytest.approx(polygon_area(FLOOR), rel=1e-12)


def test_a_box_open_at_the_back_in_a_corner_hides_its_footprint():
    """A cabinet against two walls, modelled without its back, side and bottom faces: its edges
    on the floor close a loop only with the floor's rim; its top covers that corner."""
    x0, x1, z0, z1, h = 1.5, 2.0, 1.4, 2.0, 0.6
    front = np.array([[x0, 0, z0], [x0, h, z0], [x1, h, z0], [x1, 0, z0]])  # facing -z
    side = np.array([[x0, 0, z1], [x0, h, z1], [x0, h, z0], [x0, 0, z0]])  # facing -x
    top = np.array([[x0, h, z0], [x0, h, z1], [x1, h, z1], [x1, h, z0]])  # facing +y
    cut, _, _ = _imprint({"floor": [FLOOR], "cabinet": [front, side, top]})
    assert _hidden_area(cut, 0) == pytest.approx((x1 - x0) * (z1 - z0), rel=1e-12)


def _prism_room(offset: float) -> dict[str, list[np.ndarray]]:
    """A 3 x 4 floor with a closed 12-sided prism (radius 0.3, height 1.2, caps fanned from their
    centres) standing on it, everything moved by ``offset`` along each axis."""
    ring = np.radians(30.0 * np.arange(12))
    rim = np.column_stack([1.8 + 0.3 * np.cos(ring), 2.0 + 0.3 * np.sin(ring), np.zeros(12)])
    up = rim + [0, 0, 1.2]
    sides = [np.array([rim[k], rim[(k + 1) % 12], up[(k + 1) % 12], up[k]]) for k in range(12)]
    top = [np.array([[1.8, 2.0, 1.2], up[k], up[(k + 1) % 12]]) for k in range(12)]
    bottom = [np.array([[1.8, 2.0, 0.0], rim[(k + 1) % 12], rim[k]]) for k in range(12)]
    objects = {"floor": [np.array([[0, 0, 0], [3, 0, 0], [3, 4, 0], [0, 4, 0]], float)],
               "prism": sides + top + bottom}
    return {name: [f + offset for f in faces] for name, faces in objects.items()}


def test_a_room_cut_far_from_the_origin_is_cut_as_at_the_origin(tmp_path):
    """1e6 m away the extension lines through a prism's footprint, concurrent at the origin,
    miss each other by round-off (5e-9 m); each near-duplicate corner made a sliver piece of
    1e-12 to 1e-9 m^2 (a floor of 127 pieces at the origin had 138 there). Both now cut the
    floor alike, and no piece is a sliver."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", radiosity.RadiosityWarning)
        near, far = (radiosity.load_scene(write_obj(tmp_path / f"room{k}.obj", _prism_room(offset)))
                     for k, offset in enumerate((0.0, 1e6)))
    floor = [scene.patch_object == scene.objects.index("floor") for scene in (near, far)]
    assert floor[0].sum() == floor[1].sum()
    for scene, mask in zip((near, far), floor):
        assert scene.patch_area[mask].min() > 1e-6 * 12.0
        assert scene.patch_area[mask].sum() == pytest.approx(12.0, rel=1e-9)


@pytest.mark.parametrize("subdivisions", [3, 4])
def test_a_sphere_resting_on_the_floor_hides_none_of_it(subdivisions):
    # Its bottom facets lie within the contact tolerance of the floor (their far corners 1.9 mm
    # and 0.5 mm up, the tolerance 2 mm) but tilt out of it: the sphere touches at one point.
    # Counted as lying on the floor, they hid the floor under them and not themselves, and in
    # a furnace room they saw through that hole (-46%).
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.15)
    sphere.apply_translation([1.0, -sphere.vertices[:, 1].min(), 1.0])
    cut, _, _ = _imprint({"floor": [FLOOR], "sphere": list(sphere.vertices[sphere.faces])})
    assert not cut.piece_hidden.any()
    assert all(not c.hidden for c in cut.contacts)


def test_a_block_tilted_on_its_edge_does_not_lie_on_the_floor():
    # One bottom edge on the floor, the opposite one 1.7 mm up (under the 2 mm tolerance): a
    # wedge of air, not an overlap. Tilted 0.1 degrees it still rests on the floor.
    def tilted(degrees):
        box = _box((0.0, 0.0, 0.0), (0.1, 0.1, 0.1), bottom=True)
        turn = np.radians(degrees)
        rotate = np.array([[np.cos(turn), -np.sin(turn), 0], [np.sin(turn), np.cos(turn), 0], [0, 0, 1]])
        return [f @ rotate.T + [0.5, 0.0, 0.5] for f in box]

    cut, _, _ = _imprint({"floor": [FLOOR], "box": tilted(1.0)})
    assert _hidden_area(cut, 0) == 0.0 and not cut.piece_hidden.any()
    cut, _, _ = _imprint({"floor": [FLOOR], "box": tilted(0.1)})
    assert _hidden_area(cut, 0) > 0.0099

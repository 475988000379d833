"""Imprinting conserves area: the pieces of a face cut by contacts tile it exactly.

Every shape of contact: a box near a corner, a box across an edge, several boxes, touching
boxes, boxes a hair above or below the floor, triangulated sides, with and without a bottom
face, and the floor listed from each of its corners (which turns the frame the cut is made in).
Before the fix, lines through contact edges were clipped to the face, their ends fell a hair
inside its outline, ``polygonize`` dropped them as dangles and merged cells; removing the hidden
cells then removed their neighbours too (up to 16% of a floor lost) or kept them twice.
"""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from radiosity.imprint import subdivide_imprinted
from radiosity.geometry import vector_area as _newell

# McGuire's Cornell-box floor (metres, y up, normal +y): slightly skewed, 4.06 m^2.
FLOOR = np.array([[-1.01, 0, 0.99], [1, 0, 0.99], [1, 0, -1.04], [-0.99, 0, -1.04]])
FLOOR_AREA = 4.06
UP = np.array([0.0, 1.0, 0.0])


def _box(cx, cz, w, d, angle, *, h=0.5, y0=0.0, bottom=True, triangles=False):
    """Vertices (8, 3) and outward faces of a box standing on y = y0, rotated about y."""
    c, s = np.cos(angle), np.sin(angle)
    xz = np.array([[-w / 2, -d / 2], [w / 2, -d / 2], [w / 2, d / 2], [-w / 2, d / 2]]) @ [[c, s], [-s, c]] + [cx, cz]
    base = np.column_stack([xz[:, 0], np.full(4, y0), xz[:, 1]])
    vertices = np.concatenate([base, base + [0, h, 0]])
    if _newell(base) @ UP > 0:  # make the base ring clockwise seen from above
        vertices = vertices[[3, 2, 1, 0, 7, 6, 5, 4]]
    sides = [np.array([i, i + 4, (i + 1) % 4 + 4, (i + 1) % 4]) for i in range(4)]
    faces = [np.array([4, 5, 6, 7])[::-1]]
    for side in sides:
        faces += [side[[0, 1, 2]], side[[0, 2, 3]]] if triangles else [side]
    if bottom:
        faces.append(np.array([0, 1, 2, 3]))
    centre = vertices.mean(axis=0)
    for f in faces:  # outward, checked
        poly = vertices[f]
        assert _newell(poly) @ (poly.mean(axis=0) - centre) > 0
    return vertices, faces


def _scene(boxes: list[dict], roll: int = 0):
    """The floor (object 0, its vertex list rolled) and one object per box."""
    vertices, faces, owner = [np.roll(FLOOR, roll, axis=0)], [np.arange(4)], [0]
    n = 4
    for k, spec in enumerate(boxes, start=1):
        v, f = _box(**spec)
        vertices.append(v)
        faces += [face + n for face in f]
        owner += [k] * len(f)
        n += len(v)
    return np.concatenate(vertices), faces, np.array(owner)


def _assert_tiles_floor(vertices, faces, owner, *, rel=1e-9):
    """The floor's imprinted pieces, and the patches cut from them, tile it without overlap."""
    patches, _, cut = subdivide_imprinted(vertices, faces, owner, 0.3)
    on_floor = np.flatnonzero(cut.piece_face == 0)
    pieces = [cut.vertices[cut.pieces[i]] for i in on_floor]
    normals = np.array([_newell(p) for p in pieces])
    areas = np.linalg.norm(normals, axis=1)
    assert areas.sum() == pytest.approx(FLOOR_AREA, rel=rel), "pieces must sum to the floor"
    assert (normals @ UP > 0).all(), "every piece faces up"
    union = shapely.union_all([shapely.Polygon(p[:, [0, 2]]) for p in pieces], grid_size=1e-12)
    assert union.area == pytest.approx(FLOOR_AREA, rel=rel), "pieces must not overlap"
    quads = patches.quads[patches.patch_face == 0]
    assert sum(np.linalg.norm(_newell(q)) for q in quads) == pytest.approx(FLOOR_AREA, rel=rel)
    return pieces, cut.piece_hidden[on_floor], areas


def _footprint(spec) -> shapely.Polygon:
    v, _ = _box(**spec)
    return shapely.Polygon(v[:4, [0, 2]])


def _hidden_area(areas, hidden) -> float:
    return float(areas[hidden].sum())


FLOOR_XZ = shapely.Polygon(FLOOR[:, [0, 2]])

# A box in the back-right corner, rotated 32 degrees, 4 cm from the back wall and one corner 8 cm
# through the right one; with the floor listed from its back-left corner the cut lost 0.155 m^2
# of floor (3.8%).
NEAR_CORNER = dict(cx=0.6774, cz=-0.9305, w=0.5296, d=0.6663, angle=0.5549)
# Across the floor's left edge: 0.654 m^2 lost (16.1%).
ACROSS_EDGE = dict(cx=-0.9644, cz=0.1235, w=0.5329, d=0.6679, angle=1.8271)


@pytest.mark.parametrize("roll", range(4))
@pytest.mark.parametrize("bottom", [False, True])
def test_box_near_a_corner(roll, bottom):
    spec = dict(NEAR_CORNER, bottom=bottom)
    vertices, faces, owner = _scene([spec], roll)
    _, hidden, areas = _assert_tiles_floor(vertices, faces, owner)
    assert _hidden_area(areas, hidden) == pytest.approx(_footprint(spec).intersection(FLOOR_XZ).area, rel=1e-9)


@pytest.mark.parametrize("roll", range(4))
@pytest.mark.parametrize("bottom", [False, True])
def test_box_across_an_edge(roll, bottom):
    spec = dict(ACROSS_EDGE, bottom=bottom)
    vertices, faces, owner = _scene([spec], roll)
    _, hidden, areas = _assert_tiles_floor(vertices, faces, owner)
    assert _hidden_area(areas, hidden) == pytest.approx(_footprint(spec).intersection(FLOOR_XZ).area, rel=1e-9)


@pytest.mark.parametrize("roll", range(4))
def test_touching_boxes(roll):
    """Two boxes sharing a side, a third touching one of them at a corner."""
    a = dict(cx=0.2, cz=0.1, w=0.4, d=0.3, angle=0.3)
    c, s = np.cos(0.3), np.sin(0.3)
    b = dict(a, cx=0.2 + 0.4 * c, cz=0.1 - 0.4 * s, triangles=True)  # shifted by w along its own x
    corner = np.array([0.2, 0.1]) + np.array([0.2, 0.15]) @ [[c, s], [-s, c]]  # shared by a and b
    centre = corner + 0.1 * np.sqrt(2) * np.array([-s, c])  # a square turned 45 degrees, on that corner
    third = dict(cx=float(centre[0]), cz=float(centre[1]), w=0.2, d=0.2, angle=0.3 + np.pi / 4)
    vertices, faces, owner = _scene([a, b, third], roll)
    _, hidden, areas = _assert_tiles_floor(vertices, faces, owner)
    union = shapely.union_all([_footprint(x) for x in (a, b, third)])
    assert _hidden_area(areas, hidden) == pytest.approx(union.area, rel=1e-9)


box_specs = st.fixed_dictionaries({
    "cx": st.floats(-1.2, 1.2), "cz": st.floats(-1.25, 1.2), "w": st.floats(0.05, 0.8), "d": st.floats(0.05, 0.8),
    "angle": st.floats(0, np.pi), "y0": st.sampled_from([0.0, 0.0005, -0.0005]),
    "bottom": st.booleans(), "triangles": st.booleans()})


@settings(max_examples=40)
@given(boxes=st.lists(box_specs, min_size=1, max_size=3), roll=st.integers(0, 3))
def test_random_boxes_conserve_floor_area(boxes, roll):
    vertices, faces, owner = _scene(boxes, roll)
    _assert_tiles_floor(vertices, faces, owner)


@settings(max_examples=30)
@given(spec=box_specs, roll=st.integers(0, 3), corner=st.integers(0, 3), gap=st.floats(0.0, 0.1))
def test_random_boxes_near_corners(spec, roll, corner, gap):
    """A box pushed into one corner of the floor, up to ``gap`` from both walls (0: touching)."""
    c, s = np.cos(spec["angle"]), np.sin(spec["angle"])
    half = 0.5 * np.abs(np.array([[c, s], [-s, c]])).T @ [spec["w"], spec["d"]]  # half extents (x, z)
    sx, sz = [(-1, 1), (1, 1), (1, -1), (-1, -1)][corner]
    spec = dict(spec, cx=sx * (0.99 - gap - half[0]), cz=sz * (0.99 - gap - half[1]))
    vertices, faces, owner = _scene([spec], roll)
    _assert_tiles_floor(vertices, faces, owner)


def test_geos_failure_leaves_the_face_uncut(monkeypatch):
    """A TopologyException while cutting one face leaves it whole, with a note; area kept."""
    import warnings

    import radiosity
    from radiosity import imprint

    def broken(*args, **kwargs):
        raise shapely.errors.GEOSException("TopologyException: side location conflict at 0 0")

    monkeypatch.setattr(imprint, "_emit_part", broken)
    vertices, faces, owner = _scene([dict(NEAR_CORNER)], 1)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        patches, _, cut = subdivide_imprinted(vertices, faces, owner, 0.3)
    assert any(issubclass(w.category, radiosity.RadiosityWarning) and "left uncut" in str(w.message) for w in caught)
    quads = patches.quads[patches.patch_face == 0]
    assert sum(np.linalg.norm(_newell(q)) for q in quads) == pytest.approx(FLOOR_AREA, rel=1e-12)
    assert not patches.patch_hidden.any()


def test_lamp_under_the_ceiling_of_a_one_object_room_stays_lit():
    """A room exported as one mesh (walls and ceiling together), a lamp 0.5 mm under the ceiling.

    The walls' top edges lie within the contact tolerance of the lamp's plane and close into a
    loop around it; the ceiling, just behind the lamp, was taken for a block's top covering
    that footprint, and the whole lamp was hidden: a closed room lit by nothing (100% escaped).
    """
    room = [np.array(f, float) for f in (
        [[0, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]],  # floor, up
        [[0, 1, 0], [1, 1, 0], [1, 1, 1], [0, 1, 1]],  # ceiling, down
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],  # z = 0 wall, +z
        [[0, 0, 1], [0, 1, 1], [1, 1, 1], [1, 0, 1]],  # z = 1 wall, -z
        [[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]],  # x = 0 wall, +x
        [[1, 0, 0], [1, 0, 1], [1, 1, 1], [1, 1, 0]])]  # x = 1 wall, -x
    lamp = np.array([[0.4, 0.9995, 0.4], [0.6, 0.9995, 0.4], [0.6, 0.9995, 0.6], [0.4, 0.9995, 0.6]])
    centre = np.array([0.5, 0.5, 0.5])
    for f in room:
        assert _newell(f) @ (centre - f.mean(axis=0)) > 0
    assert _newell(lamp) @ UP < 0
    vertices = np.concatenate(room + [lamp])
    faces = [np.arange(4) + 4 * k for k in range(7)]
    owner = np.array([0] * 6 + [1])
    patches, _, cut = subdivide_imprinted(vertices, faces, owner, None)
    assert not patches.patch_hidden[patches.patch_face == 6].any(), "the lamp must not be hidden"
    ceiling = patches.patch_face == 1
    hidden_ceiling = sum(np.linalg.norm(_newell(q)) for q in patches.quads[ceiling & patches.patch_hidden])
    assert hidden_ceiling == pytest.approx(0.04, rel=1e-9)  # the ceiling behind the lamp


@pytest.mark.parametrize("corners", [0, 1, 2])
def test_faces_left_with_fewer_than_three_corners_have_no_area(corners):
    """A zero-area face reduced to one or two corners (the fuzzer's) has vector area 0, as in
    geometry.vector_areas, instead of an IndexError from inside the load."""
    from radiosity.geometry import vector_areas

    poly = np.arange(3.0 * corners).reshape(corners, 3)
    np.testing.assert_array_equal(_newell(poly), np.zeros(3))
    if corners:
        np.testing.assert_array_equal(vector_areas(poly[None])[0], np.zeros(3))

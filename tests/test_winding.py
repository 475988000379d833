"""Every cut keeps a face's winding: triangulation, subdivision, imprinting, the whole pipeline.

A face is one-sided (CONTRACT.md): it emits, reflects and receives on the side its
counter-clockwise winding points to. Each piece it is cut into must face the same way, for
every polygon shape and every orientation in space; a flipped piece silently receives nothing.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import radiosity
from radiosity.formfactors import polygon_to_polygon
from radiosity.imprint import subdivide_imprinted
from radiosity.geometry import vector_area as _newell
from radiosity.patches import subdivide_faces
from radiosity.geometry import triangulate

from helpers import write_obj


def _ring(xy) -> np.ndarray:
    xy = np.asarray(xy, float)
    return np.column_stack([xy, np.zeros(len(xy))])


def _star(points: int, inner: float) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, 2 * points, endpoint=False)
    r = np.where(np.arange(2 * points) % 2 == 0, 1.0, inner)
    return _ring(np.column_stack([r * np.cos(t), r * np.sin(t)]))


# Counter-clockwise seen from +z (normal +z) before they are rotated.
SHAPES = {
    "triangle": _ring([[0, 0], [1, 0], [0.3, 0.8]]),
    "convex quad": _ring([[0, 0], [1.2, 0.1], [1, 1], [-0.1, 0.9]]),
    "non-convex quad": _ring([[0, 0], [1, 0.5], [0, 1], [0.4, 0.5]]),  # a dart
    "pentagon": _ring([[np.cos(t), np.sin(t)] for t in np.linspace(0, 2 * np.pi, 5, endpoint=False)]),
    "L hexagon": _ring([[0, 0], [2, 0], [2, 0.7], [0.7, 0.7], [0.7, 2], [0, 2]]),
    "star": _star(5, 0.4),
    "comb": _ring([[0, 0], [3, 0], [3, 1], [2.5, 1], [2.5, 0.3], [2, 0.3], [2, 1], [1, 1], [1, 0.3],
                   [0.5, 0.3], [0.5, 1], [0, 1]]),
}


def _rotation_to(axis: np.ndarray) -> np.ndarray:
    """A rotation taking +z to the unit vector ``axis``."""
    z = np.array([0.0, 0.0, 1.0])
    v, c = np.cross(z, axis), float(z @ axis)
    if np.linalg.norm(v) < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1 + c)


AXES = {name: vec for name, vec in zip(("+x", "-x", "+y", "-y", "+z", "-z"), np.vstack([np.eye(3), -np.eye(3)])[[0, 3, 1, 4, 2, 5]])}


def _random_rotation(q: tuple[float, float, float, float]) -> np.ndarray:
    w, x, y, z = np.asarray(q) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


quaternions = st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 4).filter(lambda q: np.linalg.norm(q) > 0.1)


def _placed(shape: np.ndarray, rotation: np.ndarray, offset=(0.3, -0.2, 0.5)) -> np.ndarray:
    return shape @ rotation.T + np.asarray(offset)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _patch_normals(quads: np.ndarray) -> np.ndarray:
    return np.array([_newell(q) for q in quads])


def _assert_faces_like(pieces: np.ndarray, face: np.ndarray) -> None:
    """Every piece points along the face's Newell normal, and the pieces tile its area."""
    normal = _newell(face)
    normals = _patch_normals(pieces)
    areas = np.linalg.norm(normals, axis=1)
    keep = areas > 1e-12 * np.linalg.norm(normal)
    cosines = normals[keep] @ _unit(normal) / areas[keep]
    np.testing.assert_allclose(cosines, 1.0, atol=1e-9)
    assert areas.sum() == pytest.approx(np.linalg.norm(normal), rel=1e-12)


# ----------------------------------------------------------------------------- triangulate
@pytest.mark.parametrize("axis", AXES)
@pytest.mark.parametrize("shape", SHAPES)
def test_triangulate_keeps_winding_on_every_axis(shape, axis):
    face = _placed(SHAPES[shape], _rotation_to(AXES[axis]))
    assert _unit(_newell(face)) @ AXES[axis] == pytest.approx(1.0)
    _assert_faces_like(triangulate(face), face)
    _assert_faces_like(triangulate(face[::-1].copy()), face[::-1].copy())  # and the back side


@settings(max_examples=40)
@given(q=quaternions, shape=st.sampled_from(sorted(SHAPES)))
def test_triangulate_keeps_winding_in_random_orientations(q, shape):
    face = _placed(SHAPES[shape], _random_rotation(q))
    _assert_faces_like(triangulate(face), face)


# ----------------------------------------------------------------------------- subdivision
@pytest.mark.parametrize("size", [None, 0.35])
@pytest.mark.parametrize("axis", AXES)
@pytest.mark.parametrize("shape", SHAPES)
def test_subdivision_keeps_winding(shape, axis, size):
    face = _placed(SHAPES[shape], _rotation_to(AXES[axis]))
    patches, report = subdivide_faces(face, [np.arange(len(face))], size)
    assert not report.degenerate and not report.nonplanar
    _assert_faces_like(patches.quads, face)


@settings(max_examples=30)
@given(q=quaternions, shape=st.sampled_from(sorted(SHAPES)), size=st.sampled_from([None, 0.3, 0.7]))
def test_subdivision_keeps_winding_in_random_orientations(q, shape, size):
    face = _placed(SHAPES[shape], _random_rotation(q))
    patches, _ = subdivide_faces(face, [np.arange(len(face))], size)
    _assert_faces_like(patches.quads, face)


# ----------------------------------------------------------------------------- imprinting
def _with_block(face: np.ndarray, rotation: np.ndarray, offset) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """The face plus a small open block (no bottom) standing on it, inside its outline."""
    base = _ring([[0.05, 0.05], [0.25, 0.08], [0.22, 0.28], [0.06, 0.25]])
    top = base + [0, 0, 0.2]
    block = _placed(np.concatenate([base, top]), rotation, offset)
    n = len(face)
    sides = [np.array([i, (i + 1) % 4, (i + 1) % 4 + 4, i + 4]) + n for i in range(4)]
    faces = [np.arange(n), np.array([4, 5, 6, 7]) + n, *sides]
    return np.concatenate([face, block]), faces, np.array([0] + [1] * 5)


@pytest.mark.parametrize("size", [None, 0.35])
@pytest.mark.parametrize("axis", AXES)
@pytest.mark.parametrize("shape", ["convex quad", "pentagon", "L hexagon", "star"])
def test_imprinting_keeps_winding(shape, axis, size):
    rotation, offset = _rotation_to(AXES[axis]), np.array([0.3, -0.2, 0.5])
    face = _placed(SHAPES[shape], rotation, offset)
    vertices, faces, face_object = _with_block(face, rotation, offset)
    patches, _, cut = subdivide_imprinted(vertices, faces, face_object, size)
    assert cut.contacts, "the block's foot must imprint the face"
    _assert_faces_like(patches.quads[patches.patch_face == 0], face)


# ----------------------------------------------------------------------------- form factors
@pytest.mark.parametrize("axis", AXES)
def test_pentagon_receiver_sees_what_its_pieces_see(axis):
    """F(pentagon -> source) is the area-weighted mean of F(piece -> source) over a split by hand."""
    rotation = _rotation_to(AXES[axis])
    pentagon = _placed(SHAPES["pentagon"], rotation, (0, 0, 0))
    source = _placed(_ring([[-0.4, -0.4], [0.4, -0.4], [0.4, 0.4], [-0.4, 0.4]])[::-1] + [0, 0, 1.0],
                     rotation, (0, 0, 0))
    pieces = [pentagon[[0, 1, 2, 3]], pentagon[[0, 3, 4]]]
    areas = [np.linalg.norm(_newell(p)) for p in pieces]
    by_hand = sum(a * polygon_to_polygon(p, source) for a, p in zip(areas, pieces)) / sum(areas)
    assert by_hand > 0.1
    assert polygon_to_polygon(pentagon, source) == pytest.approx(by_hand, rel=1e-5)


# ----------------------------------------------------------------------------- radiosity
def _lit_floor_scene(tmp_path, name: str, floor_pieces: list[np.ndarray], rotation: np.ndarray) -> str:
    """A floor facing a square lamp 1 m above it (lamp: black, emitting); the whole scene rotated."""
    lamp = _ring([[-0.3, -0.3], [0.3, -0.3], [0.3, 0.3], [-0.3, 0.3]])[::-1] + [0, 0, 1.0]
    objects = {"floor": [p @ rotation.T for p in floor_pieces], "lamp": [lamp @ rotation.T]}
    materials = {"white": ((0.5, 0.5, 0.5), (0, 0, 0)), "lamp": ((0, 0, 0), (1, 1, 1))}
    return write_obj(tmp_path / f"{name}.obj", objects, materials, {"floor": "white", "lamp": "lamp"})


def _floor_radiosity(path: str) -> tuple[float, np.ndarray]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", radiosity.RadiosityWarning)
        solution = radiosity.solve(radiosity.load_scene(path), preset="draft", cache=False)
    scene = solution.scene
    return float(solution.object_radiosity()["floor"][0]), scene.patch_normal[scene.patch_object == 0]


@pytest.mark.parametrize("axis", ["+x", "-x", "+y", "-z", "random"])
@pytest.mark.parametrize("shape", ["pentagon", "L hexagon"])
def test_ngon_floor_radiosity_matches_the_floor_split_by_hand(tmp_path, shape, axis):
    """The n-gon floor receives what the same floor cut by hand into triangles receives.

    With a black lamp and one reflecting surface, the floor's area-mean radiosity is
    rho * (power from the lamp landing on it) / area, whatever its patches: the two must agree
    to the form factors' accuracy. A flipped floor received nothing (radiosity 0).
    """
    rotation = _random_rotation((0.3, -0.5, 0.7, 0.2)) if axis == "random" else _rotation_to(AXES[axis])
    floor = SHAPES[shape] - SHAPES[shape].mean(axis=0)
    fan = [floor[[0, k, k + 1]] for k in range(1, len(floor) - 1)]
    if shape == "L hexagon":  # a split unlike the fan, through the inner corner
        fan = [floor[[0, 1, 3]], floor[[1, 2, 3]], floor[[0, 3, 4]], floor[[0, 4, 5]]]
    whole, whole_normals = _floor_radiosity(_lit_floor_scene(tmp_path, "whole", [floor], rotation))
    split, _ = _floor_radiosity(_lit_floor_scene(tmp_path, "split", fan, rotation))
    up = rotation @ np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(whole_normals @ up, 1.0, atol=1e-9)
    assert split > 0.02
    assert whole == pytest.approx(split, rel=2e-3)

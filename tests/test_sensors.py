"""Sensor irradiance (``Solution.irradiance``): exact shadows, every face blocks, bounded error.

References: a brute-force gather (each source cut into 48 x 48 cells, Lambert's closed form per
cell, one Embree ray per cell, independent of the exact-shadow kernels), closed scenes where
the right answer is 0, and the invariances a per-point computation must have.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import radiosity
from radiosity.scene import bundled_scene
from radiosity.visibility._embree import EmbreeOccluder
from radiosity.visibility._exact import point_factors
from radiosity.visibility._points import SensorGather, clusters, inside_hull

UP = np.array([0.0, 1.0, 0.0])
# A line across the floor penumbra of the short block (x from the red wall towards the block).
PENUMBRA = np.column_stack([[0.005, 0.02, 0.03, 0.05, 0.075, 0.09], np.zeros(6), np.full(6, 0.2)])


@pytest.fixture(scope="module")
def cornell():
    return radiosity.solve(radiosity.load_scene(bundled_scene("cornell_box")), preset="draft")


@pytest.fixture(scope="module")
def cube():
    """The bundled closed unit cube: faces wound inwards, the top emits."""
    return radiosity.solve(radiosity.load_scene(bundled_scene("unit_cube")), preset="draft")


def brute_force(solution, points, normals, cells=48):
    """H at points by cutting each lit source into cells x cells bilinear cells: Lambert's form
    factor of each cell times one ray to its centre (Embree, against every patch)."""
    scene = solution.scene
    quads = scene.patch_quads
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    area = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    tracer = EmbreeOccluder(tris[area > 0])
    lit = np.flatnonzero(solution.radiosity.any(axis=1))
    t = np.linspace(0, 1, cells + 1)
    u0, v0 = np.meshgrid(t[:-1], t[:-1], indexing="ij")
    corners = np.stack([(u0, v0), (u0 + 1 / cells, v0), (u0 + 1 / cells, v0 + 1 / cells), (u0, v0 + 1 / cells)])
    uv = corners.reshape(4, 2, -1).transpose(2, 0, 1)  # (cells^2, 4, 2)
    out = np.zeros((len(points), 3))
    for p, (x, n) in enumerate(zip(points, normals)):
        facing = np.einsum("jc,jc->j", x - scene.patch_centroid[lit], scene.patch_normal[lit]) > 0
        for j in lit[facing]:
            q = quads[j]
            u, v = uv[..., 0:1], uv[..., 1:2]
            cell = (1 - u) * (1 - v) * q[0] + u * (1 - v) * q[1] + u * v * q[2] + (1 - u) * v * q[3]
            f = point_factors(np.repeat(x[None], len(cell), 0), np.repeat(n[None], len(cell), 0), cell)
            centre = cell.mean(axis=1)
            start = x + 1e-7 * n
            end = centre + 1e-6 * (start - centre)
            seen = ~tracer.occluded(np.repeat(start[None], len(cell), 0), end)
            out[p] += (f * seen).sum() * solution.radiosity[j]
    return out


def test_penumbra_matches_brute_force_within_half_a_percent(cornell):
    normals = np.tile(UP, (len(PENUMBRA), 1))
    ref = brute_force(cornell, PENUMBRA[:5], normals[:5])
    got = cornell.irradiance(PENUMBRA[:5], normals[:5])
    assert ref[:, 1].max() > 1.3 * ref[:, 1].min()  # the line does cross a penumbra
    np.testing.assert_allclose(got, ref, rtol=5e-3)


def test_rtol_bounds_the_error_against_exact_shadows(cornell):
    rng = np.random.default_rng(3)
    points = np.column_stack([rng.uniform(0, 0.55, 200), np.zeros(200), rng.uniform(0, 0.55, 200)])
    normals = np.tile(UP, (200, 1))
    exact = cornell.irradiance(points, normals, sensor_rtol=0.0)
    for rtol in (1e-3, 1e-2):
        got = cornell.irradiance(points, normals, sensor_rtol=rtol)
        assert (np.abs(got - exact) <= rtol * exact + 1e-12).all()


@settings(max_examples=10, deadline=None)
@given(st.permutations(range(12)), st.integers(0, 11))
def test_a_value_does_not_depend_on_other_points_or_its_row(cornell_points, order, repeat):
    solution, points, normals, alone = cornell_points
    rows = np.array(order + [repeat, repeat, repeat])
    got = solution.irradiance(points[rows], normals[rows])
    np.testing.assert_allclose(got, alone[rows], rtol=1e-13, atol=1e-15)


@pytest.fixture(scope="module")
def cornell_points(cornell):
    """Twelve points (floor penumbrae, walls, mid-air, tilted) and each one's value computed alone."""
    rng = np.random.default_rng(5)
    points = np.r_[PENUMBRA, rng.uniform([0.05, 0.02, 0.05], [0.5, 0.5, 0.5], (6, 3))]
    normals = np.r_[np.tile(UP, (6, 1)), rng.normal(size=(6, 3))]
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    alone = np.concatenate([cornell.irradiance(p[None], n[None]) for p, n in zip(points, normals)])
    return cornell, points, normals, alone


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-3, 3), min_size=3, max_size=3), st.lists(st.floats(-1, 1), min_size=3, max_size=3))
def test_points_outside_the_closed_cube_read_zero(cube, xyz, direction):
    x = np.array(xyz)
    n = np.array(direction)
    if np.abs(x - 0.5).max() <= 0.5 + 1e-6 or np.linalg.norm(n) < 1e-3:
        return  # inside (or on) the cube, or no direction
    # 0, up to round-off where the point lies in the planes of two faces and sees a sliver of a
    # third along their common edge (hypothesis finds such points: 5e-17)
    assert (cube.irradiance(x[None], n[None]) <= 1e-12).all()


def test_closed_cube_under_the_floor_and_on_every_side(cube):
    points = np.array([[0.5, 0.5, -1.0], [0.5, 0.5, 2.0], [-1, 0.5, 0.5], [2, 0.5, 0.5], [0.5, -0.5, 0.5],
                       [0.5, 1.5, 0.5], [0.5, 0.5, -1e-6], [1 + 1e-6, 0.5, 0.5]])
    for n in np.r_[np.eye(3), -np.eye(3)]:
        assert (cube.irradiance(points, np.tile(n, (len(points), 1))) == 0).all()
    inside = cube.irradiance([[0.5, 0.5, 0.0], [0.5, 0.5, 0.5]], [[0, 0, 1], [0, 0, 1]])
    assert (inside > 0).all()  # the same room lights its own floor and its middle


def test_inside_a_solid_block_and_under_the_floor_read_zero(cornell):
    # inside the tall block (a closed solid standing on the floor), under the floor, behind the back wall
    points = np.array([[0.37, 0.1, 0.35], [0.37, 0.32, 0.35], [0.28, -1.0, 0.28], [0.28, 0.27, 0.6]])
    for n in np.r_[np.eye(3), -np.eye(3)]:
        assert (cornell.irradiance(points, np.tile(n, (len(points), 1))) == 0).all()


def test_hull_faces_change_nothing_inside_the_hull(cornell):
    """Faces on the convex hull block nothing between points of the hull: the kernel with every
    face as an occluder gives what it gives with the hull's faces left out."""
    cornell.irradiance(PENUMBRA[:1], UP[None])
    gather: SensorGather = cornell._sensors
    rng = np.random.default_rng(7)
    points = rng.uniform([0, 0, 0], [0.55, 0.55, 0.55], (40, 3))
    normals = rng.normal(size=(40, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    assert inside_hull(points, gather.quads.reshape(-1, 3), gather.tol).all()
    inner = gather._gather(points, normals, gather.inner, 0.0)
    outer = gather._gather(points, normals, gather.outer, 0.0)
    np.testing.assert_allclose(outer, inner, rtol=1e-10, atol=1e-14)


def test_union_fallback_agrees_with_the_kernel(cornell):
    cornell.irradiance(PENUMBRA[:1], UP[None])
    gather = cornell._sensors
    normals = np.tile(UP, (len(PENUMBRA), 1))
    np.testing.assert_allclose(gather._gather_united(PENUMBRA, normals, gather.inner),
                               gather._gather(PENUMBRA, normals, gather.inner, 0.0), rtol=1e-10, atol=1e-12)


def test_clusters_cover_every_point_once():
    points = np.random.default_rng(1).normal(size=(1000, 3))
    members, starts = clusters(points)
    assert sorted(members) == list(range(1000)) and starts[0] == 0 and starts[-1] == 1000


def test_huge_and_tiny_normals_keep_their_direction(cornell):
    x = PENUMBRA[2:3]
    base = cornell.irradiance(x, UP[None])
    for scale in (1e-300, 1e300):
        np.testing.assert_array_equal(cornell.irradiance(x, scale * UP[None]), base)


def test_bad_rtol_is_refused(cornell):
    for bad in (-1e-3, 1.0, float("nan")):
        with pytest.raises(ValueError, match="rtol"):
            cornell.irradiance(PENUMBRA[:1], UP[None], sensor_rtol=bad)


def test_a_panel_flush_on_a_luminous_ceiling_hides_it_from_a_sensor(tmp_path):
    """A black panel flush on a luminous ceiling covers (imprint.py) the ceiling's patches above
    it. Those send nothing in the solve, and the sensors must not see them either: the segment
    from a sensor to them meets the flush panel at its end only, so the gather once read their
    emission through it, 31.6x the light under the same panel hung 1 cm lower."""
    import warnings

    from helpers import axis_box, write_obj

    room = axis_box((0, 0, 0), (4, 3, 2.5), inward=True)
    ceiling = [f for f in room if np.allclose(f[:, 2], 2.5)]
    walls = [f for f in room if not np.allclose(f[:, 2], 2.5)]
    materials = {"grey": ((0.5,) * 3, (0.0,) * 3), "lum": ((0.5,) * 3, (1.0,) * 3), "black": ((0.0,) * 3, (0.0,) * 3)}
    sensor = {}
    for name, z in (("flush", 2.5), ("hung", 2.49)):
        panel = np.array([[1.5, 1, z], [1.5, 2, z], [2.5, 2, z], [2.5, 1, z]], float)  # faces down
        path = write_obj(tmp_path / f"{name}.obj", {"walls": walls, "ceiling": ceiling, "panel": [panel]}, materials,
                         {"walls": "grey", "ceiling": "lum", "panel": "black"})
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", radiosity.RadiosityWarning)
            scene = radiosity.load_scene(path, emission="exitance")
        assert scene.patch_hidden.any() == (name == "flush")
        solution = radiosity.solve(scene, preset="draft", cache=False)
        points = np.array([[2.0, 1.5, z - 0.1], [2.0, 1.5, 1.0], [2.0, 1.5, 0.0]])
        sensor[name] = solution.irradiance(points, np.tile([0.0, 0.0, 1.0], (3, 1)), sensor_rtol=0)[:, 0]
    # the 1 cm gap lets a little more light round the hung panel's edges onto the nearest sensor
    np.testing.assert_allclose(sensor["flush"], sensor["hung"], rtol=0.05)


def test_sensors_on_edges_and_corners_read_what_their_neighbours_read(tmp_path):
    """In a furnace room (every face E = 1, rho = 0.5: H = 2 at every point inside) with a box on
    its floor, a sensor exactly where the floor meets a wall lies in the wall's plane, which is
    then at grazing: it read 1.0, at the room's corner 0.5, at the box's foot 1.0 and at its
    corner 1.5. Points on surfaces in two or more planes are now taken just off them."""
    import warnings

    from helpers import axis_box, write_obj

    box = [f for f in axis_box((1, 1, 0), (2, 2, 1), inward=False) if not np.allclose(f[:, 2], 0)]
    path = write_obj(tmp_path / "furnace.obj", {"room": axis_box((0, 0, 0), (4, 3, 2.5), inward=True), "box": box},
                     {"furnace": ((0.5,) * 3, (1.0,) * 3)})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", radiosity.RadiosityWarning)
        solution = radiosity.solve(radiosity.load_scene(path, emission="exitance"), preset="draft", cache=False)
    up = [0.0, 0.0, 1.0]
    points = np.array([[0, 1.5, 0], [0, 0, 0], [2, 1.5, 0], [2, 2, 0], [0, 0, 0], [3, 2.5, 0], [2, 1.5, 0.5]])
    normals = np.array([up, up, up, up, [1, 1, 1], up, [1, 0, 0]], float)
    np.testing.assert_allclose(solution.irradiance(points, normals, sensor_rtol=0)[:, 0], 2.0, rtol=2e-3)

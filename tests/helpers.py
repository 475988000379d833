"""Canonical geometries with their reference values (see ../shared/FIELD_NOTES.md), and the
builders and checks several test modules share (test modules import from here, not from each
other)."""

from __future__ import annotations

from pathlib import Path

import mpmath as mp
import numpy as np

DATA = Path(__file__).parent / "data"
ROOM = DATA / "room.obj"  # the small room the CLI tests solve

UNIT_SQUARE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)  # normal +z


def square_at(z: float, *, facing_down: bool = True) -> np.ndarray:
    """Unit square at height z, wound so its normal points down (towards z = 0) by default."""
    sq = UNIT_SQUARE.copy()
    sq[:, 2] = z
    return sq[::-1].copy() if facing_down else sq


# Parallel unit squares, directly opposed, separated by the key (Howell C-11).
PARALLEL_SQUARES = {1.0: 0.1998248957, 0.1: 0.8269945224, 10.0: 0.0031620568}
# Perpendicular unit squares sharing an edge (Howell C-14).
PERPENDICULAR_SQUARES = 0.2000437761
WALL_X0 = np.array([[0, 0, 0], [0, 0, 1], [0, 1, 1], [0, 1, 0]], dtype=float)  # x = 0, normal -x (reverse it to face +x)
# Parallel squares 1 apart with a centred 0.5 x 0.5 blocker midway.
BLOCKED_PARALLEL_SQUARES = 0.0995062946
# Coaxial disks, radius = distance: (3 - sqrt 5) / 2.
COAXIAL_DISKS = 0.3819660113
# A unit cube without its top, faces looking in: every row sums to 0.8.
OPEN_BOX = """v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
o bottom
f 1 2 3 4
o front
f 1 5 6 2
o back
f 4 3 7 8
o left
f 1 4 8 5
o right
f 2 6 7 3
"""


def corner_point_factor(a: float, b: float, c: float) -> float:
    """Point under the corner of an a x b rectangle at height c, facing it (Howell B-3)."""
    x, y = a / c, b / c
    return (x / np.sqrt(1 + x * x) * np.arctan(y / np.sqrt(1 + x * x))
            + y / np.sqrt(1 + y * y) * np.arctan(x / np.sqrt(1 + y * y))) / (2 * np.pi)


def regular_polygon(radius: float, sides: int, z: float = 0.0, *, facing_down: bool = False) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    poly = np.column_stack([radius * np.cos(t), radius * np.sin(t), np.full(sides, z)])
    return poly[::-1].copy() if facing_down else poly


def write_obj(path, objects: dict[str, list[np.ndarray]], materials: dict[str, tuple] | None = None,
              object_material: dict[str, str] | None = None) -> str:
    """Write a small OBJ (+ MTL) from {object: [polygon (k, 3), ...]}; returns the OBJ path.

    ``materials`` maps a material name to (kd, ke) triples; ``object_material`` picks one per
    object (default: the first material).
    """
    from pathlib import Path

    path = Path(path)
    materials = materials or {"grey": ((0.5, 0.5, 0.5), (0.0, 0.0, 0.0))}
    mtl = path.with_suffix(".mtl")
    mtl.write_text("".join(f"newmtl {name}\nKd {kd[0]} {kd[1]} {kd[2]}\nKe {ke[0]} {ke[1]} {ke[2]}\n\n"
                           for name, (kd, ke) in materials.items()))
    lines = [f"mtllib {mtl.name}"]
    vid = 1
    first = next(iter(materials))
    for name, polys in objects.items():
        lines += [f"o {name}", f"usemtl {(object_material or {}).get(name, first)}"]
        for poly in polys:
            lines += ["v %.17g %.17g %.17g" % tuple(v) for v in poly]
            lines.append("f " + " ".join(str(vid + k) for k in range(len(poly))))
            vid += len(poly)
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def parallel_rectangles_mp(a, b, c):
    """Howell C-11: directly opposed a x b rectangles a distance c apart (mpmath, 30 digits)."""
    with mp.workdps(30):
        X, Y = mp.mpf(a) / c, mp.mpf(b) / c
        t = (mp.log(mp.sqrt((1 + X**2) * (1 + Y**2) / (1 + X**2 + Y**2)))
             + X * mp.sqrt(1 + Y**2) * mp.atan(X / mp.sqrt(1 + Y**2))
             + Y * mp.sqrt(1 + X**2) * mp.atan(Y / mp.sqrt(1 + X**2)) - X * mp.atan(X) - Y * mp.atan(Y))
        return 2 * t / (mp.pi * X * Y)


def perpendicular_rectangles_mp(l, w, h):
    """Howell C-14: w x l rectangle to a perpendicular h x l rectangle sharing the edge l
    (mpmath, 30 digits)."""
    with mp.workdps(30):
        H, W = mp.mpf(h) / l, mp.mpf(w) / l
        s = H**2 + W**2
        t = (W * mp.atan(1 / W) + H * mp.atan(1 / H) - mp.sqrt(s) * mp.atan(1 / mp.sqrt(s))
             + (mp.log((1 + W**2) * (1 + H**2) / (1 + s)) + W**2 * mp.log(W**2 * (1 + s) / ((1 + W**2) * s))
                + H**2 * mp.log(H**2 * (1 + s) / ((1 + H**2) * s))) / 4)
        return t / (mp.pi * W)


# ---------------------------------------------------------------- View3D models (.vs3 text)
# Parallel unit plates 1 apart with a centred 0.5 x 0.5 blocker midway (BLOCKED_PARALLEL_SQUARES).
PLATES = """T parallel plates with a blocker
C eps=1e-4
F 3
! the lower plate faces up, the upper one down
V 1 0 0 0
V 2 1 0 0
V 3 1 1 0
V 4 0 1 0
V 5 0 0 1
V 6 0 1 1
V 7 1 1 1
V 8 1 0 1
V 9 0.25 0.25 0.5
V 10 0.75 0.25 0.5
V 11 0.75 0.75 0.5
V 12 0.25 0.75 0.5
S 1 1 2 3 4 0 0 0.9 lower
S 2 5 6 7 8 0 0 0.8 upper
O 3 9 10 11 12 0 0 0 blocker
E
"""

# A 4 x 3 x 2.5 m room, every surface facing in; a door (on the floor edge) and a window in the
# south wall (y = 0) are its subsurfaces (base 3). Comments after the data, as View3D allows.
ROOM_VS3 = """T room with a door and a window in the south wall
C encl=1 eps=1e-6
F 3
V 1 0 0 0
V 2 4 0 0
V 3 4 3 0
V 4 0 3 0
V 5 0 0 2.5
V 6 4 0 2.5
V 7 4 3 2.5
V 8 0 3 2.5
V 9 0.5 0 0
V 10 1.4 0 0
V 11 1.4 0 2
V 12 0.5 0 2
V 13 2 0 1
V 14 3.5 0 1
V 15 3.5 0 2
V 16 2 0 2
!  #  v1 v2 v3 v4 base cmb emit name
S 1   1  2  3  4   0   0  0.9  floor     ! faces up
S 2   8  7  6  5   0   0  0.9  ceiling   ! faces down
S 3   1  5  6  2   0   0  0.9  south     / faces north
S 4   4  3  7  8   0   0  0.9  north
S 5   1  4  8  5   0   0  0.9  west
S 6   2  6  7  3   0   0  0.9  east
S 7   9 12 11 10   3   0  0.6  door      ! in the south wall
S 8  13 16 15 14   3   0  0.1  window
E
"""

# The same unit cube in format 3a: rectangles by origin, azimuth, tilt, width and height;
# the north wall as a general quadrilateral, the top as two triangles; a blocker obstruction.
CUBE_3A = """T unit cube, F 3a
F 3a
!  #  shape base cmb emit name
S 1 R 0 0 0.5 bottom
  1 1 0   0 0     1 1
S 2 R 0 0 0.5 south   ! faces north (azimuth 0), vertical
  1 0 0   0 90    1 1
S 3 Q 0 0 0.5 north
  0 1 0   180 90
  0 0  1 0  1 1  0 1
S 4 R 0 0 0.5 west
  0 0 0   90 90   1 1
S 5 R 0 0 0.5 east
  1 1 0   270 90  1 1
S 6 T 0 0 0.5 top
  1 0 1   0 180   0 0  1 0  1 1
S 7 T 0 6 0.5 top_b
  1 0 1   0 180   0 0  1 1  0 1
O 8 R
  0.75 0.75 0.5  0 0  0.5 0.5
E
"""


# ---------------------------------------------------------------- builders shared by test modules
def polygon_area(poly: np.ndarray) -> float:
    """Area of a planar polygon (k, 3): the centred Newell sum, written out independently of
    ``radiosity.geometry`` (an oracle for it)."""
    centred = poly - poly.mean(axis=0)
    return 0.5 * float(np.linalg.norm(np.cross(centred, np.roll(centred, -1, axis=0)).sum(axis=0)))


def grid(n, z, *, down, x0=0.0, x1=1.0, y0=0.0, y1=1.0):
    """An (x0..x1) x (y0..y1) rectangle at height z cut into n x n patches (n*n, 4, 3), facing
    +z (down=False) or -z; down=True reverses each quad's winding but keeps the patch order."""
    xs, ys = np.linspace(x0, x1, n + 1), np.linspace(y0, y1, n + 1)
    a, b = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a, b = a.ravel(), b.ravel()
    q = np.stack([np.column_stack([xs[a], ys[b]]), np.column_stack([xs[a + 1], ys[b]]),
                  np.column_stack([xs[a + 1], ys[b + 1]]), np.column_stack([xs[a], ys[b + 1]])], axis=1)
    q = np.concatenate([q, np.full(q.shape[:2] + (1,), float(z))], axis=2)
    return q[:, ::-1].copy() if down else q


def rect(x0, x1, y0, y1, z, *, down=False):
    """One (x0..x1) x (y0..y1) quad at height z facing +z (or -z)."""
    q = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], float)
    return q[::-1].copy() if down else q


def boxes_scene():
    """Floor, ceiling and two boxes (10 occluder faces) between them: a small Cornell box.

    Returns (quads (n, 4, 3), groups (n,)), one group per part."""
    def box(x0, x1, y0, y1, h):
        c = [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
        faces = [rect(x0, x1, y0, y1, h)]
        for k in range(4):
            (a0, b0), (a1, b1) = c[k], c[(k + 1) % 4]
            faces.append(np.array([[a0, b0, 0], [a1, b1, 0], [a1, b1, h], [a0, b0, h]], float))
        return faces

    parts = [grid(8, 0, down=False), grid(4, 1, down=True), np.array(box(0.2, 0.45, 0.2, 0.5, 0.6)),
             np.array(box(0.55, 0.8, 0.4, 0.7, 0.35))]
    groups = np.repeat(np.arange(len(parts)), [len(p) for p in parts])
    return np.concatenate(parts), groups


def make_vis(quads, groups=None, **kw):
    """A Visibility of the patches ``quads`` (one object each unless ``groups``), scaled by
    their bounding box; ``kw`` go to Visibility."""
    from radiosity.geometry import polygon_normals
    from radiosity.visibility import Visibility

    quads = np.asarray(quads, float)
    groups = np.arange(len(quads)) if groups is None else np.asarray(groups)
    scale = float(np.linalg.norm(np.ptp(quads.reshape(-1, 3), axis=0)))
    return Visibility(quads, polygon_normals(quads), groups, scale, **kw)


def all_pairs(n):
    """(i, j) of every ordered pair i != j of n patches."""
    i, j = np.nonzero(~np.eye(n, dtype=bool))
    return i, j


def prism(radius: float, length: float, sides: int, *, inward: bool, z0: float = 0.0) -> list[np.ndarray]:
    """A closed regular prism: walls as quads, caps as triangle fans (facing out, or in)."""
    t = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ring = np.column_stack([radius * np.cos(t), radius * np.sin(t)])
    polys = []
    for k in range(sides):
        a, b = ring[k], ring[(k + 1) % sides]
        polys.append(np.array([[*a, z0], [*b, z0], [*b, z0 + length], [*a, z0 + length]]))
    for z, up in ((z0, False), (z0 + length, True)):
        for k in range(sides):
            a, b = ring[k], ring[(k + 1) % sides]
            tri = np.array([[0.0, 0.0, z], [*a, z], [*b, z]])
            polys.append(tri if up else tri[::-1])
    return [p[::-1].copy() for p in polys] if inward else polys


def fill(parts, settings, *, groups=None, **vis_kw):
    """The uniform fill of the patches ``parts`` (a list of (n_k, 4, 3), one object each unless
    ``groups``) with ``settings`` (a FillSettings): (F as a dense array, areas, stats)."""
    from radiosity.geometry import centroids_and_areas, polygon_normals
    from radiosity.methods.uniform.assembly import assemble
    from radiosity.visibility import Visibility

    quads = np.concatenate(parts)
    groups = np.repeat(np.arange(len(parts)), [len(p) for p in parts]) if groups is None else groups
    normals = polygon_normals(quads)
    centroid, area = centroids_and_areas(quads)
    scale = float(np.linalg.norm(np.ptp(quads.reshape(-1, 3), axis=0)))
    vis = Visibility(quads, normals, groups, scale, samples=settings.visibility_samples,
                     max_samples=settings.visibility_max_samples, **vis_kw)
    F, stats = assemble(quads, normals, centroid, area, vis, settings)
    return F.toarray(), area, stats


def plate_total(F, area, n):
    """A F summed from the first n x n plate of a fill to the second: the plate-to-plate factor
    times the plate's area."""
    m = n * n
    return float((area[:m, None] * F[:m, m:2 * m]).sum())


# ---------------------------------------------------------------- command line
def solve_args(out: Path, *extra: str, scene: Path | None = ROOM) -> list[str]:
    """Arguments of a quick ``radiosity solve`` (draft, no picture) of ``scene`` into ``out``."""
    return ["solve", *([str(scene)] if scene else []), "--preset", "draft", "--no-picture", "-o", str(out), *extra]


def assert_one_line_error(capsys, code: int, *parts: str) -> str:
    """The CLI failed with exit code 2 and one line ``radiosity: error: ...`` holding ``parts``
    (no traceback); returns that line."""
    captured = capsys.readouterr()
    assert code == 2, captured.err
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("radiosity: error: ")
    assert "Traceback" not in captured.err
    for part in parts:
        assert part in lines[0], lines[0]
    return lines[0]


# --- Lambert's formula in mpmath: the reference of tests/test_extremes.py and bench/bench_extremes.py
def mp_vector(v):
    return [c if isinstance(c, mp.mpf) else mp.mpf(float(c)) for c in v]


def vec_sub(a, b):
    return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]


def vec_dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def vec_cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def lambert_mp(x, n, poly, dps=40):
    """Form factor from the point ``x`` (normal ``n``, need not be unit) to ``poly`` in mpmath.

    The polygon is clipped to the receiver's upper half-space first; a receiver in the
    polygon's plane gets 0 (the source is seen edge-on). Returns an mpf.
    """
    with mp.workdps(dps):
        x, n = mp_vector(x), mp_vector(n)
        nn = mp.sqrt(vec_dot(n, n))
        n = [c / nn for c in n]
        rel = [vec_sub(mp_vector(p), x) for p in poly]
        k = len(rel)
        # receiver in the source's plane: exactly zero (Newell normal, exact in mpmath)
        N = [mp.mpf(0)] * 3
        for i in range(k):
            c = vec_cross(rel[i], rel[(i + 1) % k])
            N = [N[0] + c[0], N[1] + c[1], N[2] + c[2]]
        if vec_dot(N, N) == 0 or vec_dot(N, rel[0]) == 0:
            return mp.mpf(0)
        h = [vec_dot(p, n) for p in rel]
        clipped = []
        for i in range(k):
            j = (i + 1) % k
            if h[i] >= 0:
                clipped.append(rel[i])
            if (h[i] > 0 > h[j]) or (h[i] < 0 < h[j]):
                t = h[i] / (h[i] - h[j])
                clipped.append([rel[i][c] + t * (rel[j][c] - rel[i][c]) for c in range(3)])
        total = mp.mpf(0)
        for i in range(len(clipped)):
            a, b = clipped[i], clipped[(i + 1) % len(clipped)]
            cr = vec_cross(a, b)
            s = mp.sqrt(vec_dot(cr, cr))
            if s == 0:
                continue
            total += mp.atan2(s, vec_dot(a, b)) / s * vec_dot(cr, n)
        return abs(total) / (2 * mp.pi)


def sphere_shell(subdivisions: int, radius: float = 1.0) -> np.ndarray:
    """(20 m^2, 3, 3) triangles of a geodesic sphere (icosahedron faces cut m x m), wound inward.

    A closed furnace: every face sees the others only, so with emission E and reflectance rho
    everywhere B = E / (1 - rho) exactly (and F_ij = A_j / A_total).
    """
    t = (1 + 5 ** 0.5) / 2
    ico = np.array([(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
                    (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)], float)
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
             (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5),
             (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    m = int(subdivisions)
    i, j = np.meshgrid(np.arange(m + 1), np.arange(m + 1), indexing="ij")
    keep = i + j <= m
    i, j = i[keep], j[keep]
    index = -np.ones((m + 1, m + 1), int)
    index[i, j] = np.arange(len(i))
    up = [(index[a, b], index[a + 1, b], index[a, b + 1]) for a in range(m) for b in range(m - a)]
    down = [(index[a + 1, b], index[a + 1, b + 1], index[a, b + 1]) for a in range(m) for b in range(m - a - 1)]
    local = np.array(up + down)
    tris = []
    for f in faces:
        p0, p1, p2 = ico[list(f)]
        pts = p0 + np.outer(i / m, p1 - p0) + np.outer(j / m, p2 - p0)
        pts = radius * pts / np.linalg.norm(pts, axis=1, keepdims=True)
        tris.append(pts[local])
    tris = np.concatenate(tris)
    return tris[:, ::-1].copy()  # icosahedron faces wind outward: reverse to face the inside


def sphere_scene(subdivisions: int, radius: float = 1.0, *, emission: float = 1.0, reflectance: float = 0.5):
    """The furnace sphere as a Scene (no OBJ round trip), one object."""
    import radiosity

    tris = sphere_shell(subdivisions, radius)
    quads = np.concatenate([tris, tris[:, 2:3]], axis=1)
    n = len(quads)
    return radiosity.Scene(objects=["sphere"], patch_quads=quads, patch_object=np.zeros(n, np.int64),
                           patch_face=np.arange(n), reflectance=np.full((n, 3), reflectance),
                           emission=np.full((n, 3), emission))


def cube_room_scene(k: int, *, emission: float = 1.0, reflectance: float = 0.5, seed: int = 0):
    """A closed unit room (normals in) holding ``k`` small floating cubes (normals out), on a
    jittered grid so none touch: a furnace with heavy occlusion (B = E / (1 - rho))."""
    import radiosity

    def box(lo, hi, inward):
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        corner = lambda bits: np.where(np.array(bits, bool), hi, lo)  # noqa: E731
        faces = [[(0, 0, 0), (0, 1, 0), (1, 1, 0), (1, 0, 0)], [(0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)],
                 [(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)], [(0, 1, 0), (0, 1, 1), (1, 1, 1), (1, 1, 0)],
                 [(0, 0, 0), (0, 0, 1), (0, 1, 1), (0, 1, 0)], [(1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 0, 1)]]
        quads = np.array([[corner(b) for b in f] for f in faces])  # wound outward
        return quads[:, ::-1].copy() if inward else quads

    rng = np.random.default_rng(seed)
    per_side = int(np.ceil(k ** (1 / 3)))
    cell = 0.8 / per_side
    idx = np.array(np.meshgrid(*[np.arange(per_side)] * 3, indexing="ij")).reshape(3, -1).T[:k]
    lo = 0.1 + idx * cell + rng.uniform(0.1, 0.3, (k, 3)) * cell
    size = rng.uniform(0.3, 0.5, (k, 1)) * cell
    quads = np.concatenate([box([0, 0, 0], [1, 1, 1], True)] + [box(a, a + s, False) for a, s in zip(lo, size)])
    n = len(quads)
    obj = np.concatenate([[0] * 6, np.repeat(np.arange(1, k + 1), 6)])
    return radiosity.Scene(objects=["room"] + [f"cube{i}" for i in range(k)], patch_quads=quads, patch_object=obj,
                           patch_face=np.arange(n), reflectance=np.full((n, 3), reflectance),
                           emission=np.full((n, 3), emission))


def axis_box(lo, hi, *, inward: bool) -> list[np.ndarray]:
    """The six faces of an axis-aligned box, wound so normals point in (a room) or out (a block)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    centre = 0.5 * (lo + hi)
    faces = []
    for axis in range(3):
        u, v = [a for a in range(3) if a != axis]
        for corner in (lo, hi):
            quad = np.zeros((4, 3))
            quad[:, axis] = corner[axis]
            for k, (a, b) in enumerate([(0, 0), (1, 0), (1, 1), (0, 1)]):
                quad[k, u] = (lo, hi)[a][u]
                quad[k, v] = (lo, hi)[b][v]
            normal = np.cross(quad[1] - quad[0], quad[2] - quad[0])
            if (normal @ (quad[0] - centre) > 0) == inward:
                quad = quad[::-1].copy()
            faces.append(quad)
    return faces


def office_scene(path, *, open_backs: bool = False):
    """A furnished office as thermal users model it, one patch per surface: a closed 4 x 3 x 2.5 m
    room (z up) with a door and a window in the south wall (y = 0, the wall cut around them), a
    desk and a cabinet standing on the floor (the cabinet in the north-east corner, touching
    both walls), and a two-sided partition standing on the floor. ``open_backs``: the desk
    without its bottom face, the cabinet without the faces on the floor and against the walls.
    Returns the loaded scene."""
    import warnings

    import radiosity

    def south(x0, x1, z0, z1):  # facing +y, into the room
        return np.array([[x0, 0, z0], [x0, 0, z1], [x1, 0, z1], [x1, 0, z0]], float)

    walls = [q for q in axis_box([0, 0, 0], [4, 3, 2.5], inward=True) if np.abs(q[:, 1]).max() > 0]
    partition = np.array([[1.0, 0.8, 0.0], [1.0, 2.2, 0.0], [1.0, 2.2, 1.6], [1.0, 0.8, 1.6]])
    objects = {"walls": walls,
               "south": [south(0, 0.5, 0, 2.5), south(0.5, 1.4, 2, 2.5), south(1.4, 2, 0, 2.5), south(2, 3.5, 0, 1),
                         south(2, 3.5, 2, 2.5), south(3.5, 4, 0, 2.5)],
               "door": [south(0.5, 1.4, 0, 2)], "window": [south(2, 3.5, 1, 2)],
               "desk": axis_box([1.5, 1.8, 0.0], [2.7, 2.4, 0.75], inward=False),
               "cabinet": axis_box([3.4, 2.5, 0.0], [4.0, 3.0, 1.8], inward=False),
               "partition": [partition, partition[::-1].copy()]}
    if open_backs:
        objects["desk"] = [q for q in objects["desk"] if q[:, 2].max() > 0]
        objects["cabinet"] = [q for q in objects["cabinet"]
                              if q[:, 2].max() > 0 and q[:, 0].min() < 4 and q[:, 1].min() < 3]
    with warnings.catch_warnings():  # no emitter: a note says so
        warnings.simplefilter("ignore", radiosity.RadiosityWarning)
        return radiosity.load_scene(write_obj(path, objects))

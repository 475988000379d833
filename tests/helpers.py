"""Canonical geometries with their reference values (see ../shared/FIELD_NOTES.md)."""

from __future__ import annotations

import mpmath as mp
import numpy as np

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

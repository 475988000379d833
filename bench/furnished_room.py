"""Generate a furnished room as OBJ + MTL: a scene we did not design the solver for.

A closed 6 m x 4 m x 3 m room (walls wound to face inwards) with ceiling lamps, tables (slab and
four legs standing on the floor, so imprinting has contacts to cut), shelves against the walls,
stools whose seats are n-gon cylinders (faces of many vertices, as CAD exports write them),
tessellated spheres and small boxes scattered on the tables. ``--faces`` sets the size: the
furniture count and the sphere tessellation grow until the scene holds about that many faces.
``--furnace`` gives every surface the same reflectance and emission, so the exact answer is
B = E / (1 - rho) on every patch (a closed room: nothing escapes).

    python bench/furnished_room.py -o /tmp/room.obj --faces 5000
    python bench/furnished_room.py -o /tmp/furnace.obj --faces 2000 --furnace
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import trimesh

ROOM = np.array([6.0, 3.0, 4.0])  # x, y (up), z in metres
MATERIALS = {
    "wall": ("0.70 0.68 0.62", None),
    "floor": ("0.45 0.32 0.20", None),
    "ceiling": ("0.80 0.80 0.80", None),
    "wood": ("0.55 0.38 0.22", None),
    "red": ("0.60 0.08 0.06", None),
    "blue": ("0.10 0.20 0.55", None),
    "green": ("0.15 0.45 0.12", None),
    "lamp": ("0.78 0.78 0.78", "12 11 9"),
}


class ObjWriter:
    """Collects named objects (vertices, faces, material) and writes one OBJ and its MTL."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self.n_vertices = 0
        self.n_faces = 0

    def add(self, name: str, material: str, vertices: np.ndarray, faces) -> None:
        self.lines += [f"o {name}", f"usemtl {material}"]
        self.lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
        base = self.n_vertices + 1
        self.lines += ["f " + " ".join(str(base + int(k)) for k in face) for face in faces]
        self.n_vertices += len(vertices)
        self.n_faces += len(faces)

    def add_mesh(self, name: str, material: str, mesh: trimesh.Trimesh) -> None:
        self.add(name, material, np.asarray(mesh.vertices), np.asarray(mesh.faces))

    def write(self, path: Path, furnace: bool) -> None:
        mtl = path.with_suffix(".mtl")
        out = [f"newmtl {name}\nKd {'0.5 0.5 0.5' if furnace else kd}\n"
               + (f"Ke {'1 1 1' if furnace else ke}\n" if (ke or furnace) else "")
               for name, (kd, ke) in MATERIALS.items()]
        mtl.write_text("\n".join(out))
        path.write_text(f"# furnished room, {self.n_faces} faces\nmtllib {mtl.name}\n" + "\n".join(self.lines) + "\n")


def box(lo, hi) -> trimesh.Trimesh:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return trimesh.creation.box(extents=hi - lo, transform=trimesh.transformations.translation_matrix((lo + hi) / 2))


def room_shell(obj: ObjWriter) -> None:
    """Six inward-facing quads; lamps are 1 cm thick panels against the ceiling (closed boxes:
    a lone quad's back would absorb in the furnace, where every surface must emit and reflect)."""
    x, y, z = ROOM
    quads = {
        "floor": [(0, 0, 0), (0, 0, z), (x, 0, z), (x, 0, 0)],
        "ceiling": [(0, y, 0), (x, y, 0), (x, y, z), (0, y, z)],
        "wall_back": [(0, 0, z), (0, y, z), (x, y, z), (x, 0, z)],
        "wall_front": [(0, 0, 0), (x, 0, 0), (x, y, 0), (0, y, 0)],
        "wall_left": [(0, 0, 0), (0, y, 0), (0, y, z), (0, 0, z)],
        "wall_right": [(x, 0, 0), (x, 0, z), (x, y, z), (x, y, 0)],
    }
    for name, quad in quads.items():
        material = name if name in MATERIALS else "wall"
        obj.add(name, material, np.array(quad, float), [[0, 1, 2, 3]])
    for k, (cx, cz) in enumerate([(1.5, 1.0), (4.5, 1.0), (1.5, 3.0), (4.5, 3.0)]):
        obj.add_mesh(f"lamp{k}", "lamp", box((cx - 0.3, y - 0.01, cz - 0.3), (cx + 0.3, y, cz + 0.3)))


def table(obj: ObjWriter, k: int, corner, rng) -> None:
    cx, cz = corner
    top = 0.75
    obj.add_mesh(f"table{k}_top", "wood", box((cx, top - 0.04, cz), (cx + 1.2, top, cz + 0.7)))
    for j, (dx, dz) in enumerate([(0.05, 0.05), (1.1, 0.05), (0.05, 0.6), (1.1, 0.6)]):
        obj.add_mesh(f"table{k}_leg{j}", "wood", box((cx + dx, 0, cz + dz), (cx + dx + 0.05, top - 0.04, cz + dz + 0.05)))
    placed: list = []  # (centre, radius) of the boxes' footprints
    for j in range(3):  # small boxes on the table top, rotated about the vertical
        size = rng.uniform(0.05, 0.15, 3)
        radius = np.hypot(size[0], size[2]) / 2
        for _ in range(200):  # clear of the boxes already there: boxes that pass through each other are
            # not a furnished room (the solver notes them: it cannot cut faces where they cross)
            centre = np.array([cx + rng.uniform(0.2, 1.0), cz + rng.uniform(0.15, 0.55)])
            if all(np.hypot(*(centre - c)) >= radius + rc + 0.01 for c, rc in placed):
                break
        else:
            continue
        placed.append((centre, radius))
        m = box(-size / 2, size / 2)
        m.apply_transform(trimesh.transformations.rotation_matrix(rng.uniform(0, np.pi), [0, 1, 0]))
        m.apply_translation([centre[0], top + size[1] / 2, centre[1]])
        obj.add_mesh(f"table{k}_item{j}", ("red", "blue", "green")[j], m)


def stool(obj: ObjWriter, k: int, centre, sides: int) -> None:
    """A stool: an n-gon cylinder seat (two faces of ``sides`` vertices plus quads) on one leg."""
    cx, cz = centre
    angle = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ring = np.c_[cx + 0.2 * np.cos(angle), np.zeros(sides), cz + 0.2 * np.sin(angle)]
    lo, hi = ring + [0, 0.42, 0], ring + [0, 0.46, 0]
    vertices = np.vstack([lo, hi])
    top = list(range(2 * sides - 1, sides - 1, -1))  # seen from above: counter-clockwise
    bottom = list(range(sides))
    sides_q = [[i, sides + i, sides + (i + 1) % sides, (i + 1) % sides] for i in range(sides)]  # facing out
    obj.add(f"stool{k}_seat", "blue", vertices, [top, bottom] + sides_q)
    obj.add_mesh(f"stool{k}_leg", "wood", box((cx - 0.02, 0, cz - 0.02), (cx + 0.02, 0.42, cz + 0.02)))


def _free_spot(rng, lo, hi, size, taken: list, gap: float, tries: int = 200):
    """A random corner in [lo, hi) for an axis-aligned footprint of ``size`` that keeps ``gap``
    from every footprint in ``taken`` ((corner, size) pairs), or None. Furniture that
    interpenetrates is not a furnished room: overlapping table tops are coplanar faces covering
    each other, which imprint hides on one of them."""
    for _ in range(tries):
        corner = rng.uniform(lo, hi)
        if all(((corner + size + gap <= c) | (c + s + gap <= corner)).any() for c, s in taken):
            return corner
    return None


def populate(obj: ObjWriter, n_tables: int, subdivisions: int, rng) -> None:
    """The room with up to ``n_tables`` tables (as many as fit without overlapping), half as
    many stools clear of the tables' legs and of each other, two shelves and spheres."""
    room_shell(obj)
    x, _, z = ROOM
    shelves = [(np.array([0.5 + 3.0 * k, z - 0.35]), np.array([1.5, 0.34])) for k in range(2)]
    tables, legs = [], list(shelves)
    for _ in range(n_tables):
        corner = _free_spot(rng, (0.3, 0.3), (x - 1.6, z - 1.1), np.array([1.2, 0.7]), tables + shelves, 0.05)
        if corner is None:
            break  # the room is full
        table(obj, len(tables), corner, rng)
        tables.append((corner, np.array([1.2, 0.7])))
        legs += [(corner + d, np.array([0.05, 0.05])) for d in ((0.05, 0.05), (1.1, 0.05), (0.05, 0.6), (1.1, 0.6))]
    seats: list = []
    for _ in range(max(1, n_tables // 2)):
        corner = _free_spot(rng, (0.2, 0.2), (x - 0.6, z - 0.6), np.array([0.4, 0.4]), seats + legs, 0.02)
        if corner is None:
            break
        stool(obj, len(seats), tuple(corner + 0.2), sides=int(rng.integers(6, 24)))
        seats.append((corner, np.array([0.4, 0.4])))
    for k, (corner, size) in enumerate(shelves):  # against the back wall, touching it
        obj.add_mesh(f"shelf{k}", "wood", box((corner[0], 0, corner[1]), (corner[0] + size[0], 1.8, corner[1] + size[1])))
    balls: list = []
    for _ in range(max(1, n_tables // 3)):  # spheres floating at head height, clear of each other
        spot = _free_spot(rng, (0.35, 1.25, 0.35), (x - 0.65, 2.05, z - 0.65), np.full(3, 0.3), balls, 0.02)
        if spot is None:
            break
        sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.15)
        sphere.apply_translation(spot + 0.15)
        obj.add_mesh(f"sphere{len(balls)}", ("red", "green")[len(balls) % 2], sphere)
        balls.append((spot, np.full(3, 0.3)))


def generate(path: Path, faces: int, furnace: bool = False, seed: int = 0) -> int:
    """Write the room with about ``faces`` faces; returns the number written."""
    best = None
    for subdivisions in range(0, 7):
        for n_tables in (2, 4, 8, 16, 32, 64, 128, 256):
            obj = ObjWriter()
            populate(obj, n_tables, subdivisions, np.random.default_rng(seed))
            if best is None or abs(obj.n_faces - faces) < abs(best.n_faces - faces):
                best = obj
            if obj.n_faces > 2 * faces:
                break  # more tables only add faces
    best.write(path, furnace)
    return best.n_faces


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", type=Path, required=True, help="OBJ path (the MTL goes beside it)")
    parser.add_argument("--faces", type=int, default=2000, help="about how many faces (default 2000)")
    parser.add_argument("--furnace", action="store_true", help="every surface Kd 0.5, Ke 1: B = E/(1-rho) exactly")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    args.output.parent.mkdir(parents=True, exist_ok=True)
    n = generate(args.output, args.faces, args.furnace, args.seed)
    print(f"wrote {args.output} ({n:,} faces)")


if __name__ == "__main__":
    main()

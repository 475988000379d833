"""Writes the corpus of exporter-style OBJ files in this folder (run once; the files are committed).

Each file is written the way some exporter writes it (Blender's n-gons with vt/vn and smoothing
groups, CRLF and negative indices, duplicate faces, non-planar quads, millimetres); the geometry
is simple enough that the solve is quick and the energy balance is known (closed rooms lose
nothing). ``python tests/data/corpus/make_corpus.py`` rewrites them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

HERE = Path(__file__).parent

MTL = """# corpus materials
newmtl white
Kd 0.70 0.70 0.70
Ks 0.00 0.00 0.00
newmtl red
Kd 0.60 0.08 0.06
newmtl green
Kd 0.15 0.45 0.10
newmtl lamp
Kd 0.00 0.00 0.00
Ke 4.0 4.0 4.0
"""


def newell(poly):
    c = poly - poly.mean(axis=0)
    return 0.5 * np.cross(c, np.roll(c, -1, axis=0)).sum(axis=0)


def facing(poly, towards):
    """The polygon wound so its normal points along ``towards``."""
    poly = np.asarray(poly, float)
    return poly if newell(poly) @ np.asarray(towards, float) > 0 else poly[::-1].copy()


def prism(outline_xz, y0, y1, *, inward: bool):
    """Floor, ceiling and walls of a vertical prism over a simple outline in (x, z)."""
    outline = np.asarray(outline_xz, float)
    bottom = np.column_stack([outline[:, 0], np.full(len(outline), y0), outline[:, 1]])
    top = bottom + [0, y1 - y0, 0]
    s = 1 if inward else -1
    faces = [facing(bottom, [0, s, 0]), facing(top, [0, -s, 0])]
    centre_sign = 1.0 if _ccw(outline) else -1.0
    for k in range(len(outline)):
        a, b = bottom[k], bottom[(k + 1) % len(outline)]
        wall = np.array([a, b, b + [0, y1 - y0, 0], a + [0, y1 - y0, 0]])
        d = b - a
        out = centre_sign * np.array([-d[2], 0, d[0]]) * -1  # outward normal of the edge
        faces.append(facing(wall, -out * s))
    return faces


def _ccw(xz):
    x, z = xz[:, 0], xz[:, 1]
    return (x * np.roll(z, -1) - np.roll(x, -1) * z).sum() > 0


def box(cx, cz, w, d, h, angle=0.0, y0=0.0):
    c, s = np.cos(angle), np.sin(angle)
    xz = np.array([[-w / 2, -d / 2], [w / 2, -d / 2], [w / 2, d / 2], [-w / 2, d / 2]]) @ [[c, s], [-s, c]] + [cx, cz]
    return prism(xz, y0, y0 + h, inward=False)


def fmt(x):
    return f"{x:.6f}".rstrip("0").rstrip(".") if x != 0 else "0"


class Writer:
    """Accumulates OBJ text with positive or negative references, vt/vn on demand."""

    def __init__(self, header: str, *, negative=False, texcoords=False, normals=False):
        self.lines = [header, "mtllib corpus.mtl"]
        self.nv = self.nt = self.nn = 0
        self.negative, self.texcoords, self.normals = negative, texcoords, normals

    def add(self, line):
        self.lines.append(line)

    def face(self, poly):
        poly = np.asarray(poly, float)
        for p in poly:
            self.add("v " + " ".join(fmt(c) for c in p))
        if self.texcoords:
            for p in poly:
                self.add(f"vt {fmt(p[0] % 1)} {fmt(p[2] % 1)}")
        if self.normals:
            n = newell(poly)
            n = n / np.linalg.norm(n)
            self.add("vn " + " ".join(f"{c:.4f}" for c in n))
        refs = []
        k = len(poly)
        for i in range(k):
            v = (i - k) if self.negative else self.nv + i + 1
            ref = str(v)
            if self.texcoords or self.normals:
                t = ((i - k) if self.negative else self.nt + i + 1) if self.texcoords else ""
                n = (-1 if self.negative else self.nn + 1) if self.normals else None
                ref += f"/{t}" + (f"/{n}" if n is not None else "")
            refs.append(ref)
        self.nv += k
        self.nt += k if self.texcoords else 0
        self.nn += 1 if self.normals else 0
        self.add("f " + " ".join(refs))

    def write(self, name, *, crlf=False):
        text = ("\r\n" if crlf else "\n").join(self.lines) + ("\r\n" if crlf else "\n")
        (HERE / name).write_bytes(text.encode())


def hexagon(r):
    t = np.linspace(0, 2 * np.pi, 6, endpoint=False)
    return np.column_stack([r * np.cos(t), r * np.sin(t)])


def blender_ngon_room():
    """A closed hexagonal room (n-gon floor and ceiling), a pentagon lamp 0.5 mm under the
    ceiling, a box on the floor; Blender's layout: o, v, vt, vn, usemtl, s, f v/vt/vn."""
    w = Writer("# Blender 3.6.1\n# www.blender.org", texcoords=True, normals=True)
    room = prism(hexagon(1.5), 0.0, 2.4, inward=True)
    w.add("o Room")
    w.add("usemtl white")
    w.add("s 0")
    for f in room:
        w.face(f)
    w.add("o Lamp")
    w.add("usemtl lamp")
    w.add("s 0")
    t = np.linspace(0, 2 * np.pi, 5, endpoint=False) + 0.3
    lamp = np.column_stack([0.4 * np.cos(t), np.full(5, 2.3995), 0.4 * np.sin(t)])
    w.face(facing(lamp, [0, -1, 0]))
    w.add("o Box")
    w.add("usemtl red")
    w.add("s 1")
    for f in box(0.3, -0.2, 0.6, 0.5, 0.7, angle=0.4):
        w.face(f)
    w.write("blender_ngon_room.obj")


def lshape_room_crlf():
    """A closed L-shaped room (non-convex hexagon floor and ceiling), written with CRLF line
    ends, negative (relative) indices, g groups and smoothing groups; a lamp on the ceiling."""
    w = Writer("# exported with CRLF and relative indices", negative=True)
    outline = [[0, 0], [3, 0], [3, 1.2], [1.2, 1.2], [1.2, 3], [0, 3]]
    room = prism(outline, 0.0, 2.5, inward=True)
    w.add("g floor")
    w.add("usemtl white")
    w.add("s 1")
    w.face(room[0])
    w.add("g ceiling")
    w.face(room[1])
    w.add("g walls")
    w.add("usemtl green")
    w.add("s 2")
    for f in room[2:]:
        w.face(f)
    w.add("g lamp")
    w.add("usemtl lamp")
    w.add("s off")
    lamp = np.array([[0.3, 2.5, 0.3], [0.9, 2.5, 0.3], [0.9, 2.5, 0.9], [0.3, 2.5, 0.9]])
    w.face(facing(lamp, [0, -1, 0]))
    w.write("lshape_room_crlf.obj", crlf=True)


def duplicate_faces():
    """McGuire's habit: a block with two identical bottom faces, on a floor under a lamp (open)."""
    w = Writer("# duplicate coincident faces")
    w.add("o floor")
    w.add("usemtl white")
    w.face(facing([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], [0, 1, 0]))
    w.add("o block")
    w.add("usemtl red")
    faces = box(0.0, 0.0, 0.5, 0.5, 0.5, angle=0.3)
    for f in faces[1:]:
        w.face(f)
    w.face(faces[0])
    w.face(faces[0])  # the same bottom face again
    w.add("o lamp")
    w.add("usemtl lamp")
    w.face(facing([[-0.3, 1.5, -0.3], [0.3, 1.5, -0.3], [0.3, 1.5, 0.3], [-0.3, 1.5, 0.3]], [0, -1, 0]))
    w.write("duplicate_faces.obj")


def nonplanar_terrain():
    """A 4 x 4 grid of non-planar quads (a bumpy terrain) under a lamp (open)."""
    rng = np.random.default_rng(12)
    n = 4
    xs = np.linspace(-1, 1, n + 1)
    height = rng.uniform(0, 0.08, (n + 1, n + 1))
    w = Writer("# non-planar quads, shared vertices")
    w.add("o terrain")
    w.add("usemtl white")
    index = {}
    for a in range(n + 1):
        for b in range(n + 1):
            index[a, b] = len(index) + 1
            w.add(f"v {fmt(xs[a])} {fmt(height[a, b])} {fmt(xs[b])}")
    for a in range(n):
        for b in range(n):
            quad = [index[a, b], index[a, b + 1], index[a + 1, b + 1], index[a + 1, b]]  # normal +y
            w.add("f " + " ".join(map(str, quad)))
    w.nv = len(index)
    w.add("o lamp")
    w.add("usemtl lamp")
    w.face(facing([[-0.4, 1.2, -0.4], [0.4, 1.2, -0.4], [0.4, 1.2, 0.4], [-0.4, 1.2, 0.4]], [0, -1, 0]))
    w.write("nonplanar_terrain.obj")


def millimetre_box():
    """A Cornell-like open box 1000 mm across, coordinates in millimetres, with v/vt faces."""
    w = Writer("# units: millimetres", texcoords=True)
    room = prism([[0, 0], [1000, 0], [1000, 1000], [0, 1000]], 0.0, 1000.0, inward=True)
    # drop the wall at z = 0 (the open front)
    walls = [f for f in room[2:] if not np.allclose(f[:, 2], 0.0)]
    for name, mat, faces in (("floor", "white", [room[0]]), ("ceiling", "white", [room[1]]),
                             ("walls", "red", walls)):
        w.add(f"o {name}")
        w.add(f"usemtl {mat}")
        for f in faces:
            w.face(f)
    w.add("o block")
    w.add("usemtl white")
    for f in box(600, 600, 250, 250, 300, angle=0.3)[1:]:
        w.face(f)
    w.add("o light")
    w.add("usemtl lamp")
    w.face(facing([[400, 999.5, 400], [600, 999.5, 400], [600, 999.5, 600], [400, 999.5, 600]], [0, -1, 0]))
    w.write("millimetre_box.obj")


def closed_room_boxes():
    """A closed 3 m room with boxes: one on the floor, one rotated against a wall, one floating."""
    w = Writer("# closed room with boxes")
    room = prism([[0, 0], [3, 0], [3, 3], [0, 3]], 0.0, 2.5, inward=True)
    w.add("o room")
    w.add("usemtl white")
    for f in room:
        w.face(f)
    for name, spec in (("box_floor", dict(cx=1.0, cz=1.0, w=0.6, d=0.6, h=0.6)),
                       ("box_wall", dict(cx=2.7, cz=2.0, w=0.6, d=0.8, h=1.0)),
                       ("box_float", dict(cx=1.8, cz=0.9, w=0.4, d=0.4, h=0.4, angle=0.5, y0=1.2))):
        w.add(f"o {name}")
        w.add("usemtl red")
        for f in box(**spec):
            w.face(f)
    w.add("o lamp")
    w.add("usemtl lamp")
    w.face(facing([[1.2, 2.4995, 1.2], [1.8, 2.4995, 1.2], [1.8, 2.4995, 1.8], [1.2, 2.4995, 1.8]], [0, -1, 0]))
    w.write("closed_room_boxes.obj")


if __name__ == "__main__":
    (HERE / "corpus.mtl").write_text(MTL)
    for make in (blender_ngon_room, lshape_room_crlf, duplicate_faces, nonplanar_terrain, millimetre_box,
                 closed_room_boxes):
        make()

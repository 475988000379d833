"""OBJ + MTL reading into plain arrays, with errors that name the file and line.

We tokenise OBJ and MTL ourselves rather than through ``trimesh.load``: trimesh logs and
skips malformed faces, triangulates quads we want to keep, keeps ``Ke`` only as strings and
can attach object names to the wrong geometry when it splits a file. Here every face keeps
its object, its material and the line it came from, so later stages can name it in errors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._errors import SceneError

__all__ = ["ObjData", "Material", "read_obj", "read_mtl"]


@dataclass
class Material:
    """Diffuse reflectance ``kd`` and emission ``ke`` (as written, per RGB channel)."""

    name: str
    kd: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ke: tuple[float, float, float] = (0.0, 0.0, 0.0)
    where: str = ""


@dataclass
class ObjData:
    """An OBJ file as arrays: faces are lists of 0-based vertex indices."""

    path: Path
    vertices: np.ndarray
    faces: list[np.ndarray]
    face_object: np.ndarray
    face_material: np.ndarray
    face_line: np.ndarray
    objects: list[str]
    materials: list[Material]
    warnings: list[str] = field(default_factory=list)


def _floats(tokens: list[str], count: int, where: str, what: str) -> list[float]:
    if len(tokens) < count:
        raise SceneError(f"{where}: {what} needs {count} numbers, got {len(tokens)}: {' '.join(tokens)!r}")
    try:
        values = [float(t) for t in tokens[:count]]
    except ValueError:
        raise SceneError(f"{where}: {what} has a value that is not a number: {' '.join(tokens)!r}") from None
    if not all(math.isfinite(v) for v in values):
        raise SceneError(f"{where}: {what} is not finite: {' '.join(tokens)!r}")
    return values


def _read_text(path: Path, what: str, referenced_from: str = "") -> list[str]:
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        origin = f"{referenced_from}: " if referenced_from else ""
        raise SceneError(f"{origin}{what} file '{path}' does not exist") from None
    except OSError as exc:
        raise SceneError(f"cannot read {what} file '{path}': {exc.strerror}") from None
    if b"\0" in data[:4096]:
        raise SceneError(f"{path}: is not a text {what} file (binary data)")
    return data.decode("utf-8", errors="replace").splitlines()


def read_mtl(path: Path, referenced_from: str = "") -> dict[str, Material]:
    """Materials of an MTL file by name; ``Kd`` and ``Ke`` per channel, the rest ignored."""
    materials: dict[str, Material] = {}
    current: Material | None = None
    for number, raw in enumerate(_read_text(path, "MTL", referenced_from), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        keyword, *tokens = line.split()
        where = f"{path}:{number}"
        if keyword == "newmtl":
            if not tokens:
                raise SceneError(f"{where}: newmtl needs a material name")
            current = Material(" ".join(tokens), where=where)
            materials[current.name] = current
        elif keyword in ("Kd", "Ke"):
            if current is None:
                raise SceneError(f"{where}: {keyword} appears before any newmtl")
            if tokens and tokens[0] in ("spectral", "xyz"):
                raise SceneError(f"{where}: {keyword} {tokens[0]} is not supported; give RGB values")
            values = _floats(tokens, 1, where, keyword)
            if len(tokens) >= 3:
                values = _floats(tokens, 3, where, keyword)
            else:
                values = values * 3
            setattr(current, keyword.lower(), tuple(values))
    return materials


def _face_index(token: str, n_vertices: int, where: str, face_number: int) -> int:
    head = token.split("/", 1)[0]
    try:
        index = int(head)
    except ValueError:
        raise SceneError(f"{where}: face {face_number} has a bad vertex reference {token!r}") from None
    resolved = index - 1 if index > 0 else n_vertices + index
    if index == 0 or not 0 <= resolved < n_vertices:
        msg = (f"{where}: face {face_number} uses vertex {index}, "
               f"but {n_vertices} vertices are defined before this line")
        raise SceneError(msg)
    return resolved


def read_obj(path) -> ObjData:
    """Read an OBJ file (and the MTL files it names) into arrays.

    Raises
    ------
    SceneError
        The file or a referenced MTL is missing or malformed; the message gives file:line.
    """
    path = Path(path)
    lines = _read_text(path, "OBJ")
    vertices: list[list[float]] = []
    faces: list[np.ndarray] = []
    face_object: list[int] = []
    face_material: list[int] = []
    face_line: list[int] = []
    objects: list[str] = []
    object_index: dict[str, int] = {}
    library: dict[str, Material] = {}
    used: list[Material] = []
    used_index: dict[str, int] = {}
    current_object = -1
    current_material = -1
    for number, raw in enumerate(lines, start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        keyword, *tokens = line.split()
        where = f"{path}:{number}"
        if keyword == "v":
            vertices.append(_floats(tokens, 3, where, "vertex"))
        elif keyword == "f":
            if len(tokens) < 3:
                raise SceneError(f"{where}: face {len(faces) + 1} has {len(tokens)} vertices; a face needs at least 3")
            idx = [_face_index(t, len(vertices), where, len(faces) + 1) for t in tokens]
            if current_object < 0:
                current_object = object_index.setdefault(path.stem, len(objects))
                if current_object == len(objects):
                    objects.append(path.stem)
            faces.append(np.asarray(idx, dtype=np.int64))
            face_object.append(current_object)
            face_material.append(current_material)
            face_line.append(number)
        elif keyword in ("o", "g"):
            name = " ".join(tokens) if tokens else f"unnamed_{number}"
            if name not in object_index:
                object_index[name] = len(objects)
                objects.append(name)
            current_object = object_index[name]
        elif keyword == "mtllib":
            if not tokens:
                raise SceneError(f"{where}: mtllib needs a file name")
            library.update(read_mtl(path.parent / " ".join(tokens), referenced_from=where))
        elif keyword == "usemtl":
            name = " ".join(tokens)
            if name not in library:
                known = ", ".join(sorted(library)) or "none (no mtllib before this line)"
                raise SceneError(f"{where}: unknown material {name!r}; defined: {known}")
            if name not in used_index:
                used_index[name] = len(used)
                used.append(library[name])
            current_material = used_index[name]
    if not faces:
        raise SceneError(f"{path}: the scene has no faces")
    used_objects = sorted(set(face_object))
    remap = {old: new for new, old in enumerate(used_objects)}
    return ObjData(
        path=path,
        vertices=np.asarray(vertices, dtype=float).reshape(-1, 3),
        faces=faces,
        face_object=np.asarray([remap[o] for o in face_object], dtype=np.int64),
        face_material=np.asarray(face_material, dtype=np.int64),
        face_line=np.asarray(face_line, dtype=np.int64),
        objects=[objects[o] for o in used_objects],
        materials=used,
    )

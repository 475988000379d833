"""OBJ + MTL reading into plain arrays, with errors that name the file and line.

We tokenise OBJ and MTL ourselves rather than through ``trimesh.load``: trimesh logs and
skips malformed faces, triangulates quads we want to keep, keeps ``Ke`` only as strings and
can attach object names to the wrong geometry when it splits a file. Here every face keeps
its object, its material and the line it came from, so later stages can name it in errors.

What the reader accepts (see ``docs/errors.md`` for every message):

- UTF-8 (with or without a byte-order mark); other encodings are read as Latin-1, with a note.
- ``\\n``, ``\\r\\n`` and ``\\r`` line endings; a ``\\`` at the end of a line continues it.
- ``f`` references as ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn``, positive (1-based) or negative
  (relative to the last vertex so far); only the ``v`` part is used.
- ``mtllib`` anywhere in the file (also after ``usemtl``), with one or more file names.
- ``o``/``g`` without faces and materials nobody uses are harmless and dropped.
- ``vt``, ``vn``, ``s`` and other statements that do not change the geometry are ignored;
  ``l``, ``p``, ``curv`` and ``surf`` elements are ignored with a note (only faces carry light).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._errors import SceneError
from ._obj_bulk import ACTIVE, F, S, V, Irregular, Scan, parse_faces, parse_vertices, scan_lines, scan_text
from ._text import excerpt, parse_float, read_input, split_lines

__all__ = ["ObjData", "Material", "read_obj", "read_mtl", "MAX_COORDINATE"]

# Largest accepted |coordinate| in file units. A million kilometres in metres: nothing real is
# modelled beyond it, and squares of larger values start to lose the precision areas need.
MAX_COORDINATE = 1e9
# Emitted radiance above this would overflow float32 outputs (PLY) once divided by 1 - rho and
# multiplied by areas; the brightest real sources are some 1e9 W/(m^2 sr).
MAX_EMISSION = 1e30
# File names are quoted whole in messages up to this length (a path names the file); past it,
# only the start of the file's own name is (an absurd name, such as a 5,000-character mtllib).
PATH_CHARS = 240

# A file whose first bytes hold this fraction of control characters (or any NUL) is binary.
_BINARY_FRACTION = 0.1
_SNIFF_BYTES = 8192

_INTEGER = re.compile(r"[+-]?[0-9]+", re.ASCII)

# Statements that carry geometry we cannot use; they are counted and reported, not read.
_IGNORED_ELEMENTS = {"l": "line", "p": "point", "curv": "curve", "curv2": "curve", "surf": "surface"}


@dataclass
class Material:
    """Diffuse reflectance ``kd`` and emission ``ke`` (as written, per RGB channel)."""

    name: str
    kd: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ke: tuple[float, float, float] = (0.0, 0.0, 0.0)
    where: str = ""  # file:line of its newmtl
    kd_where: str = ""  # file:line of its Kd (errors about the value point there)
    ke_where: str = ""
    # Statements radiosity does not model (Ka, Ks, Ns, Ni, Tf, d, Tr, illum, ...), as written
    # ({keyword: values text}); scene.py turns the meaningful ones into notes.
    ignored: dict[str, str] = field(default_factory=dict)


@dataclass
class ObjData:
    """An OBJ file as arrays: faces are lists of 0-based vertex indices.

    ``face_material`` is -1 for faces before any ``usemtl`` (black: Kd 0, Ke 0).
    ``warnings`` holds notes about input that was read but is surprising (the scene reports
    them as notes and ``RadiosityWarning``\\ s).
    """

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
        raise SceneError(f"{where}: {what} needs {count} numbers, got {len(tokens)}: {excerpt(' '.join(tokens))!r}")
    try:
        values = [parse_float(t) for t in tokens[:count]]
    except ValueError:
        raise SceneError(f"{where}: {what} has a value that is not a number: {excerpt(' '.join(tokens))!r}") from None
    if not all(math.isfinite(v) for v in values):
        raise SceneError(f"{where}: {what} is not finite: {excerpt(' '.join(tokens))!r}")
    return values


def _is_binary(data: bytes) -> bool:
    head = data[:_SNIFF_BYTES]
    if b"\0" in data:
        return True
    control = sum(1 for b in head if b < 32 and b not in (9, 10, 12, 13))
    return bool(head) and control > _BINARY_FRACTION * len(head)


def _quoted(path: Path) -> str:
    text = str(path)
    return text if len(text) <= PATH_CHARS else excerpt(Path(text).name, 60)


def _read_text(path: Path, what: str, referenced_from: str = "", notes: list[str] | None = None) -> str:
    """The file's text: checked (regular, not binary, within the size limit) and decoded."""
    origin = f"{referenced_from}: " if referenced_from else ""
    try:
        data = read_input(path, what)
    except FileNotFoundError:
        raise SceneError(f"{origin}{what} file '{_quoted(path)}' does not exist") from None
    except IsADirectoryError:
        raise SceneError(f"{origin}{what} file '{_quoted(path)}' is a folder, not a file") from None
    except OSError as exc:
        raise SceneError(f"{origin}cannot read {what} file '{_quoted(path)}': {exc.strerror or exc}") from None
    except ValueError as exc:  # e.g. a NUL byte in a file name taken from an OBJ
        raise SceneError(f"{origin}cannot read {what} file {_quoted(path)!r}: {exc}") from None
    if _is_binary(data):
        raise SceneError(f"{path}: is not a text {what} file (binary data)")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        text = data.decode("latin-1")
        if notes is not None:
            notes.append(f"{path}: is not UTF-8 (byte {exc.start}); read as Latin-1")
    return text


def _read_lines(path: Path, what: str, referenced_from: str = "", notes: list[str] | None = None
                ) -> list[tuple[int, str]]:
    """(line number, text without comment) of each logical line; continuations joined."""
    return _logical_lines(_read_text(path, what, referenced_from, notes))


def _logical_lines(text: str) -> list[tuple[int, str]]:
    """(line number, text without comment) of each logical line of ``text``."""
    raw_lines = split_lines(text)  # CR LF, LF and a lone CR (classic Mac) each end a line
    out: list[tuple[int, str]] = []
    pending: list[str] = []
    start = 0
    for number, raw in enumerate(raw_lines, start=1):
        # Comments go first, so a comment ending in a backslash (a Windows path) continues nothing.
        text = raw.split("#", 1)[0].rstrip()
        if not pending:
            start = number
        if text.endswith("\\"):
            pending.append(text[:-1])
            continue
        pending.append(text)
        line = " ".join(pending).strip()
        pending = []
        if line:
            out.append((start, line))
    line = " ".join(pending).strip()
    if line:
        out.append((start, line))
    return out


def read_mtl(path: Path, referenced_from: str = "", notes: list[str] | None = None) -> dict[str, Material]:
    """Materials of an MTL file by name; ``Kd`` and ``Ke`` per channel, the rest ignored.

    ``Kd``/``Ke`` take one number (grey) or three (RGB); a later ``newmtl`` of the same name
    replaces an earlier one.
    """
    path = Path(path)
    materials: dict[str, Material] = {}
    current: Material | None = None
    for number, line in _read_lines(path, "MTL", referenced_from, notes):
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
                raise SceneError(f"{where}: {keyword} {excerpt(tokens[0])} is not supported; give RGB values")
            if len(tokens) == 2:
                raise SceneError(f"{where}: {keyword} needs 1 number (grey) or 3 (RGB), got 2: "
                                 f"{excerpt(' '.join(tokens))!r}")
            values = _floats(tokens, 3 if len(tokens) >= 3 else 1, where, keyword)
            if len(values) == 1:
                values = values * 3
            if keyword == "Ke" and max(abs(v) for v in values) > MAX_EMISSION:
                raise SceneError(f"{where}: Ke is beyond {MAX_EMISSION:g} W/(m^2 sr); radiosities and the "
                                 f"energy balance would overflow: {excerpt(' '.join(tokens))!r}")
            setattr(current, keyword.lower(), tuple(values))
            setattr(current, f"{keyword.lower()}_where", where)
        elif current is not None:
            current.ignored[keyword] = " ".join(tokens)
    return materials


def _face_index(token: str, n_vertices: int, where: str, face_number: int) -> int:
    head = token.split("/", 1)[0]
    try:
        if not _INTEGER.fullmatch(head):  # int() also takes '1_0' and non-ASCII digits
            raise ValueError(head)
        index = int(head)
    except ValueError:
        raise SceneError(f"{where}: face {face_number} has a bad vertex reference {excerpt(token)!r}") from None
    if index == 0:
        raise SceneError(f"{where}: face {face_number} uses vertex 0, but OBJ vertex numbers start at 1")
    resolved = index - 1 if index > 0 else n_vertices + index
    if not 0 <= resolved < n_vertices:
        msg = (f"{where}: face {face_number} uses vertex {index}, "
               f"but {n_vertices} vertices are defined before this line")
        raise SceneError(msg)
    return resolved


def _mtl_paths(folder: Path, tokens: list[str]) -> list[Path]:
    """``mtllib a.mtl b.mtl`` names two files; a single name may contain spaces."""
    whole = folder / " ".join(tokens)
    if len(tokens) == 1 or whole.exists():
        return [whole]
    return [folder / t for t in tokens]


@dataclass
class _GroupLine:
    """A ``g`` or ``o`` line: where it is and what comes right before it."""

    line: int
    keyword: str
    name: str  # "" for a bare g (the default group)
    at: int  # faces before it
    run_start: int  # first face after the previous g, o or usemtl line
    after_faces: bool  # the previous statement (s lines aside) is an f line
    next_material: str = ""  # a usemtl right after it (before any v or f line)


def _trailing_groups(groups: list[_GroupLine], face_group: list[int], face_material: list[str]) -> list[int]:
    """Group lines that name the faces before them; ``face_group`` is changed to match.

    A named g/o line that comes right after an f line and has no faces of its own (the next
    g/o line or the end of the file follows before any face) names the faces before it, back
    to the previous g, o or usemtl line. Taking those faces can leave the group line before it
    empty in turn, so the lines are visited from the last to the first. Files that name each
    group before its faces never have an empty group right after faces, and are unchanged.

    The first such line of a chain must also match its faces: be the file's last g/o line, or
    share its name with their material, or be followed by a usemtl of their material (McGuire's
    ``g tallBox`` / ``usemtl tallBox``). An empty object between two others (``o Light`` with
    no faces) names nothing.
    """
    owner = np.asarray(face_group, dtype=np.int64)
    counts = np.bincount(owner + 1, minlength=len(groups) + 1)[1:]
    claimed = []
    for k in range(len(groups) - 1, -1, -1):
        g = groups[k]
        if not (g.name and g.after_faces and counts[k] == 0 and g.run_start < g.at):
            continue
        materials = set(face_material[g.run_start:g.at])
        emptied = bool(claimed) and claimed[-1] == k + 1  # the line after it took its faces
        if not (emptied or k == len(groups) - 1 or g.name in materials or g.next_material in materials):
            continue
        donors = owner[g.run_start:g.at]
        np.subtract.at(counts, donors[donors >= 0], 1)
        owner[g.run_start:g.at] = k
        counts[k] = g.at - g.run_start
        claimed.append(k)
    face_group[:] = owner.tolist()
    return sorted(claimed)


def _trailing_note(path: Path, groups: list[_GroupLine], claimed: list[int], face_group: list[int],
                   face_line: list[int]) -> str:
    last = groups[claimed[-1]]
    members: dict[int, list[int]] = {}
    for f, owner in enumerate(face_group):  # one pass, however many groups were claimed
        members.setdefault(owner, []).append(f)
    named = []
    for k in claimed[:5]:
        mine = members[k]
        named.append(f"'{groups[k].name}' (line {groups[k].line}: {len(mine)} face(s), "
                     f"lines {face_line[mine[0]]}-{face_line[mine[-1]]})")
    if len(claimed) > 5:
        named.append(f"and {len(claimed) - 5} more")
    return (f"{path}:{last.line}: '{last.keyword} {last.name}' comes right after faces and has none of its "
            f"own: this file names groups after their faces; read {len(claimed)} group line(s) as naming "
            f"the faces before them, back to the previous g, o or usemtl line: {', '.join(named)}")


def read_obj(path) -> ObjData:
    """Read an OBJ file (and the MTL files it names) into arrays.

    Parameters
    ----------
    path : str or Path
        The OBJ file; ``mtllib`` names are relative to its folder.

    Returns
    -------
    ObjData

    Raises
    ------
    SceneError
        The file or a referenced MTL is missing, unreadable or malformed, a face uses a vertex
        that does not exist, a material is unknown, or there are no faces; the message gives
        ``file:line``.
    """
    path = Path(path)
    notes: list[str] = []
    text = _read_text(path, "OBJ", notes=notes)
    try:  # the whole text at once, v and f lines without a Python step each (io/_obj_bulk.py)
        parsed = _parse_bulk(path, scan_text(text), notes)
    except Irregular:
        lines = _logical_lines(text)
        try:  # v and f lines still at once
            parsed = _parse_bulk(path, scan_lines(lines), notes)
        except Irregular:  # line by line: the exact file:line message
            parsed = _parse_lines(path, lines, notes)
    return _finish(path, parsed, notes)


@dataclass
class _Parsed:
    """What the pass over the lines found, before materials and objects are resolved."""

    vertices: np.ndarray
    faces: list[np.ndarray]
    face_object: np.ndarray
    face_material: np.ndarray  # index into material_names, -1 before any usemtl
    face_line: np.ndarray
    face_group: np.ndarray  # index into groups of the g/o line before each face (-1: none)
    groups: list[_GroupLine]
    objects: list[str]
    object_index: dict[str, int]
    library: dict[str, Material]
    material_names: list[str]
    material_first_use: dict[str, str]
    ignored: dict[str, int]


class _Statements:
    """The state the statements other than v and f change, in file order (both parsers)."""

    def __init__(self, path: Path, notes: list[str]):
        self.path, self.notes = path, notes
        self.objects: list[str] = []
        self.object_index: dict[str, int] = {}
        self.library: dict[str, Material] = {}
        self.material_names: list[str] = []
        self.material_id: dict[str, int] = {}
        self.material_first_use: dict[str, str] = {}
        self.ignored: dict[str, int] = {}
        self.groups: list[_GroupLine] = []
        self.current_object = -1
        self.current_material = -1
        self.run_start = 0  # first face after the last g, o or usemtl line
        self.o_lines: dict[str, int] = {}  # first o line of each name
        self.o_again: list[tuple[str, int, int]] = []  # (name, first o line, a later o line of it)

    def default_object(self) -> int:
        """The object of faces before any o/g line: the file's name."""
        index = self.object_index.setdefault(self.path.stem, len(self.objects))
        if index == len(self.objects):
            self.objects.append(self.path.stem)
        return index

    def take(self, number: int, keyword: str, tokens: list[str], previous: str, n_faces: int) -> None:
        """Apply one statement (not v, f); ``previous``: keyword of the statement before it
        (s lines aside), ``n_faces``: faces before it."""
        where = f"{self.path}:{number}"
        if keyword in ("o", "g", "usemtl"):
            if keyword != "usemtl":
                self.groups.append(_GroupLine(number, keyword, " ".join(tokens), n_faces, self.run_start,
                                              previous == "f"))
            elif self.groups and previous in ("g", "o", "usemtl") and self.groups[-1].at == n_faces:
                self.groups[-1].next_material = self.groups[-1].next_material or " ".join(tokens)
            self.run_start = n_faces
        if keyword in ("o", "g"):
            name = " ".join(tokens) if tokens else f"unnamed_{number}"
            if keyword == "o":
                first = self.o_lines.setdefault(name, number)
                if first != number:
                    self.o_again.append((name, first, number))
            if name not in self.object_index:
                self.object_index[name] = len(self.objects)
                self.objects.append(name)
            self.current_object = self.object_index[name]
        elif keyword == "mtllib":
            if not tokens:
                raise SceneError(f"{where}: mtllib needs a file name")
            for mtl in _mtl_paths(self.path.parent, tokens):
                self.library.update(read_mtl(mtl, referenced_from=where, notes=self.notes))
        elif keyword == "usemtl":
            if not tokens:
                raise SceneError(f"{where}: usemtl needs a material name")
            name = " ".join(tokens)
            if name not in self.material_id:
                self.material_first_use[name] = where
                self.material_id[name] = len(self.material_names)
                self.material_names.append(name)
            self.current_material = self.material_id[name]
        elif keyword in _IGNORED_ELEMENTS:
            self.ignored[keyword] = self.ignored.get(keyword, 0) + 1

    def parsed(self, vertices, faces, face_object, face_material, face_line, face_group) -> _Parsed:
        if self.o_again:
            # g names repeat by design (a group reopened); two o lines of one name are more often
            # two objects an exporter named alike, and their means would silently be one
            # (reading may not import the scene stage's _checks._named: tests/test_layout.py)
            shown = ", ".join(f"{name!r} (lines {first} and {again})" for name, first, again in self.o_again[:5])
            more = f" and {len(self.o_again) - 5} more" if len(self.o_again) > 5 else ""
            self.notes.append(f"{self.path}: object name(s) {shown}{more} appear on more than one 'o' line; "
                              "faces under one name are one object (one mean, one row of the summary); "
                              "rename them to keep them apart")
        return _Parsed(np.asarray(vertices, dtype=float).reshape(-1, 3), faces,
                       np.asarray(face_object, dtype=np.int64), np.asarray(face_material, dtype=np.int64),
                       np.asarray(face_line, dtype=np.int64), np.asarray(face_group, dtype=np.int64), self.groups,
                       self.objects, self.object_index, self.library, self.material_names,
                       self.material_first_use, self.ignored)


def _parse_lines(path: Path, lines: list[tuple[int, str]], notes: list[str]) -> _Parsed:
    """The file line by line: every check in file order, so the first problem is the one named."""
    state = _Statements(path, notes)
    vertices: list[list[float]] = []
    faces: list[np.ndarray] = []
    face_object: list[int] = []
    face_material: list[int] = []
    face_line: list[int] = []
    face_group: list[int] = []
    previous = ""  # keyword of the previous statement (s lines do not count)
    for number, line in lines:
        keyword, *tokens = line.split()
        where = f"{path}:{number}"
        if keyword == "v":
            xyz = _floats(tokens, 3, where, f"vertex {len(vertices) + 1}")
            if max(abs(c) for c in xyz) > MAX_COORDINATE:
                raise SceneError(f"{where}: vertex {len(vertices) + 1} has a coordinate beyond "
                                 f"{MAX_COORDINATE:g}: {excerpt(' '.join(tokens[:3]))!r}")
            vertices.append(xyz)
        elif keyword == "f":
            face_number = len(faces) + 1
            if len(tokens) < 3:
                raise SceneError(f"{where}: face {face_number} has {len(tokens)} vertices; a face needs at least 3")
            idx = [_face_index(t, len(vertices), where, face_number) for t in tokens]
            # Drop repeated consecutive corners (f 1 2 2 3, or two vertices at the same point):
            # they add zero-length edges. A face left with fewer than 3 has zero area.
            idx = [v for k, v in enumerate(idx) if v != idx[k - 1] and vertices[v] != vertices[idx[k - 1]]] or idx[:1]
            if state.current_object < 0:
                state.current_object = state.default_object()
            faces.append(np.asarray(idx, dtype=np.int64))
            face_object.append(state.current_object)
            face_group.append(len(state.groups) - 1)
            face_material.append(state.current_material)
            face_line.append(number)
        else:
            state.take(number, keyword, tokens, previous, len(faces))
        if keyword != "s":
            previous = keyword
    return state.parsed(vertices, faces, face_object, face_material, face_line, face_group)


def _parse_bulk(path: Path, scan: Scan, notes: list[str]) -> _Parsed:
    """The file with its v and f lines parsed at once (``_obj_bulk``); Irregular where that path
    cannot vouch for a line, before any other statement is applied."""
    kind, numbers = scan.kind, scan.numbers
    is_v, is_f = kind == V, kind == F
    f_rows = np.flatnonzero(is_f)
    vertices = parse_vertices(scan.v_bytes, int(is_v.sum()), MAX_COORDINATE)
    n_before = np.cumsum(is_v)[f_rows]  # vertices defined before each face (a face line is not one)
    faces = parse_faces(scan.f_bytes, n_before, vertices)
    # The statements that change state, in file order; faces take the state of the last one before them.
    state = _Statements(path, notes)
    active = np.flatnonzero(kind == ACTIVE)
    f_before = np.cumsum(is_f) - is_f  # faces before each line
    counted = np.flatnonzero(kind != S)  # lines whose keyword is "the previous statement" for the next
    previous_row = np.searchsorted(counted, active) - 1
    first_face = f_rows[0] if len(f_rows) else len(kind)
    first_named = next((i for i in active.tolist() if scan.words[i][0] in ("o", "g")), len(kind))
    if first_face < first_named:  # the first face comes before any o/g line
        state.current_object = state.default_object()
    marks = [(0, state.current_object, -1, -1)]  # (first face it holds for, object, material, group)
    for i, p in zip(active.tolist(), previous_row.tolist()):
        keyword, rest = scan.words[i]
        previous = _keyword(scan, int(counted[p])) if p >= 0 else ""
        state.take(int(numbers[i]), keyword, rest.split(), previous, int(f_before[i]))
        marks.append((int(f_before[i]), state.current_object, state.current_material, len(state.groups) - 1))
    at = np.array([m[0] for m in marks], dtype=np.int64)
    table = np.array([m[1:] for m in marks], dtype=np.int64)
    which = np.searchsorted(at, np.arange(len(faces)), side="right") - 1  # the last mark at or before the face
    face_object, face_material, face_group = table[which].T
    return state.parsed(vertices, faces, face_object, face_material, numbers[f_rows], face_group)


def _keyword(scan: Scan, row: int) -> str:
    kind = scan.kind[row]
    return "v" if kind == V else "f" if kind == F else scan.words[row][0]


def _finish(path: Path, p: _Parsed, notes: list[str]) -> ObjData:
    """Resolve materials, trailing group names and object numbers; the notes about faces."""
    if not p.faces:
        raise SceneError(f"{path}: the scene has no faces (no 'f' lines)")
    face_object = p.face_object.copy()
    names = np.array(p.material_names + [""], dtype=object)  # -1 (no usemtl) reads ""
    face_group = p.face_group.tolist()
    trailing = _trailing_groups(p.groups, face_group, names[p.face_material])
    if trailing:
        group_object = np.array([p.object_index[g.name or f"unnamed_{g.line}"] for g in p.groups] + [-1], np.int64)
        grouped = np.asarray(face_group, dtype=np.int64)
        face_object = np.where(grouped >= 0, group_object[grouped], face_object)
        notes.append(_trailing_note(path, p.groups, trailing, face_group, p.face_line.tolist()))

    # Materials are resolved after the whole file is read: mtllib may come after usemtl.
    used_materials = np.unique(p.face_material[p.face_material >= 0])
    for m in used_materials.tolist():
        name = p.material_names[m]
        if name not in p.library:
            known = ", ".join(sorted(p.library)) or "none (no mtllib in the file)"
            raise SceneError(f"{p.material_first_use[name]}: unknown material {excerpt(name)!r}; "
                             f"defined: {excerpt(known)}")
    material_remap = np.full(len(p.material_names) + 1, -1, np.int64)  # the last entry: -1 stays -1
    material_remap[used_materials] = np.arange(len(used_materials))

    used_objects = np.unique(face_object)
    bare = np.flatnonzero(p.face_material < 0)
    if len(bare):
        notes.append(f"{path}:{p.face_line[bare[0]]}: {len(bare)} face(s) come before any usemtl and have no "
                     "material; they absorb everything and emit nothing (Kd 0, Ke 0)")
    for keyword, count in p.ignored.items():
        notes.append(f"{path}: {count} '{keyword}' ({_IGNORED_ELEMENTS[keyword]}) element(s) ignored; "
                     "only faces take part in radiosity")
    return ObjData(
        path=path,
        vertices=p.vertices,
        faces=p.faces,
        face_object=np.searchsorted(used_objects, face_object).astype(np.int64),
        face_material=material_remap[p.face_material],
        face_line=p.face_line,
        objects=[p.objects[o] for o in used_objects.tolist()],
        materials=[p.library[p.material_names[m]] for m in used_materials.tolist()],
        warnings=notes,
    )

"""Load-time checks for common modelling mistakes: each returns notes (``RadiosityWarning`` text).

- Materials with non-diffuse parts (``Ks``, transparency, mirror ``illum`` modes) that radiosity
  ignores, and ``Ka`` on a material without ``Ke`` (a light given by ``Ka`` emits nothing).
- Duplicate coincident faces (same corners, same winding): the later copies are dropped.

See ``docs/errors.md`` for the exact messages.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .geometry import flat_faces

__all__ = ["material_notes", "duplicate_faces"]

# illum modes with mirror reflection or transparency (MTL spec: 3-9); 0-2 are diffuse/Phong.
_MIRROR_OR_GLASS_ILLUM = {3, 4, 5, 6, 7, 8, 9}
# The statements shown when a material is named as non-diffuse, in this order.
_SHOWN = ("Ks", "Ns", "Ni", "Tf", "d", "Tr", "illum")
# At most this many materials or faces are named in one note; the rest are counted.
_NAMED = 5


def _numbers(text: str | None) -> list[float]:
    """The numbers of a statement's value text ('' or unparsable -> [])."""
    if not text:
        return []
    try:
        return [float(t) for t in text.split()]
    except ValueError:
        return []


def _non_diffuse(ignored: dict[str, str]) -> bool:
    """True if a material's ignored statements describe light that is not diffuse.

    Specular colour above 0, dissolve below 1, Tr above 0, a transmission filter above 0 when
    nothing says the material is opaque (3ds Max writes ``Tf 1 1 1`` with ``d 1`` on opaque
    materials), or an illum mode with mirror reflection or transparency. ``Ns`` or ``Ni`` alone
    change nothing without a specular or transmitted part, so they do not count by themselves.
    """
    ks, d, tr, tf = (_numbers(ignored.get(k)) for k in ("Ks", "d", "Tr", "Tf"))
    illum = _numbers(ignored.get("illum"))
    opaque_said = "d" in ignored or "Tr" in ignored
    return bool((ks and max(ks) > 0) or (d and d[0] < 1) or (tr and tr[0] > 0)
                or (tf and max(tf) > 0 and not opaque_said)
                or (illum and int(illum[0]) in _MIRROR_OR_GLASS_ILLUM))


def _ambient_only(material) -> bool:
    """Ka above 0 on a material with no Ke statement, and Ka not just a copy of Kd (the usual
    "ambient = diffuse colour" export, which is no light)."""
    ka = _numbers(material.ignored.get("Ka"))
    if material.ke_where or not ka or max(ka) <= 0:
        return False
    ka3 = ka * 3 if len(ka) == 1 else ka[:3]
    return not np.allclose(ka3, material.kd)


def _fmt(values) -> str:
    return " ".join(f"{v:g}" for v in values)


def _mtl_files(materials) -> str:
    files = sorted({m.where.rsplit(":", 1)[0] for m in materials if m.where})
    return ", ".join(files)


def _named(items: list[str]) -> str:
    text = ", ".join(items[:_NAMED])
    if len(items) > _NAMED:
        text += f" and {len(items) - _NAMED} more"
    return text


def material_notes(materials) -> list[str]:
    """Notes on the used materials' ignored statements.

    Parameters
    ----------
    materials : list of radiosity.io.obj.Material
        The materials faces use.

    Returns
    -------
    list of str
        At most two notes: non-diffuse parts ignored (naming the materials, with their Kd and
        the ignored values), and ``Ka`` on materials that have no ``Ke`` statement.
    """
    notes = []
    glossy = [m for m in materials if _non_diffuse(m.ignored)]
    if glossy:
        described = []
        for m in glossy:
            shown = ", ".join(f"{k} {m.ignored[k]}" for k in _SHOWN if k in m.ignored)
            described.append(f"{m.name!r} (Kd {_fmt(m.kd)}; {shown})")
        notes.append(f"{_mtl_files(glossy)}: only diffuse reflection (Kd) and emission (Ke) are modelled; "
                     f"ignored: {_named(described)}; light these would reflect as a mirror or gloss, or "
                     "transmit, is absorbed here")
    ambient = [m for m in materials if _ambient_only(m)]
    if ambient:
        described = [f"{m.name!r} (Ka {m.ignored['Ka']})" for m in ambient]
        notes.append(f"{_mtl_files(ambient)}: material(s) {_named(described)} have Ka but no Ke; Ka (ambient "
                     "colour) is ignored, so they emit nothing; a light's radiance goes in Ke "
                     "(W/(m^2 sr), or exitance with --emission exitance)")
    return notes


def _duplicate_pairs(vertices: np.ndarray, faces: list[np.ndarray], grid: float) -> list[tuple[int, int]]:
    """(later face, first face) for faces with the same corners on ``grid``, wound the same way,
    in the later face's order. Faces of each corner count are compared at once: each cycle is
    read from its smallest corner (x, then y, then z; the first of equal ones) and equal
    cycles are found by a hash of each cycle (:func:`_equal_rows`; a loop over faces took
    seconds on 500k faces, and sorting the cycles as rows a few seconds)."""
    flat, sizes = flat_faces(faces)
    offsets = np.cumsum(sizes) - sizes
    on_grid = np.round(vertices / grid).astype(np.int64)  # per vertex: the same numbers as per corner
    pairs: list[tuple[int, int]] = []
    for k in np.unique(sizes).tolist():
        which = np.flatnonzero(sizes == k)
        if k == 0:
            pairs += [(int(i), int(which[0])) for i in which[1:]]
            continue
        corners = on_grid[flat[offsets[which, None] + np.arange(k)]]  # (m, k, 3)
        start = np.zeros(len(which), np.int64)
        rows = np.arange(len(which))
        for c in range(1, k):
            a, b = corners[:, c], corners[rows, start]
            less = (a[:, 0] < b[:, 0]) | ((a[:, 0] == b[:, 0]) & ((a[:, 1] < b[:, 1])
                                                                   | ((a[:, 1] == b[:, 1]) & (a[:, 2] < b[:, 2]))))
            start[less] = c
        cycle = corners[rows[:, None], (start[:, None] + np.arange(k)) % k].reshape(len(which), -1)
        later, original = _equal_rows(cycle)
        pairs += list(zip(which[later].tolist(), which[original].tolist()))
    pairs.sort()
    return pairs


# Odd multipliers of the cycle hash (splitmix64 constants); any odd numbers would do.
_HASH_A, _HASH_B = np.uint64(0x9E3779B97F4A7C15), np.uint64(0xBF58476D1CE4E5B9)


def _equal_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(later, first) row indices: each row equal to an earlier one, and the first row equal to it.

    Rows whose 64-bit hash no other row shares are unique; only the rest are compared as rows
    (``np.unique(axis=0)``), so a hash collision costs time, never a wrong pair.
    """
    h = np.zeros(len(rows), np.uint64)
    with np.errstate(over="ignore"):
        for column in rows.T.astype(np.uint64):
            h = (h ^ column) * _HASH_A
            h ^= h >> np.uint64(31)
        h *= _HASH_B
    _, inverse, counts = np.unique(h, return_inverse=True, return_counts=True)
    shared = np.flatnonzero(counts[inverse.reshape(-1)] > 1)
    if not len(shared):
        return shared, shared
    _, first, inverse = np.unique(rows[shared], axis=0, return_index=True, return_inverse=True)
    original = shared[first[inverse.reshape(-1)]]
    later = original != shared
    return shared[later], original[later]


def duplicate_faces(path: Path, vertices: np.ndarray, faces: list[np.ndarray], face_line: np.ndarray,
                    face_object: np.ndarray, objects: list[str]) -> tuple[np.ndarray, list[str]]:
    """Faces to keep (later copies of a face with the same corners and winding dropped), and notes.

    Parameters
    ----------
    path : Path
        The OBJ file (for the notes).
    vertices : (v, 3) float
        Vertex positions (any units).
    faces : list of (k,) int
        Corner indices of each face.
    face_line, face_object : (f,) int
        Line and object index of each face.
    objects : list of str

    Returns
    -------
    keep : (f,) bool
    notes : list of str

    Notes
    -----
    Two coincident faces wound the same way would each block the other and share the light
    between them at random; the first in file order is kept. Faces with the same corners wound
    the opposite way are a two-sided sheet and are both kept.
    """
    keep = np.ones(len(faces), dtype=bool)
    if not faces:
        return keep, []
    extent = float(np.ptp(vertices, axis=0).max()) if len(vertices) else 0.0
    grid = max(extent, 1e-300) * 1e-9
    pairs = _duplicate_pairs(vertices, faces, grid)
    for index, _ in pairs:
        keep[index] = False
    if not pairs:
        return keep, []
    notes = []
    for dup, original in pairs[:_NAMED]:
        notes.append(f"{path}:{face_line[dup]}: face {dup + 1} ({objects[face_object[dup]]}) duplicates face "
                     f"{original + 1} (line {face_line[original]}, {objects[face_object[original]]}): same corners, "
                     "same winding; dropped (coincident copies would shade each other)")
    if len(pairs) > _NAMED:
        notes.append(f"{path}: {len(pairs) - _NAMED} more duplicate face(s) dropped")
    return keep, notes

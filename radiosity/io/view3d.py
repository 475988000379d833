"""View3D (NIST/LBNL) ``.vs3`` models: read surfaces and obstructions, write them back.

The vertex/surface format (View3D 3.x/4.x, "F 3") is line oriented; the first letter of a
line says what it holds::

    T  title                                    ! comments start with ! or /
    C  eps=1e-4 ...                             control line (ignored here)
    F  3                                        geometry format: 3 = three-dimensional
    V  n  x  y  z                               vertex n (numbered from 1, in order)
    S  n  v1 v2 v3 v4  base cmbn emit  name     radiating surface; v4 = 0 for a triangle
    O  n  v1 v2 v3 v4  [...]                    obstruction only (blocks, never exchanges)
    E                                           end of data

Vertices are listed counter-clockwise seen from the surface's front, as in OBJ. Surfaces
become one patch each (View3D never subdivides its input); obstructions become blocking
patches flagged in ``Scene.patch_obstruction``. ``emit`` (thermal emissivity) is kept in
``Scene.notes``-free form as reflectance ``1 - emit`` so a grey-body solve makes sense.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._errors import SceneError

__all__ = ["read_vs3", "write_vs3"]


def _number(token: str, where: str, what: str, kind=float):
    try:
        value = kind(token)
    except ValueError:
        raise SceneError(f"{where}: {what} must be a number, got {token!r}") from None
    if kind is float and not np.isfinite(value):
        raise SceneError(f"{where}: {what} is not finite: {token!r}")
    return value


def read_vs3(path) -> dict:
    """Parse a ``.vs3`` file into vertices, surfaces (index lists), names, kinds and emissivities.

    Raises
    ------
    SceneError
        Out-of-sequence numbers, bad vertex references, unknown identifiers, not 3-D.
    """
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except FileNotFoundError:
        raise SceneError(f"View3D file '{path}' does not exist") from None
    except OSError as exc:
        raise SceneError(f"cannot read View3D file '{path}': {exc.strerror}") from None
    vertices: list[list[float]] = []
    surfaces: list[list[int]] = []
    names: list[str] = []
    obstruction: list[bool] = []
    emissivity: list[float] = []
    title = ""
    for number, raw in enumerate(lines, start=1):
        tokens = raw.split()
        if not tokens:
            continue
        where = f"{path}:{number}"
        key = tokens[0][0].upper()
        if key in "!/":
            continue
        if key == "T":
            title = raw.strip()[1:].strip()
        elif key in "CX":
            continue
        elif key == "F":
            if len(tokens) > 1 and tokens[1] != "3":
                raise SceneError(f"{where}: only 3-D View3D models (F 3) are supported, got F {tokens[1]}")
        elif key == "V":
            if len(tokens) < 5:
                raise SceneError(f"{where}: a vertex line needs 'V n x y z', got {raw.strip()!r}")
            n = _number(tokens[1], where, "vertex number", int)
            if n != len(vertices) + 1:
                raise SceneError(f"{where}: vertex {n} out of sequence (expected {len(vertices) + 1})")
            vertices.append([_number(t, where, "a coordinate") for t in tokens[2:5]])
        elif key in "SO":
            if len(tokens) < 6:
                raise SceneError(f"{where}: a surface line needs '{key} n v1 v2 v3 v4 ...', got {raw.strip()!r}")
            n = _number(tokens[1], where, "surface number", int)
            if n != len(surfaces) + 1:
                raise SceneError(f"{where}: surface {n} out of sequence (expected {len(surfaces) + 1})")
            refs = [_number(t, where, "a vertex reference", int) for t in tokens[2:6]]
            if refs[3] == 0:
                refs = refs[:3]
            for r in refs:
                if not 1 <= r <= len(vertices):
                    raise SceneError(f"{where}: surface {n} uses vertex {r}, but {len(vertices)} vertices are defined before it")
            surfaces.append([r - 1 for r in refs])
            obstruction.append(key == "O")
            emit = 0.9
            if key == "S" and len(tokens) >= 9:
                emit = _number(tokens[8], where, "emissivity")
                if not 0 < emit <= 1:
                    raise SceneError(f"{where}: surface {n} emissivity must be in (0, 1], got {emit}")
            emissivity.append(emit)
            names.append(" ".join(tokens[9:]) if key == "S" and len(tokens) > 9 else f"{'obstruction' if key == 'O' else 'surface'}_{n}")
        elif key in "E*":
            break
        elif key in "MN":
            raise SceneError(f"{where}: View3D mask/null surfaces ({key}) are not supported")
        else:
            raise SceneError(f"{where}: unknown View3D identifier {tokens[0]!r}")
    if not surfaces:
        raise SceneError(f"{path}: the model has no surfaces")
    return {"title": title, "vertices": np.asarray(vertices, float).reshape(-1, 3), "surfaces": surfaces,
            "names": names, "obstruction": np.asarray(obstruction), "emissivity": np.asarray(emissivity)}


def write_vs3(scene, path, *, title: str = "exported by radiosity") -> None:
    """Write a scene's patches as a View3D model: one ``S`` surface per patch, ``O`` for obstructions.

    Surface names are ``object:k``; View3D requires radiating surfaces before obstructions, so
    patches are reordered that way (the order is ``S`` patches in scene order, then ``O``).
    """
    from .export import atomic_path

    quads = scene.patch_quads
    is_tri = (quads[:, 3] == quads[:, 2]).all(axis=1)
    obstruction = getattr(scene, "patch_obstruction", np.zeros(len(quads), bool))
    order = np.concatenate([np.flatnonzero(~obstruction), np.flatnonzero(obstruction)])
    emissivity = 1.0 - scene.reflectance.mean(axis=1)
    lines = [f"T {title}", "C eps=1.e-6 col=0 list=0", "F 3", "!  #   x   y   z"]
    vid = 0
    surface_lines = ["!  #  v1  v2  v3  v4  base  cmbn  emit  name"]
    for rank, p in enumerate(order, start=1):
        count = 3 if is_tri[p] else 4
        refs = []
        for v in quads[p, :count]:
            vid += 1
            lines.append(f"V {vid} {v[0]:.17g} {v[1]:.17g} {v[2]:.17g}")
            refs.append(vid)
        refs += [0] * (4 - count)
        kind = "O" if obstruction[p] else "S"
        name = f"{scene.objects[scene.patch_object[p]]}:{rank}".replace(" ", "_")
        surface_lines.append(f"{kind} {rank} {' '.join(map(str, refs))} 0 0 {min(1.0, max(1e-6, emissivity[p])):.6g} {name}")
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines + surface_lines + ["E"]) + "\n")

"""The bulk OBJ reader (``io/_obj_bulk.py``) gives what the line-by-line reader gives.

``read_obj`` tries three ways in turn: the whole text at once (``scan_text``), the logical lines
with v and f lines at once (``scan_lines``), and line by line (``_parse_lines``), which alone
raises the ``file:line`` messages. Each test reads a file all three ways and compares every
array, name and note; a file the bulk paths cannot vouch for must come out Irregular there,
never different.
"""

from __future__ import annotations

import random
import warnings
from pathlib import Path

import numpy as np
import pytest

import radiosity.io.obj as obj
from radiosity import SceneError
from radiosity.io._obj_bulk import Irregular, scan_lines, scan_text

MESHES = Path(obj.__file__).resolve().parents[1] / "meshes"


def _read(path: Path, how: str):
    """ObjData (or the SceneError message, or "irregular") read one of the three ways."""
    notes: list[str] = []
    try:
        text = obj._read_text(path, "OBJ", notes=notes)
        if how == "text":
            parsed = obj._parse_bulk(path, scan_text(text), notes)
        elif how == "lines":
            parsed = obj._parse_bulk(path, scan_lines(obj._logical_lines(text)), notes)
        else:
            parsed = obj._parse_lines(path, obj._logical_lines(text), notes)
        return obj._finish(path, parsed, notes)
    except Irregular:
        return "irregular"
    except SceneError as exc:
        return f"SceneError: {exc}"


def _same(a, b) -> bool:
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    return (np.array_equal(a.vertices, b.vertices) and a.vertices.shape == b.vertices.shape
            and len(a.faces) == len(b.faces)
            and all(np.array_equal(x, y) and x.dtype == y.dtype for x, y in zip(a.faces, b.faces))
            and all(np.array_equal(getattr(a, k), getattr(b, k)) and getattr(a, k).dtype == getattr(b, k).dtype
                    for k in ("face_object", "face_material", "face_line"))
            and a.objects == b.objects and a.materials == b.materials and a.warnings == b.warnings)


def check_three_ways(path: Path) -> str:
    """Assert the bulk ways agree with the line-by-line one; returns the way read_obj takes."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        slow = _read(path, "slow")
        taken = "slow"
        for how in ("lines", "text"):
            fast = _read(path, how)
            if fast == "irregular":  # left to the next way (valid files too: odd white space, ...)
                continue
            assert _same(fast, slow), (how, path, fast if isinstance(fast, str) else "",
                                       slow if isinstance(slow, str) else "")
            taken = how
        return taken


@pytest.mark.parametrize("name", ["cornell_box", "unit_cube"])
def test_bundled_scenes_take_the_whole_text_path(name):
    assert check_three_ways(MESHES / f"{name}.obj") == "text"


CASES = {
    "plain": "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n",
    "no final newline, CRLF, lone CR": "v 0 0 0\r\nv 1 0 0\rv 1 1 0\nf 1 2 3",
    "indented, tabs, comments": "  v\t0 0 0 # a\n\tv 1 0 0\nv 1 1 0 1.0\n# f 9 9 9\nf 1 2 3 # tri\n",
    "references": "v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvn 0 0 1\nf 1/1/1 2//1 -1/1\nf -3 -2 -1\nf +1 002 3\n",
    "repeats": "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 1 1 0\nf 1 2 2 3 4 1\nf 1 1 1\nf 3 4 3\n",
    "groups and objects": ("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\ng a\nusemtl red\nf 1 2 3\n"
                           "o b\ns 1\nf 3 2 1\ng tail\nusemtl red\nusemtl blue\nl 1 2\np 1\n"),
    "faces before a group": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\nf 1 3 2\ng after\n",
    "unknown keywords": "v 0 0 0\nvp 1 2\nv 1 0 0\nv 1 1 0\ncstype bspline\nf 1 2 3\n",
    "w and colours": "v 0 0 0 1\nv 1 0 0 1 0.5 0.5 0.5\nv 1 1 0 junk\nf 1 2 3\n",
    "numbers": "v +.5 -5. 1E3\nv 1e-3 2.0e+1 -0\nv 1.5e-400 3 4\nf 1 2 3\n",
    "continued": "v 0 0 \\\n0\nv 1 0 0\nv 1 1 0\nf 1 2 \\\n3\n",
    "unicode names": "o caf\u00e9\nv 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\ng \u00a0x\u3000y\nf 1 3 2\n",
    "unicode space in a face": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1\u00a02 3\n",
    "form feed keyword": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf\x0c1 2 3\n",
    "bom": "\ufeffv 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n",
    # refused: the line-by-line reader names the line
    "vertex 0": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 0 1 2\n",
    "lone sign": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 +\n",
    "too far": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 4\nv 2 2 2\n",
    "too far back": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 -4\n",
    "huge index": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 99999999999999999999999\n",
    "negative huge": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 -9223372036854775809\n",
    "two numbers in one": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2-3\n",
    "underscore": "v 0 0 0\nv 1_0 0 0\nv 1 1 0\nf 1 2 3\n",
    "arabic digit": "v 0 0 0\nv \u0663 0 0\nv 1 1 0\nf 1 2 3\n",
    "inf": "v 0 0 0\nv inf 0 0\nv 1 1 0\nf 1 2 3\n",
    "overflow": "v 0 0 0\nv 1e400 0 0\nv 1 1 0\nf 1 2 3\n",
    "beyond": "v 0 0 0\nv 2e9 0 0\nv 1 1 0\nf 1 2 3\n",
    "short vertex": "v 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n",
    "short face": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2\n",
    "empty ref": "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 /3\n",
    "bad number then bad usemtl": "v 0 0 0\nv 1 x 0\nv 1 1 0\nusemtl\nf 1 2 3\n",
    "bad usemtl then bad face": "v 0 0 0\nv 1 0 0\nv 1 1 0\nusemtl\nf 1 2 9\n",
    "v without space": "v#1 2 3\nv 1 0 0\nv 1 1 0\nf 1 2 3\n",
    "no faces": "v 0 0 0\n",
    "empty": "",
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_cases_read_alike(tmp_path, case):
    (tmp_path / "m.mtl").write_text("newmtl red\nKd 0.5 0 0\nnewmtl blue\nKd 0 0 0.5\n")
    path = tmp_path / "s.obj"
    path.write_bytes(CASES[case].encode("utf-8"))
    check_three_ways(path)


def test_fuzzed_bundled_scenes_read_alike(tmp_path):
    """Mutants of the bundled scenes (tests/fuzzing.py): same data, or the same message."""
    import fuzzing

    taken = {}
    for seed in range(150):
        mutant = fuzzing.obj_mutant(random.Random(seed))
        folder = tmp_path / str(seed)
        folder.mkdir()
        for name, data in mutant.files.items():
            (folder / name).write_bytes(data)
        way = check_three_ways(folder / f"{mutant.base}.obj")
        taken[way] = taken.get(way, 0) + 1
    assert taken.get("text", 0) > 0


def test_line_bodies_by_runs_match_the_byte_mask(monkeypatch):
    """``scan_text`` slices v and f bodies per run of lines; the byte mask (every line by itself)
    gives the same bytes, with comments, indents and other lines between the runs."""
    import radiosity.io._obj_bulk as bulk

    rng = random.Random(7)
    pieces = ["v 1 2 3", "v\t1 2 3 4", "f 1 2 3", "f 1/1 2/2 3/3", "  v 1 2 3", "f 1 2 3 # c", "# x", "",
              "vt 0 0", "o a", "usemtl m", "s 1", "v 1 2 3  ", "\tf 1 2 3", "v 1e5 -2 3"]
    for _ in range(300):
        text = "\n".join(rng.choice(pieces) for _ in range(rng.randrange(1, 30))) + "\n"
        runs = scan_text(text)
        with monkeypatch.context() as m:
            m.setattr(bulk, "_MAX_RUNS", 0)  # every file on the mask path
            mask = scan_text(text)
        assert runs.v_bytes.tobytes() == mask.v_bytes.tobytes()
        assert runs.f_bytes.tobytes() == mask.f_bytes.tobytes()

"""Seeded mutants of the bundled scenes, ``.vs3`` models and points files, run through the CLI.

Shared by ``tests/test_fuzz.py`` (a bounded count in CI) and ``bench/fuzz.py`` (a larger
campaign). A mutant is one or more edits of a base input; each edit says what a correct reader
must do with it:

- ``same``: the input means the same thing (BOM, CR/CRLF, comments, tabs, ``5e-1`` for ``0.5``,
  negative face indices): the run must succeed with the base run's numbers;
- ``refuse``: the input is invalid (NaN, 1e200 or ``1_0`` in a number that is read, a bad face
  index, a missing MTL): exit 2 with one line;
- ``any``: anything clean goes (byte flips, truncation, lines deleted or swapped).

Edits that may undo a refusal (``any``) are never combined with a ``refuse`` edit. The outcome
classes are those of issue 19's table; :func:`classify` puts each run in one of them.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import random
import re
import signal
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MESHES = ROOT / "meshes"
MAX_MESSAGE = 300  # characters of an error line above which it is "too long"

SOLVED = "solved"
CLEAN = "exit 2, one clean line"
TOO_LONG = "exit 2, message too long or misleading"
REFUSED_VALID = "valid input refused"
ACCEPTED_INVALID = "invalid input silently accepted"
WRONG = "silent wrong result"
NAN_EXIT0 = "NaN/Inf with exit 0"
TRACEBACK = "raw traceback"
HANG = "hang, timeout or memory exhaustion"
OUTCOMES = (SOLVED, CLEAN, TOO_LONG, REFUSED_VALID, ACCEPTED_INVALID, WRONG, NAN_EXIT0, TRACEBACK, HANG)
CLEAN_OUTCOMES = (SOLVED, CLEAN)

_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?", re.ASCII)
_UNICODE_DIGITS = ("\u0663", "\uff13", "\u0969", "\u06f7", "\U0001d7d1")  # Arabic-Indic, fullwidth, ...
_SPECIAL = ("nan", "inf", "-inf", "1e400", "1e200", "-1e200", "1e308", "1e38", "1e30", "1e10", "1e-320",
            "5e-324", "1e-200", "0", "-0", "-1", "1", "0.999999", "1e-12", "NaN", "Infinity")


@dataclass
class Mutant:
    """Files to write (name -> bytes), the command line to run on them, and what must happen."""

    kind: str  # "obj", "vs3" or "points"
    base: str
    files: dict[str, bytes]
    args: list[str]  # {dir} is the folder the files are written to
    expect: str = "any"  # "same", "refuse" or "any"
    edits: list[str] = field(default_factory=list)


# ---------------------------------------------------------------------------------------------
# Base inputs

def _vs3_bases() -> dict[str, str]:
    from helpers import CUBE_3A, PLATES, ROOM_VS3

    return {"plates": PLATES, "room": ROOM_VS3, "cube_3a": CUBE_3A}


POINTS = """# x y z nx ny nz: receivers in the unit cube
0.5 0.5 0.0 0 0 1
0.25 0.5 0.5 1 0 0
0.5 0.5 0.99 0 0 -1
0.1, 0.9, 0.3, 0, -1, 0
"""


def _obj_bases() -> dict[str, dict[str, bytes]]:
    return {name: {f"{name}.obj": (MESHES / f"{name}.obj").read_bytes(),
                   f"{name}.mtl": (MESHES / f"{name}.mtl").read_bytes()}
            for name in ("unit_cube", "cornell_box")}


# ---------------------------------------------------------------------------------------------
# Where numbers are read: (line index, token index, kind) of every token a reader parses

def _obj_fields(lines: list[str]) -> list[tuple[int, int, str]]:
    out = []
    for i, line in enumerate(lines):
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        if words[0] == "v":
            out += [(i, k, "coord") for k in range(1, min(4, len(words)))]
        elif words[0] == "f":
            out += [(i, k, "index") for k in range(1, len(words))]
        elif words[0] in ("Kd", "Ke"):
            out += [(i, k, words[0].lower()) for k in range(1, min(4, len(words)))]
    return out


def _vs3_fields(lines: list[str]) -> list[tuple[int, int, str]]:
    out = []
    for i, line in enumerate(lines):
        words = re.split(r"(?:^|\s)/", line.split("!", 1)[0], maxsplit=1)[0].split()
        if not words:
            continue
        if words[0] == "V":
            out += [(i, k, "coord") for k in range(2, min(5, len(words)))]
        elif words[0] == "S" and len(words) > 2 and words[2] not in "RQT":
            out += [(i, k, "vref") for k in range(2, 6)] + [(i, 8, "emit")]
        elif words[0] in "SO":
            out += [(i, k, "vref") for k in range(2, 6) if words[0] == "O" and len(words) > 5]
        elif _NUMBER.fullmatch(words[0]):  # F 3a geometry lines
            out += [(i, k, "shape") for k in range(len(words))]
    count = {i: len(lines[i].split("!", 1)[0].split()) for i in {i for i, _, _ in out}}  # once per line
    return [(i, k, kind) for i, k, kind in out if k < count[i]]


def _points_fields(lines: list[str]) -> list[tuple[int, int, str]]:
    out = []
    for i, line in enumerate(lines):
        words = line.split("#", 1)[0].replace(",", " ").split()
        if len(words) == 6:
            out += [(i, k, "coord" if k < 3 else "normal") for k in range(6)]
    return out


FIELDS = {"obj": _obj_fields, "mtl": _obj_fields, "vs3": _vs3_fields, "points": _points_fields}


def _refused_value(kind: str, text: str) -> bool | None:
    """Whether ``text`` in a field of ``kind`` must be refused (None: cannot tell)."""
    value = float(text)
    if not math.isfinite(value):
        return True
    if kind == "coord":
        return abs(value) > 1e9 or None
    if kind == "kd":
        return value < 0 or value >= 1 or None
    if kind == "ke":
        return value < 0 or value > 1e30 or None
    if kind == "emit":
        return not 0 < value <= 1 or None
    return None


# ---------------------------------------------------------------------------------------------
# Edits: each takes (rng, text, kind) and returns (new text, expectation) or None if it cannot apply

def _lines(text: str) -> list[str]:
    return text.split("\n")


def _pick_field(rng, text, kind, want=None):
    lines = _lines(text)
    fields = [f for f in FIELDS[kind](lines) if want is None or f[2] in want]
    if not fields:
        return None
    i, k, what = rng.choice(fields)
    return lines, i, k, what


def _set_token(lines, i, k, new):
    body, sep, comment = lines[i].partition("!" if "!" in lines[i] else "#")
    words = body.split()
    words[k] = new
    lines[i] = " ".join(words) + (f" {sep}{comment}" if sep else "")
    return "\n".join(lines)


def edit_special_number(rng, text, kind):
    picked = _pick_field(rng, text, kind, want={"coord", "kd", "ke", "emit", "normal", "shape"})
    if picked is None:
        return None
    lines, i, k, what = picked
    new = rng.choice(_SPECIAL)
    refused = _refused_value(what, new)
    return _set_token(lines, i, k, new), "refuse" if refused else "any"


def edit_unicode_digit(rng, text, kind):
    picked = _pick_field(rng, text, kind)
    if picked is None:
        return None
    lines, i, k, what = picked
    token = lines[i].split("!" if "!" in lines[i] else "#", 1)[0].split()[k]
    digits = [m.start() for m in re.finditer(r"[0-9]", token)]
    if not digits:
        return None
    at = rng.choice(digits)
    new = token[:at] + rng.choice(_UNICODE_DIGITS) + token[at + 1:]
    return _set_token(lines, i, k, new), "refuse"


def edit_underscore(rng, text, kind):
    picked = _pick_field(rng, text, kind)
    if picked is None:
        return None
    lines, i, k, what = picked
    token = lines[i].split("!" if "!" in lines[i] else "#", 1)[0].split()[k]
    pairs = [m.start() + 1 for m in re.finditer(r"(?=[0-9][0-9])", token)]
    if not pairs:
        return None
    at = rng.choice(pairs)
    return _set_token(lines, i, k, token[:at] + "_" + token[at:]), "refuse"


def edit_bad_index(rng, text, kind):
    picked = _pick_field(rng, text, kind, want={"index", "vref"})
    if picked is None:
        return None
    lines, i, k, what = picked
    new = rng.choice(["0", "99999", "-99999", "1e3", "1.5", "x", "10" * 20, "-" + "9" * 30, "1/2/3/4/5", "/"])
    if what == "vref" and new in ("0",) and k == 5:
        return None  # v4 = 0 makes a triangle: valid
    expect = "any" if new == "1/2/3/4/5" else "refuse"
    return _set_token(lines, i, k, new), expect


def edit_equivalent_number(rng, text, kind):
    """0.5 -> 5.0000000000000000e-01: the same float written another way."""
    picked = _pick_field(rng, text, kind, want={"coord", "kd", "ke", "emit", "normal", "shape"})
    if picked is None:
        return None
    lines, i, k, what = picked
    token = lines[i].split("!" if "!" in lines[i] else "#", 1)[0].split()[k]
    if not _NUMBER.fullmatch(token):
        return None
    value = float(token)
    new = rng.choice([f"{value:.17e}", f"{value!r}", f"+{value!r}" if value >= 0 else repr(value), f"{value:.17E}"])
    return _set_token(lines, i, k, new), "same"


def edit_negative_indices(rng, text, kind):
    """f 1 2 3 -> f -3 -2 -1 where that names the same vertices (OBJ only)."""
    if kind != "obj":
        return None
    lines, count, changed = _lines(text), 0, False
    for i, line in enumerate(lines):
        words = line.split("#", 1)[0].split()
        if words[:1] == ["v"]:
            count += 1
        elif words[:1] == ["f"] and rng.random() < 0.5 and all(re.fullmatch("[0-9]+", w) for w in words[1:]):
            lines[i] = "f " + " ".join(str(int(w) - count - 1) for w in words[1:])
            changed = True
    return ("\n".join(lines), "same") if changed else None


def edit_bom(rng, text, kind):
    if text.startswith("\ufeff"):
        return None  # a second mark is a character (U+FEFF) in the text, not a mark
    return "\ufeff" + text, "same"


def edit_line_ends(rng, text, kind):
    style = rng.choice(["\r\n", "\r", "mixed"])
    if style != "mixed":
        return text.replace("\n", style), "same"
    parts = text.split("\n")
    return "".join(p + rng.choice(["\n", "\r\n", "\r"]) for p in parts[:-1]) + parts[-1], "same"


def edit_comment(rng, text, kind):
    mark = "!" if kind == "vs3" else "#"
    lines = _lines(text)
    at = rng.randrange(len(lines) + 1)
    body = rng.choice(["", "x" * rng.choice([10, 1000, 400_000]), "\u00e9\u4e2d\U0001f600", "1_0 \u0663 nan"])
    lines.insert(at, f"{mark} {body}" if rng.random() < 0.8 else "")
    return "\n".join(lines), "same"


def edit_tabs(rng, text, kind):
    return text.replace(" ", "\t"), "same"


def edit_long_line(rng, text, kind):
    lines = _lines(text)
    at = rng.randrange(len(lines) + 1)
    filler = rng.choice(["9" * 300_000, "v " + "1 " * 150_000, "f " + "1 " * 150_000, "S " + "x" * 300_000,
                         "1 2 3 " * 50_000, "Kd " + "0.5 " * 100_000])
    lines.insert(at, filler)
    return "\n".join(lines), "any"


def edit_flip_byte(rng, text, kind):
    data = bytearray(text.encode("utf-8", errors="surrogateescape"))
    if not data:
        return None
    at = rng.randrange(len(data))
    data[at] ^= 1 << rng.randrange(8)
    return data.decode("utf-8", errors="surrogateescape"), "any"


def edit_truncate(rng, text, kind):
    return text[:rng.randrange(len(text) + 1)], "any"


def edit_empty(rng, text, kind):
    return "", "refuse"


def edit_nul(rng, text, kind):
    at = rng.randrange(len(text) + 1)
    return text[:at] + "\0" + text[at:], "refuse" if kind in ("obj", "mtl") else "any"


def edit_line_shuffle(rng, text, kind):
    lines = _lines(text)
    if len(lines) < 2:
        return None
    i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
    how = rng.choice(["duplicate", "delete", "swap"])
    if how == "duplicate":
        lines.insert(j, lines[i])
    elif how == "delete":
        del lines[i]
    else:
        lines[i], lines[j] = lines[j], lines[i]
    return "\n".join(lines), "any"


def edit_scale(rng, text, kind):
    """Every coordinate times a factor: 1e150 must be refused; tiny factors are anything clean."""
    factor = rng.choice([1e150, 1e12, 1e-150, 1e-160, 1e-300, 1e6, 1e-6])
    lines = _lines(text)
    fields = [(i, k) for i, k, what in FIELDS[kind](lines) if what == "coord"]
    if not fields:
        return None
    for i, k in fields:
        words = lines[i].split()
        try:
            words[k] = repr(float(words[k].rstrip(",")) * factor)
        except (ValueError, IndexError):
            continue
        lines[i] = " ".join(words)
    return "\n".join(lines), "refuse" if factor > 1e9 else "any"


def edit_zero_area(rng, text, kind):
    """A face or surface whose corners repeat one point, or lie on a line."""
    if kind == "obj":
        lines = _lines(text)
        count = sum(1 for line in lines if line.startswith("v "))
        if count < 2:
            return None
        a, b = rng.randrange(1, count + 1), rng.randrange(1, count + 1)
        lines.append(rng.choice([f"f {a} {a} {a}", f"f {a} {b} {a}", f"f {a} {b} {a} {b}"]))
        return "\n".join(lines), "any"
    if kind == "vs3":
        picked = _pick_field(rng, text, kind, want={"vref"})
        if picked is None:
            return None
        lines, i, k, _ = picked
        words = lines[i].split("!", 1)[0].split()
        words[3] = words[4] = words[2]
        lines[i] = " ".join(words)
        return "\n".join(lines), "any"
    return None


EDITS = {
    "special_number": edit_special_number, "unicode_digit": edit_unicode_digit, "underscore": edit_underscore,
    "bad_index": edit_bad_index, "equivalent_number": edit_equivalent_number,
    "negative_indices": edit_negative_indices, "bom": edit_bom, "line_ends": edit_line_ends,
    "comment": edit_comment, "tabs": edit_tabs, "long_line": edit_long_line, "flip_byte": edit_flip_byte,
    "truncate": edit_truncate, "empty": edit_empty, "nul": edit_nul, "line_shuffle": edit_line_shuffle,
    "scale": edit_scale, "zero_area": edit_zero_area,
}
SAME_EDITS = ("equivalent_number", "negative_indices", "bom", "line_ends", "comment", "tabs")
REFUSE_EDITS = ("special_number", "unicode_digit", "underscore", "bad_index", "empty", "nul", "scale")
ANY_EDITS = ("flip_byte", "truncate", "line_shuffle", "long_line", "zero_area", "special_number", "scale",
             "bad_index", "nul")


def _apply(rng, text: str, kind: str, names: tuple[str, ...], want: str | None = None):
    """One edit drawn from ``names`` (whose expectation is ``want`` if given); None if none applies."""
    for _ in range(20):
        name = rng.choice(names)
        result = EDITS[name](rng, text, kind)
        if result is not None and (want is None or result[1] == want):
            return name, result
    return None


def _mutate_text(rng, text: str, kind: str) -> tuple[str, str, list[str]]:
    """A mutated text, its expectation and the edits applied."""
    plan = rng.choice(["same", "refuse", "any", "any"])
    edits, expect = [], plan
    if plan == "refuse":
        picked = _apply(rng, text, kind, REFUSE_EDITS, want="refuse")
        if picked is None:
            plan = expect = "any"
        else:
            edits.append(picked[0])
            text = picked[1][0]
    if plan == "any":
        for _ in range(rng.randint(1, 3)):
            picked = _apply(rng, text, kind, ANY_EDITS)
            if picked:
                edits.append(picked[0])
                text = picked[1][0]
    # Line ends change last: the token edits split lines on "\n" and join words with spaces.
    names = [rng.choice(SAME_EDITS) for _ in range(rng.randint(1 if plan == "same" else 0, 2))]
    for name in sorted(names, key=lambda n: n == "line_ends"):
        picked = _apply(rng, text, kind, (name,), want="same")
        if picked:
            edits.append(picked[0])
            text = picked[1][0]
    return text, expect, edits


def _encode(text: str) -> bytes:
    return text.encode("utf-8", errors="surrogateescape")


# ---------------------------------------------------------------------------------------------
# Mutants

# --max-patch-size 10 keeps the faces whole: a solve of the mutant then costs well under a second,
# and the readers and checks before the patches are what is fuzzed.
OBJ_ARGS = ["solve", "{dir}/{main}", "--preset", "draft", "--max-patch-size", "10", "--no-picture", "--no-cache",
            "-o", "{dir}/out"]
VS3_ARGS = ["viewfactors", "{dir}/{main}", "--preset", "draft", "--no-cache", "-o", "{dir}/F.npz"]
POINTS_ARGS = ["solve", "{dir}/unit_cube.obj", "--points", "{dir}/{main}", "--preset", "draft",
               "--max-patch-size", "10", "--no-picture", "--no-cache", "-o", "{dir}/out"]


def obj_mutant(rng: random.Random, base: str | None = None) -> Mutant:
    bases = _obj_bases()
    base = base or rng.choice(sorted(bases))
    files = {k: v.decode() for k, v in bases[base].items()}
    obj, mtl = f"{base}.obj", f"{base}.mtl"
    special = rng.random()
    if special < 0.06:  # the MTL is missing, or the mtllib line goes
        if rng.random() < 0.5:
            del files[mtl]
        else:
            files[obj] = "\n".join(l for l in files[obj].split("\n") if not l.startswith("mtllib"))
        return _mutant("obj", base, files, obj, OBJ_ARGS, "refuse", ["missing_mtl"])
    if special < 0.09:  # mtllib names something that is not a readable MTL
        target = rng.choice(["/dev/zero", "/dev/null", "/", "nowhere.mtl", "a\0b.mtl", "x" * 5000])
        files[obj] = files[obj].replace(f"mtllib {mtl}", f"mtllib {target}")
        return _mutant("obj", base, files, obj, OBJ_ARGS, "refuse", ["mtllib_target"])
    target = obj if rng.random() < 0.65 else mtl
    text, expect, edits = _mutate_text(rng, files[target], "obj" if target == obj else "mtl")
    files[target] = text
    return _mutant("obj", base, files, obj, OBJ_ARGS, expect, [f"{target.split('.')[1]}:{e}" for e in edits])


def vs3_mutant(rng: random.Random, base: str | None = None) -> Mutant:
    bases = _vs3_bases()
    base = base or rng.choice(sorted(bases))
    text, expect, edits = _mutate_text(rng, bases[base], "vs3")
    return _mutant("vs3", base, {f"{base}.vs3": text}, f"{base}.vs3", VS3_ARGS, expect, edits)


def points_mutant(rng: random.Random) -> Mutant:
    text, expect, edits = _mutate_text(rng, POINTS, "points")
    files = {k: v.decode() for k, v in _obj_bases()["unit_cube"].items()}
    files["points.txt"] = text
    return _mutant("points", "unit_cube+points", files, "points.txt", POINTS_ARGS, expect, edits)


def base_mutant(kind: str, base: str) -> Mutant:
    """The unmutated input, whose run gives the numbers 'same' mutants must reproduce."""
    if kind == "obj":
        return _mutant("obj", base, {k: v.decode() for k, v in _obj_bases()[base].items()}, f"{base}.obj",
                       OBJ_ARGS, "same", [])
    if kind == "vs3":
        return _mutant("vs3", base, {f"{base}.vs3": _vs3_bases()[base]}, f"{base}.vs3", VS3_ARGS, "same", [])
    files = {k: v.decode() for k, v in _obj_bases()["unit_cube"].items()}
    files["points.txt"] = POINTS
    return _mutant("points", base, files, "points.txt", POINTS_ARGS, "same", [])


def _mutant(kind, base, files, main, args, expect, edits) -> Mutant:
    return Mutant(kind, base, {name: _encode(t) for name, t in files.items()},
                  [a.replace("{main}", main) for a in args], expect, edits)


def mutants(kind: str, count: int, seed: int) -> list[Mutant]:
    """``count`` mutants of ``kind`` ("obj", "vs3", "points") from ``seed``: the same list every time."""
    rng = random.Random(f"{kind}:{seed}")
    make = {"obj": obj_mutant, "vs3": vs3_mutant, "points": points_mutant}[kind]
    return [make(rng) for _ in range(count)]


# ---------------------------------------------------------------------------------------------
# Running and classifying

class Timeout(BaseException):
    """The run took longer than its budget (not an Exception: the CLI must not catch it)."""


@dataclass
class Run:
    code: int | None
    stderr: str
    stdout: str
    error: str = ""  # an exception that escaped main, or "timeout"
    results: dict | None = None  # numbers to compare ('same' mutants), when the run succeeded
    nonfinite: str = ""  # which output held NaN/Inf


def run_mutant(mutant: Mutant, timeout: float = 60.0) -> Run:
    """Write the mutant's files to a fresh folder and run the CLI on them in this process."""
    from radiosity.cli import main

    with tempfile.TemporaryDirectory(prefix="radiosity-fuzz-") as folder:
        for name, data in mutant.files.items():
            (Path(folder) / name).write_bytes(data)
        args = [a.replace("{dir}", folder) for a in mutant.args]
        out, err = io.StringIO(), io.StringIO()
        previous = signal.signal(signal.SIGALRM, _on_alarm)
        signal.setitimer(signal.ITIMER_REAL, timeout)
        code, escaped = None, ""
        try:
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                code = main(args)
        except Timeout:
            escaped = "timeout"
        except MemoryError as exc:
            escaped = f"memory: {exc}"
        except BaseException as exc:  # noqa: BLE001 - anything escaping main is a finding
            escaped = f"{type(exc).__name__}: {str(exc)[:200]}"
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)
        run = Run(code, err.getvalue(), out.getvalue(), escaped)
        if code == 0:
            run.results, run.nonfinite = _read_results(mutant, Path(folder))
        return run


def _on_alarm(signum, frame):
    raise Timeout()


def _nonfinite_json(value) -> bool:
    if isinstance(value, float):
        return not math.isfinite(value)
    if isinstance(value, dict):
        return any(_nonfinite_json(v) for v in value.values())
    if isinstance(value, list):
        return any(_nonfinite_json(v) for v in value)
    return False


def _read_results(mutant: Mutant, folder: Path) -> tuple[dict, str]:
    """Numbers of a successful run, and the name of an output holding NaN/Inf ('' if none)."""
    bad = []
    results = {}
    if mutant.args[0] == "viewfactors":
        with np.load(folder / "F.npz") as arrays:
            for key in arrays.files:
                a = arrays[key]
                if a.dtype.kind == "f" and not np.isfinite(a).all():
                    bad.append(f"F.npz[{key}]")
            results = {"F": (arrays["data"].copy(), arrays["indices"].copy(), arrays["indptr"].copy()),
                       "area": arrays["area"].copy()}
        return results, ", ".join(bad)
    summary = json.loads((folder / "out" / "summary.json").read_text())
    if _nonfinite_json(summary):
        bad.append("summary.json")
    results["objects"] = summary.get("objects", {})
    csv = folder / "out" / "irradiance.csv"
    if csv.exists():
        values = np.loadtxt(csv, delimiter=",", skiprows=1, ndmin=2)
        if not np.isfinite(values).all():
            bad.append("irradiance.csv")
        results["irradiance"] = values[:, 6:]
    ply = folder / "out" / "solution.ply"
    if ply.exists() and not _ply_finite(ply):
        bad.append("solution.ply")
    return results, ", ".join(bad)


def _ply_finite(path: Path) -> bool:
    """The ASCII PLY's body holds no nan or inf (radiosity is written as float32)."""
    body = path.read_text(errors="replace").split("end_header", 1)[-1].lower()
    return "nan" not in body and "inf" not in body


def _same_numbers(a: dict, b: dict) -> bool:
    if a.keys() != b.keys():
        return False
    for key in a:
        x, y = a[key], b[key]
        if key == "objects":
            if x.keys() != y.keys() or not all(np.allclose(x[k], y[k], rtol=1e-7, atol=1e-12) for k in x):
                return False
        elif key == "F":
            if any(u.shape != v.shape for u, v in zip(x, y)) or not all(
                    np.allclose(u, v, rtol=1e-7, atol=1e-12) for u, v in zip(x, y)):
                return False
        elif np.shape(x) != np.shape(y) or not np.allclose(x, y, rtol=1e-7, atol=1e-12):
            return False
    return True


def classify(mutant: Mutant, run: Run, base: Run | None = None) -> tuple[str, str]:
    """(outcome class, why) of one run; ``base`` is the unmutated input's run ('same' mutants)."""
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    if run.error == "timeout" or run.error.startswith("memory"):
        return HANG, run.error
    if run.error or "Traceback" in run.stderr:
        return TRACEBACK, run.error or lines[-1][:200]
    if run.code == 0:
        if run.nonfinite:
            return NAN_EXIT0, run.nonfinite
        if mutant.expect == "refuse":
            return ACCEPTED_INVALID, "exit 0"
        if mutant.expect == "same" and base is not None and base.results is not None \
                and not _same_numbers(run.results, base.results):
            return WRONG, "numbers differ from the unmutated input's"
        return SOLVED, ""
    if run.code != 2:
        return TRACEBACK, f"exit {run.code}: {(lines[:1] or [''])[0][:200]}"
    if mutant.expect == "same":
        return REFUSED_VALID, lines[0][:200] if lines else ""
    errors = [line for line in lines if line.startswith("radiosity: error:")]
    if len(lines) != 1 or len(errors) != 1:
        return TOO_LONG, f"{len(lines)} stderr lines: {(lines[:1] or [''])[0][:200]}"
    if len(lines[0]) > MAX_MESSAGE:
        return TOO_LONG, f"{len(lines[0])} characters: {lines[0][:200]}"
    # Every reader error names its file; a memory refusal is about the request (scene size, patch size).
    if not any(name in lines[0] for name in mutant.files) and " of memory, more than " not in lines[0]:
        return TOO_LONG, f"names no input file: {lines[0][:200]}"
    return CLEAN, lines[0][:200]

"""The fast path of ``read_obj``: all ``v`` and ``f`` lines parsed at once with numpy.

A large OBJ is almost all ``v``, ``vt``, ``vn`` and ``f`` lines; parsing them one by one in
Python (tokens, checks, a small array per face) took minutes for 581k triangles. Here:

- every line is split once into keyword and rest;
- the rests of all ``v`` lines are joined and converted in one call, the first three tokens of
  each line; those of all ``f`` lines likewise, after cutting each reference at its first ``/``;
- the repeated-corner rule and the index checks run on whole arrays;
- only the few statements that change state (``o``, ``g``, ``usemtl``, ``mtllib``, ignored
  elements) go through a Python loop, in file order.

This path accepts exactly what the per-line path (``obj._parse_lines``) accepts and gives the
same arrays. Anything it is not sure of (a bad number, an index out of range, vertex 0, a face
of fewer than 3 corners, a coordinate beyond the limit, non-ASCII or control characters in
``v``/``f`` lines) raises :class:`Irregular` before any state changes, and the caller reruns
the file on the per-line path, which gives the ``file:line`` message it always gave. So an
invalid file costs its per-line time; a valid one never does.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass

import numpy as np

from ..geometry import FaceList

__all__ = ["Irregular", "Scan", "scan_lines", "scan_text", "parse_vertices", "parse_faces", "KINDS"]

# Bytes a v or f line may hold on this path: printable ASCII, space and tab (the separator is
# then exactly space or tab; str.split also splits on other characters, left to the slow path).
_UNUSUAL = re.compile(r"[^\x20-\x7e\t\n]")
_FLOAT_BYTES = np.zeros(256, bool)
_FLOAT_BYTES[list(b"0123456789+-.eE \t\n")] = True
_INT_BYTES = np.zeros(256, bool)
_INT_BYTES[list(b"0123456789+- \t\n")] = True
_UNUSUAL_BYTES = np.ones(256, bool)
_UNUSUAL_BYTES[0x20:0x7f] = False
_UNUSUAL_BYTES[[9, 10]] = False
_SPACE, _TAB, _NEWLINE, _SLASH, _HASH = 32, 9, 10, 47, 35


class Irregular(Exception):
    """The bulk path cannot vouch for these lines; read the file line by line."""


# Kinds of logical line. INERT: vt/vn (and any keyword that changes nothing); ACTIVE: o, g,
# usemtl, mtllib and the ignored elements, which change the reader's state.
V, F, S, ACTIVE, INERT = 1, 2, 3, 4, 0
_IGNORED = ("l", "p", "curv", "curv2", "surf")
KINDS = {"v": V, "f": F, "s": S, "o": ACTIVE, "g": ACTIVE, "usemtl": ACTIVE, "mtllib": ACTIVE,
         **{k: ACTIVE for k in _IGNORED}}


@dataclass
class Scan:
    """The logical lines of an OBJ file, sorted for the bulk parsers.

    ``numbers``/``kind``: line number and kind of every non-blank line; ``words[i]``: keyword and
    rest of line i if it is neither v nor f; ``v_bytes``/``f_bytes``: the rests of all v (f)
    lines, each ended by a newline, as bytes.
    """

    numbers: np.ndarray
    kind: np.ndarray
    words: dict[int, tuple[str, str]]
    v_bytes: np.ndarray
    f_bytes: np.ndarray


def scan_lines(lines: list[tuple[int, str]]) -> Scan:
    """A Scan of lines already split and cleaned (``obj._read_lines``)."""
    words, v_rests, f_rests = {}, [], []
    kind = np.empty(len(lines), np.int8)
    for i, (_, line) in enumerate(lines):
        head = line.split(None, 1)
        rest = head[1] if len(head) > 1 else ""
        k = kind[i] = KINDS.get(head[0], INERT)
        if k == V:
            v_rests.append(rest)
        elif k == F:
            f_rests.append(rest)
        else:
            words[i] = (head[0], rest)
    numbers = np.fromiter((n for n, _ in lines), np.int64, len(lines))
    return Scan(numbers, kind, words, _bytes_of(v_rests), _bytes_of(f_rests))


def _bytes_of(rests: list[str]) -> np.ndarray:
    """The lines each ended by a newline, as a byte array; ASCII only."""
    text = "\n".join(rests) + "\n" if rests else ""
    if _UNUSUAL.search(text):
        raise Irregular("unusual characters")
    return np.frombuffer(text.encode("ascii"), np.uint8)


def scan_text(text: str) -> Scan:
    """A Scan of a whole file's text, without a Python step per v or f line.

    Line ends are CR LF, LF or a lone CR, and ``#`` starts a comment, as in ``obj._read_lines``;
    a file with a backslash (a line continued) is Irregular here. A line is v or f when its
    first character is ``v`` or ``f`` followed by a space or tab; every other non-blank line is
    decoded and split as the per-line reader does, and if that makes it a v or f line after all
    (other white space than spaces and tabs), the file is Irregular.
    """
    if "\\" in text:
        raise Irregular("continued lines")
    text = text.replace("\r\n", "\n").replace("\r", "\n")
    if text and not text.endswith("\n"):
        text += "\n"
    data = text.encode("utf-8", "surrogatepass")
    buf = np.frombuffer(data, np.uint8)
    ends = np.flatnonzero(buf == _NEWLINE)
    if not len(ends):
        return Scan(np.zeros(0, np.int64), np.zeros(0, np.int8), {}, buf[:0], buf[:0])
    starts = np.concatenate([[0], ends[:-1] + 1]).astype(np.int64)
    cut = ends.copy()  # where each line's text ends: its first '#', or its newline
    hashes = np.flatnonzero(buf == _HASH)
    if len(hashes):
        np.minimum.at(cut, np.searchsorted(ends, hashes), hashes)
    first = starts.copy()  # first byte that is not a space or tab
    while True:
        blank = (first < cut) & ((buf[first] == _SPACE) | (buf[first] == _TAB))
        if not blank.any():
            break
        first[blank] += 1
    full = first < cut
    c0 = buf[first]
    c1 = buf[np.minimum(first + 1, len(buf) - 1)]
    c2 = buf[np.minimum(first + 2, len(buf) - 1)]
    after = (c1 == _SPACE) | (c1 == _TAB)
    kind = np.full(len(ends), -1, np.int8)  # -1: decide in Python
    kind[full & (c0 == ord("v")) & after] = V
    kind[full & (c0 == ord("f")) & after] = F
    inert = (c0 == ord("v")) & ((c1 == ord("t")) | (c1 == ord("n")))
    inert &= (c2 == _SPACE) | (c2 == _TAB) | (first + 2 >= cut)
    kind[full & inert] = INERT
    kind[~full] = -2  # blank or comment only
    words = {}
    for i in np.flatnonzero(kind == -1).tolist():
        line = data[starts[i]:ends[i]].decode("utf-8", "surrogatepass").split("#", 1)[0].strip()
        if not line:
            kind[i] = -2
            continue
        head = line.split(None, 1)
        kind[i] = KINDS.get(head[0], INERT)
        if kind[i] in (V, F):
            raise Irregular("white space other than spaces and tabs")
        words[i] = (head[0], head[1] if len(head) > 1 else "")
    keep = np.flatnonzero(kind != -2)
    renumber = np.cumsum(kind != -2) - 1
    words = {int(renumber[i]): w for i, w in words.items()}
    return Scan(keep + 1, kind[keep], words, _bodies(buf, first, cut, ends, kind == V, starts),
                _bodies(buf, first, cut, ends, kind == F, starts))


# At most this many runs of consecutive lines are sliced out whole (``_bodies``); more go by a mask.
_MAX_RUNS = 10_000


def _bodies(buf: np.ndarray, first: np.ndarray, cut: np.ndarray, ends: np.ndarray, rows: np.ndarray,
            starts: np.ndarray | None = None) -> np.ndarray:
    """The bytes after the keyword (one byte) up to the comment of the lines ``rows``, each
    followed by a newline."""
    if not rows.any():
        return np.zeros(0, np.uint8)
    if starts is not None:
        out = _bodies_by_runs(buf, first, cut, ends, np.flatnonzero(rows), starts)
        if out is not None:
            return out
    marks = np.zeros(len(buf) + 1, np.int8)
    marks[first[rows] + 1] = 1  # the lines' spans are disjoint and non-empty: no position repeats
    marks[cut[rows]] = -1
    inside = np.cumsum(marks[:-1], dtype=np.int8) > 0
    inside[ends[rows]] = True
    out = buf[inside]
    if _UNUSUAL_BYTES[out].any():
        raise Irregular("unusual characters")
    return out


def _bodies_by_runs(buf: np.ndarray, first: np.ndarray, cut: np.ndarray, ends: np.ndarray, rows: np.ndarray,
                    starts: np.ndarray) -> np.ndarray | None:
    """:func:`_bodies` when the lines have no leading blanks and no comments and come in few runs
    of consecutive lines (as exporters write ``v`` and ``f`` blocks): each run is one slice, less
    its keyword bytes; None otherwise. A mask and a running sum over every byte of the file cost
    about a second on 43 MB."""
    if not ((first[rows] == starts[rows]).all() and (cut[rows] == ends[rows]).all()):
        return None
    breaks = np.flatnonzero(np.diff(rows) != 1)
    if len(breaks) >= _MAX_RUNS:
        return None
    run_first, run_last = rows[np.r_[0, breaks + 1]], rows[np.r_[breaks, len(rows) - 1]]
    out = np.concatenate([buf[starts[a]:ends[b] + 1] for a, b in zip(run_first.tolist(), run_last.tolist())])
    lengths = ends[run_last] + 1 - starts[run_first]
    base = np.cumsum(lengths) - lengths  # where each run begins in ``out``
    run_of = np.repeat(np.arange(len(run_first)), np.diff(np.r_[0, breaks + 1, len(rows)]))
    keyword = starts[rows] - starts[run_first][run_of] + base[run_of]
    keep = np.ones(len(out), bool)
    keep[keyword] = False
    out = out[keep]
    if _UNUSUAL_BYTES[out].any():
        raise Irregular("unusual characters")
    return out


def _tokens(buf: np.ndarray, n_lines: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Separator mask of the bytes, first byte of each token, and tokens per line."""
    sep = (buf == _SPACE) | (buf == _TAB) | (buf == _NEWLINE)
    start = ~sep
    start[1:] &= sep[:-1]
    starts = np.flatnonzero(start)
    line_of_token = np.searchsorted(np.flatnonzero(buf == _NEWLINE), starts)
    return sep, starts, np.bincount(line_of_token, minlength=n_lines)


def _first_tokens(buf: np.ndarray, sep: np.ndarray, starts: np.ndarray, per_line: np.ndarray, k: int) -> np.ndarray:
    """Byte mask keeping the separators and the first ``k`` tokens of each line."""
    first = np.concatenate([[0], np.cumsum(per_line)[:-1]])
    rank = np.arange(len(starts)) - np.repeat(first, per_line)
    dropped = starts[rank >= k]  # a dropped token runs from its start to the next separator
    separators = np.flatnonzero(sep)
    cover = np.zeros(len(buf) + 1, np.int32)
    np.add.at(cover, dropped, 1)
    np.add.at(cover, separators[np.searchsorted(separators, dropped)], -1)
    return np.cumsum(cover[:-1]) == 0


def _checked(buf: np.ndarray, allowed: np.ndarray) -> bytes:
    if len(buf) and not allowed[buf].all():
        raise Irregular("not a plain number")
    return buf.tobytes()


def _floats(buf: np.ndarray, count: int) -> np.ndarray:
    """Exactly ``count`` floats from the separated bytes ``buf``, or Irregular.

    Each token goes through Python's float (what ``parse_float`` calls); the byte check first
    keeps out what float takes and the OBJ grammar does not (``1_0``, ``inf``, other digits).
    """
    tokens = _checked(buf, _FLOAT_BYTES).split()
    if len(tokens) != count:
        raise Irregular("token count")
    try:
        return np.array(tokens, dtype=np.float64)
    except ValueError:
        raise Irregular("not a number") from None


def _ints(buf: np.ndarray, count: int) -> np.ndarray:
    """Exactly ``count`` integers from the separated bytes ``buf``, or Irregular.

    ``np.fromstring`` is three times faster than ``int`` per token, with two quirks the caller's
    checks cover: a lone ``+`` or ``-`` reads as 0 (vertex 0 is refused), and numbers beyond
    int64 saturate (out of range). It stops early (a warning, raised here) at anything else
    that is not an integer, and reads ``1-2`` as two numbers (the count).
    """
    text = _checked(buf, _INT_BYTES).decode("ascii")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            values = np.fromstring(text, dtype=np.int64, sep=" ")
        except (ValueError, DeprecationWarning):
            raise Irregular("not an integer") from None
    if len(values) != count:
        raise Irregular("token count")
    return values


def parse_vertices(buf: np.ndarray, n_lines: int, max_coordinate: float) -> np.ndarray:
    """(n, 3) coordinates of the ``v`` lines' rests (``Scan.v_bytes``): their first three numbers each."""
    if not n_lines:
        return np.zeros((0, 3))
    sep, starts, per_line = _tokens(buf, n_lines)
    if (per_line < 3).any():
        raise Irregular("short vertex")
    if (per_line > 3).any():  # what follows the third number (w, colours) is not read
        buf = buf[_first_tokens(buf, sep, starts, per_line, 3)]
    xyz = _floats(buf, 3 * n_lines).reshape(-1, 3)
    if not (np.abs(xyz) <= max_coordinate).all():  # also false for inf and nan
        raise Irregular("coordinate")
    return xyz


def parse_faces(buf: np.ndarray, n_before: np.ndarray, vertices: np.ndarray) -> list[np.ndarray]:
    """0-based corner indices of each ``f`` line, repeated consecutive corners dropped.

    ``buf`` holds the rests of the lines (``Scan.f_bytes``); ``n_before[i]`` is the number of
    vertices defined before face i (negative references count back from it).
    """
    if not len(n_before):
        return []
    sep, starts, sizes = _tokens(buf, len(n_before))
    if (sizes < 3).any():
        raise Irregular("short face")
    # only the v part of v/vt/vn is read: drop every byte from a token's first '/' on
    slashes = np.flatnonzero(buf == _SLASH)
    if len(slashes):
        buf = buf[~_tails(sep, starts, slashes)]
    index = _ints(buf, int(sizes.sum()))
    limit = np.repeat(n_before, sizes)
    if (index == 0).any():
        raise Irregular("vertex 0")
    resolved = np.where(index > 0, index - 1, limit + index)
    if ((resolved < 0) | (resolved >= limit)).any():
        raise Irregular("vertex out of range")
    return _drop_repeats(resolved, sizes, vertices)


def _tails(sep: np.ndarray, starts: np.ndarray, slashes: np.ndarray) -> np.ndarray:
    """Byte mask of each token's tail: from its first ``/`` up to the separator after it.

    Per token, not per byte (a running maximum over the bytes took a second on 27 MB of faces):
    every token ends at a separator, since each line ends with a newline.
    """
    separators = np.flatnonzero(sep)
    ends = separators[np.searchsorted(separators, starts)]
    first = np.searchsorted(slashes, starts)
    slash = slashes[np.minimum(first, len(slashes) - 1)]
    tailed = (first < len(slashes)) & (slash < ends)
    cover = np.zeros(len(sep) + 1, np.int8)  # +1 where a tail starts, -1 where it ends: disjoint spans
    cover[slash[tailed]] = 1
    cover[ends[tailed]] = -1
    return np.cumsum(cover[:-1], dtype=np.int8) > 0


def _drop_repeats(corners: np.ndarray, sizes: np.ndarray, vertices: np.ndarray) -> list[np.ndarray]:
    """The faces with every corner dropped that sits where the corner before it does (cyclically;
    the first corner's predecessor is the last). A face left with no corner keeps its first."""
    ends = np.cumsum(sizes)
    starts = ends - sizes
    prev = np.arange(len(corners)) - 1
    prev[starts] = ends - 1
    keep = (vertices[corners] != vertices[corners[prev]]).any(axis=1)
    kept = np.add.reduceat(keep, starts) if len(starts) else np.zeros(0, np.int64)
    keep[starts[kept == 0]] = True  # zero area: "or idx[:1]"
    flat = corners[keep]
    sizes = np.maximum(kept, 1).astype(np.int64)
    bounds = np.concatenate([[0], np.cumsum(sizes)]).tolist()
    return FaceList([flat[a:b] for a, b in zip(bounds[:-1], bounds[1:])], flat, sizes)

"""Reading text inputs safely: regular files only, a stated size limit, one line and number grammar.

Every reader (OBJ, MTL, ``.vs3``, points files) goes through here, so an OBJ from someone else
cannot make the tool read ``/dev/zero`` until memory runs out, hang on a FIFO, or read ``1_0``
as ten.

- Only regular files are read; FIFOs, devices and sockets are refused by name.
- A file larger than ``max_input_bytes()`` (1 GiB, or ``RADIOSITY_MAX_INPUT_BYTES``) is refused
  with the limit, before it is read.
- A UTF-8 byte-order mark is dropped. ``\\r\\n``, ``\\n`` and a lone ``\\r`` all end a line.
- Numbers are ASCII decimal floats (``-1``, ``.5``, ``2.``, ``1e-3``, ``inf``, ``nan``): Python's
  ``float`` also takes ``1_0`` and Arabic-Indic digits, which no exporter writes on purpose.
- Messages quote at most ``EXCERPT_CHARS`` characters of a line.
"""

from __future__ import annotations

import errno
import os
import re
import stat
from pathlib import Path

__all__ = ["ENV_MAX_INPUT", "max_input_bytes", "read_input", "check_regular", "split_lines", "decode",
           "parse_float", "excerpt"]

ENV_MAX_INPUT = "RADIOSITY_MAX_INPUT_BYTES"
DEFAULT_MAX_INPUT = 1 << 30
EXCERPT_CHARS = 80

_LINE_END = re.compile(r"\r\n|\r|\n")
_FLOAT = re.compile(r"[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|inf(?:inity)?|nan)", re.ASCII | re.IGNORECASE)
_KINDS = ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def max_input_bytes() -> int:
    """The largest input file read, in bytes (``RADIOSITY_MAX_INPUT_BYTES``, default 1 GiB)."""
    raw = os.environ.get(ENV_MAX_INPUT, "").strip()
    if not raw:
        return DEFAULT_MAX_INPUT
    try:
        value = int(float(raw))
    except ValueError:
        raise ValueError(f"{ENV_MAX_INPUT}={raw!r} is not a number of bytes") from None
    if value <= 0:
        raise ValueError(f"{ENV_MAX_INPUT}={raw!r} must be positive")
    return value


def read_input(path: str | Path, what: str) -> bytes:
    """The bytes of a regular file of at most ``max_input_bytes()``.

    ``what`` names the file's role in messages ("OBJ", "MTL", "points"). A missing or unreadable
    file raises the usual OSError (with ``filename``); a refused one an OSError whose message
    says why ("it is a FIFO ...", "it is 2,000,000 bytes, above ..."), for the caller to prefix
    with the path.
    """
    path = Path(path)
    limit = max_input_bytes()
    check_regular(path, what)  # before open: opening a FIFO blocks until someone writes to it
    with open(path, "rb") as handle:
        info = os.fstat(handle.fileno())
        _check_kind(info, path, what)  # it may have been swapped since the check
        if info.st_size > limit:
            raise OSError(f"it is {info.st_size:,} bytes, above the input limit of {limit:,} bytes "
                          f"(raise it with {ENV_MAX_INPUT})")
        data = handle.read(limit + 1)
    if len(data) > limit:  # the file grew while being read
        raise OSError(f"it grew above the input limit of {limit:,} bytes while being read")
    return data


def _check_kind(info: os.stat_result, path: Path, what: str) -> None:
    if stat.S_ISDIR(info.st_mode):
        raise IsADirectoryError(errno.EISDIR, "is a folder, not a file", str(path))
    for test, kind in _KINDS:
        if test(info.st_mode):
            raise OSError(f"it is {kind}, not a regular {what} file")


def check_regular(path: str | Path, what: str) -> None:
    """Refuse a path that is not a regular file, without opening it (a FIFO would block ``open``)."""
    path = Path(path)
    info = os.stat(path)
    _check_kind(info, path, what)


def split_lines(text: str) -> list[str]:
    """Lines of ``text``; CR LF, LF and a lone CR each end one (``str.splitlines`` also splits on
    form feeds and Unicode separators, which are not line ends in these formats)."""
    lines = _LINE_END.split(text)
    if lines and lines[-1] == "":
        lines.pop()
    return lines


def decode(data: bytes) -> str:
    """UTF-8 text without a byte-order mark (undecodable bytes replaced)."""
    return data.decode("utf-8-sig", errors="replace")


def parse_float(token: str) -> float:
    """``float(token)`` for ASCII decimal numbers only; ValueError otherwise."""
    if not _FLOAT.fullmatch(token):
        raise ValueError(f"not a number: {excerpt(token)!r}")
    return float(token)


def excerpt(text: str, limit: int = EXCERPT_CHARS) -> str:
    """``text`` cut to ``limit`` characters, with an ellipsis and the full length when cut."""
    text = text.strip()
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text):,} characters)"

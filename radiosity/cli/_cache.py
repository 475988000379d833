"""``radiosity cache info|clear``: what the form-factor cache holds, and emptying it."""

from __future__ import annotations

from ..methods.uniform.cache import ENV_SIZE, FormFactorCache
from .._memory import format_bytes

NAME = "cache"
HELP = "show (info) or empty (clear) the form-factor cache"


def add_args(parser) -> None:
    parser.add_argument("action", choices=("info", "clear"),
                        help=f"info: folder, entries and size against the cap ({ENV_SIZE}); clear: remove every entry")


def run(args) -> int:
    cache = FormFactorCache.default()
    if args.action == "clear":
        count, size = cache.clear()
        print(f"removed {count} entr{'y' if count == 1 else 'ies'} ({format_bytes(size)}) from {cache.folder}")
        return 0
    info = cache.info()
    print(f"folder     {info['folder']}  (RADIOSITY_CACHE)")
    print(f"entries    {info['entries']}, {format_bytes(info['bytes'])} of {format_bytes(info['limit'])} "
          f"({ENV_SIZE}; the least recently used are removed beyond it)")
    return 0

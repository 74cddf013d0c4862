"""JSON a user hands us (a JSONL file of records), read with bounds: one line at a time, each line
capped in bytes, its nesting depth checked before the parser recurses.

Why: ``json.loads`` recurses once per ``[``/``{``, so a line of 200,000 brackets ends in
``RecursionError`` (a traceback or an exit 1 with no ``file:line``), and reading a whole file to
split it into lines holds all of it in memory before its first record is looked at. Here a file is
read line by line (:func:`lines`, at most :data:`MAX_LINE_BYTES` held at once), a line's depth is
counted over its brackets outside strings with an early stop (:func:`too_deep`), and only then
parsed (:func:`loads`). Every refusal is a :class:`ValueError` of one line, for the caller to prefix
with ``FILE:LINE``. No record of SWE-bench (or of any benchmark here) nests deeper than 4 levels;
:data:`MAX_DEPTH` leaves room for a user's extra fields.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from typing import IO, Any

#: the deepest nesting of arrays and objects accepted in one value
MAX_DEPTH = 64
#: the longest line accepted (a SWE-bench Verified record is well under 2 MB)
MAX_LINE_BYTES = 16 << 20
#: a JSON string (its escapes included): brackets inside one do not nest
_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)
#: every byte but the four brackets, deleted before counting
_NOT_BRACKETS = bytes(b for b in range(256) if b not in b"[]{}")


def too_deep(text: str | bytes, limit: int = MAX_DEPTH) -> bool:
    """Whether ``text`` nests arrays/objects deeper than ``limit`` (brackets inside strings not
    counted); stops at the first bracket past the limit, so a hostile line costs one regex pass."""
    raw = text.encode("utf-8", errors="surrogatepass") if isinstance(text, str) else text
    brackets = _STRING.sub(b"", raw).translate(None, _NOT_BRACKETS)
    depth = 0
    for b in brackets:
        depth += 1 if b in b"[{" else -1
        if depth > limit:
            return True
    return False


def loads(text: str | bytes, limit: int = MAX_DEPTH) -> Any:
    """``json.loads`` of one value after the depth check; ValueError (one line) for nesting past
    ``limit`` or bad JSON (``json.JSONDecodeError`` is a ValueError: its ``msg``/``colno`` kept)."""
    if too_deep(text, limit):
        raise ValueError(f"nested deeper than {limit} levels of arrays/objects")
    try:
        return json.loads(text)
    except RecursionError:  # a depth the scan let through cannot recurse this far; kept as a guard
        raise ValueError(f"nested deeper than {limit} levels of arrays/objects") from None


class LineTooLong(ValueError):
    """A line over the byte cap: ``number`` is its line number (the message names the cap)."""

    def __init__(self, number: int, max_bytes: int) -> None:
        super().__init__(f"longer than {max_bytes} bytes (one record a line)")
        self.number = number


def lines(f: IO[bytes], max_bytes: int = MAX_LINE_BYTES) -> Iterator[tuple[int, bytes]]:
    """``(line number, line)`` of a binary stream, read as it is consumed (a FIFO or a file of a
    million lines costs only the lines taken); LineTooLong once a line passes ``max_bytes``,
    without reading the rest of it."""
    number = 0
    while True:
        line = f.readline(max_bytes + 1)
        if not line:
            return
        number += 1
        if len(line) > max_bytes and not (len(line) == max_bytes + 1 and line.endswith(b"\n")):
            raise LineTooLong(number, max_bytes)
        yield number, line.rstrip(b"\r\n")


def records(f: IO[bytes], name: str, max_bytes: int = MAX_LINE_BYTES) -> Iterator[tuple[int, Any]]:
    """``(line number, value)`` of each non-blank line of the JSONL stream ``f`` named ``name``,
    read as consumed (:func:`lines`) and parsed with the depth bound (:func:`loads`); every refusal
    is a one-line ValueError ``name:LINE: what is wrong`` (not UTF-8, not JSON, too deep, too long)."""
    try:
        for number, line in lines(f, max_bytes):
            if not line.strip():
                continue
            try:
                text = line.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise ValueError(f"{name}:{number}: cannot be read as UTF-8 text ({exc.reason} at byte {exc.start})") from None
            try:
                yield number, loads(text)
            except json.JSONDecodeError as exc:
                raise ValueError(f"{name}:{number}: not valid JSON ({exc.msg} at column {exc.colno})") from None
            except ValueError as exc:
                raise ValueError(f"{name}:{number}: {exc}") from None
    except LineTooLong as exc:
        raise ValueError(f"{name}:{exc.number}: {exc}") from None

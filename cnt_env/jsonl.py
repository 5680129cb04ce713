"""JSON-lines results files: one line per finished item, appended as items end and read
back to resume or to summarise.

The benchmarks and studies that run episodes or sweep points write here (``--out``). A
run killed mid-write leaves its last line cut short: :func:`read_rows` drops it and
:func:`append_row` cuts it off before appending, so that a resumed run's rows are read
back and the cut item is run again. A line that is not a JSON object anywhere else is not
a crash's work, so it is refused with an error naming the file and the line; the file is
never rewritten.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any


class JsonlError(ValueError):
    """A results file that this module did not write (or that was edited by hand)."""


def _complete_end(path: Path, data: bytes) -> int:
    """Byte length of ``data`` up to its last complete line (newline-terminated, or a
    whole JSON object without its newline)."""
    if not data or data.endswith(b"\n"):
        return len(data)
    start = data.rfind(b"\n") + 1
    try:
        _parse(path, data[start:].decode(), data.count(b"\n") + 1)
    except (JsonlError, UnicodeDecodeError):
        return start  # the last line was cut short by a crash
    return len(data)


def _parse(path: Path, line: str, number: int) -> dict[str, Any]:
    try:
        row = json.loads(line)
    except ValueError as exc:
        raise JsonlError(
            f"{path}, line {number}: not a JSON line ({exc}); mend or delete that line, "
            "or pass another --out"
        ) from None
    if not isinstance(row, dict):
        raise JsonlError(f"{path}, line {number}: a JSON {type(row).__name__}, not an object")
    return row


def read_rows(path: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """The rows of a JSON-lines file, in order ([] if it does not exist). Blank lines are
    skipped and a last line cut short by a crash is dropped; any other bad line raises
    :class:`JsonlError`."""
    path = Path(path)
    if not path.exists():
        return []
    data = path.read_bytes()
    try:
        text = data[: _complete_end(path, data)].decode()
    except UnicodeDecodeError as exc:
        raise JsonlError(f"{path} is not UTF-8 text ({exc}); pass another --out") from None
    return [_parse(path, line, i) for i, line in enumerate(text.split("\n"), 1) if line.strip()]


def append_row(path: str | os.PathLike[str], row: Mapping[str, Any], echo: bool = False) -> None:
    """Append ``row`` as one line (flushed to the OS before returning), after cutting off a
    last line left incomplete by a crash (with a warning on stderr). ``echo`` also prints
    the line to stdout."""
    path = Path(path)
    line = json.dumps(row)
    with path.open("ab+") as fh:
        size = fh.seek(0, os.SEEK_END)
        if size:
            fh.seek(max(0, size - 1))
            if fh.read(1) != b"\n":
                fh.seek(0)
                data = fh.read()
                end = _complete_end(path, data)
                if end < size:
                    print(f"{path}: dropped {size - end} bytes of an incomplete last line",
                          file=sys.stderr)  # fmt: skip
                    fh.truncate(end)
                if end and not data[:end].endswith(b"\n"):
                    fh.write(b"\n")
        fh.write(line.encode() + b"\n")
        fh.flush()
    if echo:
        print(line, flush=True)

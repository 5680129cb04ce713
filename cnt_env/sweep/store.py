"""The sweep CSV: one flushed row per finished point, read back to resume.

A row cut short by a crash (the last line, or a line ending inside an unclosed quote) is
dropped when read and cut off before the next rows are appended, so that every appended
row is read again. A file that is not UTF-8 text, or not a CSV, is refused with an error
naming ``--out``; it is never rewritten.
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cnt_env.runs import RunInputError
from cnt_env.sweep.grid import LATER_RESULT_COLUMNS, point_key

_INT_COLUMNS = frozenset(
    {"seed", "n_uturns", "n_loops", "n_cycles", "settled_loop_events", "steps", "newton_iterations"}
)
_TEXT_COLUMNS = frozenset({"pattern", "failure", "config_hash"})
#: Largest sweep CSV read back (bytes): a bigger file is not one this tool wrote.
MAX_CSV_BYTES = 1 << 30


def format_cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return repr(v) if math.isfinite(v) else ""
    return str(value)


def parse_cell(column: str, text: str) -> Any:
    if column in _TEXT_COLUMNS:
        return text
    if text == "":
        return math.nan
    try:
        value = float(text)
    except ValueError:
        return text
    if column in _INT_COLUMNS and value.is_integer():
        return int(value)
    return value


@dataclass
class CsvContent:
    """What a sweep CSV holds: ``header`` (None when empty), parsed ``rows``, and
    ``good_end``, the byte offset after the last complete line (``size`` when intact)."""

    header: list[str] | None
    rows: list[dict[str, Any]]
    good_end: int
    size: int


def scan(path: Path) -> CsvContent:
    """Read a sweep CSV; raises RunInputError (naming ``--out``) when it is not one."""
    try:
        if not path.exists() or path.stat().st_size == 0:
            return CsvContent(None, [], 0, 0)
        if not path.is_file():
            raise RunInputError(f"--out {path} is not a regular file")
        if path.stat().st_size > MAX_CSV_BYTES:
            raise RunInputError(f"--out {path} is over {MAX_CSV_BYTES} bytes: not a sweep CSV")
        data = path.read_bytes()
    except OSError as exc:
        raise RunInputError(f"--out {path} cannot be read: {exc.strerror or exc}") from exc
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RunInputError(
            f"--out {path} is not a sweep CSV: it is not UTF-8 text (byte {exc.start}); "
            "pass another --out, or repair or remove the file"
        ) from exc
    pieces = text.split("\n")
    lines = [p + "\n" for p in pieces[:-1]] + ([pieces[-1]] if pieces[-1] else [])
    offsets = [0]
    for line in lines:
        offsets.append(offsets[-1] + len(line.encode("utf-8")))
    reader = csv.reader(iter(lines), strict=True)
    header: list[str] | None = None
    rows: list[dict[str, Any]] = []
    good_end = 0
    try:
        for record in reader:
            complete = lines[reader.line_num - 1].endswith("\n")
            if header is None:
                if not record or not complete:
                    break
                header = record
            elif len(record) != len(header) or not complete:
                if reader.line_num < len(lines):
                    good_end = offsets[reader.line_num]
                continue  # a line cut short by a crash
            else:
                rows.append({c: parse_cell(c, t) for c, t in zip(header, record, strict=True)})
            good_end = offsets[reader.line_num]
    except csv.Error:
        pass  # an unclosed quote: everything from its line on is a cut row
    if header is None:
        if text.strip():
            raise RunInputError(
                f"--out {path} is not a sweep CSV (no header line); pass another --out or remove it"
            )
        return CsvContent(None, [], 0, len(data))
    return CsvContent(header, rows, good_end, len(data))


def read_rows(path: Path) -> tuple[list[str] | None, list[dict[str, Any]]]:
    """Header and rows of a sweep CSV (numbers parsed; incomplete lines dropped)."""
    content = scan(path)
    return content.header, content.rows


class CsvSink:
    """Appends rows to the sweep CSV, one flushed line per finished point."""

    def __init__(
        self, path: Path, columns: Sequence[str], warn: Callable[[str], None] | None = None
    ) -> None:
        self.path = path
        content = scan(path)
        header = content.header
        missing = [] if header is None else [c for c in columns if c not in header]
        if header is not None and (
            set(header) - set(columns) or not set(missing) <= LATER_RESULT_COLUMNS
        ):
            raise RunInputError(
                f"--out {path} holds a different sweep (columns {', '.join(header)[:300]}); "
                "pass another --out or remove it"
            )
        if missing and warn is not None:
            # written before those result columns existed: resumed with its own header
            warn(f"--out {path} predates the columns {', '.join(missing)}; its new rows "
                 "leave them out too (pass another --out to have them)")  # fmt: skip
        self.columns = list(header or columns)
        try:
            if header is not None and content.good_end < content.size:
                # a cut row at the end (or an unclosed quote): cut it off so that the
                # rows appended now are read back
                if warn is not None:
                    warn(f"--out {path}: dropped {content.size - content.good_end} bytes of "
                         "an incomplete last row")  # fmt: skip
                with path.open("r+b") as f:
                    f.truncate(content.good_end)
            needs_newline = False
            if header is not None and content.good_end > 0:
                with path.open("rb") as f:
                    f.seek(content.good_end - 1)
                    needs_newline = f.read(1) != b"\n"
            if header is None and content.size:
                path.open("wb").close()  # whitespace only
            self._file = path.open("a", newline="", encoding="utf-8")
        except OSError as exc:
            raise RunInputError(f"--out {path} cannot be written: {exc.strerror or exc}") from exc
        if needs_newline:
            self._file.write("\n")
        self._writer = csv.writer(self._file)
        if header is None:
            self._writer.writerow(self.columns)
            self._file.flush()

    def write(self, row: Mapping[str, Any]) -> None:
        self._writer.writerow([format_cell(row.get(c)) for c in self.columns])
        self._file.flush()
        os.fsync(self._file.fileno())

    def close(self) -> None:
        self._file.close()


def finished_rows(
    rows: Iterable[Mapping[str, Any]], params: Sequence[str], retry_failed: bool
) -> dict[tuple, Mapping[str, Any]]:
    """Rows that count as done, by point key (the last row of a key wins)."""
    done: dict[tuple, Mapping[str, Any]] = {}
    for row in rows:
        try:
            key = point_key(row["config_hash"], [row[p] for p in params], row["seed"])
        except (KeyError, TypeError, ValueError):
            continue
        failed = bool(row.get("failure")) and not str(row["failure"]).startswith("not measured")
        if retry_failed and failed:
            done.pop(key, None)
            continue
        done[key] = row
    return done


__all__ = ["CsvSink", "finished_rows", "format_cell", "parse_cell", "read_rows", "scan"]

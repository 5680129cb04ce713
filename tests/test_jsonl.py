"""cnt_env.jsonl: the results files of the benchmarks and studies survive a crash mid-write
and refuse a file they did not write."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from cnt_env.jsonl import JsonlError, append_row, read_rows

ROWS = [{"seed": 0, "score": 0.5}, {"seed": 1, "score": math.inf, "name": "a\nb"}]


def test_rows_round_trip_in_order(tmp_path: Path, capsys) -> None:
    path = tmp_path / "r.jsonl"
    assert read_rows(path) == []
    for row in ROWS:
        append_row(path, row, echo=True)
    assert read_rows(path) == ROWS
    assert capsys.readouterr().out.count("\n") == 2
    assert path.read_text().count("\n") == 2


def test_a_line_cut_by_a_crash_is_dropped_then_cut_off(tmp_path: Path, capsys) -> None:
    path = tmp_path / "r.jsonl"
    append_row(path, ROWS[0])
    with path.open("a") as fh:
        fh.write('{"seed": 1, "sco')  # killed mid-write
    assert read_rows(path) == ROWS[:1]
    append_row(path, ROWS[1])
    assert "dropped 16 bytes" in capsys.readouterr().err
    assert read_rows(path) == ROWS


def test_a_whole_last_line_without_its_newline_is_kept(tmp_path: Path) -> None:
    path = tmp_path / "r.jsonl"
    path.write_text('{"seed": 0, "score": 0.5}')  # written by hand, no final newline
    assert read_rows(path) == ROWS[:1]
    append_row(path, ROWS[1])
    assert read_rows(path) == ROWS


def test_blank_lines_are_skipped(tmp_path: Path) -> None:
    path = tmp_path / "r.jsonl"
    path.write_text('\n{"seed": 0, "score": 0.5}\n\n')
    assert read_rows(path) == ROWS[:1]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('{"seed": 0}\nnot json\n{"seed": 2}\n', "line 2: not a JSON line"),
        ('{"seed": 0}\n[1, 2]\n', "line 2: a JSON list, not an object"),
    ],
)
def test_a_bad_line_before_the_last_is_refused(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "r.jsonl"
    path.write_text(text)
    with pytest.raises(JsonlError, match=message):
        read_rows(path)
    assert path.read_text() == text  # nothing lost


def test_a_file_that_is_not_text_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "r.jsonl"
    path.write_bytes(b'{"seed": 0}\n\xff\xfe{"seed": 1}\n')
    with pytest.raises(JsonlError, match="not UTF-8"):
        read_rows(path)

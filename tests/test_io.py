"""The file formats and output helpers of ``cnt_env.io``: the trace file, JSON, the
config hash, and outputs written safely (regular files only, never through a symlink,
as a unit)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from cnt_env import units
from cnt_env.io import (
    OutputError,
    OutputSet,
    TraceFileError,
    check_output_path,
    config_hash,
    load_trace,
    save_trace,
    to_jsonable,
)


def test_trace_file_rejects_bad_contents(tmp_path: Path) -> None:
    params = units.paper_groups("coil")
    with pytest.raises(ValueError, match="NaN"):
        save_trace(tmp_path / "x.npz", np.full((3, 3), np.nan), params, {}, {})
    with pytest.raises(ValueError, match="shape"):
        save_trace(tmp_path / "x.npz", np.zeros((3, 2)), params, {}, {})
    damaged = tmp_path / "damaged.npz"
    np.savez(damaged, format=np.array("cnt_env.trace"), format_version=np.array(1))
    with pytest.raises(TraceFileError, match="missing"):
        load_trace(damaged)
    newer = tmp_path / "newer.npz"
    save_trace(newer, np.zeros((3, 3)), params, {}, {})
    with np.load(newer) as npz:
        entries = dict(npz)
    entries["format_version"] = np.array(2)
    np.savez(newer, **entries)
    with pytest.raises(TraceFileError, match="upgrade"):
        load_trace(newer)


def test_trace_file_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "no_suffix"
    trace = np.arange(12.0).reshape(4, 3)
    params = units.paper_groups("coil")
    save_trace(path, trace, params, {"seed": 3}, {"steps": np.int64(7), "x": np.nan})
    assert path.exists()  # no .npz appended
    saved = load_trace(path)
    np.testing.assert_array_equal(saved["trace"], trace)
    assert saved["suspended"] is None
    assert units.DimensionlessParams(**saved["params"]) == params
    assert saved["config"] == {"seed": 3} and saved["stats"] == {"steps": 7, "x": None}


def test_to_jsonable_makes_valid_json() -> None:
    value = {"a": np.float64("nan"), "b": (np.int32(2), np.inf), "c": np.array([1.0, np.nan])}
    assert to_jsonable(value) == {"a": None, "b": [2, None], "c": [1.0, None]}
    json.dumps(to_jsonable(value), allow_nan=False)


def test_config_hash_is_stable_and_order_free() -> None:
    a = config_hash({"x": 1.0, "y": [1, np.float64(2.0)], "z": np.nan})
    assert a == config_hash({"z": None, "y": [1, 2.0], "x": 1.0})
    assert len(a) == 16 and a != config_hash({"x": 2.0})


def _saved(tmp_path: Path, **changes: dict) -> Path:
    path = tmp_path / "t.npz"
    save_trace(path, np.zeros((3, 3)), units.paper_groups("coil"), {"seed": 1}, {"steps": 2})
    with np.load(path) as npz:
        entries = dict(npz)
    for key, value in changes.items():
        entries[key] = np.array(json.dumps(value))
    np.savez(path, **entries)
    return path


@pytest.mark.parametrize(
    ("entry", "value", "names"),
    [
        ("stats", {"steps": "many"}, ["stats['steps']", "str"]),
        ("stats", {"deposited_length": [1, 2]}, ["deposited_length"]),
        ("config", {"transient_length": "x"}, ["transient_length"]),
        ("config", {"preset": 3}, ["preset"]),
        ("config", {"si": 1.5}, ["si"]),
    ],
)
def test_trace_entries_of_the_wrong_type_are_damaged(
    tmp_path: Path, entry: str, value: dict, names: list[str]
) -> None:
    """Issue 14, defect 13: stats/config fields of the wrong type are a TraceFileError."""
    path = _saved(tmp_path, **{entry: value})
    with pytest.raises(TraceFileError) as info:
        load_trace(path)
    for name in names:
        assert name in str(info.value)


def test_output_path_refuses_devices_fifos_dirs_symlinks_and_long_names(tmp_path: Path) -> None:
    """Issue 14, defects 2, 3, 13: only regular files or new paths are outputs."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    target = tmp_path / "target"
    target.write_text("keep")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    for bad, words in [
        ("/dev/null", "not a regular file"),
        (str(fifo), "not a regular file"),
        (str(tmp_path), "directory"),
        (str(link), "symbolic link"),
        (str(tmp_path / ("a" * 300)), "longer than 255"),
    ]:
        with pytest.raises(OutputError, match=words) as info:
            check_output_path(bad, "--out")
        assert str(info.value).startswith("--out")
    assert target.read_text() == "keep"
    assert check_output_path(tmp_path / "new" / "x.npz", "--out").parent.is_dir()


def test_output_set_writes_all_or_nothing(tmp_path: Path) -> None:
    """Issue 14, defect 5: outputs are moved into place together, at the end."""
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text("old a")
    with pytest.raises(RuntimeError):
        with OutputSet() as outputs:
            outputs.add(a, "--out").write_text("new a")
            outputs.add(b, "--png").write_text("new b")
            raise RuntimeError("the run failed")
    assert a.read_text() == "old a" and not b.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"]  # no temporaries left
    with OutputSet() as outputs:
        outputs.add(a, "--out").write_text("new a")
        outputs.add(b, "--png").write_text("new b")
        assert a.read_text() == "old a"  # kept until the new ones are complete
    assert a.read_text() == "new a" and b.read_text() == "new b"
    outputs = OutputSet()
    outputs.check(a, "--out")
    with pytest.raises(OutputError, match="same file"):
        outputs.check(tmp_path / "." / "a.txt", "--png")


def test_to_jsonable_takes_dataclasses_and_config_hash_matches_plain_json() -> None:
    import hashlib

    params = units.paper_groups("coil")
    assert to_jsonable(params) == {k: to_jsonable(v) for k, v in params.as_dict().items()}
    payload = {"config": params, "seed": 1}
    plain = json.dumps(to_jsonable(payload), sort_keys=True)
    assert config_hash(payload, length=64) == hashlib.sha256(plain.encode()).hexdigest()

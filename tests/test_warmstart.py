"""The warm-start cache (cnt_env.sim.warmstart): the snapshot codec round-trips every
leaf type, a damaged file of any kind is detected and rebuilt (never a traceback), and
the cache directory comes from the environment or the OS's user cache directory.

The simulation is replaced by a stub here; test_env.py covers the real warm state."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cnt_env.sim import warmstart as ws


def _snapshot() -> dict:
    return {
        "rod": {"q": np.arange(7.0), "fixed": np.array([1, 0, 1], dtype=np.int8)},
        "n": 3,
        "beta0": 0.25,
        "flag": True,
        "name": "x",
        "nothing": None,
        "pair": (1.0, 2.0),
        "list": [1, 2, 3],
        "np_scalar": np.float64(1.5),
    }


def _assert_same(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for k in a:
        if isinstance(a[k], dict):
            _assert_same(a[k], b[k])
        elif isinstance(a[k], np.ndarray):
            assert a[k].dtype == b[k].dtype and np.array_equal(a[k], b[k])
        else:
            assert type(a[k]) is type(b[k]) and a[k] == b[k], k


def test_codec_round_trips_every_leaf_type() -> None:
    snap = _snapshot()
    _assert_same(snap, ws.unflatten_snapshot(ws.flatten_snapshot(snap)))


def test_file_round_trip_and_wrong_key(tmp_path: Path) -> None:
    path = tmp_path / "s.npz"
    ws.save_snapshot(path, _snapshot(), key="k1")
    _assert_same(_snapshot(), ws.load_snapshot(path, "k1"))
    with pytest.raises(ws.CacheError, match="another configuration"):
        ws.load_snapshot(path, "k2")


def _write_raw(path: Path, arrays: dict[str, np.ndarray], key: str) -> None:
    """Write a file the way save_snapshot does, from arrays we tamper with first."""
    arrays = dict(arrays)
    arrays[ws._META] = np.asarray(json.dumps({"key": key, "format": ws.FORMAT_VERSION}))
    arrays[ws._CHECKSUM] = np.asarray(ws._checksum(arrays))
    np.savez(path, **arrays)


@pytest.mark.parametrize(
    "tamper",
    [
        "missing_array",  # the manifest names an array the file does not hold
        "leaf_under_leaf",  # a path whose parent is not a dict
        "manifest_not_object",
        "unknown_tag",
    ],
)
def test_a_checksum_valid_file_that_does_not_match_its_manifest_is_a_cache_error(
    tmp_path: Path, tamper: str
) -> None:
    arrays = ws.flatten_snapshot(_snapshot())
    manifest = json.loads(str(arrays[ws._MANIFEST][()]))
    if tamper == "missing_array":
        del arrays["beta0"]
    elif tamper == "leaf_under_leaf":
        manifest["n/child"] = "float"
        arrays["n/child"] = np.asarray(1.0)
    elif tamper == "manifest_not_object":
        manifest = [1, 2]
    else:
        manifest["beta0"] = "complex"
    arrays[ws._MANIFEST] = np.asarray(json.dumps(manifest))
    path = tmp_path / "bad.npz"
    _write_raw(path, arrays, "k")
    with pytest.raises(ws.CacheError):
        ws.load_snapshot(path, "k")


@pytest.mark.parametrize("damage", ["truncate", "garbage", "bitflip"])
def test_damaged_files_are_cache_errors(tmp_path: Path, damage: str) -> None:
    path = tmp_path / "s.npz"
    ws.save_snapshot(path, _snapshot(), key="k")
    data = bytearray(path.read_bytes())
    if damage == "truncate":
        data = data[: len(data) // 2]
    elif damage == "garbage":
        data = bytearray(b"\x00not a zip" * 10)
    else:
        data[len(data) // 3] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(ws.CacheError):
        ws.load_snapshot(path, "k")


def test_warm_state_rebuilds_a_file_that_does_not_match_its_manifest(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls = []

    def fake_simulate(config, warmup_length, seed):
        calls.append(seed)
        return _snapshot()

    monkeypatch.setattr(ws, "_simulate", fake_simulate)
    monkeypatch.setattr(ws, "config_key", lambda config, length, seed: "fixedkey")
    ws.clear_memory_cache()
    path = ws.cache_path("fixedkey", tmp_path)
    arrays = ws.flatten_snapshot(_snapshot())
    del arrays["rod/q"]
    path.parent.mkdir(parents=True, exist_ok=True)
    _write_raw(path, arrays, "fixedkey")

    snap, source = ws.warm_state(object(), 10.0, seed=0, cache_dir=tmp_path)
    assert source == "rebuilt" and calls == [0]
    _assert_same(_snapshot(), snap)
    # the file was rewritten and now loads
    ws.clear_memory_cache()
    _, source = ws.warm_state(object(), 10.0, seed=0, cache_dir=tmp_path)
    assert source == "disk" and calls == [0]
    ws.clear_memory_cache()


def test_cache_directory(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv(ws.CACHE_ENV_VAR, str(tmp_path / "from_env"))
    assert ws.default_cache_dir() == tmp_path / "from_env"
    monkeypatch.delenv(ws.CACHE_ENV_VAR)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    # platformdirs follows the XDG variable on Linux
    assert ws.default_cache_dir() == tmp_path / "xdg" / "cnt_env"

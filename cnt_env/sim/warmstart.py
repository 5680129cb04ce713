"""Warm start for ``CNTDeposit-v0``: a post-transient simulator state per configuration,
computed once and cached on disk (docs/architecture.md, "Start").

* :func:`warm_state` returns a :meth:`DepositionSim.snapshot` taken after
  ``warmup_length`` L_vb of trace has been laid from the start-up shape. It looks in a
  per-process memory cache, then on disk, and simulates only when both miss.
* The cache file is named by :func:`config_key`: a SHA-256 of the deposition
  configuration (every field of :class:`DepositionConfig`, recursively), the warm-up
  length and seed, the package version, and a fingerprint of the simulator's source
  files (so that a physics change without a version bump cannot serve a stale state).
* Files are ``.npz`` archives written without pickle: the nested snapshot dict is
  flattened to ``"rod/q"``-style keys, with a JSON manifest of the Python types of the
  leaves, the key, and a SHA-256 checksum of every array. A file that fails to load,
  belongs to another key or fails its checksum is rebuilt. Writes are atomic (a
  temporary file, then :func:`os.replace`), so concurrent workers never see half a file.
* The directory is ``cache_dir`` if given, else ``$CNT_ENV_CACHE_DIR``, else
  the OS's user cache directory (platformdirs; ``~/.cache/cnt_env`` on Linux).
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from cnt_env import __version__
from cnt_env.io import atomic_savez, config_hash

__all__ = [
    "CACHE_ENV_VAR",
    "CacheError",
    "cache_path",
    "clear_memory_cache",
    "config_key",
    "default_cache_dir",
    "flatten_snapshot",
    "load_snapshot",
    "save_snapshot",
    "unflatten_snapshot",
    "warm_state",
]

#: Environment variable that overrides the cache directory.
CACHE_ENV_VAR = "CNT_ENV_CACHE_DIR"
#: Bump when the file layout changes.
FORMAT_VERSION = 1
# Simulator sources whose content enters the cache key (relative to the package).
_SIM_SOURCES = ("sim", "rod", "units.py", "presets.py")
_MANIFEST = "__manifest__"
_META = "__meta__"
_CHECKSUM = "__checksum__"
_SEP = "/"

_memory: dict[str, dict[str, np.ndarray]] = {}


class CacheError(ValueError):
    """A cache file is missing, unreadable, corrupt, or belongs to another configuration."""


# --------------------------------------------------------------------------- codec


def flatten_snapshot(snap: dict[str, Any]) -> dict[str, np.ndarray]:
    """Nested snapshot dict -> flat ``{path: array}`` plus a JSON manifest of leaf types.

    Leaves may be numpy arrays (not of object dtype), numpy scalars, ``bool``, ``int``,
    ``float``, ``str``, ``None``, or lists/tuples of numbers; keys must be strings
    without ``"/"``. :func:`unflatten_snapshot` restores the same types and values.
    """
    arrays: dict[str, np.ndarray] = {}
    manifest: dict[str, str] = {}

    def walk(prefix: str, node: Any) -> None:
        if isinstance(node, dict):
            manifest[prefix] = "dict"
            for key, value in node.items():
                if not isinstance(key, str) or _SEP in key or key.startswith("__"):
                    raise TypeError(f"snapshot key {key!r} at {prefix!r} cannot be stored")
                walk(f"{prefix}{_SEP}{key}" if prefix else key, value)
            return
        if isinstance(node, np.ndarray):
            if node.dtype.hasobject:
                raise TypeError(f"snapshot array {prefix!r} has object dtype")
            tag, arr = "array", node
        elif isinstance(node, np.generic):
            tag, arr = "np", np.asarray(node)
        elif isinstance(node, bool):
            tag, arr = "bool", np.asarray(node)
        elif isinstance(node, int):
            tag, arr = "int", np.asarray(node, dtype=np.int64)
        elif isinstance(node, float):
            tag, arr = "float", np.asarray(node, dtype=np.float64)
        elif isinstance(node, str):
            tag, arr = "str", np.asarray(node)
        elif node is None:
            tag, arr = "none", np.zeros(0)
        elif isinstance(node, (list, tuple)):
            arr = np.asarray(node)
            if arr.dtype.hasobject:
                raise TypeError(f"snapshot sequence {prefix!r} is not numeric")
            tag = "list" if isinstance(node, list) else "tuple"
        else:
            raise TypeError(f"snapshot leaf {prefix!r} of type {type(node).__name__}")
        manifest[prefix] = tag
        arrays[prefix] = arr

    walk("", snap)
    arrays[_MANIFEST] = np.asarray(json.dumps(manifest, sort_keys=True))
    return arrays


def unflatten_snapshot(arrays: dict[str, np.ndarray]) -> dict[str, Any]:
    """Inverse of :func:`flatten_snapshot`; arrays are copied (the input is not aliased)."""
    try:
        manifest: dict[str, str] = json.loads(str(arrays[_MANIFEST][()]))
    except (KeyError, ValueError, TypeError) as exc:
        raise CacheError(f"snapshot manifest missing or unreadable: {exc}") from exc
    try:
        return _build(manifest, arrays)
    except (KeyError, IndexError, TypeError, ValueError, AttributeError) as exc:
        # a manifest that names a missing array, or a leaf under a non-dict: a damaged
        # or foreign file, never a traceback (the caller rebuilds it)
        raise CacheError(f"snapshot does not match its manifest: {exc!r}") from exc


def _build(manifest: dict[str, str], arrays: dict[str, np.ndarray]) -> dict[str, Any]:
    if not isinstance(manifest, dict):
        raise TypeError("manifest is not a JSON object")
    root: dict[str, Any] = {}
    for path in sorted(manifest, key=lambda p: p.count(_SEP)):
        tag = manifest[path]
        if path == "":
            continue
        *parents, leaf = path.split(_SEP)
        node = root
        for p in parents:
            node = node[p]
        if tag == "dict":
            node[leaf] = {}
            continue
        arr = arrays[path]
        if tag == "array":
            value: Any = np.array(arr, copy=True)
        elif tag == "np":
            value = arr[()]
        elif tag == "bool":
            value = bool(arr)
        elif tag == "int":
            value = int(arr)
        elif tag == "float":
            value = float(arr)
        elif tag == "str":
            value = str(arr[()])
        elif tag == "none":
            value = None
        elif tag == "list":
            value = arr.tolist()
        elif tag == "tuple":
            value = tuple(arr.tolist())
        else:
            raise CacheError(f"unknown leaf type {tag!r} at {path!r}")
        node[leaf] = value
    return root


def _checksum(arrays: dict[str, np.ndarray]) -> str:
    h = hashlib.sha256()
    for name in sorted(arrays):
        if name == _CHECKSUM:
            continue
        arr = np.ascontiguousarray(arrays[name])
        h.update(name.encode())
        h.update(arr.dtype.str.encode())
        h.update(repr(arr.shape).encode())
        h.update(arr.tobytes())
    return h.hexdigest()


def save_snapshot(path: str | os.PathLike[str], snap: dict[str, Any], key: str) -> None:
    """Write ``snap`` to ``path`` (``.npz``, no pickle) atomically, tagged with ``key``."""
    arrays = flatten_snapshot(snap)
    arrays[_META] = np.asarray(json.dumps({"key": key, "format": FORMAT_VERSION}))
    arrays[_CHECKSUM] = np.asarray(_checksum(arrays))
    atomic_savez(Path(path), arrays, compressed=False)


def _load_arrays(path: Path, key: str) -> dict[str, np.ndarray]:
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {name: z[name] for name in z.files}
    except Exception as exc:  # zip, format and I/O errors alike mean "rebuild"
        raise CacheError(f"cannot read {path}: {exc}") from exc
    if _CHECKSUM not in arrays or str(arrays[_CHECKSUM][()]) != _checksum(arrays):
        raise CacheError(f"checksum mismatch in {path}")
    try:
        meta = json.loads(str(arrays[_META][()]))
    except (KeyError, ValueError) as exc:
        raise CacheError(f"no metadata in {path}") from exc
    if meta.get("key") != key or meta.get("format") != FORMAT_VERSION:
        raise CacheError(f"{path} belongs to another configuration")
    for name in (_CHECKSUM, _META):
        del arrays[name]
    return arrays


def load_snapshot(path: str | os.PathLike[str], key: str) -> dict[str, Any]:
    """Read a snapshot written by :func:`save_snapshot`; raises :class:`CacheError` when
    the file is unreadable, corrupt (checksum) or was written for another key."""
    return unflatten_snapshot(_load_arrays(Path(path), key))


# --------------------------------------------------------------------------- keys


def default_cache_dir() -> Path:
    """``$CNT_ENV_CACHE_DIR``, else the user cache directory of the OS (platformdirs:
    ``$XDG_CACHE_HOME/cnt_env`` or ``~/.cache/cnt_env`` on Linux, ``~/Library/Caches/cnt_env``
    on macOS, ``%LOCALAPPDATA%\\cnt_env\\Cache`` on Windows)."""
    override = os.environ.get(CACHE_ENV_VAR)
    if override:
        return Path(override).expanduser()
    import platformdirs

    return Path(platformdirs.user_cache_dir("cnt_env", appauthor=False))


@functools.cache
def source_fingerprint() -> str:
    """SHA-256 of the simulator's source (``sim/``, ``rod/``, units, presets): anything
    cached from a simulation is stale when it changes."""
    root = Path(__file__).resolve().parent.parent  # the cnt_env package
    h = hashlib.sha256()
    for name in _SIM_SOURCES:
        p = root / name
        files = sorted(p.glob("*.py")) if p.is_dir() else [p]
        for f in files:
            try:
                h.update(f.relative_to(root).as_posix().encode())
                h.update(f.read_bytes())
            except OSError:
                h.update(b"<unreadable>")
    return h.hexdigest()


def config_key(config: Any, warmup_length: float, seed: int) -> str:
    """SHA-256 naming the warm state of ``config`` (a :class:`DepositionConfig`)."""
    payload = {
        "format": FORMAT_VERSION,
        "version": __version__,
        "source": source_fingerprint(),
        "config": config,
        "warmup_length": float(warmup_length),
        "seed": int(seed),
    }
    return config_hash(payload, length=64)


def cache_path(key: str, cache_dir: str | os.PathLike[str] | None = None) -> Path:
    """Where the warm state with ``key`` lives."""
    base = Path(cache_dir).expanduser() if cache_dir is not None else default_cache_dir()
    return base / f"warm-{key[:40]}.npz"


def clear_memory_cache() -> None:
    """Forget the warm states held in this process (the disk cache is untouched)."""
    _memory.clear()


# --------------------------------------------------------------------------- warm state


def _simulate(config: Any, warmup_length: float, seed: int) -> dict[str, Any]:
    from cnt_env.sim.deposition import DepositionSim
    from cnt_env.sim.stepper import SimulationError

    sim = DepositionSim(config, seed=seed)
    p = config.params
    # generous bound: 20x the time to lay the warm-up at a fifth of the speed scale 1/Hbar
    max_time = 100.0 * p.Hbar * (warmup_length + 10.0)
    try:
        sim.run(warmup_length, max_time=max_time)
    except SimulationError as exc:
        raise RuntimeError(
            f"no warm state for this configuration: the start-up transient failed ({exc})"
        ) from exc
    return sim.snapshot()


def warm_state(
    config: Any,
    warmup_length: float,
    seed: int = 0,
    cache_dir: str | os.PathLike[str] | None = None,
) -> tuple[dict[str, Any], str]:
    """The snapshot after laying ``warmup_length`` L_vb from the start-up shape.

    Returns ``(snapshot, source)`` with ``source`` one of ``"memory"``, ``"disk"``,
    ``"computed"`` (no file) or ``"rebuilt"`` (the file was corrupt or stale). The
    snapshot is a fresh copy, safe to hand to :meth:`DepositionSim.restore`.
    """
    if not (math.isfinite(warmup_length) and warmup_length >= 0):
        raise ValueError(f"warmup_length must be finite and >= 0, got {warmup_length!r}")
    key = config_key(config, warmup_length, seed)
    if key in _memory:
        return unflatten_snapshot(_memory[key]), "memory"
    path = cache_path(key, cache_dir)
    source = "computed"
    if path.exists():
        try:
            arrays = _load_arrays(path, key)
            snap = unflatten_snapshot(arrays)
        except CacheError:
            source = "rebuilt"
        else:
            _memory[key] = _readonly(arrays)
            return snap, "disk"
    snap = _simulate(config, warmup_length, seed)
    try:
        save_snapshot(path, snap, key)
    except OSError:
        pass  # a read-only cache directory costs a recomputation next time, nothing more
    _memory[key] = _readonly(flatten_snapshot(snap))
    return unflatten_snapshot(_memory[key]), source


def _readonly(arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    out = {}
    for name, arr in arrays.items():
        a = np.array(arr, copy=True)
        a.setflags(write=False)
        out[name] = a
    return out

"""The trace file: one deposition run saved as a ``.npz`` archive (format version 1).

A trace file holds plain arrays only (it is read with ``allow_pickle=False``):

==================  ============  ==================================================
entry               shape, dtype  meaning
==================  ============  ==================================================
``format``          (), str       always ``"cnt_env.trace"``
``format_version``  (), int       ``TRACE_FORMAT_VERSION``
``version``         (), str       cnt_env version that wrote the file
``trace``           (n, 3), f8    deposited nodes (x, y=0, z) in order of deposition
``suspended``       (m, 3), f8    the free rod from the contact node to the top, at
                                  the end of the run ((0, 3) when not saved)
``params``          (), str       JSON: every dimensionless group
                                  (``DimensionlessParams.as_dict()``)
``config``          (), str       JSON: the rest of the run's configuration
``stats``           (), str       JSON: solver counters and timings
==================  ============  ==================================================

Lengths are in L_vb (units.py). JSON has no NaN: non-finite floats are stored as
``null`` (:func:`to_jsonable`).
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import zipfile
import zlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from cnt_env.units import DimensionlessParams

__all__ = [
    "TRACE_FORMAT",
    "TRACE_FORMAT_VERSION",
    "TraceFileError",
    "load_trace",
    "save_trace",
    "to_jsonable",
]

TRACE_FORMAT = "cnt_env.trace"
TRACE_FORMAT_VERSION = 1

_JSON_ENTRIES = ("params", "config", "stats")
_REQUIRED = ("format_version", "version", "trace", *_JSON_ENTRIES)
_WRITE_HINT = "write traces with `cnt-sim run --out FILE.npz`"
# Errors a damaged archive can raise while it is opened or a member is read.
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")  # a zip's first entry, or an empty zip
_NPY_MAGIC = b"\x93NUMPY"
_READ_ERRORS = (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, KeyError)


class TraceFileError(ValueError):
    """A trace file is missing, unreadable, foreign or damaged (the message says which)."""


def to_jsonable(value: Any) -> Any:
    """``value`` with numpy scalars and arrays turned into Python ones, tuples into
    lists, and non-finite floats into ``None``, so that ``json.dumps(...,
    allow_nan=False)`` always succeeds and the output is valid JSON."""
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return v if math.isfinite(v) else None
    return value


def _dumps(value: Any) -> str:
    return json.dumps(to_jsonable(value), allow_nan=False)


def _points(name: str, value: Any, *, min_rows: int) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] < min_rows:
        raise ValueError(f"{name} must have shape (n >= {min_rows}, 3), got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} has NaN or inf values")
    return np.ascontiguousarray(arr)


def save_trace(
    path: str | os.PathLike[str],
    trace: Any,
    params: DimensionlessParams | Mapping[str, Any],
    config: Mapping[str, Any],
    stats: Mapping[str, Any],
    suspended: Any = None,
    *,
    version: str | None = None,
) -> Path:
    """Write one run to ``path`` (the name is kept as given; no ``.npz`` is appended).

    ``trace`` is ``(n, 3)``, ``suspended`` ``(m, 3)`` or None; ``params`` a
    :class:`DimensionlessParams` or its ``as_dict()``; ``config`` and ``stats``
    JSON-able mappings. The file is written to a temporary name and renamed, so
    an interrupted save never leaves a half-written trace. Returns the path.
    """
    path = Path(path)
    trace = _points("trace", trace, min_rows=2)
    suspended = (
        np.zeros((0, 3)) if suspended is None else _points("suspended", suspended, min_rows=0)
    )
    if isinstance(params, DimensionlessParams):
        params = params.as_dict()
    if version is None:
        from cnt_env import __version__ as version
    entries = {
        "format": np.array(TRACE_FORMAT),
        "format_version": np.array(TRACE_FORMAT_VERSION, dtype=np.int64),
        "version": np.array(str(version)),
        "trace": trace,
        "suspended": suspended,
        "params": np.array(_dumps(dict(params))),
        "config": np.array(_dumps(dict(config))),
        "stats": np.array(_dumps(dict(stats))),
    }
    atomic_savez(path, entries)
    return path


def atomic_savez(path: Path, entries: dict[str, np.ndarray], compressed: bool = True) -> None:
    """Write ``entries`` as an ``.npz`` (no pickle) atomically: into a temporary file in the
    same folder, then :func:`os.replace`, so a reader (or a concurrent worker) never sees
    half a file. The one home of this for traces, episodes and warm-start snapshots."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            (np.savez_compressed if compressed else np.savez)(fh, **entries)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _string(arr: np.ndarray) -> str | None:
    if arr.ndim == 0 and arr.dtype.kind == "U":
        return str(arr[()])
    return None


def load_trace(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read and validate a trace file written by :func:`save_trace`.

    Returns ``format_version``, ``version``, ``trace`` ((n, 3)), ``suspended``
    ((m, 3), or None when not saved), ``params``, ``config`` and ``stats``
    (dicts; ``params`` are checked by :class:`DimensionlessParams`). Raises
    :class:`TraceFileError` when the file is missing, is not an ``.npz``
    archive, is another program's ``.npz``, or is damaged.
    """
    path = Path(path)
    if not path.exists():
        raise TraceFileError(f"{path}: no such file; {_WRITE_HINT}.")
    if path.is_dir():
        raise TraceFileError(f"{path} is a directory, not a trace file; {_WRITE_HINT}.")
    try:
        with path.open("rb") as fh:
            magic = fh.read(len(_NPY_MAGIC))
    except OSError as exc:
        raise TraceFileError(f"{path} cannot be read: {exc}") from exc
    if magic.startswith(_NPY_MAGIC):
        raise TraceFileError(
            f"{path} is a single .npy array, not a cnt_env trace (.npz archive); {_WRITE_HINT}."
        )
    if not magic.startswith(_ZIP_MAGIC):
        # checked here so that np.load never treats the bytes as a pickle
        raise TraceFileError(
            f"{path} is not a cnt_env trace file: it is not an .npz (zip) archive at all "
            f"(empty, corrupt or another format); {_WRITE_HINT}."
        )
    try:
        npz = np.load(path, allow_pickle=False)
    except _READ_ERRORS as exc:
        raise TraceFileError(
            f"{path} is not a readable .npz archive (corrupt or truncated: {exc}); "
            f"re-run the simulation to write it again, or {_WRITE_HINT}."
        ) from exc
    if not isinstance(npz, np.lib.npyio.NpzFile):
        raise TraceFileError(f"{path} is not an .npz archive; {_WRITE_HINT}.")
    with npz:
        try:
            names = set(npz.files)
            if "format" not in names:
                held = ", ".join(sorted(names)) or "nothing"
                raise TraceFileError(
                    f"{path} is an .npz archive but not a cnt_env trace: it has no 'format' "
                    f"entry (it holds: {held}); {_WRITE_HINT}."
                )
            fmt = _string(npz["format"])
            if fmt != TRACE_FORMAT:
                raise TraceFileError(
                    f"{path} is an .npz archive of another format ({fmt!r}), not "
                    f"{TRACE_FORMAT!r}; {_WRITE_HINT}."
                )
            missing = [k for k in _REQUIRED if k not in names]
            if missing:
                raise TraceFileError(
                    f"{path} is a damaged cnt_env trace: missing {', '.join(missing)}; "
                    "re-run the simulation to write it again."
                )
            version_arr = npz["format_version"]
            if version_arr.ndim != 0 or version_arr.dtype.kind not in "iu":
                raise TraceFileError(f"{path}: format_version is not an integer; damaged file.")
            format_version = int(version_arr)
            if format_version > TRACE_FORMAT_VERSION:
                raise TraceFileError(
                    f"{path} has trace format version {format_version}, newer than this "
                    f"cnt_env reads ({TRACE_FORMAT_VERSION}); upgrade cnt_env."
                )
            if format_version < 1:
                raise TraceFileError(f"{path}: invalid format_version {format_version}.")
            out: dict[str, Any] = {
                "format_version": format_version,
                "version": _string(npz["version"]),
            }
            for key in _JSON_ENTRIES:
                text = _string(npz[key])
                try:
                    value = json.loads(text) if text is not None else None
                except json.JSONDecodeError:
                    value = None
                if not isinstance(value, dict):
                    raise TraceFileError(
                        f"{path} is a damaged cnt_env trace: '{key}' is not a JSON object."
                    )
                out[key] = value
            try:
                out["trace"] = _points("trace", npz["trace"], min_rows=2)
                suspended = (
                    _points("suspended", npz["suspended"], min_rows=0)
                    if "suspended" in names
                    else np.zeros((0, 3))
                )
            except ValueError as exc:
                raise TraceFileError(f"{path} is a damaged cnt_env trace: {exc}.") from exc
            out["suspended"] = suspended if suspended.shape[0] else None
        except TraceFileError:
            raise
        except _READ_ERRORS as exc:
            raise TraceFileError(
                f"{path} is a damaged cnt_env trace (an entry cannot be read: {exc}); "
                "re-run the simulation to write it again."
            ) from exc
    try:
        DimensionlessParams(**out["params"])
    except (TypeError, ValueError) as exc:
        raise TraceFileError(f"{path} has invalid params: {exc}") from exc
    return out

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

import dataclasses
import hashlib
import json
import math
import os
import stat
import struct
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
    "OutputError",
    "OutputSet",
    "TraceFileError",
    "check_output_path",
    "config_hash",
    "load_trace",
    "package_version",
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
_READ_ERRORS = (
    OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zipfile.LargeZipFile,
    zlib.error, struct.error, OverflowError,
    RuntimeError,  # zipfile: an entry flagged as encrypted
    NotImplementedError,  # zipfile: an unknown compression method
)  # fmt: skip


class TraceFileError(ValueError):
    """A trace file is missing, unreadable, foreign or damaged (the message says which)."""


def to_jsonable(value: Any) -> Any:
    """``value`` with numpy scalars and arrays turned into Python ones, tuples into
    lists, and non-finite floats into ``None``, so that ``json.dumps(...,
    allow_nan=False)`` always succeeds and the output is valid JSON. A dataclass
    instance becomes the dict of its fields. The one JSON converter of the package."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
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


def config_hash(payload: Mapping[str, Any], length: int = 16) -> str:
    """The one config hash: SHA-256 of ``payload`` as sorted JSON (:func:`to_jsonable`),
    its first ``length`` hex digits."""
    blob = json.dumps(to_jsonable(payload), sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:length]


def package_version() -> str:
    """The installed distribution's version, or the source tree's when not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("cnt-env")
    except PackageNotFoundError:
        from cnt_env import __version__

        return __version__


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
                held = ", ".join(repr(n) for n in sorted(names)) or "nothing"
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
    _check_entry_types(path, out)
    return out


# Types of the entries of ``config`` and ``stats`` that readers use (None: absent/NaN).
_ENTRY_TYPES: dict[str, dict[str, tuple[type, ...]]] = {
    "config": {
        "preset": (str,), "substrate": (str,), "drag_law": (str,), "sliding": (str,),
        "contact_mode": (str,), "transient_length": (int, float), "deposit_length": (int, float),
        "dt": (int, float), "seed": (int,), "si": (dict,),
    },
    "stats": {
        "deposited_length": (int, float), "time": (int, float), "steps": (int,),
        "newton_iterations": (int,), "wall_time_s": (int, float),
    },
}  # fmt: skip


def _check_entry_types(path: Path, out: Mapping[str, Any]) -> None:
    for entry, types in _ENTRY_TYPES.items():
        for key, allowed in types.items():
            value = out[entry].get(key)
            if value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, allowed):
                names = " or ".join("number" if t in (int, float) else t.__name__ for t in allowed)
                raise TraceFileError(
                    f"{path} is a damaged cnt_env trace: {entry}['{key}'] is "
                    f"{type(value).__name__} {str(value)[:40]!r}, not a {names}."
                )
    transient = out["config"].get("transient_length")
    if transient is not None and not (math.isfinite(transient) and transient >= 0):
        raise TraceFileError(f"{path}: config['transient_length'] = {transient!r} is invalid.")


# --------------------------------------------------------------------------- outputs

#: Longest file name (one path component) an output may have, in bytes (POSIX NAME_MAX).
MAX_NAME_BYTES = 255


class OutputError(ValueError):
    """An output path cannot be written safely (the message names the flag)."""


def check_output_path(value: str | os.PathLike[str], flag: str) -> Path:
    """``value`` as an output path, checked before any work: every component short enough,
    not a symlink, a regular file or a new path (never a directory, device or FIFO),
    its folder created and writable. Raises :class:`OutputError` naming ``flag``."""
    text = os.fspath(value)
    shown = text if len(text) <= 80 else text[:60] + "..." + text[-12:]
    if not text or "\x00" in text:
        raise OutputError(f"{flag}: give a file name, got {shown!r}")
    if text.endswith(("/", os.sep)):
        raise OutputError(f"{flag} {shown} ends in '/': pass a file name, not a directory")
    path = Path(text)
    for part in path.parts:
        if len(os.fsencode(part)) > MAX_NAME_BYTES:
            raise OutputError(
                f"{flag} {shown}: a file or folder name is longer than {MAX_NAME_BYTES} bytes"
            )
    if path.is_symlink():
        raise OutputError(
            f"{flag} {shown} is a symbolic link; outputs are never written through links: "
            "remove it or pass another name"
        )
    try:
        st = path.stat()
    except FileNotFoundError:
        st = None
    except OSError as exc:
        raise OutputError(f"{flag} {shown}: cannot check it: {exc.strerror or exc}") from exc
    if st is not None and not stat.S_ISREG(st.st_mode):
        what = "a directory" if stat.S_ISDIR(st.st_mode) else "not a regular file"
        raise OutputError(
            f"{flag} {shown} is {what} (a device, FIFO or socket is never replaced); "
            "pass a file name"
        )
    parent = path.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(
            f"{flag} {shown}: cannot create its directory: {exc.strerror or exc}"
        ) from exc
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"{flag} {shown}: its directory {parent} is not writable")
    return path


class OutputSet:
    """The outputs of one command, written as a unit.

    :meth:`add` checks a final path (:func:`check_output_path`, and that no two outputs
    name one file) and returns a temporary path in the same folder for the writer;
    :meth:`commit` moves every temporary into place (after checking each final path
    again), :meth:`discard` removes them. An existing output is kept until the new ones
    are complete; used as a context manager, an exception discards everything::

        with OutputSet() as outputs:
            tmp = outputs.add(path, "--out")
            save_trace(tmp, ...)
    """

    def __init__(self, inputs: Mapping[str, str | os.PathLike[str] | None] | None = None) -> None:
        """``inputs``: the command's input files by what they are ("the trace", "--config"):
        no output may name one (it would be replaced by the output)."""
        self._staged: list[tuple[Path, Path, str]] = []
        self._finals: dict[Path, str] = {}
        self._inputs = {os.path.realpath(p): what for what, p in (inputs or {}).items()
                        if p is not None}  # fmt: skip

    def check(self, path: str | os.PathLike[str], flag: str) -> Path:
        """Check ``path`` as an output of this set without staging it yet."""
        final = check_output_path(path, flag)
        key = Path(os.path.abspath(final))
        other = self._finals.get(key)
        if other is not None:
            raise OutputError(f"{flag} and {other} name the same file ({final})")
        source = self._inputs.get(os.path.realpath(final))
        if source is not None:
            raise OutputError(f"{flag} {final} is {source}, an input of this command: the "
                              "output would replace it; pass another name")  # fmt: skip
        self._finals[key] = flag
        return final

    def add(self, path: str | os.PathLike[str], flag: str, *, checked: bool = False) -> Path:
        """Stage ``path``; returns the temporary file to write it to."""
        final = Path(path) if checked else self.check(path, flag)
        suffix = "".join(final.suffixes[-1:])[:20]
        try:
            fd, tmp = tempfile.mkstemp(
                prefix=f".{final.name[:100]}.", suffix=f".part{suffix}", dir=final.parent
            )
        except OSError as exc:
            raise OutputError(
                f"{flag} {final}: cannot write in {final.parent}: {exc.strerror or exc}"
            ) from exc
        os.close(fd)
        self._staged.append((Path(tmp), final, flag))
        return Path(tmp)

    def temp_for(self, path: str | os.PathLike[str]) -> Path:
        """The temporary file staged for ``path`` (KeyError when not staged)."""
        final = Path(path)
        for tmp, staged, _ in self._staged:
            if staged == final:
                return tmp
        raise KeyError(str(path))

    def write_text(self, path: str | os.PathLike[str], flag: str, text: str) -> Path:
        tmp = self.add(path, flag)
        tmp.write_text(text)
        return tmp

    def commit(self) -> list[Path]:
        """Move every staged file into place; returns the final paths."""
        umask = os.umask(0)
        os.umask(umask)
        try:
            for tmp, final, flag in self._staged:
                check_output_path(final, flag)  # nothing swapped in meanwhile
                os.chmod(tmp, 0o666 & ~umask)
            for tmp, final, _ in self._staged:
                os.replace(tmp, final)
        except BaseException:
            self.discard()
            raise
        done = [final for _, final, _ in self._staged]
        self._staged = []
        return done

    def discard(self) -> None:
        for tmp, _, _ in self._staged:
            tmp.unlink(missing_ok=True)
        self._staged = []

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.discard()


def config_json_text(path: str | os.PathLike[str], resolved: Mapping[str, Any]) -> str:
    """The resolved config saved next to an output ``path`` as ``<path>.json``
    (docs/architecture.md rule 12)."""
    body = json.dumps(to_jsonable({**resolved, "output": str(path)}), indent=2, allow_nan=False)
    return body + "\n"


def write_config_json(path: Path, resolved: Mapping[str, Any]) -> Path:
    """Write :func:`config_json_text` to ``<path>.json`` atomically; returns that path."""
    out = Path(f"{path}.json")
    with OutputSet() as outputs:
        outputs.write_text(out, "--out", config_json_text(path, resolved))
    return out

"""The episode as plain arrays: :class:`Frame`, :class:`Episode` and its ``.npz`` file.

Nothing here imports rerun or gymnasium: an episode is data. :class:`Frame` is one
logged moment (what :mod:`cnt_env.replay.rerun` logs and :mod:`cnt_env.replay.video`
draws); :class:`Episode` is a whole episode, validated on construction; the episode
file (``format`` ``"cnt_env.episode"``, version 1) is written by :func:`save_episode`
and read by :func:`load_episode`, never with pickle.

Scalar series get their entity path from the ``info`` key (:func:`series_path`):
``reward_<term>`` -> ``reward/<term>``, the score keys -> ``score/...``, solver counts
-> ``solver/...``, ``pattern_<key>`` -> ``pattern/<key>``, the rest -> ``metrics/...``.
"""

from __future__ import annotations

import json
import math
import os
import zipfile
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cnt_env.io import atomic_savez, to_jsonable

__all__ = [
    "APPLICATION_ID",
    "EPISODE_FORMAT",
    "EPISODE_FORMAT_VERSION",
    "Episode",
    "EpisodeFileError",
    "Frame",
    "file_format",
    "load_episode",
    "route_geometry",
    "save_episode",
    "series_path",
    "split_info",
]

APPLICATION_ID = "cnt_env"
EPISODE_FORMAT = "cnt_env.episode"
EPISODE_FORMAT_VERSION = 1

# info entries that are not plotted as metrics (they have another place).
_NOT_METRICS = frozenset({"sim_time", "flow_vbar", "flow_phi", "target_length", "reset_advance"})
_SCORE_KEYS = ("score", "coverage", "precision", "progress")
_SOLVER_KEYS = ("physics_steps", "newton_iterations")
_PATTERN_PREFIX = "pattern_"


@dataclass
class Frame:
    """One logged moment.

    ``rod``: (m, 3) suspended nodes, contact node first. ``trace``: (k, 3) the trace to
    draw as ``world/trace`` (episodes: from the contact point at reset on). ``flow``:
    (fx, fz) flow velocity in e_v/(mu H), or None. ``scalars``: entity path -> value
    (NaN values are skipped; the reward is ``reward/total``). ``events``: (level, text)
    pairs for the TextLog. ``geometry``: False logs the scalars only. ``extra_times``:
    more sequence timelines (frame by frame only).
    """

    step: int
    sim_time: float
    rod: np.ndarray
    trace: np.ndarray
    flow: tuple[float, float] | None = None
    scalars: dict[str, float] = field(default_factory=dict)
    events: list[tuple[str, str]] = field(default_factory=list)
    geometry: bool = True
    extra_times: dict[str, int] = field(default_factory=dict)


def series_path(name: str) -> str:
    """Entity path of an ``info`` entry, by the group it belongs to."""
    if name.startswith("reward_"):
        return "reward/" + name[len("reward_") :]
    if name in _SCORE_KEYS:
        return "score/" + name
    if name in _SOLVER_KEYS:
        return "solver/" + name
    if name.startswith(_PATTERN_PREFIX):
        return "pattern/" + name[len(_PATTERN_PREFIX) :]
    return "metrics/" + name


def is_number(value: Any) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
        value, (bool, np.bool_)
    )


def split_info(info: Mapping[str, Any]) -> tuple[dict[str, float], dict[str, float]]:
    """(reward terms, metrics) of a step's ``info``: every numeric entry, the
    ``pattern`` measures as ``pattern_<key>``."""
    terms: dict[str, float] = {}
    metrics: dict[str, float] = {}
    for key, value in info.items():
        if key.startswith("reward_") and is_number(value):
            terms[key] = float(value)
        elif key not in _NOT_METRICS and is_number(value):
            metrics[key] = float(value)
    pattern = info.get("pattern")
    if isinstance(pattern, Mapping):
        for key, value in pattern.items():
            if is_number(value):
                metrics[_PATTERN_PREFIX + key] = float(value)
    return terms, metrics


# ---- the episode file ------------------------------------------------------------------


class EpisodeFileError(ValueError):
    """An episode file is missing, unreadable, foreign or damaged (the message says which)."""


_EPISODE_HINT = (
    "write episodes with cnt_env.replay.save_episode (RerunRecorder(save_episodes=True), "
    "EpisodeSaver, or `training/evaluate.py --save-episodes`)"
)
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")
_READ_ERRORS = (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, KeyError)
_EPISODE_ARRAYS = (
    "step",
    "sim_time",
    "flow",
    "reward",
    "reward_terms",
    "reward_term_names",
    "metrics",
    "metric_names",
    "rod_nodes",
    "rod_offsets",
    "trace_len",
    "trace",
    "target",
    "terminated",
    "truncated",
)
_EPISODE_REQUIRED = ("format_version", "version", *_EPISODE_ARRAYS, "failure", "meta")


@dataclass(frozen=True)
class Episode:
    """One episode as arrays, with F = n_steps + 1 frames (frame 0: the state after
    reset; frame i: after the i-th ``step``). Lengths in L_vb, times in tau.

    ===================  ============  ===============================================
    field                shape, dtype  meaning
    ===================  ============  ===============================================
    ``step``             (F,) i8       control step of each frame, 0, 1, ...
    ``sim_time``         (F,) f8       ``info["sim_time"]``: tau since reset
    ``flow``             (F, 2) f8     flow (v̄, φ): ``info["flow_vbar"]`` (e_v/(mu H)),
                                       ``info["flow_phi"]`` (rad from +x in x-z)
    ``reward``           (F,) f8       the reward ``step`` returned (0 at reset)
    ``reward_terms``     (F, K) f8     ``info["reward_*"]`` (0 at reset)
    ``reward_term_names``(K,) str      their keys
    ``metrics``          (F, M) f8     other numeric ``info`` entries (NaN: absent)
    ``metric_names``     (M,) str      their keys (``pattern_*``: ``info["pattern"]``)
    ``rod_nodes``        (R, 3) f8     the suspended rods of all frames, concatenated
    ``rod_offsets``      (F+1,) i8     frame i's rod is rod_nodes[off[i]:off[i+1]]
    ``trace_len``        (F,) i8       trace nodes laid by each frame (prefix of trace)
    ``trace``            (N, 3) f8     the whole trace at the end, in order of deposition
    ``target``           (T, 2) f8     target polyline, absolute (x, z); (0, 2): none
    ``terminated``       (F,) bool     as returned by ``step`` (False at reset)
    ``truncated``        (F,) bool     as returned by ``step`` (False at reset)
    ``failure``          str           ``info["failure"]``, "" when none
    ``meta``             dict          JSON: recording_id, seed, episode, target, params…
    ===================  ============  ===============================================

    Trace nodes never change index once laid (cnt_env.sim.deposition), so frame i's trace
    is ``trace[:trace_len[i]]``; nodes still in the solve may have slid a little since.
    The episode's own trace starts at the contact point at reset,
    ``trace[trace_len[0] - 1]``.
    """

    step: np.ndarray
    sim_time: np.ndarray
    flow: np.ndarray
    reward: np.ndarray
    reward_terms: np.ndarray
    reward_term_names: tuple[str, ...]
    metrics: np.ndarray
    metric_names: tuple[str, ...]
    rod_nodes: np.ndarray
    rod_offsets: np.ndarray
    trace_len: np.ndarray
    trace: np.ndarray
    target: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    failure: str = ""
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        f = int(np.asarray(self.step).shape[0]) if np.ndim(self.step) == 1 else -1
        if f < 1:
            raise ValueError(
                f"step must be a 1-D array of >= 1 frames, got shape {np.shape(self.step)}"
            )
        set_ = object.__setattr__
        set_(self, "step", _ints("step", self.step, (f,)))
        if np.any(np.diff(self.step) <= 0):
            raise ValueError("step must increase strictly")
        set_(self, "sim_time", _floats("sim_time", self.sim_time, (f,)))
        if np.any(np.diff(self.sim_time) < 0):
            raise ValueError("sim_time must not decrease")
        set_(self, "flow", _floats("flow", self.flow, (f, 2)))
        set_(self, "reward", _floats("reward", self.reward, (f,)))
        names = _names("reward_term_names", self.reward_term_names)
        set_(self, "reward_term_names", names)
        set_(self, "reward_terms", _floats("reward_terms", self.reward_terms, (f, len(names))))
        names = _names("metric_names", self.metric_names)
        set_(self, "metric_names", names)
        set_(self, "metrics", _floats("metrics", self.metrics, (f, len(names)), nan_ok=True))
        set_(self, "rod_nodes", _floats("rod_nodes", self.rod_nodes, (-1, 3)))
        off = _ints("rod_offsets", self.rod_offsets, (f + 1,))
        if off[0] != 0 or off[-1] != len(self.rod_nodes) or np.any(np.diff(off) < 0):
            raise ValueError(
                f"rod_offsets must rise from 0 to len(rod_nodes) = {len(self.rod_nodes)}"
            )
        set_(self, "rod_offsets", off)
        set_(self, "trace", _floats("trace", self.trace, (-1, 3)))
        tl = _ints("trace_len", self.trace_len, (f,))
        if tl[0] < 1 or np.any(np.diff(tl) < 0) or tl[-1] > len(self.trace):
            raise ValueError(
                f"trace_len must rise from >= 1 to at most len(trace) = {len(self.trace)}"
            )
        set_(self, "trace_len", tl)
        set_(self, "target", _floats("target", self.target, (-1, 2)))
        for name in ("terminated", "truncated"):
            arr = np.asarray(getattr(self, name))
            if arr.shape != (f,) or arr.dtype != np.bool_:
                raise ValueError(
                    f"{name} must be a bool array of shape ({f},), got {arr.dtype} {arr.shape}"
                )
            set_(self, name, arr)
        if not isinstance(self.failure, str):
            raise ValueError(f"failure must be a str, got {type(self.failure).__name__}")
        set_(self, "meta", dict(self.meta))

    @property
    def n_steps(self) -> int:
        """Number of ``step`` calls (frames after the reset frame)."""
        return len(self.step) - 1

    @property
    def n_start(self) -> int:
        """Trace nodes laid before the episode (the contact point at reset is the last)."""
        return int(self.trace_len[0])

    def rod(self, i: int) -> np.ndarray:
        """The suspended rod of frame ``i``, (m, 3)."""
        return self.rod_nodes[self.rod_offsets[i] : self.rod_offsets[i + 1]]

    def frame(self, i: int) -> Frame:
        """Frame ``i`` in the form the logger takes."""
        terms = dict(zip(self.reward_term_names, self.reward_terms[i].tolist(), strict=True))
        metrics = dict(zip(self.metric_names, self.metrics[i].tolist(), strict=True))
        events: list[tuple[str, str]] = []
        ret = sum(self.reward[1 : i + 1].tolist())  # in order, as the wrapper sums it
        if i == 0:
            from cnt_env.task.targets import polyline_length  # (loads scipy.signal: lazily)

            name = self.meta.get("target", "?")
            length = polyline_length(self.target) if len(self.target) else math.nan
            events.append(reset_event(name, length))
        last = i == len(self.step) - 1
        if last and self.failure:
            events.append(("ERROR", f"simulation failed: {self.failure}"))
        if self.terminated[i] or self.truncated[i]:
            events.append(
                end_event(
                    int(self.step[i]),
                    bool(self.terminated[i]),
                    bool(self.truncated[i]),
                    self.failure,
                    ret,
                    metrics,
                )
            )
        return episode_frame(
            step=int(self.step[i]),
            sim_time=float(self.sim_time[i]),
            rod=self.rod(i),
            trace=self.trace[self.n_start - 1 : self.trace_len[i]],
            flow_polar=(float(self.flow[i, 0]), float(self.flow[i, 1])),
            reward=None if i == 0 else float(self.reward[i]),
            reward_return=None if i == 0 else ret,
            terms=terms,
            metrics=metrics,
            events=events,
        )


def _floats(name: str, value: Any, shape: tuple[int, ...], nan_ok: bool = False) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must hold numbers: {exc}") from exc
    if arr.ndim != len(shape) or any(
        s not in (-1, a) for s, a in zip(shape, arr.shape, strict=True)
    ):
        want = "(" + ", ".join("n" if s == -1 else str(s) for s in shape) + ")"
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    bad = ~np.isfinite(arr) & ~np.isnan(arr) if nan_ok else ~np.isfinite(arr)
    if np.any(bad):
        raise ValueError(f"{name} has {'inf' if nan_ok else 'NaN or inf'} values")
    return np.ascontiguousarray(arr)


def _ints(name: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    arr = np.asarray(value)
    if arr.dtype.kind not in "iu" or arr.shape != shape:
        raise ValueError(
            f"{name} must be an integer array of shape {shape}, got {arr.dtype} {arr.shape}"
        )
    return arr.astype(np.int64)


def _names(name: str, value: Any) -> tuple[str, ...]:
    arr = np.asarray(value) if not isinstance(value, tuple) else np.asarray(value, dtype=str)
    if arr.ndim != 1 or (arr.size and arr.dtype.kind != "U"):
        raise ValueError(f"{name} must be a 1-D array of strings, got {arr.dtype} {arr.shape}")
    names = tuple(str(s) for s in arr)
    if len(set(names)) != len(names):
        raise ValueError(f"{name} has duplicates: {names}")
    return names


def save_episode(path: str | os.PathLike[str], episode: Episode) -> Path:
    """Write ``episode`` to ``path`` as a ``.npz`` archive of plain arrays (no pickle).

    The archive holds every :class:`Episode` field under its name (``failure`` a str,
    ``meta`` a JSON str), plus ``format`` = ``"cnt_env.episode"``, ``format_version``
    = 1 and ``version`` (the cnt_env version). The file is written to a temporary
    name and renamed. Returns the path.
    """
    from cnt_env import __version__

    path = Path(path)
    entries: dict[str, np.ndarray] = {
        "format": np.array(EPISODE_FORMAT),
        "format_version": np.array(EPISODE_FORMAT_VERSION, dtype=np.int64),
        "version": np.array(str(__version__)),
        "failure": np.array(episode.failure),
        "meta": np.array(json.dumps(to_jsonable(episode.meta), allow_nan=False)),
    }
    for name in _EPISODE_ARRAYS:
        value = getattr(episode, name)
        if name.endswith("_names"):
            value = np.array(list(value), dtype=str) if value else np.zeros(0, dtype="<U1")
        entries[name] = np.asarray(value)
    atomic_savez(path, entries)
    return path


def file_format(path: str | os.PathLike[str]) -> str | None:
    """The ``format`` entry of a cnt_env ``.npz`` file (``"cnt_env.trace"``,
    ``"cnt_env.episode"``), or None when it has none. Raises :class:`EpisodeFileError`
    when the file is missing or not an ``.npz`` archive. Never unpickles."""
    path = Path(path)
    with _open_npz(path, "a cnt_env trace or episode file") as npz:
        if "format" not in npz.files:
            return None
        return _string(npz["format"])


def _string(arr: np.ndarray) -> str | None:
    if arr.ndim == 0 and arr.dtype.kind == "U":
        return str(arr[()])
    return None


def _open_npz(path: Path, what: str) -> Any:
    if not path.exists():
        raise EpisodeFileError(f"{path}: no such file")
    if path.is_dir():
        raise EpisodeFileError(f"{path} is a directory, not {what}")
    try:
        with path.open("rb") as fh:
            magic = fh.read(4)
    except OSError as exc:
        raise EpisodeFileError(f"{path} cannot be read: {exc}") from exc
    if not magic.startswith(_ZIP_MAGIC):  # checked first, so np.load never unpickles
        raise EpisodeFileError(f"{path} is not an .npz archive, so not {what}")
    try:
        npz = np.load(path, allow_pickle=False)
    except _READ_ERRORS as exc:
        raise EpisodeFileError(f"{path} is not a readable .npz archive: {exc}") from exc
    return npz


def load_episode(path: str | os.PathLike[str]) -> Episode:
    """Read and validate an episode file written by :func:`save_episode`.

    Raises :class:`EpisodeFileError` when the file is missing, not an ``.npz``
    archive, of another format, of a newer format version, or damaged (a missing
    entry, a wrong shape or dtype, a non-finite value, inconsistent offsets).
    """
    path = Path(path)
    with _open_npz(path, "a cnt_env episode file") as npz:
        try:
            names = set(npz.files)
            fmt = _string(npz["format"]) if "format" in names else None
            if fmt != EPISODE_FORMAT:
                held = f"format {fmt!r}" if fmt else "no 'format' entry"
                raise EpisodeFileError(
                    f"{path} is not a cnt_env episode file ({held}); {_EPISODE_HINT}"
                )
            missing = [k for k in _EPISODE_REQUIRED if k not in names]
            if missing:
                raise EpisodeFileError(
                    f"{path} is a damaged episode file: missing {', '.join(missing)}"
                )
            version = npz["format_version"]
            if version.ndim != 0 or version.dtype.kind not in "iu" or int(version) < 1:
                raise EpisodeFileError(f"{path}: invalid format_version; damaged file")
            if int(version) > EPISODE_FORMAT_VERSION:
                raise EpisodeFileError(
                    f"{path} has episode format version {int(version)}, newer than this "
                    f"cnt_env reads ({EPISODE_FORMAT_VERSION}); upgrade cnt_env"
                )
            fields_: dict[str, Any] = {k: npz[k] for k in _EPISODE_ARRAYS}
            failure, meta_text = _string(npz["failure"]), _string(npz["meta"])
        except EpisodeFileError:
            raise
        except _READ_ERRORS as exc:
            raise EpisodeFileError(
                f"{path} is a damaged episode file (an entry cannot be read: {exc})"
            ) from exc
    try:
        meta = json.loads(meta_text) if meta_text is not None else None
    except json.JSONDecodeError:
        meta = None
    if not isinstance(meta, dict) or failure is None:
        raise EpisodeFileError(f"{path} is a damaged episode file: bad 'meta' or 'failure'")
    try:
        return Episode(**fields_, failure=failure, meta=meta)
    except ValueError as exc:
        raise EpisodeFileError(f"{path} is a damaged episode file: {exc}") from exc


def route_geometry(meta: Mapping[str, Any]) -> dict[str, Any] | None:
    """The route drawn around the target, from an episode's ``meta["route"]`` (written by
    the wrappers when the env's target is a route with a corridor): ``width`` (the
    corridor's half-width w, L_vb), ``pads`` (a list of (2, 2) segments) and ``keepouts``
    (a list of (k, 2) polygons), absolute (x, z). None when the episode has none or it
    is malformed (an episode stays readable; only the drawing goes)."""
    route = meta.get("route")
    if not isinstance(route, Mapping):
        return None
    try:
        width = float(route["width"])
        pads = [np.asarray(p, dtype=np.float64).reshape(2, 2) for p in route.get("pads") or ()]
        keepouts = [np.asarray(k, dtype=np.float64) for k in route.get("keepouts") or ()]
    except (KeyError, TypeError, ValueError):
        return None
    if not (math.isfinite(width) and width > 0) or any(
        k.ndim != 2 or k.shape[1] != 2 or len(k) < 3 for k in keepouts
    ):
        return None
    return {"width": width, "pads": pads, "keepouts": keepouts}


# ---- events and frames, shared by the episode and the live wrappers --------------------


def reset_event(target: Any, length: float) -> tuple[str, str]:
    return ("INFO", f"reset: target {target}, {length:.4g} L_vb")


def end_event(
    step: int,
    terminated: bool,
    truncated: bool,
    failure: str,
    ret: float,
    metrics: Mapping[str, float],
) -> tuple[str, str]:
    if failure:
        why = f"terminated: simulation failed ({failure})"
    elif terminated:
        why = "terminated: target laid"
    else:
        why = "truncated: time limit"
    score = metrics.get("score", math.nan)
    text = f"episode end at step {step}, {why}; return {ret:.4g}, score {score:.4g}"
    return ("WARN" if failure else "INFO", text)


def episode_frame(
    *,
    step: int,
    sim_time: float,
    rod: np.ndarray,
    trace: np.ndarray,
    flow_polar: tuple[float, float],
    reward: float | None,
    reward_return: float | None,
    terms: Mapping[str, float],
    metrics: Mapping[str, float],
    events: list[tuple[str, str]],
    geometry: bool = True,
) -> Frame:
    scalars: dict[str, float] = {}
    if reward is not None:
        scalars["reward/total"] = reward
        scalars["reward/return"] = reward_return if reward_return is not None else math.nan
        for key, value in terms.items():
            scalars[series_path(key)] = value
    for key, value in metrics.items():
        scalars[series_path(key)] = value
    vbar, phi = flow_polar
    scalars["flow/vbar"] = vbar
    scalars["flow/phi"] = phi
    return Frame(
        step=step,
        sim_time=sim_time,
        rod=rod,
        trace=trace,
        flow=(vbar * math.cos(phi), vbar * math.sin(phi)),
        scalars=scalars,
        events=events,
        geometry=geometry,
    )

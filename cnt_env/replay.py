"""Replay: log episodes and simulations to rerun (an optional dependency).

Replay is decoupled from the simulation (docs/architecture.md rule 13). The simulation side records
plain arrays (:class:`EpisodeBuffer`, the episode file of :func:`save_episode`, the trace
file of :mod:`cnt_env.io`) as :class:`Frame` s; one logger turns frames into a rerun
recording, either frame by frame (a live viewer) or column by column (``send_columns``,
for files: the same recording at a fraction of the cost). So an episode recorded by the
wrapper (:class:`RerunRecorder`), a saved episode (:func:`record_episode`), a saved run
(:func:`record_simulation`) and a run recorded as it goes (:func:`record_run`) all give
the same entities. rerun is imported only when a recording is made: importing this
module, or using :class:`EpisodeSaver` and the episode file, never imports it.
Install it with ``pip install -e ".[rerun]"`` (rerun-sdk 0.41).

Recordings
----------
One ``RecordingStream`` per episode or run, with an explicit recording id (episodes:
``"<tag>-s<seed>-e<episode>"``) and no automatic timelines and properties: no
``log_time`` (wall clock) timeline and no start-time property, so that the same data
give the same recording. Timelines:

* ``step``: sequence. Episodes: the control step (0 = the state after reset). Runs: the
  physics step.
* ``sim_time``: duration, in tau (time unit mu L_vb^2 / e_v, units.py), shown by the
  viewer as seconds: 1 s = 1 tau. Episodes: since reset; runs: since the start.
* ``trace_node`` (saved runs only, :func:`record_simulation`): the number of trace
  nodes shown, for a trace without a time history.

Entities (lengths in L_vb; the substrate is the x-z plane, y up):

======================  ======================  ===================================
entity                  archetype               content
======================  ======================  ===================================
``world``               ViewCoordinates         right-handed, y up (static)
``world/substrate``     LineStrips3D            outline of the substrate (static)
``world/target``        LineStrips3D            target path at y = 0 (static)
``world/trace_before``  LineStrips3D            trace laid before reset (static)
``world/trace``         LineStrips3D            trace laid since reset (runs: all)
``world/rod``           LineStrips3D            the suspended rod, contact to top
``world/flow``          Arrows3D                flow velocity at the contact point
``top/...``             LineStrips2D, Arrows2D  the same seen from above: (x, z)
``reward/total``        Scalars                 the reward ``step`` returned
``reward/<term>``       Scalars                 ``info["reward_<term>"]``
``reward/return``       Scalars                 the return so far
``score/...``           Scalars                 score, coverage, precision, progress
``metrics/...``         Scalars                 the other numeric ``info`` entries
``pattern/...``         Scalars                 ``info["pattern"]`` measures, if any
``solver/...``          Scalars                 physics steps and Newton iterations
``flow/vbar``, ``phi``  Scalars                 flow speed (e_v/(mu H)) and angle
``events``              TextLog                 reset, failures, the episode's end
======================  ======================  ===================================

Each series' ``SeriesLines`` style is logged once, static. The default blueprint
(:func:`default_blueprint`) shows a 3D view, the top view and the plots.

The episode file (``format`` ``"cnt_env.episode"``, version 1) is described at
:func:`save_episode`. Open a recording with ``rerun FILE.rrd``.
"""

from __future__ import annotations

import json
import math
import os
import secrets
import time
import zipfile
import zlib
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

from cnt_env.io import atomic_savez, to_jsonable

if TYPE_CHECKING:
    from cnt_env.sim.deposition import DepositionConfig, DepositionSim

__all__ = [
    "APPLICATION_ID",
    "EPISODE_FORMAT",
    "EPISODE_FORMAT_VERSION",
    "INSTALL_HINT",
    "Episode",
    "EpisodeBuffer",
    "EpisodeFileError",
    "EpisodeSaver",
    "Frame",
    "RerunRecorder",
    "default_blueprint",
    "episode_recording_id",
    "file_format",
    "import_rerun",
    "load_episode",
    "read_rrd",
    "record_episode",
    "record_run",
    "record_simulation",
    "render_top_view",
    "save_episode",
]

APPLICATION_ID = "cnt_env"
EPISODE_FORMAT = "cnt_env.episode"
EPISODE_FORMAT_VERSION = 1
INSTALL_HINT = 'pip install -e ".[rerun]"'
RERUN_SERIES = "0.41"
MODES = ("save", "spawn", "connect")

# Most frames a recorded run (record_run) or a saved run (record_simulation) holds.
RUN_FRAMES = 200
SAVED_RUN_FRAMES = 100
# The longest flow arrow (at v̄ = v̄_max) is this fraction of H̄.
FLOW_ARROW_FRACTION = 0.25
# Margin (L_vb) of the substrate outline around what lies on it at the start; its
# corners are rounded outwards to multiples of this too.
SUBSTRATE_MARGIN = 10.0

# Colours (RGB).
TARGET_COLOR = (220, 60, 60)
TRACE_COLOR = (40, 90, 230)
TRACE_BEFORE_COLOR = (150, 150, 150)
ROD_COLOR = (30, 160, 60)
FLOW_COLOR = (20, 20, 20)
SUBSTRATE_COLOR = (190, 190, 190)
# Line widths, in UI points (negative radii are UI points in rerun).
LINE_POINTS = 1.5
SERIES_COLORS = {
    "reward/total": (20, 20, 20),
    "reward/return": (120, 120, 120),
    "reward/coverage": (40, 90, 230),
    "reward/precision": (230, 140, 20),
    "reward/progress": (30, 160, 60),
    "reward/failure": (220, 40, 40),
    "score/score": (20, 20, 20),
    "score/coverage": (40, 90, 230),
    "score/precision": (230, 140, 20),
    "score/progress": (30, 160, 60),
    "flow/vbar": (20, 20, 20),
    "flow/phi": (150, 60, 200),
}

# info entries that are not plotted as metrics (they have another place).
_NOT_METRICS = frozenset({"sim_time", "flow_vbar", "flow_phi", "target_length", "reset_advance"})
_SCORE_KEYS = ("score", "coverage", "precision", "progress")
_SOLVER_KEYS = ("physics_steps", "newton_iterations")
_PATTERN_PREFIX = "pattern_"


# =====================================================================================
# rerun, imported lazily
# =====================================================================================


def import_rerun() -> Any:
    """The ``rerun`` module; an ImportError that says how to install it when missing."""
    try:
        import rerun
    except ImportError as exc:
        raise ImportError(
            "rerun replay needs the optional dependency rerun-sdk "
            f"{RERUN_SERIES}: install it with `{INSTALL_HINT}` "
            f'(or `pip install "rerun-sdk~={RERUN_SERIES}.0"`)'
        ) from exc
    return rerun


# =====================================================================================
# frames: what one moment of an episode or run shows (plain arrays)
# =====================================================================================


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


def _series_path(name: str) -> str:
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


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
        value, (bool, np.bool_)
    )


def _split_info(info: Mapping[str, Any]) -> tuple[dict[str, float], dict[str, float]]:
    """(reward terms, metrics) of a step's ``info``: every numeric entry, the
    ``pattern`` measures as ``pattern_<key>``."""
    terms: dict[str, float] = {}
    metrics: dict[str, float] = {}
    for key, value in info.items():
        if key.startswith("reward_") and _is_number(value):
            terms[key] = float(value)
        elif key not in _NOT_METRICS and _is_number(value):
            metrics[key] = float(value)
    pattern = info.get("pattern")
    if isinstance(pattern, Mapping):
        for key, value in pattern.items():
            if _is_number(value):
                metrics[_PATTERN_PREFIX + key] = float(value)
    return terms, metrics


# =====================================================================================
# the episode file
# =====================================================================================


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
            name = self.meta.get("target", "?")
            length = _polyline_length(self.target) if len(self.target) else math.nan
            events.append(_reset_event(name, length))
        last = i == len(self.step) - 1
        if last and self.failure:
            events.append(("ERROR", f"simulation failed: {self.failure}"))
        if self.terminated[i] or self.truncated[i]:
            events.append(
                _end_event(
                    int(self.step[i]),
                    bool(self.terminated[i]),
                    bool(self.truncated[i]),
                    self.failure,
                    ret,
                    metrics,
                )
            )
        return _episode_frame(
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


# =====================================================================================
# recording episodes from the env (plain arrays)
# =====================================================================================


def _simulator(env: gym.Env) -> DepositionSim:
    """The DepositionSim behind a CNTDepositEnv (``sim``, else ``_sim``)."""
    u = env.unwrapped
    sim = getattr(u, "sim", None)
    if sim is None:
        sim = getattr(u, "_sim", None)
    if sim is None:
        raise TypeError(f"replay needs a CNTDepositEnv that has been reset, got {type(u).__name__}")
    return sim


def _flow_polar(info: Mapping[str, Any]) -> tuple[float, float]:
    return float(info.get("flow_vbar", 0.0)), float(info.get("flow_phi", 0.0))


def _reset_event(target: Any, length: float) -> tuple[str, str]:
    return ("INFO", f"reset: target {target}, {length:.4g} L_vb")


def _polyline_length(points: np.ndarray) -> float:
    return float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))


def _end_event(
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


def _episode_frame(
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
            scalars[_series_path(key)] = value
    for key, value in metrics.items():
        scalars[_series_path(key)] = value
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


class EpisodeBuffer:
    """Collects one episode of a CNTDepositEnv as arrays (no rerun involved).

    Call :meth:`start` after ``reset`` and :meth:`add` after every ``step``;
    :meth:`episode` returns the :class:`Episode`. Each call also returns the
    :class:`Frame` it recorded, for live logging.
    """

    def __init__(self, meta: Mapping[str, Any] | None = None) -> None:
        self.meta = dict(meta or {})
        self._rows: list[dict[str, Any]] = []
        self._rods: list[np.ndarray] = []
        self._n0 = 0
        self._return = 0.0
        self._target = np.zeros((0, 2))
        self._failure = ""
        self._final_trace: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self._rows)

    @property
    def target(self) -> np.ndarray:
        """The target polyline, absolute (x, z), (T, 2); (0, 2) before start."""
        return self._target

    def start(self, env: gym.Env, info: Mapping[str, Any]) -> Frame:
        sim = _simulator(env)
        trace = sim.trace()
        self._n0 = len(trace)
        target = getattr(env.unwrapped, "target", None)
        if target is not None:
            self._target = np.asarray(target.points, dtype=np.float64) + trace[-1, [0, 2]]
        return self._record(sim, trace, 0, info, 0.0, False, False, None)

    def add(
        self,
        env: gym.Env,
        reward: float,
        terminated: bool,
        truncated: bool,
        info: Mapping[str, Any],
        geometry: bool = True,
    ) -> Frame:
        if not self._rows:
            raise RuntimeError("EpisodeBuffer.add before start")
        sim = _simulator(env)
        trace = sim.trace()
        self._return += float(reward)
        if info.get("failure"):
            self._failure = str(info["failure"])
        frame = self._record(
            sim,
            trace,
            len(self._rows),
            info,
            float(reward),
            terminated,
            truncated,
            self._return,
            geometry,
        )
        if terminated or truncated:
            self._final_trace = trace
        return frame

    def _record(
        self,
        sim: DepositionSim,
        trace: np.ndarray,
        step: int,
        info: Mapping[str, Any],
        reward: float,
        terminated: bool,
        truncated: bool,
        ret: float | None,
        geometry: bool = True,
    ) -> Frame:
        terms, metrics = _split_info(info)
        rod = np.array(sim.suspended_nodes, dtype=np.float64)
        flow = _flow_polar(info)
        sim_time = float(info.get("sim_time", 0.0))
        self._rows.append(
            dict(
                step=step,
                sim_time=sim_time,
                flow=flow,
                reward=reward,
                terms=terms,
                metrics=metrics,
                trace_len=len(trace),
                terminated=bool(terminated),
                truncated=bool(truncated),
            )
        )
        self._rods.append(rod)
        events: list[tuple[str, str]] = []
        if step == 0:
            length = float(info.get("target_length", math.nan))
            events.append(_reset_event(info.get("target", "?"), length))
        if info.get("failure"):
            events.append(("ERROR", f"simulation failed: {info['failure']}"))
        if terminated or truncated:
            events.append(
                _end_event(
                    step, bool(terminated), bool(truncated), self._failure, self._return, metrics
                )
            )
        return _episode_frame(
            step=step,
            sim_time=sim_time,
            rod=rod,
            trace=trace[self._n0 - 1 :],
            flow_polar=flow,
            reward=None if step == 0 else reward,
            reward_return=ret,
            terms=terms,
            metrics=metrics,
            events=events,
            geometry=geometry,
        )

    def episode(self, env: gym.Env | None = None) -> Episode:
        """The episode so far; the final trace is the one at the end of the episode, else
        ``env``'s current one."""
        if not self._rows:
            raise RuntimeError("EpisodeBuffer.episode before start")
        trace = self._final_trace
        if trace is None:
            if env is None:
                raise RuntimeError("the episode has not ended: pass the env")
            trace = _simulator(env).trace()
        rows = self._rows
        term_names = _union(r["terms"] for r in rows)
        metric_names = _union(r["metrics"] for r in rows)
        offsets = np.concatenate([[0], np.cumsum([len(r) for r in self._rods])])
        return Episode(
            step=np.array([r["step"] for r in rows], dtype=np.int64),
            sim_time=np.array([r["sim_time"] for r in rows]),
            flow=np.array([r["flow"] for r in rows]).reshape(-1, 2),
            reward=np.array([r["reward"] for r in rows]),
            reward_terms=np.array(
                [[r["terms"].get(k, 0.0) for k in term_names] for r in rows]
            ).reshape(len(rows), len(term_names)),
            reward_term_names=term_names,
            metrics=np.array(
                [[r["metrics"].get(k, math.nan) for k in metric_names] for r in rows]
            ).reshape(len(rows), len(metric_names)),
            metric_names=metric_names,
            rod_nodes=np.concatenate(self._rods) if self._rods else np.zeros((0, 3)),
            rod_offsets=offsets.astype(np.int64),
            trace_len=np.array([r["trace_len"] for r in rows], dtype=np.int64),
            trace=np.array(trace, dtype=np.float64),
            target=self._target,
            terminated=np.array([r["terminated"] for r in rows], dtype=bool),
            truncated=np.array([r["truncated"] for r in rows], dtype=bool),
            failure=self._failure,
            meta=self.meta,
        )


def _union(dicts: Iterable[Mapping[str, Any]]) -> tuple[str, ...]:
    seen: dict[str, None] = {}
    for d in dicts:
        for k in d:
            seen.setdefault(k, None)
    return tuple(seen)


def episode_recording_id(tag: str, seed: int | None, episode: int) -> str:
    """The recording id of an episode: ``"<tag>-s<seed>-e<episode>"`` (seed ``none``
    when the env was never seeded)."""
    return f"{tag}-s{'none' if seed is None else seed}-e{episode:04d}"


def _env_meta(env: gym.Env) -> dict[str, Any]:
    u = env.unwrapped
    params = getattr(u, "params", None)
    target = getattr(u, "target", None)
    return {
        "params": params.as_dict() if hasattr(params, "as_dict") else None,
        "substrate": getattr(u, "substrate", None),
        "vbar_max": getattr(u, "vbar_max", None),
        "tolerance": getattr(u, "tolerance", None),
        "control_interval": getattr(u, "control_interval", None),
        "target": getattr(target, "name", None),
        "target_params": dict(getattr(target, "params", {}) or {}),
    }


class _EpisodeWrapper(gym.Wrapper):
    """Episode bookkeeping shared by :class:`EpisodeSaver` and :class:`RerunRecorder`:
    the episode index, the seed, the recording id and the :class:`EpisodeBuffer`."""

    def __init__(self, env: gym.Env, tag: str | None) -> None:
        super().__init__(env)
        self.tag = secrets.token_hex(4) if tag is None else str(tag)
        if not self.tag or any(c in self.tag for c in "/\\ "):
            raise ValueError(f"tag must be non-empty, without '/', '\\' or spaces: {tag!r}")
        self.episode_index = -1
        self.seed: int | None = None
        self.recording_id: str | None = None
        self.recording_ids: list[str] = []
        self._buffer: EpisodeBuffer | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        self._end_episode(interrupted=True)
        obs, info = self.env.reset(seed=seed, options=options)
        if seed is not None:
            self.seed = int(seed)
        self.episode_index += 1
        self.recording_id = episode_recording_id(self.tag, self.seed, self.episode_index)
        self.recording_ids.append(self.recording_id)
        meta = {
            "recording_id": self.recording_id,
            "application_id": APPLICATION_ID,
            "tag": self.tag,
            "seed": self.seed,
            "episode": self.episode_index,
            **_env_meta(self.env),
        }
        self._buffer = EpisodeBuffer(meta)
        frame = self._buffer.start(self.env, info)
        self._on_start(frame)
        return obs, info

    def step(self, action: Any):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self._buffer is not None:
            due = terminated or truncated or self._geometry_due(len(self._buffer))
            frame = self._buffer.add(
                self.env, float(reward), bool(terminated), bool(truncated), info, geometry=bool(due)
            )
            self._on_frame(frame)
            if terminated or truncated:
                self._end_episode(interrupted=False)
        return obs, reward, terminated, truncated, info

    def close(self) -> None:
        self._end_episode(interrupted=True)
        super().close()

    def _end_episode(self, interrupted: bool) -> None:
        buffer, self._buffer = self._buffer, None
        if buffer is not None:
            self._on_end(buffer, interrupted)

    # hooks
    def _geometry_due(self, step: int) -> bool:
        return True

    def _on_start(self, frame: Frame) -> None:
        pass

    def _on_frame(self, frame: Frame) -> None:
        pass

    def _on_end(self, buffer: EpisodeBuffer, interrupted: bool) -> None:
        pass


class EpisodeSaver(_EpisodeWrapper):
    """Save every episode to ``directory/<recording id>.npz`` (:func:`save_episode`),
    without rerun. Episodes cut short by ``reset`` or ``close`` are saved too.
    ``paths`` lists the files written."""

    def __init__(
        self, env: gym.Env, directory: str | os.PathLike[str], *, tag: str | None = None
    ) -> None:
        super().__init__(env, tag)
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.paths: list[Path] = []

    def _on_end(self, buffer: EpisodeBuffer, interrupted: bool) -> None:
        episode = buffer.episode(self.env)
        path = self.directory / f"{episode.meta['recording_id']}.npz"
        self.paths.append(save_episode(path, episode))


# =====================================================================================
# the rerun side: one logger for every source
# =====================================================================================


def default_blueprint(kind: str = "episode") -> Any:
    """The default layout: the 3D view and the top view on the left, the plots and the
    event log on the right. ``kind``: ``"episode"`` or ``"simulation"``."""
    import_rerun()
    import rerun.blueprint as rrb

    if kind not in ("episode", "simulation"):
        raise ValueError(f"kind must be 'episode' or 'simulation', got {kind!r}")
    scene = rrb.Vertical(
        rrb.Spatial3DView(origin="/world", name="3D"),
        rrb.Spatial2DView(origin="/top", name="Top view (x right, z down)"),
        row_shares=[3, 2],
    )
    if kind == "episode":
        plots: list[Any] = [
            rrb.TimeSeriesView(origin="/reward", name="Reward"),
            rrb.TimeSeriesView(origin="/score", name="Score"),
            rrb.Tabs(
                rrb.TimeSeriesView(origin="/metrics", name="Metrics"),
                rrb.TimeSeriesView(origin="/flow", name="Flow"),
                rrb.TimeSeriesView(origin="/pattern", name="Pattern"),
                rrb.TimeSeriesView(origin="/solver", name="Solver"),
            ),
        ]
    else:
        plots = [
            rrb.TimeSeriesView(origin="/metrics", name="Metrics"),
            rrb.TimeSeriesView(origin="/solver", name="Solver"),
        ]
    side = rrb.Vertical(*plots, rrb.TextLogView(origin="/events", name="Events"))
    return rrb.Blueprint(rrb.Horizontal(scene, side, column_shares=[3, 2]), collapse_panels=True)


def _open_stream(
    rr: Any,
    recording_id: str,
    *,
    name: str,
    mode: str,
    path: Path | None = None,
    url: str | None = None,
    blueprint: Any = None,
    properties: Mapping[str, Any] | None = None,
    application_id: str = APPLICATION_ID,
) -> Any:
    """A RecordingStream with the log-time timeline and the automatic (wall-clock)
    properties off, connected to its sink."""
    rec = rr.RecordingStream(application_id, recording_id=recording_id, send_properties=False)
    rec.set_log_time_enabled(False)
    rec.set_log_tick_enabled(False)
    if mode == "save":
        assert path is not None
        path.parent.mkdir(parents=True, exist_ok=True)
        rec.save(path, default_blueprint=blueprint)
    elif mode == "spawn":
        rec.spawn(default_blueprint=blueprint)
    elif mode == "connect":
        rec.connect_grpc(url, default_blueprint=blueprint)
    else:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    rec.send_recording_name(name)
    if properties:
        values = {
            k: (
                json.dumps(to_jsonable(v), allow_nan=False)
                if isinstance(v, (Mapping, list, tuple))
                else v
            )
            for k, v in to_jsonable(properties).items()
            if v is not None
        }
        if values:
            rec.send_property("cnt_env", rr.AnyValues(**values))
    return rec


def _close_stream(rec: Any) -> None:
    rec.flush()
    rec.disconnect()


class _SceneLogger:
    """Logs static scenes and :class:`Frame` s to one RecordingStream."""

    def __init__(self, rr: Any, rec: Any, *, flow_scale: float) -> None:
        self.rr = rr
        self.rec = rec
        self.flow_scale = flow_scale
        self._styled: set[str] = set()
        self._radius = rr.Radius.ui_points(LINE_POINTS)
        # Styles of the moving geometry, once and static: a component logged with every
        # frame costs as much as the data (rerun 0.41, ~0.1 ms per component and call).
        for path, cls, color, order in (
            ("world/trace", rr.LineStrips3D, TRACE_COLOR, None),
            ("world/rod", rr.LineStrips3D, ROD_COLOR, None),
            ("world/flow", rr.Arrows3D, FLOW_COLOR, None),
            ("top/trace", rr.LineStrips2D, TRACE_COLOR, 2.0),
            ("top/rod", rr.LineStrips2D, ROD_COLOR, 3.0),
            ("top/flow", rr.Arrows2D, FLOW_COLOR, 4.0),
        ):
            style: dict[str, Any] = {"colors": color, "radii": self._radius}
            if order is not None:
                style["draw_order"] = order
            rec.log(path, cls.from_fields(**style), static=True)

    def static_scene(
        self,
        *,
        target: np.ndarray | None,
        trace_before: np.ndarray | None,
        extent_points: Sequence[np.ndarray],
        substrate: str | None,
    ) -> None:
        rr, rec = self.rr, self.rec
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Y_UP, static=True)
        pts = [
            np.asarray(p)[:, :2] if np.shape(p)[-1] == 2 else np.asarray(p)[:, [0, 2]]
            for p in extent_points
            if len(p)
        ]
        if pts:
            xz = np.concatenate(pts)
            m = SUBSTRATE_MARGIN
            lo = np.floor((xz.min(axis=0) - m) / m) * m
            hi = np.ceil((xz.max(axis=0) + m) / m) * m
            box = np.array(
                [[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]], [lo[0], lo[1]]]
            )
            label = f"{substrate or 'flat'} substrate"
            rec.log(
                "world/substrate",
                rr.LineStrips3D(
                    [_lift(box)], colors=SUBSTRATE_COLOR, radii=self._radius, labels=label
                ),
                static=True,
            )
        if target is not None and len(target) >= 2:
            rec.log(
                "world/target",
                rr.LineStrips3D([_lift(target)], colors=TARGET_COLOR, radii=self._radius),
                static=True,
            )
            rec.log(
                "top/target",
                rr.LineStrips2D([target], colors=TARGET_COLOR, radii=self._radius, draw_order=1.0),
                static=True,
            )
        if trace_before is not None and len(trace_before) >= 2:
            rec.log(
                "world/trace_before",
                rr.LineStrips3D([trace_before], colors=TRACE_BEFORE_COLOR, radii=self._radius),
                static=True,
            )
            rec.log(
                "top/trace_before",
                rr.LineStrips2D(
                    [trace_before[:, [0, 2]]],
                    colors=TRACE_BEFORE_COLOR,
                    radii=self._radius,
                    draw_order=0.0,
                ),
                static=True,
            )

    def frame(self, f: Frame) -> None:
        rr, rec = self.rr, self.rec
        rec.set_time("step", sequence=f.step)
        rec.set_time("sim_time", duration=f.sim_time)
        for timeline, value in f.extra_times.items():
            rec.set_time(timeline, sequence=value)
        if f.geometry:
            self._geometry(f)
        for path, value in f.scalars.items():
            if value is None or not math.isfinite(value):
                continue
            self._style(path)
            rec.log(path, rr.Scalars(value))
        for level, text in f.events:
            rec.log("events", rr.TextLog(text, level=level))

    def frames(self, frames: Sequence[Frame]) -> None:
        """Log ``frames`` column by column (``send_columns``, one call per entity): the
        same recording as :meth:`frame` for each, at a fraction of the cost. Frames with
        ``extra_times`` are not supported here."""
        rr, rec = self.rr, self.rec
        if not frames:
            return
        if any(f.extra_times for f in frames):
            raise ValueError("frames with extra_times are logged one by one (frame())")
        steps = np.array([f.step for f in frames], dtype=np.int64)
        times = np.array([f.sim_time for f in frames], dtype=np.float64)

        def send(path: str, rows: Sequence[int], columns: Any) -> None:
            idx = np.asarray(rows, dtype=np.int64)
            if idx.size:
                indexes = [
                    rr.TimeColumn("step", sequence=steps[idx]),
                    rr.TimeColumn("sim_time", duration=times[idx]),
                ]
                rec.send_columns(path, indexes=indexes, columns=columns)

        geo = [i for i, f in enumerate(frames) if f.geometry]
        for name in ("trace", "rod"):
            # one strip per row, or none before there is a line to draw (as in frame())
            rows = [[x] if len(x := getattr(frames[i], name)) >= 2 else [] for i in geo]
            lengths = [len(r) for r in rows]
            flat = [x for r in rows for x in r]
            world = rr.LineStrips3D.columns(strips=flat).partition(lengths)
            send(f"world/{name}", geo, world)
            top = rr.LineStrips2D.columns(strips=[x[:, [0, 2]] for x in flat]).partition(lengths)
            send(f"top/{name}", geo, top)
        arrows = [i for i in geo if frames[i].flow is not None and len(frames[i].rod)]
        if arrows:
            origins = np.array([frames[i].rod[0] for i in arrows])
            flows = np.array([frames[i].flow for i in arrows], dtype=np.float64)
            vectors = np.zeros((len(arrows), 3))
            vectors[:, 0], vectors[:, 2] = flows[:, 0], flows[:, 1]
            vectors *= self.flow_scale
            send("world/flow", arrows, rr.Arrows3D.columns(vectors=vectors, origins=origins))
            top = rr.Arrows2D.columns(vectors=vectors[:, [0, 2]], origins=origins[:, [0, 2]])
            send("top/flow", arrows, top)
        series: dict[str, tuple[list[int], list[float]]] = {}
        for i, f in enumerate(frames):
            for path, value in f.scalars.items():
                if value is not None and math.isfinite(value):
                    rows_, values = series.setdefault(path, ([], []))
                    rows_.append(i)
                    values.append(value)
        for path, (rows_, values) in series.items():
            self._style(path)
            send(path, rows_, rr.Scalars.columns(scalars=np.array(values)))
        events = [(i, level, text) for i, f in enumerate(frames) for level, text in f.events]
        if events:
            texts = rr.TextLog.columns(text=[e[2] for e in events], level=[e[1] for e in events])
            send("events", [e[0] for e in events], texts)

    def _style(self, path: str) -> None:
        """The SeriesLines style of a scalar series, once and static."""
        if path not in self._styled:
            self._styled.add(path)
            color = SERIES_COLORS.get(path)
            name = path.split("/", 1)[1]
            self.rec.log(path, self.rr.SeriesLines(names=name, colors=color), static=True)

    def _geometry(self, f: Frame) -> None:
        rr, rec = self.rr, self.rec
        # one row per frame even before there is a line to draw (an empty strip list)
        trace = [f.trace] if len(f.trace) >= 2 else []
        rec.log("world/trace", rr.LineStrips3D(trace))
        rec.log("top/trace", rr.LineStrips2D([t[:, [0, 2]] for t in trace]))
        rod = [f.rod] if len(f.rod) >= 2 else []
        rec.log("world/rod", rr.LineStrips3D(rod))
        rec.log("top/rod", rr.LineStrips2D([r[:, [0, 2]] for r in rod]))
        if f.flow is not None and len(f.rod):
            c = f.rod[0]
            v = np.array([f.flow[0], 0.0, f.flow[1]]) * self.flow_scale
            rec.log("world/flow", rr.Arrows3D(vectors=[v], origins=[c]))
            rec.log("top/flow", rr.Arrows2D(vectors=[v[[0, 2]]], origins=[c[[0, 2]]]))


def _lift(xz: np.ndarray) -> np.ndarray:
    """(n, 2) substrate points (x, z) -> (n, 3) at y = 0."""
    out = np.zeros((len(xz), 3))
    out[:, 0], out[:, 2] = xz[:, 0], xz[:, 1]
    return out


def _flow_scale(Hbar: float | None, vbar_max: float | None) -> float:
    if not Hbar or not vbar_max or vbar_max <= 0:
        return 1.0
    return FLOW_ARROW_FRACTION * float(Hbar) / float(vbar_max)


def _episode_name(meta: Mapping[str, Any]) -> str:
    return f"episode {meta.get('episode')} (seed {meta.get('seed')}, target {meta.get('target')})"


def _properties(meta: Mapping[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in meta.items() if k not in ("application_id",)}


class RerunRecorder(_EpisodeWrapper):
    """Record every episode of a ``CNTDeposit-v0`` env to rerun.

    Each episode gets its own ``RecordingStream`` with the recording id
    ``"<tag>-s<seed>-e<episode>"`` (:func:`episode_recording_id`): ``seed`` is the last
    seed given to ``reset`` (None: never seeded), ``episode`` counts this wrapper's
    episodes from 0, and ``tag`` names the wrapper instance (default: 8 random hex
    digits, so that SubprocVecEnv workers never collide; pass e.g. ``tag=f"rank{i}"`` for
    ids that are the same from run to run). The log-time timeline is off.

    ======================  ============================================================
    argument                meaning
    ======================  ============================================================
    ``directory``           where ``mode="save"`` writes ``<recording id>.rrd``
    ``mode``                ``"save"`` (files), ``"spawn"`` (start or reuse a local
                            viewer), ``"connect"`` (a viewer at ``url``)
    ``url``                 gRPC url for ``"connect"`` (None: rerun's default,
                            ``rerun+http://127.0.0.1:9876/proxy``)
    ``tag``                 wrapper-instance part of the recording ids
    ``geometry_every``      log the rod, trace and flow every this many steps (and at
                            reset and the episode's end); scalars every step
    ``save_episodes``       also write ``<recording id>.npz`` (:func:`save_episode`) in
                            ``directory``
    ``stream``              log every step as it happens (default: only for ``"spawn"``
                            and ``"connect"``); else the episode is collected as arrays
                            (:class:`EpisodeBuffer`) and logged column by column when it
                            ends, which costs far less per step
    ======================  ============================================================

    A recording is finished (flushed and closed; without ``stream``, written) when the
    episode terminates or is truncated, at the next ``reset``, or at ``close``. Either
    way the recording holds the same data, except that a streamed trace is drawn as it
    was at each step while a collected one is drawn from the final trace (laid nodes
    still in the solve may have slid a little since). ``paths`` lists the ``.rrd``
    files, ``recording_ids`` every recording id. See the module docstring for the
    entities.
    """

    def __init__(
        self,
        env: gym.Env,
        directory: str | os.PathLike[str] | None = None,
        *,
        mode: str = "save",
        url: str | None = None,
        tag: str | None = None,
        geometry_every: int = 1,
        save_episodes: bool = False,
        stream: bool | None = None,
    ) -> None:
        self.rr = import_rerun()
        super().__init__(env, tag)
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        if (mode == "save" or save_episodes) and directory is None:
            raise ValueError("mode='save' and save_episodes=True need a directory")
        if (
            isinstance(geometry_every, bool)
            or not isinstance(geometry_every, int)
            or (geometry_every < 1)
        ):
            raise ValueError(f"geometry_every must be an int >= 1, got {geometry_every!r}")
        self.mode = mode
        self.url = url
        self.directory = None if directory is None else Path(directory)
        if self.directory is not None:
            self.directory.mkdir(parents=True, exist_ok=True)
        self.geometry_every = geometry_every
        self.save_episodes = save_episodes
        self.stream = mode != "save" if stream is None else bool(stream)
        self.paths: list[Path] = []
        self.episode_paths: list[Path] = []
        self._blueprint = default_blueprint("episode")
        self._rec: Any = None
        self._logger: _SceneLogger | None = None

    def _geometry_due(self, step: int) -> bool:
        return step % self.geometry_every == 0

    def _rrd_path(self, recording_id: str) -> Path | None:
        if self.mode != "save":
            return None
        assert self.directory is not None
        path = self.directory / f"{recording_id}.rrd"
        self.paths.append(path)
        return path

    def _on_start(self, frame: Frame) -> None:
        if not self.stream:
            return
        assert self._buffer is not None and self.recording_id is not None
        meta = self._buffer.meta
        path = self._rrd_path(self.recording_id)
        self._rec = _open_stream(
            self.rr,
            self.recording_id,
            name=_episode_name(meta),
            mode=self.mode,
            path=path,
            url=self.url,
            blueprint=self._blueprint,
            properties=_properties(meta),
        )
        Hbar = (meta.get("params") or {}).get("Hbar")
        self._logger = _SceneLogger(
            self.rr, self._rec, flow_scale=_flow_scale(Hbar, meta.get("vbar_max"))
        )
        trace = _simulator(self.env).trace()
        target = self._buffer.target
        self._logger.static_scene(
            target=target,
            trace_before=trace,
            extent_points=[target, trace[:, [0, 2]]],
            substrate=meta.get("substrate"),
        )
        self._logger.frame(frame)

    def _on_frame(self, frame: Frame) -> None:
        if self._logger is not None:
            self._logger.frame(frame)

    def _on_end(self, buffer: EpisodeBuffer, interrupted: bool) -> None:
        cut = f"episode cut short after {len(buffer) - 1} steps (reset or close)"
        episode = buffer.episode(self.env) if self.save_episodes or not self.stream else None
        if self._rec is not None:  # streamed
            if interrupted and self._logger is not None:
                self._logger.rec.log("events", self.rr.TextLog(cut, level="WARN"))
            _close_stream(self._rec)
            self._rec = None
            self._logger = None
        elif not self.stream:
            assert episode is not None
            rid = str(episode.meta["recording_id"])
            _write_episode(
                self.rr,
                episode,
                mode=self.mode,
                path=self._rrd_path(rid),
                url=self.url,
                recording_id=rid,
                blueprint=self._blueprint,
                geometry_every=self.geometry_every,
                extra_events=[("WARN", cut)] if interrupted else (),
            )
        if self.save_episodes:
            assert self.directory is not None and episode is not None
            path = self.directory / f"{episode.meta['recording_id']}.npz"
            self.episode_paths.append(save_episode(path, episode))

    def __getstate__(self) -> dict[str, Any]:
        raise TypeError(
            "a RerunRecorder holds a live rerun stream and cannot be pickled; "
            "wrap the env in each process instead"
        )


def _write_episode(
    rr: Any,
    episode: Episode,
    *,
    mode: str = "save",
    path: Path | None = None,
    url: str | None = None,
    recording_id: str | None = None,
    blueprint: Any = None,
    geometry_every: int = 1,
    extra_events: Sequence[tuple[str, str]] = (),
) -> str:
    """One recording of ``episode``, logged column by column; returns its id."""
    meta = episode.meta
    name = Path(str(path)).stem if path is not None else "episode"
    rid = recording_id or str(meta.get("recording_id") or f"episode-{name}")
    rec = _open_stream(
        rr,
        rid,
        name=_episode_name(meta),
        mode=mode,
        path=path,
        url=url,
        blueprint=default_blueprint("episode") if blueprint is None else blueprint,
        properties=_properties(meta),
    )
    try:
        Hbar = (meta.get("params") or {}).get("Hbar")
        logger = _SceneLogger(rr, rec, flow_scale=_flow_scale(Hbar, meta.get("vbar_max")))
        before = episode.trace[: episode.n_start]
        logger.static_scene(
            target=episode.target if len(episode.target) else None,
            trace_before=before,
            extent_points=[episode.target, before[:, [0, 2]]],
            substrate=meta.get("substrate"),
        )
        last = len(episode.step) - 1
        frames = [episode.frame(i) for i in range(last + 1)]
        for i, f in enumerate(frames):
            f.geometry = i % geometry_every == 0 or i == last
        frames[-1].events.extend(extra_events)
        logger.frames(frames)
    finally:
        _close_stream(rec)
    return rid


def record_episode(
    episode: Episode | str | os.PathLike[str],
    path: str | os.PathLike[str],
    *,
    recording_id: str | None = None,
) -> str:
    """Write an episode (an :class:`Episode` or an episode file) to the recording
    ``path`` (``.rrd``). The recording id is the episode's own unless given. Returns
    the recording id."""
    rr = import_rerun()
    if not isinstance(episode, Episode):
        episode = load_episode(episode)
    return _write_episode(rr, episode, path=Path(path), recording_id=recording_id)


def _run_scalars(stats: Mapping[str, Any]) -> dict[str, float]:
    out = {}
    for key, path in (
        ("deposited_length", "metrics/deposited_length"),
        ("n_nodes", "metrics/n_nodes"),
        ("snaps", "metrics/snaps"),
        ("newton_iterations", "solver/newton_iterations"),
        ("halvings", "solver/halvings"),
    ):
        value = stats.get(key)
        if _is_number(value):
            out[path] = float(value)
    return out


def _run_name(params: Mapping[str, Any], config: Mapping[str, Any]) -> str:
    return (
        f"cnt-sim run: {config.get('preset', '?')} preset, "
        f"{config.get('substrate', 'flat')} substrate, Hbar {params.get('Hbar')}"
    )


def _run_recording_id(params: Mapping[str, Any], config: Mapping[str, Any]) -> str:
    return f"run-{config.get('preset', 'custom')}-s{config.get('seed', 0)}"


def _flow_of(params: Mapping[str, Any]) -> tuple[float, float]:
    vbar, phi = float(params.get("vbar") or 0.0), float(params.get("phi") or 0.0)
    return vbar * math.cos(phi), vbar * math.sin(phi)


def record_simulation(
    saved: Mapping[str, Any],
    path: str | os.PathLike[str],
    *,
    recording_id: str | None = None,
    max_frames: int = SAVED_RUN_FRAMES,
) -> str:
    """Write a saved run (:func:`cnt_env.io.load_trace`'s dict) to the recording
    ``path``. A trace file has no time history, so the trace is revealed in order of
    deposition over at most ``max_frames`` frames on the ``trace_node`` timeline; the
    final state (the trace, the suspended rod if saved, the run's stats) is logged at
    ``step`` = its physics steps and ``sim_time`` = its time. Returns the recording id.
    """
    rr = import_rerun()
    trace = np.asarray(saved["trace"], dtype=np.float64)
    params, config, stats = saved["params"], saved["config"], saved["stats"]
    suspended = saved.get("suspended")
    rod = np.zeros((0, 3)) if suspended is None else np.asarray(suspended, dtype=np.float64)
    rid = recording_id or _run_recording_id(params, config)
    rec = _open_stream(
        rr,
        rid,
        name=_run_name(params, config),
        mode="save",
        path=Path(path),
        blueprint=default_blueprint("simulation"),
        properties={
            "params": params,
            "config": config,
            "stats": stats,
            "source": saved.get("source"),
        },
    )
    try:
        flow = _flow_of(params)
        vbar = math.hypot(*flow)
        logger = _SceneLogger(rr, rec, flow_scale=_flow_scale(params.get("Hbar"), vbar))
        logger.static_scene(
            target=None,
            trace_before=None,
            extent_points=[trace[:, [0, 2]]],
            substrate=config.get("substrate"),
        )
        n = len(trace)
        marks = np.unique(np.linspace(2, n, min(max_frames, n - 1)).round().astype(int))
        for k in marks:
            rec.set_time("trace_node", sequence=int(k))
            rec.log("world/trace", rr.LineStrips3D([trace[:k]]))
            rec.log("top/trace", rr.LineStrips2D([trace[:k, [0, 2]]]))
        rec.reset_time()
        steps, sim_time = stats.get("steps"), stats.get("time")
        final = Frame(
            step=int(steps) if _is_number(steps) else 0,
            sim_time=float(sim_time) if _is_number(sim_time) else 0.0,
            rod=rod,
            trace=trace,
            flow=flow,
            scalars=_run_scalars(stats),
            events=[
                ("INFO", "end of the saved run: " + json.dumps(to_jsonable(stats), allow_nan=False))
            ],
            extra_times={"trace_node": int(n)},
        )
        logger.frame(final)
    finally:
        _close_stream(rec)
    return rid


def record_run(
    config: DepositionConfig,
    deposit_length: float,
    path: str | os.PathLike[str],
    *,
    seed: int = 0,
    progress: Callable[[float, float], None] | None = None,
    run_config: Mapping[str, Any] | None = None,
    max_frames: int = RUN_FRAMES,
    recording_id: str | None = None,
) -> tuple[DepositionSim, dict[str, Any]]:
    """Run one deposition like :func:`cnt_env.cli.simulate` and record it to ``path``.

    The rod and the trace are sampled every ``deposit_length / max_frames`` L_vb of
    trace laid (through the progress callback of :meth:`DepositionSim.run`), with the
    step and the simulated time; ``progress(done, total)`` is still called after every
    step. ``run_config`` (the CLI's resolved config) goes into the recording's
    properties. If the solver fails, the failure is logged, the recording finished,
    and the ``SimulationError`` re-raised. Returns ``(sim, stats)``, ``stats`` with
    ``wall_time_s`` (which includes the logging).
    """
    from cnt_env.sim.deposition import DepositionSim
    from cnt_env.sim.stepper import SimulationError

    rr = import_rerun()
    run_config = dict(run_config or {})
    params = config.params.as_dict()
    rid = recording_id or _run_recording_id(params, {**run_config, "seed": seed})
    start = time.perf_counter()
    sim = DepositionSim(config, seed=seed)
    rec = _open_stream(
        rr,
        rid,
        name=_run_name(params, run_config),
        mode="save",
        path=Path(path),
        blueprint=default_blueprint("simulation"),
        properties={"params": params, "config": run_config},
    )
    flow = _flow_of(params)
    logger = _SceneLogger(rr, rec, flow_scale=_flow_scale(params.get("Hbar"), math.hypot(*flow)))
    spacing = float(deposit_length) / max(1, int(max_frames))
    next_mark = [spacing]

    def log_state(events: list[tuple[str, str]] | None = None) -> None:
        stats = sim.stats()
        logger.frame(
            Frame(
                step=int(stats["steps"]),
                sim_time=float(sim.time),
                rod=np.array(sim.suspended_nodes),
                trace=sim.trace(),
                flow=flow,
                scalars=_run_scalars(stats),
                events=events or [],
            )
        )

    def sample(done: float, total: float) -> None:
        if sim.deposited_length >= next_mark[0]:
            next_mark[0] = (math.floor(sim.deposited_length / spacing) + 1) * spacing
            log_state()
        if progress is not None:
            progress(done, total)

    try:
        log_state([("INFO", f"start: deposit {deposit_length:g} L_vb")])
        try:
            sim.run(deposit_length, progress=sample)
        except SimulationError as exc:
            log_state([("ERROR", f"simulation failed: {exc}")])
            raise
        stats = dict(sim.stats())
        stats["wall_time_s"] = time.perf_counter() - start
        log_state([("INFO", "end of the run: " + json.dumps(to_jsonable(stats), allow_nan=False))])
    finally:
        logger.static_scene(  # static: its outline can wait for the whole trace
            target=None,
            trace_before=None,
            extent_points=[sim.trace()[:, [0, 2]]],
            substrate="stepped" if config.params.kappa_c_bar is not None else "flat",
        )
        _close_stream(rec)
    return sim, stats


# =====================================================================================
# reading recordings back
# =====================================================================================


def read_rrd(path: str | os.PathLike[str]) -> dict[str, Any]:
    """What a ``.rrd`` file holds (with ``rerun.chunk.RrdReader``).

    Returns ``recordings`` (the recording ids), ``application_ids``, ``blueprints``
    (count), ``rows`` (entity path -> number of temporal rows), ``static`` (entity
    paths with static data), ``timelines`` (every timeline name), ``scalars`` (entity
    path -> list of (step, value), for ``Scalars`` entities logged on ``step``) and
    ``texts`` (the TextLog lines). Entity paths start with ``/``.
    """
    import_rerun()
    from rerun.chunk import RrdReader

    reader = RrdReader(Path(path))
    recordings = reader.recordings()
    rows: dict[str, int] = {}
    static: set[str] = set()
    timelines: set[str] = set()
    scalars: dict[str, list[tuple[int, float]]] = {}
    texts: list[str] = []
    for chunk in reader.stream():
        entity = chunk.entity_path
        if chunk.is_static:
            static.add(entity)
            continue
        rows[entity] = rows.get(entity, 0) + chunk.num_rows
        timelines.update(chunk.timeline_names)
        batch = chunk.to_record_batch()
        names = batch.schema.names
        if "Scalars:scalars" in names and "step" in names:
            steps = batch.column("step").to_pylist()
            values = batch.column("Scalars:scalars").to_pylist()
            scalars.setdefault(entity, []).extend(
                (int(s), float(v[0])) for s, v in zip(steps, values, strict=True) if v
            )
        if "TextLog:text" in names:
            texts.extend(
                t[0] if isinstance(t, list) else t
                for t in batch.column("TextLog:text").to_pylist()
                if t
            )
    for series in scalars.values():
        series.sort()
    return {
        "recordings": [r.recording_id for r in recordings],
        "application_ids": [r.application_id for r in recordings],
        "blueprints": len(reader.blueprints()),
        "rows": rows,
        "static": sorted(static),
        "timelines": sorted(timelines),
        "scalars": scalars,
        "texts": texts,
    }


# =====================================================================================
# a still frame (matplotlib), e.g. for the README
# =====================================================================================


def render_top_view(
    episode: Episode | str | os.PathLike[str],
    path: str | os.PathLike[str],
    *,
    frame: int = -1,
    dpi: int = 150,
) -> Path:
    """Save the top view of an episode's frame (default: the last) as a PNG, drawn like
    the recording's ``top`` view: target (red), trace before reset (grey), the
    episode's trace (blue), the suspended rod seen from above (green), the flow
    (arrow). x to the right, z down, as in the viewer."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    if not isinstance(episode, Episode):
        episode = load_episode(episode)
    i = frame % len(episode.step)
    f = episode.frame(i)
    rgb = [
        tuple(c / 255 for c in col)
        for col in (TARGET_COLOR, TRACE_BEFORE_COLOR, TRACE_COLOR, ROD_COLOR)
    ]
    fig, ax = plt.subplots(figsize=(6, 6))
    before = episode.trace[: episode.n_start]
    if len(episode.target):
        ax.plot(episode.target[:, 0], episode.target[:, 1], color=rgb[0], lw=2, label="target")
    ax.plot(before[:, 0], before[:, 2], color=rgb[1], lw=1.2, label="trace before reset")
    ax.plot(f.trace[:, 0], f.trace[:, 2], color=rgb[2], lw=1.8, label="trace")
    ax.plot(f.rod[:, 0], f.rod[:, 2], color=rgb[3], lw=1.2, label="suspended rod (from above)")
    if len(f.rod) and f.flow is not None:
        Hbar = (episode.meta.get("params") or {}).get("Hbar")
        s = _flow_scale(Hbar, episode.meta.get("vbar_max"))
        ax.annotate(
            "",
            xy=(f.rod[0, 0] + s * f.flow[0], f.rod[0, 2] + s * f.flow[1]),
            xytext=(f.rod[0, 0], f.rod[0, 2]),
            arrowprops={"arrowstyle": "->", "color": "k", "lw": 1.5},
        )
        ax.plot([], [], color="k", label="flow")
    ax.set_aspect("equal")
    ax.invert_yaxis()  # z down: the view from above (+y) of the right-handed x, y, z
    ax.set_xlabel("x / L_vb")
    ax.set_ylabel("z / L_vb")
    meta = episode.meta
    ax.set_title(
        f"{meta.get('recording_id', '')}: target {meta.get('target')}, step {f.step}, "
        f"t = {f.sim_time:.4g} tau",
        fontsize=9,
    )
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    return path

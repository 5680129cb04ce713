"""Gymnasium wrappers that record episodes as arrays, without rerun.

:class:`EpisodeBuffer` collects one episode of a ``CNTDeposit-v0`` env as an
:class:`~cnt_env.replay.episode.Episode`, reading the simulator through the env's public,
read-only ``sim`` property and the env's ``target_path``. :class:`EpisodeSaver` writes
every episode to an episode file. The rerun recorder
(:class:`cnt_env.replay.rerun.RerunRecorder`) shares their bookkeeping
(:class:`EpisodeWrapper`). Nothing here imports rerun.
"""

from __future__ import annotations

import math
import os
import secrets
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

from cnt_env.replay.episode import (
    APPLICATION_ID,
    Episode,
    Frame,
    end_event,
    episode_frame,
    reset_event,
    save_episode,
    split_info,
)

if TYPE_CHECKING:
    from cnt_env.sim.deposition import DepositionSim

__all__ = ["EpisodeBuffer", "EpisodeSaver", "EpisodeWrapper", "episode_recording_id"]


def _simulator(env: gym.Env) -> DepositionSim:
    """The DepositionSim behind a CNTDepositEnv (its read-only ``sim`` property)."""
    u = env.unwrapped
    sim = getattr(u, "sim", None)
    if sim is None:
        raise TypeError(f"replay needs a CNTDepositEnv that has been reset, got {type(u).__name__}")
    return sim


def _flow_polar(info: Mapping[str, Any]) -> tuple[float, float]:
    return float(info.get("flow_vbar", 0.0)), float(info.get("flow_phi", 0.0))


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
    def n_start(self) -> int:
        """Trace nodes laid before the episode (0 before start)."""
        return self._n0

    def final_trace(self, env: gym.Env) -> np.ndarray:
        """The trace at the episode's end, else ``env``'s current one."""
        return _simulator(env).trace() if self._final_trace is None else self._final_trace

    @property
    def target(self) -> np.ndarray:
        """The target polyline, absolute (x, z), (T, 2); (0, 2) before start."""
        return self._target

    def start(self, env: gym.Env, info: Mapping[str, Any]) -> Frame:
        sim = _simulator(env)
        trace = sim.trace()
        self._n0 = len(trace)
        target = getattr(env.unwrapped, "target_path", None)  # absolute, from the contact
        if target is not None:
            self._target = np.asarray(target, dtype=np.float64)
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
        terms, metrics = split_info(info)
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
            events.append(reset_event(info.get("target", "?"), length))
        if info.get("failure"):
            events.append(("ERROR", f"simulation failed: {info['failure']}"))
        if terminated or truncated:
            events.append(
                end_event(
                    step, bool(terminated), bool(truncated), self._failure, self._return, metrics
                )
            )
        return episode_frame(
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
        if self._final_trace is None and env is None:
            raise RuntimeError("the episode has not ended: pass the env")
        trace = self._final_trace if env is None else self.final_trace(env)
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
        "route": _route_meta(target, getattr(u, "target_path", None)),
    }


def _route_meta(target: Any, path: Any) -> dict[str, Any] | None:
    """The corridor half-width, pads and keep-outs of a route target, absolute (x, z)
    (the route starts at ``path[0]``, the contact point at reset); None for a target
    without a corridor."""
    width = getattr(target, "width", None)
    if width is None or path is None or len(path) == 0:
        return None
    origin = np.asarray(path, dtype=np.float64)[0]
    pads = np.asarray(getattr(target, "pads", ()), dtype=np.float64).reshape(-1, 2, 2)
    keepouts = [np.asarray(k, dtype=np.float64) + origin for k in getattr(target, "keepouts", ())]
    return {
        "width": float(width),
        "pads": (pads + origin).tolist(),
        "keepouts": [k.tolist() for k in keepouts],
    }


class EpisodeWrapper(gym.Wrapper):
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


class EpisodeSaver(EpisodeWrapper):
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

"""Episodes to rerun: the :class:`RerunRecorder` wrapper and :func:`record_episode`.

Both go through one writer (:func:`write_episode`) or, when streaming, through the same
:class:`~cnt_env.replay.rerun.SceneLogger` frame by frame, so an episode recorded live,
collected and written at its end, or replayed from its episode file gives the same
recording.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym

from cnt_env.plotting import flow_arrow_scale
from cnt_env.replay.episode import Episode, Frame, load_episode, route_geometry, save_episode
from cnt_env.replay.rerun import (
    MODES,
    SceneLogger,
    close_stream,
    default_blueprint,
    episode_name,
    episode_properties,
    import_rerun,
    open_stream,
)
from cnt_env.replay.wrappers import EpisodeBuffer, EpisodeWrapper, _simulator

__all__ = ["RerunRecorder", "record_episode", "write_episode"]


class RerunRecorder(EpisodeWrapper):
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
        self._logger: SceneLogger | None = None

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
        self._rec = open_stream(
            self.rr,
            self.recording_id,
            name=episode_name(meta),
            mode=self.mode,
            path=path,
            url=self.url,
            blueprint=self._blueprint,
            properties=episode_properties(meta),
        )
        Hbar = (meta.get("params") or {}).get("Hbar")
        self._logger = SceneLogger(
            self.rr, self._rec, flow_scale=flow_arrow_scale(Hbar, meta.get("vbar_max"))
        )
        trace = _simulator(self.env).trace()
        # the substrate outline waits for the episode's end, as in write_episode
        self._logger.static_scene(
            target=self._buffer.target, trace_before=trace, extent_points=None, substrate=None
        )
        self._logger.route(self._buffer.target, route_geometry(meta))
        self._logger.frame(frame)

    def _on_frame(self, frame: Frame) -> None:
        if self._logger is not None:
            self._logger.frame(frame)

    def _on_end(self, buffer: EpisodeBuffer, interrupted: bool) -> None:
        cut = f"episode cut short after {len(buffer) - 1} steps (reset or close)"
        episode = buffer.episode(self.env) if self.save_episodes or not self.stream else None
        if self._rec is not None:  # streamed
            assert self._logger is not None
            if interrupted:
                self._logger.rec.log("events", self.rr.TextLog(cut, level="WARN"))
            before = buffer.final_trace(self.env)[: buffer.n_start]
            self._logger.substrate_outline([buffer.target, before], buffer.meta.get("substrate"))
            close_stream(self._rec)
            self._rec = None
            self._logger = None
        elif not self.stream:
            assert episode is not None
            rid = str(episode.meta["recording_id"])
            write_episode(
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


def write_episode(
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
    rec = open_stream(
        rr,
        rid,
        name=episode_name(meta),
        mode=mode,
        path=path,
        url=url,
        blueprint=default_blueprint("episode") if blueprint is None else blueprint,
        properties=episode_properties(meta),
    )
    try:
        Hbar = (meta.get("params") or {}).get("Hbar")
        logger = SceneLogger(rr, rec, flow_scale=flow_arrow_scale(Hbar, meta.get("vbar_max")))
        before = episode.trace[: episode.n_start]
        logger.static_scene(
            target=episode.target if len(episode.target) else None,
            trace_before=before,
            extent_points=[episode.target, before[:, [0, 2]]],
            substrate=meta.get("substrate"),
        )
        logger.route(episode.target, route_geometry(meta))
        last = len(episode.step) - 1
        frames = [episode.frame(i) for i in range(last + 1)]
        for i, f in enumerate(frames):
            f.geometry = i % geometry_every == 0 or i == last
        frames[-1].events.extend(extra_events)
        logger.frames(frames)
    finally:
        close_stream(rec)
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
    return write_episode(rr, episode, path=Path(path), recording_id=recording_id)

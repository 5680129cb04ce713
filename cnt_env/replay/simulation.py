"""Deposition runs to rerun: a saved run (:func:`record_simulation`) and a run recorded
as it goes (:class:`RunRecording`, :func:`record_run`).

Replay does not run simulations of its own: :class:`RunRecording` logs the arrays of a
:class:`~cnt_env.sim.deposition.DepositionSim` it is handed (through its public
``trace()``, ``suspended_nodes``, ``time``, ``deposited_length`` and ``stats()``), sampled
from the run's progress callback; :func:`record_run` is the thin composition of
``DepositionSim(config).run(...)`` with a recording that ``cnt-sim run --rrd`` calls.
Timelines: ``step`` (the physics step), ``sim_time`` (tau) and, for saved runs, which
have no time history, ``trace_node`` (the number of trace nodes shown).
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from cnt_env.io import to_jsonable
from cnt_env.plotting import flow_arrow_scale
from cnt_env.replay.episode import Frame, is_number
from cnt_env.replay.rerun import (
    SceneLogger,
    close_stream,
    default_blueprint,
    import_rerun,
    open_stream,
)

if TYPE_CHECKING:
    from cnt_env.sim.deposition import DepositionConfig, DepositionSim

__all__ = ["RUN_FRAMES", "SAVED_RUN_FRAMES", "RunRecording", "record_run", "record_simulation"]

# Most frames a recorded run (record_run) or a saved run (record_simulation) holds.
RUN_FRAMES = 200
SAVED_RUN_FRAMES = 100


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
        if is_number(value):
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
    rec = open_stream(
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
        logger = SceneLogger(rr, rec, flow_scale=flow_arrow_scale(params.get("Hbar"), vbar))
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
            step=int(steps) if is_number(steps) else 0,
            sim_time=float(sim_time) if is_number(sim_time) else 0.0,
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
        close_stream(rec)
    return rid


class RunRecording:
    """A rerun recording of one deposition run, fed with the simulator as it runs.

    Open it (a context manager, or :meth:`close`), call :meth:`start` with the
    :class:`~cnt_env.sim.deposition.DepositionSim`, pass :meth:`sampler` as the run's
    progress callback, then :meth:`end` with the run's stats (or :meth:`failed` with the
    solver's error). The rod and the trace are logged every ``deposit_length /
    max_frames`` L_vb of trace laid, with the step and the simulated time. The substrate
    outline is logged (static) at :meth:`close`, when the whole trace is known.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        params: Mapping[str, Any],
        deposit_length: float,
        *,
        run_config: Mapping[str, Any] | None = None,
        seed: int = 0,
        max_frames: int = RUN_FRAMES,
        recording_id: str | None = None,
        substrate: str = "flat",
    ) -> None:
        self.rr = rr = import_rerun()
        self.params = dict(params)
        self.run_config = dict(run_config or {})
        self.deposit_length = float(deposit_length)
        self.substrate = substrate
        self.recording_id = recording_id or _run_recording_id(
            self.params, {**self.run_config, "seed": seed}
        )
        self.flow = _flow_of(self.params)
        self._rec = open_stream(
            rr,
            self.recording_id,
            name=_run_name(self.params, self.run_config),
            mode="save",
            path=Path(path),
            blueprint=default_blueprint("simulation"),
            properties={"params": self.params, "config": self.run_config},
        )
        self._logger = SceneLogger(
            rr,
            self._rec,
            flow_scale=flow_arrow_scale(self.params.get("Hbar"), math.hypot(*self.flow)),
        )
        self._spacing = self.deposit_length / max(1, int(max_frames))
        self._next_mark = self._spacing
        self._sim: DepositionSim | None = None

    def __enter__(self) -> RunRecording:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def log_state(self, sim: DepositionSim, events: list[tuple[str, str]] | None = None) -> None:
        """Log ``sim``'s rod, trace, flow and counters now."""
        self._sim = sim
        stats = sim.stats()
        self._logger.frame(
            Frame(
                step=int(stats["steps"]),
                sim_time=float(sim.time),
                rod=np.array(sim.suspended_nodes),
                trace=sim.trace(),
                flow=self.flow,
                scalars=_run_scalars(stats),
                events=events or [],
            )
        )

    def start(self, sim: DepositionSim) -> None:
        self.log_state(sim, [("INFO", f"start: deposit {self.deposit_length:g} L_vb")])

    def sampler(
        self, sim: DepositionSim, progress: Callable[[float, float], None] | None = None
    ) -> Callable[[float, float], None]:
        """A progress callback for ``sim.run``: logs a frame when due, then calls
        ``progress(done, total)``."""

        def sample(done: float, total: float) -> None:
            if sim.deposited_length >= self._next_mark:
                spacing = self._spacing
                self._next_mark = (math.floor(sim.deposited_length / spacing) + 1) * spacing
                self.log_state(sim)
            if progress is not None:
                progress(done, total)

        return sample

    def failed(self, sim: DepositionSim, error: BaseException) -> None:
        self.log_state(sim, [("ERROR", f"simulation failed: {error}")])

    def end(self, sim: DepositionSim, stats: Mapping[str, Any]) -> None:
        text = "end of the run: " + json.dumps(to_jsonable(stats), allow_nan=False)
        self.log_state(sim, [("INFO", text)])

    def close(self) -> None:
        """Log the substrate outline around the whole trace and finish the file."""
        if self._rec is None:
            return
        try:
            trace = self._sim.trace() if self._sim is not None else np.zeros((0, 3))
            self._logger.static_scene(
                target=None,
                trace_before=None,
                extent_points=[trace[:, [0, 2]]],
                substrate=self.substrate,
            )
        finally:
            close_stream(self._rec)
            self._rec = None


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
    """Run one deposition (``DepositionSim(config, seed).run(deposit_length)``, as
    ``cnt-sim run`` does) with a :class:`RunRecording` to ``path`` as its progress
    callback; ``progress(done, total)`` is still called after every step. ``run_config``
    (the CLI's resolved config) goes into the recording's properties. If the solver
    fails, the failure is logged, the recording finished, and the ``SimulationError``
    re-raised. Returns ``(sim, stats)``, ``stats`` with ``wall_time_s`` (which includes
    the logging).
    """
    from cnt_env.sim.deposition import DepositionSim
    from cnt_env.sim.stepper import SimulationError

    start = time.perf_counter()
    sim = DepositionSim(config, seed=seed)
    substrate = "stepped" if config.params.kappa_c_bar is not None else "flat"
    with RunRecording(path, config.params.as_dict(), deposit_length, run_config=run_config,
                      seed=seed, max_frames=max_frames, recording_id=recording_id,
                      substrate=substrate) as recording:  # fmt: skip
        recording.start(sim)
        try:
            sim.run(deposit_length, progress=recording.sampler(sim, progress))
        except SimulationError as exc:
            recording.failed(sim, exc)
            raise
        stats = dict(sim.stats())
        stats["wall_time_s"] = time.perf_counter() - start
        recording.end(sim, stats)
    return sim, stats

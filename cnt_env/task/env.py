"""``CNTDeposit-v0``: steer the gas flow so that a depositing CNT lays a target path.

The env only translates (docs/architecture.md rule 3): actions to a flow
(:mod:`cnt_env.task.spaces`), the simulator's state to observations (``spaces``,
:mod:`cnt_env.task.raster`), and the trace against the target to rewards
(:mod:`cnt_env.task.scoring`). The physics lives in :mod:`cnt_env.sim.deposition`; the warm
start in :mod:`cnt_env.sim.warmstart`; the targets in :mod:`cnt_env.task.targets`; the
keyword validation in :mod:`cnt_env.task.settings`. See :class:`CNTDepositEnv` for the
specification.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from cnt_env import MAX_EPISODE_STEPS
from cnt_env.patterns import MeasureOptions, measure
from cnt_env.sim.deposition import DepositionSim
from cnt_env.sim.forces import DRAG_LAWS
from cnt_env.sim.stepper import SimulationError
from cnt_env.sim.warmstart import flatten_snapshot, unflatten_snapshot, warm_state
from cnt_env.task import raster, settings
from cnt_env.task import targets as targets_mod
from cnt_env.task.scoring import COVERAGE_SPACING, ThinScore
from cnt_env.task.spaces import (
    LAID_RATIO_BOUND,
    LEAN_HEIGHT_FRACTIONS,
    LEAN_HEIGHTS,
    POSITION_BOUND,
    ObservationLayout,
    flow_from_action,
    rod_features,
)
from cnt_env.task.targets import Target

__all__ = ["DEFAULT_MAX_EPISODE_STEPS", "CNTDepositEnv", "flow_from_action"]

#: Default speed cap of the flow, in units of e_v / (mu H) (the paper's range, docs/model.md §6).
DEFAULT_VBAR_MAX = 0.13
#: The default control interval is this many Hbar (time units tau), rounded to whole
#: physics steps: about 1 L_vb of trace, since the deposition speed is ~0.65 / Hbar.
CONTROL_INTERVAL_HBAR = 1.5
#: Episode length registered with ``max_episode_steps`` (TimeLimit; its one home is
#: cnt_env/__init__.py): ~400 L_vb of trace, about 4 periods of the baseline serpentine
#: (benchmarks/env_throughput.py --baseline: amplitude ~24, wavelength ~7.7, ~95 L_vb of
#: trace per period under the paper's constant flow).
DEFAULT_MAX_EPISODE_STEPS = MAX_EPISODE_STEPS
#: Most physics steps one control step may take.
MAX_SUBSTEPS = 100_000
OBS_MODES = ("vector", "image")
# Pattern measurements kept in info["pattern"] (patterns.measure keys).
_PATTERN_KEYS = ("pattern", "measured_length", "amplitude", "peak_to_peak", "wavelength",
                 "coil_radius", "n_uturns", "n_cycles", "n_loops", "n_self_crossings")  # fmt: skip
_REWARD_KEYS = ("reward_coverage", "reward_precision", "reward_progress", "reward_failure")
_MEASURE_OPTIONS = MeasureOptions(transient_length=0.0)
# re-exported for callers of the v0 layout
__all__ += ["COVERAGE_SPACING", "LAID_RATIO_BOUND", "POSITION_BOUND"]


class CNTDepositEnv(gym.Env[np.ndarray, np.ndarray]):
    r"""Flow-directed deposition of a carbon nanotube onto a target circuit path.

    ## Description

    A carbon nanotube (CNT), modelled as a discrete elastic rod of height H̄, is fed from
    the top and falls onto a substrate (the x-z plane, y up), where van der Waals
    adhesion makes it stick (docs/model.md §1, §4). The shape it leaves, the *trace*, is a
    coil on a flat sticky substrate and a serpentine on a stepped one with flow (§5-6).
    The agent sets the rarefied gas flow, in the substrate plane, every control
    interval. The task: make the trace follow a target path (a polyline in the
    substrate plane that starts at the contact point; :mod:`cnt_env.task.targets`).

    All quantities are dimensionless (docs/model.md §2): lengths in L_vb = sqrt(k_b / e_v),
    time in tau = mu L_vb² / e_v, flow speeds v̄ in units of e_v / (mu H).

    ## Action Space

    ``Box(-1, 1, (2,), float32)``: the flow velocity in the substrate plane. The square
    is mapped one-to-one onto the disk of radius ``vbar_max`` (elliptical grid map,
    :func:`flow_from_action`), so the speed never exceeds ``vbar_max``. Out-of-range
    actions are clipped (an action past a bound acts exactly like the bound); a NaN or
    infinite action raises ``ValueError`` and leaves the env untouched.

    | Num | Action                                  | Min | Max | Unit              |
    |-----|-----------------------------------------|-----|-----|-------------------|
    | 0   | flow along x (across the steps), scaled | -1  | 1   | v̄_max             |
    | 1   | flow along z (along the steps), scaled  | -1  | 1   | v̄_max             |

    The flow is held for ``control_interval`` (tau), simulated as ``n_substeps``
    physics steps of ``dt``; the default lays about 1 L_vb of trace per control step.

    ## Observation Space

    ``obs_mode="vector"`` (default): a flat ``Box`` of float32 with finite bounds. With
    K = ``n_trace_points`` and M = ``n_target_points`` (16 each by default: 81 values),
    in order (``observation_structure`` gives the sizes, ``observation_slices`` the
    slices). The *contact point* is the last deposited node; positions are (x, z)
    relative to it, clipped to ±``POSITION_BOUND`` = 1000 L_vb.

    | Slice    | Size | Observation                                        | Bounds  | Unit |
    |----------|------|----------------------------------------------------|---------|------|
    | trace    | 2K   | last K deposited nodes before the contact point,   | ±1000   | L_vb |
    |          |      | oldest first, (x, z) pairs, δ̄ apart along the      |         |      |
    |          |      | trace (padded with the oldest while shorter)       |         |      |
    | target   | 2M   | M target points ahead of the furthest covered one, | ±1000   | L_vb |
    |          |      | ``target_spacing`` apart in arc length, (x, z)     |         |      |
    |          |      | pairs (the end point repeats past the end)         |         |      |
    | flow     | 2    | current flow (v̄ cos φ, v̄ sin φ) / v̄_max            | ±1      | 1    |
    | rod      | 1    | height y_c of the contact node                     | ±1000   | L_vb |
    |          | 2    | horizontal unit direction (x, z) of the contact    | ±1      | 1    |
    |          |      | edge (from the contact point to the contact node)  |         |      |
    |          | 8    | horizontal offset (x, z) of the suspended rod at   | ±1000   | L_vb |
    |          |      | heights 2, 8, H̄/2 and H̄: where it leans            |         |      |
    | progress | 3    | progress G, coverage C, precision P (see Rewards)  | [0, 1]  | 1    |
    |          | 1    | length laid this episode / target length           | [0, 100]| 1    |

    ``obs_mode="image"``: ``Box(0, 255, (S, S, 3), uint8)`` with S = ``image_size``
    (>= 64), a top view of ``image_extent`` L_vb square centred on the contact point,
    x to the right and z up. Channel 0: the trace (255 laid in this episode, 128
    before); channel 1: the target (255 not yet covered, 128 covered); channel 2: the
    horizontal projection of the suspended rod.

    ## Rewards

    Potential-based: each step pays the change in an agreement score Φ, so the return
    of an episode is its final score (Φ = 0 at reset, nothing laid yet). With the
    tolerance band τ_b = ``tolerance`` (L_vb) and only the trace laid since reset:

    * coverage C: fraction of the target's arc length within τ_b of a trace node;
    * precision P: fraction of the trace nodes within τ_b of the target (0 before any);
    * progress G: arc length of the furthest covered target point over the target length;

    Φ = w_c C + w_p P + w_g G - penalty · [simulation failed], with the weights
    ``coverage_weight`` (0.5), ``precision_weight`` (0.25), ``progress_weight`` (0.25)
    and ``failure_penalty`` (1.0). Φ lies in [0, 1] without a failure. The reward is
    ``reward_coverage + reward_precision + reward_progress + reward_failure``, each in
    ``info``; ``info["score"]`` is Φ.

    ``info`` also holds the raw metrics: ``coverage``, ``precision``, ``progress``,
    ``mean_distance`` (mean distance of the episode's trace nodes to the target, L_vb;
    0 before any), ``n_laid`` (nodes), ``laid_length`` (L_vb), ``sim_time`` (tau since
    reset), ``flow_vbar``, ``flow_phi``, ``target``, ``target_length``, ``is_success``,
    ``physics_steps``, ``newton_iterations``, and every ``pattern_every`` steps, at
    termination and on the last step before the TimeLimit, ``info["pattern"]``: the
    pattern measures of the episode's trace (:func:`cnt_env.patterns.measure`; NaN
    where a measure does not apply).

    ## Starting State

    A warm state per configuration: the simulator after ``warmup_length`` L_vb of trace
    laid from the start-up shape (default H̄, so the suspended rod no longer holds any
    of the artificial initial shape) with the configured flow (``vbar``, ``phi``). It is
    computed once, cached on disk (:mod:`cnt_env.sim.warmstart`; ``cache_dir``, or
    ``$CNT_ENV_CACHE_DIR``, or the user cache directory) and restored exactly at every
    reset. Then the simulator advances for a random time, uniform in
    [0, ``reset_advance`` * ``control_interval``), with that flow, and the target (drawn
    from the training ``families`` with ``np_random``, or given by
    ``reset(options={"target": ...})``: a family name, a held-out name, a
    :class:`~cnt_env.task.targets.Target`, or an (n, 2) polyline) is placed at the contact
    point.

    ## Episode End

    ### Termination
    1. The target is laid: its end point is within τ_b of the episode's trace
       (``info["is_success"]``).
    2. The simulation failed (the Newton solve failed even after halving dt):
       ``reward_failure = -failure_penalty`` and ``info["failure"]`` holds the reason.
       The observation stays finite; stepping again repeats the terminal step with
       reward 0.

    ### Truncation
    By ``TimeLimit``: ``max_episode_steps`` = 400 when made with
    ``gymnasium.make("CNTDeposit-v0")``: ~400 L_vb of trace, about 4 periods of the
    baseline serpentine (~95 L_vb of trace per period).

    ## Arguments

    | Parameter          | Default      | Description                                     |
    |--------------------|--------------|-------------------------------------------------|
    | `render_mode`      | None         | "rgb_array" or "human"                          |
    | `preset`           | "serpentine" | paper groups (units.paper_groups): or "coil"    |
    | `substrate`        | preset's     | "stepped" or "flat" (flat: κ̄_c = None)          |
    | `Hbar`, `Ibar`     | preset's     | rod height (L_vb), mass per length              |
    | `kappa_c_bar`      | 0.2          | critical curvature (stepped only; 1/L_vb)       |
    | `delta_bar`        | 1.0          | discretisation length (L_vb)                    |
    | `vbar`, `phi`      | preset's     | warm-start flow: speed <= vbar_max, angle (rad) |
    | `physics`          | None         | other DimensionlessParams fields (dict)         |
    | `dt`               | 0.2 H̄        | physics time step (tau); stepped: ENV_SIM_DEFAULTS |
    | `coarse_delta`     | None         | graded discretisation (DepositionConfig)        |
    | `initial_radius`   | preset's     | start-up arc radius (L_vb): 3.9 stepped, 6.4 flat |
    | `drag_law`         | "linear"     | "linear" or "printed"                           |
    | `sim_options`      | None         | other DepositionConfig fields (dict)            |
    | `vbar_max`         | 0.13         | flow speed cap (e_v / (mu H))                   |
    | `control_interval` | ~1.5 H̄       | simulated time per step (tau), whole dt's       |
    | `warmup_length`    | H̄            | trace laid to reach the warm state (L_vb)       |
    | `warmup_seed`      | 0            | seed of the start-up perturbation               |
    | `reset_advance`    | 4.0          | max random advance at reset (control intervals) |
    | `tolerance`        | 2.0          | tolerance band τ_b (L_vb)                       |
    | `n_trace_points`   | 16           | K                                               |
    | `n_target_points`  | 16           | M                                               |
    | `target_spacing`   | 2.0          | spacing of the observed target points (L_vb)    |
    | `coverage_weight`  | 0.5          | w_c                                             |
    | `precision_weight` | 0.25         | w_p                                             |
    | `progress_weight`  | 0.25         | w_g                                             |
    | `failure_penalty`  | 1.0          | paid once on a simulation failure               |
    | `families`         | all six      | training target families (targets.FAMILIES)     |
    | `obs_mode`         | "vector"     | "vector" or "image"                             |
    | `image_size`       | 64           | S of the image observation (>= 64 pixels)       |
    | `image_extent`     | 64.0         | side of the image observation (L_vb)            |
    | `render_size`      | 256          | side of the rendered frame (pixels)             |
    | `pattern_every`    | 50           | steps between pattern measures (0: at the end)  |
    | `cache_dir`        | None         | warm-state cache directory                      |

    ## Version History

    * v0: initial version.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array", "human"], "render_fps": 10}

    def __init__(
        self,
        render_mode: str | None = None,
        *,
        preset: str = "serpentine",
        substrate: str | None = None,
        Hbar: float | None = None,
        Ibar: float | None = None,
        kappa_c_bar: float | None = None,
        delta_bar: float | None = None,
        vbar: float | None = None,
        phi: float | None = None,
        physics: Mapping[str, Any] | None = None,
        dt: float | None = None,
        coarse_delta: float | None = None,
        initial_radius: float | None = None,
        drag_law: str = "linear",
        sim_options: Mapping[str, Any] | None = None,
        vbar_max: float = DEFAULT_VBAR_MAX,
        control_interval: float | None = None,
        warmup_length: float | None = None,
        warmup_seed: int = 0,
        reset_advance: float = 4.0,
        tolerance: float = 2.0,
        n_trace_points: int = 16,
        n_target_points: int = 16,
        target_spacing: float = 2.0,
        coverage_weight: float = 0.5,
        precision_weight: float = 0.25,
        progress_weight: float = 0.25,
        failure_penalty: float = 1.0,
        families: Sequence[str] | str | None = None,
        obs_mode: str = "vector",
        image_size: int = 64,
        image_extent: float = 64.0,
        render_size: int = 256,
        pattern_every: int = 50,
        cache_dir: str | None = None,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}")
        self.render_mode = render_mode
        s = settings
        self.params = s.physics_params(preset, substrate, Hbar, Ibar, kappa_c_bar, delta_bar,
                                       vbar, phi, physics)  # fmt: skip
        self.substrate = "flat" if self.params.kappa_c_bar is None else "stepped"
        self.config = s.deposition_config(
            preset, self.params, delta_bar, s.choice("drag_law", drag_law, tuple(DRAG_LAWS)),
            sim_options, dt=dt, coarse_delta=coarse_delta, initial_radius=initial_radius,
        )  # fmt: skip
        self.vbar_max = s.positive("vbar_max", vbar_max)
        if self.params.vbar > self.vbar_max:
            raise ValueError(f"vbar = {self.params.vbar} exceeds vbar_max = {self.vbar_max}")
        self.dt = self.config.time_step
        self.control_interval, self.n_substeps = self._substeps(control_interval)
        self.warmup_length = s.non_negative(
            "warmup_length", self.params.Hbar if warmup_length is None else warmup_length
        )
        self.warmup_seed = s.seed("warmup_seed", warmup_seed)
        self.reset_advance = s.non_negative("reset_advance", reset_advance)
        self.tolerance = s.positive("tolerance", tolerance)
        self.target_spacing = s.positive("target_spacing", target_spacing)
        self.weights = np.array([s.non_negative("coverage_weight", coverage_weight),
                                 s.non_negative("precision_weight", precision_weight),
                                 s.non_negative("progress_weight", progress_weight)])  # fmt: skip
        if not self.weights.sum() > 0:
            raise ValueError("at least one reward weight must be > 0")
        self.failure_penalty = s.non_negative("failure_penalty", failure_penalty)
        self.families = s.families_tuple(families, targets_mod.FAMILIES)
        self.obs_mode = s.choice("obs_mode", obs_mode, OBS_MODES)
        self.image_size = s.count("image_size", image_size, minimum=64)
        self.image_extent = s.positive("image_extent", image_extent)
        self.render_size = s.count("render_size", render_size, minimum=16)
        self.pattern_every = s.count("pattern_every", pattern_every, minimum=0)
        self.cache_dir = s.optional_path("cache_dir", cache_dir)
        self.lean_heights = LEAN_HEIGHTS + tuple(f * self.params.Hbar
                                                 for f in LEAN_HEIGHT_FRACTIONS)  # fmt: skip
        self.layout = ObservationLayout(s.count("n_trace_points", n_trace_points),
                                        s.count("n_target_points", n_target_points),
                                        self.lean_heights)  # fmt: skip
        self.n_trace_points = self.layout.n_trace_points
        self.n_target_points = self.layout.n_target_points
        self.observation_structure: dict[str, int] = dict(self.layout.structure)
        self.observation_slices: dict[str, slice] = dict(self.layout.slices)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        if self.obs_mode == "vector":
            self.observation_space = self.layout.space()
        else:
            size = self.image_size
            self.observation_space = spaces.Box(0, 255, shape=(size, size, 3), dtype=np.uint8)

        self._sim: DepositionSim | None = None
        self._warm: dict[str, np.ndarray] | None = None
        self.warm_start_source: str | None = None
        self._window = raster.Window(self.metadata["render_fps"])

    def _substeps(self, control_interval: float | None) -> tuple[float, int]:
        """The control interval (tau) and its whole number of physics steps
        (docs/architecture.md rule 4)."""
        if control_interval is None:
            n = max(1, round(CONTROL_INTERVAL_HBAR * self.params.Hbar / self.dt))
            control_interval = n * self.dt
        interval = settings.positive("control_interval", control_interval)
        n = round(interval / self.dt)
        if n < 1 or abs(n * self.dt - interval) > 1e-9 * interval:
            raise ValueError(
                f"control_interval = {interval!r} must be a whole multiple of the "
                f"physics dt = {self.dt!r}; e.g. {max(n, 1) * self.dt!r}"
            )
        if n > MAX_SUBSTEPS:
            raise ValueError(f"control_interval needs {n} physics steps, more than {MAX_SUBSTEPS}")
        return interval, n

    # ---- read-only views for wrappers (replay, plots) ---------------------------------------
    @property
    def sim(self) -> DepositionSim | None:
        """The simulator behind the env (None before the first reset). Read it; stepping
        or restoring it behind the env's back breaks the episode's bookkeeping."""
        return self._sim

    @property
    def target_path(self) -> np.ndarray:
        """The episode's target, absolute (x, z) in L_vb, starting at the contact point
        at reset, (n, 2) (a copy)."""
        return self._target_abs.copy()

    @property
    def episode_start(self) -> int:
        """Index in ``sim.trace()`` of the first node laid in this episode."""
        return self._n0

    # ---- reset ------------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        options = dict(options or {})
        target_spec = options.pop("target", None)
        if options:
            raise ValueError(f"unknown reset options {sorted(options)}; only 'target' is known")
        rng = self.np_random
        if target_spec is None:
            target = targets_mod.sample(rng, self.families)
        else:
            target = targets_mod.resolve(target_spec, rng)
        if self._warm is None:
            snap, self.warm_start_source = warm_state(
                self.config, self.warmup_length, self.warmup_seed, self.cache_dir
            )
            self._warm = flatten_snapshot(snap)
            self._sim = DepositionSim(self.config, seed=self.warmup_seed)
        sim = self._sim
        assert sim is not None
        advance = float(rng.uniform(0.0, 1.0)) * self.reset_advance * self.control_interval
        sim.restore(unflatten_snapshot(self._warm))
        if advance > 0.0:
            try:
                sim.advance(advance)
            except SimulationError:
                sim.restore(unflatten_snapshot(self._warm))  # start from the warm state itself
                advance = 0.0
        self._flow = (self.params.vbar, self.params.phi)
        self._begin_episode(target)
        trace = sim.trace()
        metrics = self._last_metrics = self._metrics(trace)
        self._potentials = self._score.potentials(metrics)
        obs = self._observation(trace, metrics)
        info = self._info(metrics, dict.fromkeys(_REWARD_KEYS, 0.0), 0, 0)
        info["reset_advance"] = advance
        if self.render_mode == "human":
            self.render()
        return obs, info

    def _begin_episode(self, target: Target) -> None:
        sim = self._sim
        trace = sim.trace()
        self._n0 = sim.n_trace
        self._origin = trace[-1, [0, 2]].copy()
        self._laid0 = float(sim.deposited_length)
        self._t0 = float(sim.time)
        self.target = target
        self._target_abs = target.points + self._origin
        self._score = ThinScore(self._target_abs, self.tolerance, self.weights)
        self._target_s = targets_mod.cumulative_length(self._target_abs)
        self._target_length = float(self._target_s[-1])
        self._steps = 0
        self._failure: str | None = None

    # ---- step -------------------------------------------------------------------------
    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (2,):
            raise ValueError(f"action must have shape (2,), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action must be finite, got {a.tolist()}")
        if self._sim is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        sim = self._sim
        if self._failure is not None:  # stepping past a failure repeats the terminal step
            trace = sim.trace()
            metrics = self._metrics(trace)
            info = self._info(metrics, dict.fromkeys(_REWARD_KEYS, 0.0), 0, 0)
            info["failure"] = self._failure
            return self._observation(trace, metrics), 0.0, True, False, info
        self._flow = flow_from_action(np.clip(a, -1.0, 1.0), self.vbar_max)
        before = sim.stats()
        try:
            sim.set_flow(*self._flow)
            sim.advance(self.control_interval)
        except SimulationError as exc:
            self._failure = str(exc.reason)
        after = sim.stats()
        self._steps += 1
        trace = sim.trace()
        metrics = self._last_metrics = self._metrics(trace)
        potentials = self._score.potentials(metrics)
        obs = self._observation(trace, metrics)
        if self._failure is None and not np.all(np.isfinite(obs)):
            self._failure = "non-finite simulator state"
        if self._failure is not None:
            obs = np.nan_to_num(obs, nan=0.0, posinf=0.0, neginf=0.0)
            if obs.dtype != np.uint8:
                obs = self.layout.clip(obs)
            potentials = self._potentials  # a failed state scores nothing new
        delta = potentials - self._potentials
        self._potentials = potentials
        terms = dict(zip(_REWARD_KEYS[:-1], (float(d) for d in delta), strict=True))
        terms["reward_failure"] = -self.failure_penalty if self._failure is not None else 0.0
        reward = 0.0
        for key in _REWARD_KEYS:
            reward += terms[key]
        terminated = bool(metrics["covered_end"]) or self._failure is not None
        info = self._info(metrics, terms, after["steps"] - before["steps"],
                          after["newton_iterations"] - before["newton_iterations"])  # fmt: skip
        if self._failure is not None:
            info["failure"] = self._failure
        limit = self.spec.max_episode_steps if self.spec is not None else None
        if (
            terminated
            or (self.pattern_every and self._steps % self.pattern_every == 0)
            or (limit is not None and self._steps == limit)
        ):
            pattern = self._pattern(trace)
            if pattern is not None:
                info["pattern"] = pattern
        if self.render_mode == "human":
            self.render()
        return obs, reward, terminated, False, info

    # ---- scoring (task/scoring.py) -------------------------------------------------------
    def _metrics(self, trace: np.ndarray) -> dict[str, Any]:
        """The score's metrics of the episode's trace (nodes from ``_n0`` on); the nodes
        that left the solve are frozen."""
        sim = self._sim
        n_frozen = sim.n_trace - sim.n_deposited - self._n0
        return self._score.update(trace[self._n0 :][:, [0, 2]], n_frozen)

    def _info(self, metrics: dict[str, Any], terms: dict[str, float], physics_steps: int,
              newton_iterations: int) -> dict[str, Any]:  # fmt: skip
        sim = self._sim
        score = float(np.sum(self._potentials))
        if self._failure is not None:
            score -= self.failure_penalty
        info: dict[str, Any] = dict(terms)
        info.update(
            score=score,
            coverage=metrics["coverage"],
            precision=metrics["precision"],
            progress=metrics["progress"],
            mean_distance=metrics["mean_distance"],
            n_laid=int(metrics["n_laid"]),
            laid_length=float(sim.deposited_length) - self._laid0,
            sim_time=float(sim.time) - self._t0,
            flow_vbar=float(self._flow[0]),
            flow_phi=float(self._flow[1]),
            target=self.target.name,
            target_length=self._target_length,
            is_success=bool(metrics["covered_end"]) and self._failure is None,
            physics_steps=int(physics_steps),
            newton_iterations=int(newton_iterations),
        )
        return info

    def _pattern(self, trace: np.ndarray) -> dict[str, Any] | None:
        """Pattern measures of the episode's trace (from the contact point at reset)."""
        pts = trace[self._n0 - 1 :]
        try:
            m = measure(pts, _MEASURE_OPTIONS, substrate=self.substrate, flow_direction=None)
        except ValueError:
            return None  # too short or degenerate to measure
        return {k: m[k] for k in _PATTERN_KEYS}

    # ---- observation (task/spaces.py, task/raster.py) -------------------------------------
    def _observation(self, trace: np.ndarray, metrics: dict[str, Any]) -> np.ndarray:
        sim = self._sim
        if self.obs_mode == "image":
            return raster.image_observation(
                self.image_size, self.image_extent, trace[:, [0, 2]], self._n0,
                self._target_abs, self._target_done(metrics), sim.suspended_nodes[:, [0, 2]],
            )  # fmt: skip
        m = self.n_target_points
        s_ahead = np.minimum(metrics["furthest"] + self.target_spacing * np.arange(1, m + 1),
                             self._target_length)  # fmt: skip
        ahead = np.column_stack([np.interp(s_ahead, self._target_s, self._target_abs[:, k])
                                 for k in (0, 1)])  # fmt: skip
        vbar, phi = self._flow
        flow = np.array([vbar * math.cos(phi), vbar * math.sin(phi)]) / self.vbar_max
        rod = rod_features(sim.suspended_nodes, trace[-1], self.lean_heights)
        laid_ratio = (float(sim.deposited_length) - self._laid0) / self._target_length
        progress = [metrics["progress"], metrics["coverage"], metrics["precision"], laid_ratio]
        return self.layout.build(trace, ahead, flow, rod, np.array(progress))

    def _target_done(self, metrics: dict[str, Any]) -> np.ndarray | None:
        """The target up to its furthest covered point (None before any)."""
        s = metrics["furthest"]
        return raster.path_head(self._target_abs, self._target_s, s) if s > 0 else None

    def render(self) -> np.ndarray | None:
        """Top view (uint8 (H, W, 3); :func:`cnt_env.task.raster.top_view`)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode=...")
            return None
        if self._sim is None:
            frame = np.full((self.render_size, self.render_size, 3), 255, dtype=np.uint8)
        else:
            frame = raster.top_view(
                self.render_size, self._sim.trace()[:, [0, 2]], self._n0, self._target_abs,
                self._target_done(self._last_metrics), self._sim.suspended_nodes[:, [0, 2]],
                self._flow, self.vbar_max, 4.0 * self.tolerance,
            )  # fmt: skip
        if self.render_mode == "rgb_array":
            return frame
        self._window.show(frame)
        return None

    def close(self) -> None:
        self._window.close()

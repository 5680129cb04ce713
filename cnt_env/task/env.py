"""``CNTDeposit-v0``: steer the gas flow so that a depositing CNT lays a target path.

The env only translates (docs/architecture.md rule 3): actions to a flow, the simulator's state to
observations, and the trace against the target to rewards. The physics lives in
:mod:`cnt_env.sim.deposition`; the warm start in :mod:`cnt_env.sim.warmstart`; the targets in
:mod:`cnt_env.task.targets`. See :class:`CNTDepositEnv` for the specification.
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
from cnt_env.presets import DEFAULT_KAPPA_C, ENV_SIM_DEFAULTS, mesh_for
from cnt_env.sim.deposition import DepositionConfig, DepositionSim
from cnt_env.sim.stepper import SimulationError
from cnt_env.sim.warmstart import flatten_snapshot, unflatten_snapshot, warm_state
from cnt_env.task import targets as targets_mod
from cnt_env.task.targets import Target
from cnt_env.units import DimensionlessParams, paper_groups

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
#: Bound (L_vb) of every position in the vector observation; values are clipped to it.
POSITION_BOUND = 1000.0
#: Bound of the laid-length / target-length ratio in the observation.
LAID_RATIO_BOUND = 100.0
#: Heights (L_vb) at which the lean of the suspended rod is observed: two absolute ones
#: near the contact, where the next trace is shaped, and fractions of Hbar.
LEAN_HEIGHTS = (2.0, 8.0)
LEAN_HEIGHT_FRACTIONS = (0.5, 1.0)
#: Largest spacing (L_vb) of the target samples used for coverage.
COVERAGE_SPACING = 0.5
OBS_MODES = ("vector", "image")
SUBSTRATES = ("flat", "stepped")
# Pattern measurements kept in info["pattern"] (patterns.measure keys).
_PATTERN_KEYS = ("pattern", "measured_length", "amplitude", "peak_to_peak", "wavelength",
                 "coil_radius", "n_uturns", "n_cycles", "n_loops", "n_self_crossings")  # fmt: skip
_REWARD_KEYS = ("reward_coverage", "reward_precision", "reward_progress", "reward_failure")
_MEASURE_OPTIONS = MeasureOptions(transient_length=0.0)


def flow_from_action(action: np.ndarray, vbar_max: float) -> tuple[float, float]:
    """Map a clipped action in [-1, 1]^2 to a flow ``(vbar, phi)``.

    The square is mapped onto the disk of radius ``vbar_max`` by the elliptical grid
    map u = a_x sqrt(1 - a_z^2 / 2), w = a_z sqrt(1 - a_x^2 / 2): smooth, one-to-one,
    the edges' midpoints and the corners all land on the rim. (u, w) are the flow's x and
    z components over ``vbar_max``.
    """
    ax, az = float(action[0]), float(action[1])
    u = ax * math.sqrt(1.0 - 0.5 * az * az)
    w = az * math.sqrt(1.0 - 0.5 * ax * ax)
    vbar = min(vbar_max * math.hypot(u, w), vbar_max)
    phi = math.atan2(w, u) if vbar > 0.0 else 0.0
    return vbar, phi


def _distances(points: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Distance from each point (p, 2) to the polyline ``vertices`` (n, 2)."""
    out = np.empty(len(points))
    targets_mod.polyline_distances(np.ascontiguousarray(points), vertices, out)
    return out


def _covered(samples: np.ndarray, points: np.ndarray, tol: float) -> np.ndarray:
    """Which samples (s, 2) lie within ``tol`` of any of ``points`` (p, 2)."""
    hit = np.zeros(len(samples), dtype=np.bool_)
    targets_mod.mark_covered(samples, np.ascontiguousarray(points), tol, hit)
    return hit


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
        families: Sequence[str] | None = None,
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
        self.params = _physics(preset, substrate, Hbar, Ibar, kappa_c_bar, delta_bar, vbar,
                               phi, physics)  # fmt: skip
        self.substrate = "flat" if self.params.kappa_c_bar is None else "stepped"
        # the preset's validated start-up radius and mesh, then the env's speed settings
        # (ENV_SIM_DEFAULTS), then the caller's options
        mesh = mesh_for(preset)
        cfg: dict[str, Any] = {"initial_radius": mesh["initial_radius"]}
        if delta_bar is None and mesh["coarse_delta"] is not None:
            cfg["coarse_delta"] = mesh["coarse_delta"]
        if self.params.kappa_c_bar is not None:
            cfg.update(ENV_SIM_DEFAULTS)
        cfg.update(sim_options or {})
        for name, value in (("dt", dt), ("coarse_delta", coarse_delta),
                            ("initial_radius", initial_radius)):  # fmt: skip
            if value is not None:
                cfg[name] = value
        self.config = DepositionConfig(params=self.params, drag_law=drag_law, **cfg)

        self.vbar_max = _positive("vbar_max", vbar_max)
        if self.params.vbar > self.vbar_max:
            raise ValueError(f"vbar = {self.params.vbar} exceeds vbar_max = {self.vbar_max}")
        # control interval (tau) and the derived number of physics steps
        # (docs/architecture.md rule 4)
        self.dt = self.config.time_step
        if control_interval is None:
            n = max(1, round(CONTROL_INTERVAL_HBAR * self.params.Hbar / self.dt))
            control_interval = n * self.dt
        self.control_interval = _positive("control_interval", control_interval)
        n = round(self.control_interval / self.dt)
        if n < 1 or abs(n * self.dt - self.control_interval) > 1e-9 * self.control_interval:
            raise ValueError(
                f"control_interval = {self.control_interval!r} must be a whole multiple of the "
                f"physics dt = {self.dt!r}; e.g. {max(n, 1) * self.dt!r}"
            )
        if n > MAX_SUBSTEPS:
            raise ValueError(f"control_interval needs {n} physics steps, more than {MAX_SUBSTEPS}")
        self.n_substeps = n

        self.warmup_length = float(self.params.Hbar if warmup_length is None else warmup_length)
        _non_negative("warmup_length", self.warmup_length)
        self.warmup_seed = int(warmup_seed)
        self.reset_advance = _non_negative("reset_advance", reset_advance)
        self.tolerance = _positive("tolerance", tolerance)
        self.n_trace_points = _count("n_trace_points", n_trace_points)
        self.n_target_points = _count("n_target_points", n_target_points)
        self.target_spacing = _positive("target_spacing", target_spacing)
        self.weights = np.array([_non_negative("coverage_weight", coverage_weight),
                                 _non_negative("precision_weight", precision_weight),
                                 _non_negative("progress_weight", progress_weight)])  # fmt: skip
        if not self.weights.sum() > 0:
            raise ValueError("at least one reward weight must be > 0")
        self.failure_penalty = _non_negative("failure_penalty", failure_penalty)
        self.families = tuple(targets_mod.FAMILIES) if families is None else tuple(families)
        for f in self.families:
            if f not in targets_mod.FAMILIES:
                raise ValueError(f"unknown training family {f!r}; choose from "
                                 f"{sorted(targets_mod.FAMILIES)}")  # fmt: skip
        if not self.families:
            raise ValueError("families must name at least one family")
        if obs_mode not in OBS_MODES:
            raise ValueError(f"obs_mode must be one of {OBS_MODES}, got {obs_mode!r}")
        self.obs_mode = obs_mode
        self.image_size = _count("image_size", image_size)
        if self.image_size < 64:
            raise ValueError(f"image_size must be >= 64, got {image_size}")
        self.image_extent = _positive("image_extent", image_extent)
        self.render_size = _count("render_size", render_size)
        if self.render_size < 16:
            raise ValueError(f"render_size must be >= 16, got {render_size}")
        if isinstance(pattern_every, bool) or not isinstance(pattern_every, (int, np.integer)):
            raise ValueError(f"pattern_every must be an int >= 0, got {pattern_every!r}")
        if pattern_every < 0:
            raise ValueError(f"pattern_every must be >= 0, got {pattern_every}")
        self.pattern_every = int(pattern_every)
        self.cache_dir = cache_dir
        self.lean_heights = LEAN_HEIGHTS + tuple(f * self.params.Hbar
                                                 for f in LEAN_HEIGHT_FRACTIONS)  # fmt: skip

        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        k, m = self.n_trace_points, self.n_target_points
        self.observation_structure: dict[str, int] = {
            "trace": 2 * k, "target": 2 * m, "flow": 2,
            "rod": 3 + 2 * len(self.lean_heights), "progress": 4,
        }  # fmt: skip
        self.observation_slices: dict[str, slice] = {}
        start = 0
        for name, size in self.observation_structure.items():
            self.observation_slices[name] = slice(start, start + size)
            start += size
        self._obs_low, self._obs_high = self._vector_bounds(start)
        if obs_mode == "vector":
            self.observation_space = spaces.Box(self._obs_low, self._obs_high, dtype=np.float32)
        else:
            s = self.image_size
            self.observation_space = spaces.Box(0, 255, shape=(s, s, 3), dtype=np.uint8)

        self._sim: DepositionSim | None = None
        self._warm: dict[str, np.ndarray] | None = None
        self.warm_start_source: str | None = None
        self._fig: Any = None
        self._image: Any = None

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

    # ---- spaces -----------------------------------------------------------------------
    def _vector_bounds(self, size: int) -> tuple[np.ndarray, np.ndarray]:
        low = np.full(size, -POSITION_BOUND, dtype=np.float32)
        high = np.full(size, POSITION_BOUND, dtype=np.float32)
        sl = self.observation_slices
        low[sl["flow"]], high[sl["flow"]] = -1.0, 1.0
        rod = sl["rod"]
        low[rod.start + 1 : rod.start + 3], high[rod.start + 1 : rod.start + 3] = -1.0, 1.0
        prog = sl["progress"]
        low[prog] = 0.0
        high[prog.start : prog.start + 3] = 1.0
        high[prog.start + 3] = LAID_RATIO_BOUND
        return low, high

    # ---- reset ------------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        options = dict(options or {})
        target_spec = options.pop("target", None)
        if options:
            raise ValueError(f"unknown reset options {sorted(options)}; only 'target' is known")
        if self._warm is None:
            snap, self.warm_start_source = warm_state(
                self.config, self.warmup_length, self.warmup_seed, self.cache_dir
            )
            self._warm = flatten_snapshot(snap)
            self._sim = DepositionSim(self.config, seed=self.warmup_seed)
        sim = self._sim
        assert sim is not None
        rng = self.np_random
        if target_spec is None:
            target = targets_mod.sample(rng, self.families)
        else:
            target = targets_mod.resolve(target_spec, rng)
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
        self._potentials = self._weighted(metrics)
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
        pts = target.points + self._origin
        self._target_abs = pts
        self._target_s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
        self._target_length = float(self._target_s[-1])
        spacing = min(COVERAGE_SPACING, 0.5 * self.tolerance)
        self._samples, s = targets_mod.resample(pts, spacing)
        self._sample_s = s
        w = np.zeros(len(s))
        w[:-1] += 0.5 * np.diff(s)
        w[1:] += 0.5 * np.diff(s)
        self._sample_w = w / w.sum()
        self._cov_frozen = np.zeros(len(s), dtype=bool)
        self._frozen_upto = self._n0
        self._n_in_frozen = 0
        self._dist_sum_frozen = 0.0
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
        a = np.clip(a, -1.0, 1.0)
        self._flow = flow_from_action(a, self.vbar_max)
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
        potentials = self._weighted(metrics)
        obs = self._observation(trace, metrics)
        if self._failure is None and not np.all(np.isfinite(obs)):
            self._failure = "non-finite simulator state"
        if self._failure is not None:
            obs = np.nan_to_num(obs, nan=0.0, posinf=0.0, neginf=0.0)
            if obs.dtype != np.uint8:
                obs = np.clip(obs, self._obs_low, self._obs_high).astype(np.float32)
            potentials = self._potentials  # a failed state scores nothing new
        delta = potentials - self._potentials
        self._potentials = potentials
        terms = {
            "reward_coverage": float(delta[0]),
            "reward_precision": float(delta[1]),
            "reward_progress": float(delta[2]),
            "reward_failure": -self.failure_penalty if self._failure is not None else 0.0,
        }
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

    # ---- scoring ----------------------------------------------------------------------
    def _metrics(self, trace: np.ndarray) -> dict[str, Any]:
        """Coverage, precision, progress and distances of the episode's trace (nodes with
        index >= n0). Nodes that left the solve never move again, so their contribution
        is accumulated once; the deposited nodes still in the solve (they may slide on
        the stepped substrate) are re-measured every step."""
        sim = self._sim
        tol = self.tolerance
        frozen_end = max(self._n0, min(len(trace), sim.n_trace - sim.n_deposited))
        if frozen_end > self._frozen_upto:
            new = trace[self._frozen_upto : frozen_end][:, [0, 2]]
            d = _distances(new, self._target_abs)
            self._n_in_frozen += int(np.count_nonzero(d <= tol))
            self._dist_sum_frozen += float(d.sum())
            self._cov_frozen |= _covered(self._samples, new, tol)
            self._frozen_upto = frozen_end
        tail = trace[frozen_end:][:, [0, 2]]
        d_tail = _distances(tail, self._target_abs)
        covered = self._cov_frozen | _covered(self._samples, tail, tol)
        n_laid = len(trace) - self._n0
        n_in = self._n_in_frozen + int(np.count_nonzero(d_tail <= tol))
        hit = np.flatnonzero(covered)
        return {
            "coverage": float(np.dot(self._sample_w, covered)),
            "precision": n_in / n_laid if n_laid > 0 else 0.0,
            "progress": float(self._sample_s[hit[-1]] / self._target_length) if hit.size else 0.0,
            "furthest": float(self._sample_s[hit[-1]]) if hit.size else 0.0,
            "covered_end": bool(covered[-1]),
            "mean_distance": (self._dist_sum_frozen + float(d_tail.sum())) / n_laid
            if n_laid > 0 else 0.0,
            "n_laid": n_laid,
        }  # fmt: skip

    def _weighted(self, metrics: dict[str, Any]) -> np.ndarray:
        return self.weights * np.array(
            [metrics["coverage"], metrics["precision"], metrics["progress"]]
        )

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

    # ---- observation --------------------------------------------------------------------
    def _observation(self, trace: np.ndarray, metrics: dict[str, Any]) -> np.ndarray:
        if self.obs_mode == "image":
            return self._image_obs(trace, metrics)
        sim = self._sim
        contact3 = trace[-1]
        contact = contact3[[0, 2]]
        k, m = self.n_trace_points, self.n_target_points
        past = trace[max(0, len(trace) - 1 - k) : len(trace) - 1][:, [0, 2]] - contact
        if len(past) == 0:
            past = np.zeros((1, 2))
        if len(past) < k:
            past = np.concatenate([np.repeat(past[:1], k - len(past), axis=0), past])
        s_ahead = np.minimum(metrics["furthest"] + self.target_spacing * np.arange(1, m + 1),
                             self._target_length)  # fmt: skip
        ahead = np.column_stack([
            np.interp(s_ahead, self._target_s, self._target_abs[:, 0]),
            np.interp(s_ahead, self._target_s, self._target_abs[:, 1]),
        ]) - contact  # fmt: skip
        vbar, phi = self._flow
        flow = np.array([vbar * math.cos(phi), vbar * math.sin(phi)]) / self.vbar_max
        rod = self._rod_features(sim.suspended_nodes, contact3)
        laid_ratio = (float(sim.deposited_length) - self._laid0) / self._target_length
        progress = [metrics["progress"], metrics["coverage"], metrics["precision"], laid_ratio]
        obs = np.concatenate([past.ravel(), ahead.ravel(), flow, rod, progress])
        return np.clip(obs, self._obs_low, self._obs_high).astype(np.float32)

    def _rod_features(self, nodes: np.ndarray, contact3: np.ndarray) -> np.ndarray:
        """Contact height, contact-edge direction, and the rod's horizontal offset at
        the lean heights, relative to the contact point."""
        out = np.zeros(3 + 2 * len(self.lean_heights))
        if len(nodes) == 0:
            return out
        c = nodes[0]
        out[0] = c[1]
        h = np.array([c[0] - contact3[0], c[2] - contact3[2]])
        norm = math.hypot(h[0], h[1])
        out[1:3] = h / norm if norm > 1e-12 else (1.0, 0.0)
        ys = nodes[:, 1]
        for j, height in enumerate(self.lean_heights):
            above = np.flatnonzero(ys >= height)
            if above.size == 0:
                p = nodes[-1]
            elif above[0] == 0:
                p = nodes[0]
            else:
                i = above[0]
                y0, y1 = ys[i - 1], ys[i]
                t = (height - y0) / (y1 - y0) if y1 > y0 else 1.0
                p = nodes[i - 1] + t * (nodes[i] - nodes[i - 1])
            out[3 + 2 * j] = p[0] - contact3[0]
            out[4 + 2 * j] = p[2] - contact3[2]
        return out

    # ---- rasters ------------------------------------------------------------------------
    def _image_obs(self, trace: np.ndarray, metrics: dict[str, Any]) -> np.ndarray:
        s = self.image_size
        img = np.zeros((s, s, 3), dtype=np.uint8)
        scale = s / self.image_extent  # pixels per L_vb
        centre = trace[-1, [0, 2]]

        def px(points: np.ndarray) -> np.ndarray:
            return (points - centre) * scale + 0.5 * s

        xz = trace[:, [0, 2]]
        _draw(img, px(xz[: self._n0]), 128, channel=0)
        _draw(img, px(xz[self._n0 - 1 :]), 255, channel=0)
        covered_to = metrics["furthest"]
        _draw(img, px(self._target_abs), 255, channel=1)
        if covered_to > 0:
            _draw(img, px(self._covered_part(covered_to)), 128, channel=1)
        _draw(img, px(self._sim.suspended_nodes[:, [0, 2]]), 255, channel=2)
        return img

    def _covered_part(self, s: float) -> np.ndarray:
        """The target from its start to arc length s."""
        cut = int(np.searchsorted(self._target_s, s, side="right"))
        head = [np.interp(s, self._target_s, self._target_abs[:, k]) for k in (0, 1)]
        return np.concatenate([self._target_abs[:cut], [head]])

    def render(self) -> np.ndarray | None:
        """Top view (uint8 (H, W, 3)): target (red, dark up to the furthest covered
        point), earlier trace (grey),
        this episode's trace (blue), the suspended rod's projection (green), the contact
        point (black) and the flow (arrow in the corner, length v̄ / v̄_max)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode=...")
            return None
        if self._sim is None:
            frame = np.full((self.render_size, self.render_size, 3), 255, dtype=np.uint8)
        else:
            frame = self._frame()
        if self.render_mode == "rgb_array":
            return frame
        self._show(frame)
        return None

    def _frame(self) -> np.ndarray:
        n = self.render_size
        img = np.full((n, n, 3), 255, dtype=np.uint8)
        trace = self._sim.trace()
        xz = trace[:, [0, 2]]
        rod = self._sim.suspended_nodes[:, [0, 2]]
        recent = xz[max(0, self._n0 - 50) :]
        box = np.concatenate([self._target_abs, recent, rod])
        lo, hi = box.min(axis=0), box.max(axis=0)
        centre = 0.5 * (lo + hi)
        extent = 1.15 * max(float(np.max(hi - lo)), 4.0 * self.tolerance)
        scale = n / extent

        def px(points: np.ndarray) -> np.ndarray:
            return (points - centre) * scale + 0.5 * n

        metrics = self._last_metrics
        _draw(img, px(self._target_abs), (240, 150, 150), width=2)
        if metrics["furthest"] > 0:
            _draw(img, px(self._covered_part(metrics["furthest"])), (190, 30, 30), width=2)
        _draw(img, px(xz[: self._n0]), (170, 170, 170))
        _draw(img, px(xz[self._n0 - 1 :]), (30, 80, 220), width=2)
        _draw(img, px(rod), (40, 160, 40))
        _draw(img, px(xz[-1:]), (0, 0, 0), width=3)
        # flow arrow in the lower-left corner
        vbar, phi = self._flow
        base = np.array([0.1 * n, 0.1 * n])
        tip = base + (0.08 * n * vbar / self.vbar_max) * np.array([math.cos(phi), math.sin(phi)])
        _draw(img, np.array([base, tip]), (0, 0, 0), width=2)
        return img

    def _show(self, frame: np.ndarray) -> None:
        import matplotlib
        import matplotlib.pyplot as plt

        if self._fig is None:
            self._fig, ax = plt.subplots(figsize=(5, 5))
            ax.set_axis_off()
            self._image = ax.imshow(frame)
        else:
            self._image.set_data(frame)
        backend = matplotlib.get_backend().lower()
        try:
            from matplotlib.backends import BackendFilter, backend_registry

            interactive = backend not in backend_registry.list_builtin(
                BackendFilter.NON_INTERACTIVE
            )
        except ImportError:  # older matplotlib
            interactive = backend not in ("agg", "pdf", "ps", "svg", "cairo", "pgf", "template")
        if interactive:
            plt.pause(1.0 / self.metadata["render_fps"])
        else:
            self._fig.canvas.draw()

    def close(self) -> None:
        if self._fig is not None:
            import matplotlib.pyplot as plt

            plt.close(self._fig)
            self._fig = None
            self._image = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_fig"] = None
        state["_image"] = None
        return state


# ---- helpers ----------------------------------------------------------------------------


def _draw(img: np.ndarray, points: np.ndarray, color: int | tuple[int, int, int],
          width: int = 1, channel: int | None = None) -> None:  # fmt: skip
    """Rasterise the polyline ``points`` (pixel coordinates (col, row-from-bottom)) into
    ``img`` (rows top-down), clipped to the image, ``width`` pixels wide: every channel
    set to ``color``, or only ``channel`` set to the value ``color``."""
    if len(points) == 0:
        return
    h, w = img.shape[:2]
    if len(points) == 1:
        samples = points
    else:
        seg = np.diff(points, axis=0)
        n_sub = np.maximum(1, np.ceil(2.0 * np.max(np.abs(seg), axis=1)).astype(np.int64))
        n_sub = np.minimum(n_sub, 4 * (h + w))  # a segment far longer than the view
        k = np.arange(int(n_sub.sum())) - np.repeat(np.cumsum(n_sub) - n_sub, n_sub)
        t = k / np.repeat(n_sub, n_sub)
        samples = np.repeat(points[:-1], n_sub, axis=0) + t[:, None] * np.repeat(seg, n_sub, 0)
        samples = np.concatenate([samples, points[-1:]])
    cols = np.floor(samples[:, 0]).astype(np.int64)
    rows = h - 1 - np.floor(samples[:, 1]).astype(np.int64)
    lo = -(width // 2)
    for dr in range(lo, lo + width):
        for dc in range(lo, lo + width):
            r, c = rows + dr, cols + dc
            ok = (r >= 0) & (r < h) & (c >= 0) & (c < w)
            if channel is None:
                img[r[ok], c[ok]] = color
            else:
                img[r[ok], c[ok], channel] = color


def _physics(
    preset: str,
    substrate: str | None,
    Hbar: float | None,
    Ibar: float | None,
    kappa_c_bar: float | None,
    delta_bar: float | None,
    vbar: float | None,
    phi: float | None,
    physics: Mapping[str, Any] | None,
) -> DimensionlessParams:
    """The dimensionless groups: the preset's, with the keywords on top."""
    base = paper_groups(preset)
    if substrate is None:
        substrate = "flat" if base.kappa_c_bar is None else "stepped"
    if substrate not in SUBSTRATES:
        raise ValueError(f"substrate must be one of {SUBSTRATES}, got {substrate!r}")
    overrides: dict[str, Any] = dict(physics or {})
    for name, value in (("Hbar", Hbar), ("Ibar", Ibar), ("delta_bar", delta_bar),
                        ("vbar", vbar), ("phi", phi)):  # fmt: skip
        if value is not None:
            overrides[name] = value
    if substrate == "flat":
        if kappa_c_bar is not None:
            raise ValueError("kappa_c_bar applies to the stepped substrate; pass "
                             "substrate='stepped' or drop kappa_c_bar")  # fmt: skip
        overrides["kappa_c_bar"] = None
    else:
        default = base.kappa_c_bar if base.kappa_c_bar is not None else DEFAULT_KAPPA_C
        overrides["kappa_c_bar"] = default if kappa_c_bar is None else kappa_c_bar
    return paper_groups(preset, **overrides)


def _positive(name: str, value: Any) -> float:
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return v


def _non_negative(name: str, value: Any) -> float:
    v = float(value)
    if not (math.isfinite(v) and v >= 0):
        raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
    return v


def _count(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be an int >= 1, got {value!r}")
    return int(value)

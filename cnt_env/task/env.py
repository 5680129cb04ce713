"""``CNTDeposit-v0``: steer the gas flow so that a depositing CNT lays a circuit route.

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
from cnt_env.presets import MODEL
from cnt_env.sim.deposition import DepositionSim, z_mirrored
from cnt_env.sim.forces import DRAG_LAWS
from cnt_env.sim.stepper import SimulationError
from cnt_env.sim.warmstart import flatten_snapshot, unflatten_snapshot, warm_state
from cnt_env.task import raster, routes, settings
from cnt_env.task import targets as targets_mod
from cnt_env.task.geometry import nearest_on_polygons
from cnt_env.task.routes import DEFAULT_HALF_WIDTH, Route
from cnt_env.task.scoring import (
    COVERAGE_SPACING,
    ROUTE_TERMS,
    ThinScore,
    pattern_measures,
    route_score,
)
from cnt_env.task.spaces import (
    LAID_RATIO_BOUND,
    LEAN_HEIGHT_FRACTIONS,
    LEAN_HEIGHTS,
    POSITION_BOUND,
    ObservationLayout,
    flow_from_action,
    rod_features,
)

__all__ = ["DEFAULT_MAX_EPISODE_STEPS", "CNTDepositEnv", "flow_from_action"]

#: Default speed cap of the flow, in units of e_v / (mu H) (the paper's range, docs/model.md §6).
DEFAULT_VBAR_MAX = 0.13
#: The default control interval is this many Hbar (time units tau), rounded to whole
#: physics steps, per score mode. The deposition speed is ~0.80 L_vb / Hbar. "thin" (v0):
#: ~1.2 L_vb of trace. "corridor": ~24 L_vb, no more than the median trace laid before
#: the suspended rod leans the new way after a switch of the flow direction (23-27 L_vb
#: when chosen; 28-44, then 15-20 with the lagged Jacobian, 9-31 with the env's mesh,
#: re-measured on the shipped simulator, noisy medians over six switches:
#: benchmarks/results/step_response_surrogate.json, docs/task.md), so the agent never
#: acts faster than the rod can follow; the pattern's drift follows in a few intervals.
CONTROL_INTERVAL_HBAR = {"thin": 1.5, "corridor": 30.0}
#: Trace window (L_vb) the K trace points of the observation span in the route task:
#: about the 60 L_vb whose mean is the pattern's centre.
ROUTE_TRACE_WINDOW = 64.0
SCORES = ("corridor", "thin")
#: ``start_mirror``: whether an episode starts from the warm state's mirror image in z.
START_MIRROR = ("never", "always", "random")
#: Episode length registered with ``max_episode_steps`` (TimeLimit; its one home is
#: cnt_env/__init__.py): ~400 L_vb of trace, about 4 periods of the baseline serpentine
#: (benchmarks/env_throughput.py --baseline: amplitude ~24, wavelength ~7.7, ~95 L_vb of
#: trace per period under the paper's constant flow).
DEFAULT_MAX_EPISODE_STEPS = MAX_EPISODE_STEPS
#: Most physics steps one control step may take.
MAX_SUBSTEPS = 100_000
#: ``obs_mode``: "dict" gives both, ``{"image": ..., "vector": ...}`` (SB3's
#: MultiInputPolicy).
OBS_MODES = ("vector", "image", "dict")
IMAGE_LAYERS = ("route", "path")
#: How render() draws (the env's ``render_style``).
RENDER_STYLES = ("figure", "raster")
_REWARD_KEYS = {
    "thin": ("reward_coverage", "reward_precision", "reward_progress", "reward_failure"),
    "corridor": (*(f"reward_{t}" for t in ROUTE_TERMS), "reward_failure"),
}
# re-exported for callers of the v0 layout
__all__ += ["COVERAGE_SPACING", "LAID_RATIO_BOUND", "POSITION_BOUND"]


class CNTDepositEnv(gym.Env[np.ndarray, np.ndarray]):
    r"""Flow-directed deposition of a carbon nanotube along a target circuit route.

    ## Description

    A carbon nanotube (CNT), modelled as a discrete elastic rod of height H̄, is fed from
    the top and falls onto a substrate (the x-z plane, y up), where van der Waals
    adhesion makes it stick (docs/model.md §1, §4). The shape it leaves, the *trace*, is a
    coil on a flat sticky substrate and a serpentine on a stepped one with flow (§5-6).
    The agent sets the rarefied gas flow in the substrate plane every control interval.
    The flow steers the pattern's *drift*: on the default physics (the model), across
    the steps (±x) a serpentine band ~33-40 L_vb wide drifts 0.17-0.30 L_vb per L_vb of
    trace at v̄ 0.065-0.13; along them (±z) an almost straight run drifts 0.82-1.0
    (benchmarks/results/step_response.json; the fast surrogate's figures, on which the
    task's widths and rates were set, are in docs/task.md).

    The task (``score="corridor"``, default; docs/task.md): lay the trace along a circuit
    route (:class:`~cnt_env.task.routes.Route`): waypoints from the contact point, a
    corridor of half-width w (default 18.5 L_vb), optional pads to cross and keep-out
    regions to avoid. ``score="thin"`` keeps the v0 task: follow a thin polyline within
    τ_b = ``tolerance`` (:mod:`cnt_env.task.targets`).

    Units (docs/model.md §2): lengths in L_vb = sqrt(k_b / e_v), time in
    tau = mu L_vb² / e_v, flow speeds v̄ in e_v / (mu H).

    ## Action Space

    ``Box(-1, 1, (2,), float32)``: the flow (x, z) / v̄_max, mapped one-to-one onto the
    disk of radius ``vbar_max`` (elliptical grid map, :func:`flow_from_action`; inverse
    :func:`cnt_env.task.spaces.action_from_flow`). Out-of-range actions are clipped (past a
    bound acts exactly like the bound); a NaN or infinite action raises ``ValueError`` and
    leaves the env untouched. The flow is held for ``control_interval`` (tau), simulated
    as ``n_substeps`` physics steps of ``dt``. Default: 30 H̄ (~24 L_vb of trace) for
    routes, about the trace laid before the suspended rod leans the new way after a
    switch of direction (step response: 23-27 L_vb when chosen; a median 9-31 on the
    shipped simulator, noisy, single switches 1-160; docs/task.md); 1.5 H̄ (~1.2 L_vb)
    for ``score="thin"``.

    ## Observation Space

    ``obs_mode="vector"`` (default): a flat float32 ``Box`` with finite bounds, in order
    (``observation_structure`` sizes, ``observation_slices`` slices; K =
    ``n_trace_points``, M = ``n_target_points``, 16 each: 84 values for routes, 81 thin).
    Positions are (x, z) relative to the contact point (the last deposited node), clipped
    to ±1000 L_vb.

    | Slice    | Size | Observation                                           | Bounds  | Unit |
    |----------|------|-------------------------------------------------------|---------|------|
    | trace    | 2K   | routes: K points evenly spaced over the last          | ±1000   | L_vb |
    |          |      | ``trace_window`` (64) L_vb of trace (their mean is    |         |      |
    |          |      | the pattern's centre); thin: the last K nodes         |         |      |
    | target   | 2M   | M route points ahead of the furthest point reached,   | ±1000   | L_vb |
    |          |      | ``target_spacing`` apart (the end repeats)            |         |      |
    | flow     | 2    | current flow (v̄ cos φ, v̄ sin φ) / v̄_max               | ±1      | 1    |
    | rod      | 1    | height y_c of the contact node                        | ±1000   | L_vb |
    |          | 2    | horizontal unit direction of the contact edge         | ±1      | 1    |
    |          | 8    | rod's horizontal offset at heights 2, 8, H̄/2, H̄       | ±1000   | L_vb |
    | progress | 3    | progress G, coverage, precision (inside fraction)     | [0, 1]  | 1    |
    |          | 1    | length laid this episode / target length              | [0, 100]| 1    |
    | route    | 1    | corridor half-width w (routes only)                   | [0,1000]| L_vb |
    |          | 2    | nearest keep-out boundary point (1000 when none)      | ±1000   | L_vb |

    ``obs_mode="image"``: ``Box(0, 255, (S, S, 3), uint8)``, S = ``image_size`` (>= 64), a
    top view ``image_extent`` L_vb square centred on the contact point (x right, z up):
    channel 0 the trace (255 this episode, 128 before), 1 the target (128 where reached),
    2 the suspended rod (:mod:`cnt_env.task.raster`). Routes with ``image_layers="route"``
    (the default) also show, beneath those, the corridor in channel 1 (64) and the
    keep-outs (96, filled) and pads (160; rectangles when ``pad_width`` > 0) in channel 2;
    ``"path"`` leaves them out (the image before 2026-12-07).

    ``obs_mode="dict"``: ``Dict({"image": <the image>, "vector": <the vector>})``, both as
    above, for policies that take several inputs (SB3's ``MultiInputPolicy``: a CNN on
    the image, the vector flattened beside it).

    ## Rewards

    Potential-based: each step pays the change in a score Φ, so the return of an episode
    is its final score (Φ = 0 at reset). Every term is in ``info`` as ``reward_<term>``
    and ``reward == sum(info["reward_*"])``; ``info["score"]`` is Φ.

    Routes (:class:`~cnt_env.task.scoring.RouteScore`): G = furthest arc length reached by
    trace inside the corridor / route length; P = pads met / pads (crossed, or entered as
    rectangles with the route's ``pad_width`` > 0); C = 1 once G = 1;
    o = fraction of the episode's trace nodes outside the corridor; L_s = length of trace
    in keep-outs (L_vb). A = (0.8 G + 0.2 P + 0.2 C) / (0.8 + 0.2 [pads] + 0.2),
    Φ = A (1 - o)(1 - min(1, 0.05 L_s)) ∈ [0, 1]; terms ``progress``, ``pads``,
    ``completion``, ``outside`` (-A o), ``short`` (-A (1 - o) min(1, 0.05 L_s)).

    Thin (:class:`~cnt_env.task.scoring.ThinScore`): coverage C (target length within τ_b
    of the trace), precision P (trace nodes within τ_b), progress G; Φ = w_c C + w_p P +
    w_g G with ``coverage_weight``, ``precision_weight``, ``progress_weight``.

    A simulation failure adds ``reward_failure = -failure_penalty`` once.

    ``info`` also holds ``coverage``, ``precision``, ``progress``, ``mean_distance``
    (L_vb), ``n_laid``, ``laid_length``, ``sim_time``, ``flow_vbar``, ``flow_phi``,
    ``target``, ``target_length``, ``is_success``, ``physics_steps``,
    ``newton_iterations``; routes: ``inside``, ``outside``, ``shorts`` (nodes in
    keep-outs), ``short_length`` (L_vb), ``pads_crossed``, ``n_pads``, ``completed``,
    ``route_width``, ``max_episode_steps``; and every
    ``pattern_every`` steps and at the end, ``info["pattern"]`` (pattern measures,
    :func:`cnt_env.patterns.measure`).

    ## Starting State

    A warm state per configuration (the simulator after ``warmup_length`` L_vb of trace
    with the configured flow ``vbar``, ``phi``), computed once, cached on disk
    (``cache_dir``, ``$CNT_ENV_CACHE_DIR`` or the user cache) and restored exactly at every
    reset (with ``start_mirror``, its mirror image in z under the mirrored flow;
    ``info["start_mirrored"]``; with a ``flow_gain`` range, the episode's gain is drawn,
    ``info["flow_gain"]``); then a random advance in [0, ``reset_advance`` ·
    ``control_interval``). The
    target is placed at the contact point: drawn from ``families`` at ``difficulty`` with
    ``np_random`` (or, with ``route_file``, one of that file's routes, uniformly), or
    ``reset(options={"target": ...})``: a family or held-out name, a
    Route, a dict ``{"waypoints", "width", "pads", "pad_width", "keepouts", "name"}``, or an (n, 2)
    polyline (corridor ``route_width``). A bad target (say zero length) raises
    ``ValueError`` before anything changes.

    ## Episode End

    Termination: the route is completed (``info["completed"]``; thin: the target's end is
    covered), or the simulation failed (``info["failure"]``; the observation stays finite,
    stepping again repeats the terminal step with reward 0). ``info["is_success"]`` (read
    by SB3's Monitor and EvalCallback) is stricter than termination: the route completed
    with every pad met and no trace in a keep-out (a completed but shorted route is not a
    success), and no failure; thin: the end covered.

    Truncation: routes end after ``max_episode_steps`` (set at reset,
    :meth:`episode_steps_for`): 1.5 · route length / (``routes.PROGRESS_RATE`` = 0.17
    L_vb per L_vb · trace per step) + 10, 83 steps for the held-out ``u_turn`` (197
    L_vb). ``gymnasium.make`` also wraps the env
    in a ``TimeLimit`` of 400 steps (the thin task's ~400 L_vb).

    ## Arguments

    | Parameter          | Default      | Description                                     |
    |--------------------|--------------|-------------------------------------------------|
    | `render_mode`      | None         | "rgb_array" or "human"                          |
    | `preset`           | "serpentine" | paper groups (units.paper_groups) or "coil"     |
    | `substrate`        | preset's     | "stepped" or "flat" (flat: κ̄_c = None)          |
    | `Hbar`, `Ibar`     | preset's     | rod height (L_vb), mass per length              |
    | `kappa_c_bar`      | 0.2          | critical curvature (stepped only; 1/L_vb)       |
    | `delta_bar`        | 0.2          | discretisation length (L_vb; presets.MESH)      |
    | `vbar`, `phi`      | preset's     | warm-start flow (simulated): speed, angle (rad) |
    | `physics`          | None         | other DimensionlessParams fields (dict)         |
    | `dt`               | 0.2/0.1 H̄    | stepped/flat time step (tau); ENV_SIM_DEFAULTS  |
    | `coarse_delta`     | 6.0          | graded mesh (DepositionConfig); ENV_MESH        |
    | `initial_radius`   | preset's     | start-up arc radius (L_vb)                      |
    | `drag_law`         | "linear"     | "linear" or "printed" (presets.MODEL)           |
    | `sim_options`      | None         | other DepositionConfig fields (dict); e.g.      |
    |                    |              | {"contact": {"adhesion": "cohesive"}}           |
    | `vbar_max`         | 0.13         | flow speed cap (e_v / (mu H))                   |
    | `flow_gain`        | 1.0          | simulated / commanded flow speed (calibrates a  |
    |                    |              | surrogate's kinematics to the model's); or      |
    |                    |              | [lo, hi]: each episode's own, log-uniformly     |
    |                    |              | (np_random; info["flow_gain"] at reset)         |
    | `control_interval` | 30 / 1.5 H̄   | simulated time per step (tau), whole dt's       |
    | `warmup_length`    | H̄            | trace laid to reach the warm state (L_vb)       |
    | `warmup_seed`      | 0            | seed of the start-up perturbation (int >= 0)    |
    | `reset_advance`    | 4.0          | max random advance at reset (control intervals) |
    | `start_mirror`     | "never"      | start from the warm state's mirror image in z   |
    |                    |              | (and its flow, phi -> -phi): "never", "always"  |
    |                    |              | or "random" (half the resets, np_random)        |
    | `score`            | "corridor"   | "corridor" (routes) or "thin" (v0 polylines)    |
    | `route_width`      | 18.5         | corridor half-width of bare polylines (L_vb)    |
    | `difficulty`       | 0.5          | route length, turns, narrowness, in [0, 1]; or  |
    |                    |              | [lo, hi]: each drawn route's own, uniformly     |
    | `families`         | all          | families drawn uniformly; repeat one to weight  |
    | `route_file`       | None         | draw your own routes instead of `families`      |
    |                    |              | (routes.load_file; JSON/YAML; docs/task.md)     |
    | `trace_window`     | 64 / None    | span of the observed trace points (L_vb)        |
    | `tolerance`        | 2.0          | thin: tolerance band τ_b (L_vb)                 |
    | `n_trace_points`   | 16           | K                                               |
    | `n_target_points`  | 16           | M                                               |
    | `target_spacing`   | 2.0          | spacing of the observed target points (L_vb)    |
    | `coverage_weight`  | 0.5          | thin: w_c                                       |
    | `precision_weight` | 0.25         | thin: w_p                                       |
    | `progress_weight`  | 0.25         | thin: w_g                                       |
    | `failure_penalty`  | 1.0          | paid once on a simulation failure               |
    | `obs_mode`         | "vector"     | "vector", "image" or "dict" (both)              |
    | `image_size`       | 64           | S of the image observation (>= 64 pixels)       |
    | `image_extent`     | 64.0         | side of the image observation (L_vb)            |
    | `image_layers`     | "route"      | "route": the image shows the corridor, pads and |
    |                    |              | keep-outs; "path": only the route's line        |
    | `render_size`      | 512          | side of the rendered frame (pixels)             |
    | `render_style`     | "figure"     | "figure": fixed extent per episode, legend,     |
    |                    |              | scale bar (L_vb, µm), matplotlib; "raster":     |
    |                    |              | numpy lines, fitted each frame, ~10x faster     |
    | `pattern_every`    | 50           | steps between pattern measures (0: at the end)  |
    | `cache_dir`        | None         | warm-state cache directory                      |

    ## Version History

    * v0, revision 5 (issue 12's model): the default physics is the model on a fine mesh
      (``presets.MODEL`` and ``MESH``: the linear drag law on a rod of delta_bar = 0.2)
      instead of the printed law at delta_bar = 1, which stays as the fast surrogate
      (``presets.SURROGATE``: ``drag_law="printed", delta_bar=1.0``, 13.8x the trace per
      CPU-second on the serpentine, 4.1x on the coil) that training/configs train on;
      rollouts differ from revision 4's.
    * v0, revision 4 (simulator speed and robustness): the env's suspended rod is graded
      more coarsely than the model's (``presets.ENV_MESH``: ``coarse_delta`` 6 within
      ``fine_length`` 10, against ``presets.MESH``'s 4 / 20; serpentine A and lambda
      within 0.75%, the coil's R0 +0.23%), a step that turns an edge past 30 deg is
      halved, and Newton keeps a step's soft Jacobian blocks (``presets.NEWTON``):
      203.8 -> 361.2 L_vb of trace per CPU-second (stepped) and 166.2 -> 326.7 (flat)
      (RESULTS.md, issue 11); rollouts differ from revision 3's.
      ``sim_options={"coarse_delta": 4.0, "fine_length": 20.0}`` gives the model's mesh.
    * v0, revision 3 (simulator speed): the suspended rod is graded (``coarse_delta`` 4,
      ``fine_length`` 20) and Newton stops at 1e-5 e_v, on both substrates
      (now the model's own defaults, ``presets.MESH`` and ``presets.NEWTON``; this note
      keeps its history): ~2x (stepped) and ~3.7x (flat) the trace per
      CPU-second, pattern figures within ~1%; rollouts differ from revision 2's.
      ``sim_options={"coarse_delta": None, "newton": {"residual_tol": 1e-8}}`` gives
      revision 2's simulator.
    * v0, revision 2 (route task): ``score="corridor"`` by default: circuit routes with a
      corridor, pads and keep-outs (docs/task.md), the corridor score, per-route
      ``max_episode_steps`` and termination on completion, a control interval of 30 H̄
      from the measured step response, the trace observed over its last 64 L_vb, the
      corridor width observed. ``score="thin"`` is the v0 task unchanged.
    * v0: initial version (thin polylines, ~1 L_vb per step).
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
        drag_law: str = MODEL["drag_law"],
        sim_options: Mapping[str, Any] | None = None,
        vbar_max: float = DEFAULT_VBAR_MAX,
        flow_gain: float | Sequence[float] = 1.0,
        control_interval: float | None = None,
        warmup_length: float | None = None,
        warmup_seed: int = 0,
        reset_advance: float = 4.0,
        start_mirror: str = "never",
        tolerance: float = 2.0,
        n_trace_points: int = 16,
        n_target_points: int = 16,
        target_spacing: float = 2.0,
        coverage_weight: float = 0.5,
        precision_weight: float = 0.25,
        progress_weight: float = 0.25,
        failure_penalty: float = 1.0,
        families: Sequence[str] | str | None = None,
        route_file: str | None = None,
        score: str = "corridor",
        route_width: float = DEFAULT_HALF_WIDTH,
        difficulty: float | Sequence[float] = routes.DEFAULT_DIFFICULTY,
        trace_window: float | None = None,
        obs_mode: str = "vector",
        image_size: int = 64,
        image_extent: float = 64.0,
        image_layers: str = "route",
        render_size: int = 512,
        render_style: str = "figure",
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
            preset, self.params, s.choice("drag_law", drag_law, tuple(DRAG_LAWS)),
            sim_options, dt=dt, coarse_delta=coarse_delta, initial_radius=initial_radius,
        )  # fmt: skip
        self.vbar_max = s.positive("vbar_max", vbar_max)
        gain = s.gain_value(flow_gain)
        #: The range each episode draws its gain from (None: the gain is fixed).
        self.flow_gain_range: tuple[float, float] | None = gain if isinstance(gain, tuple) else None
        #: The episode's gain (the range's low end before the first reset).
        self.flow_gain = gain[0] if isinstance(gain, tuple) else gain
        if self.params.vbar > self.vbar_max * self.flow_gain:
            raise ValueError(f"vbar = {self.params.vbar} exceeds vbar_max x flow_gain = "
                             f"{self.vbar_max * self.flow_gain}")  # fmt: skip
        self.dt = self.config.time_step
        self.score_mode = s.choice("score", score, SCORES)
        self.control_interval, self.n_substeps = self._substeps(control_interval)
        self.warmup_length = s.non_negative(
            "warmup_length", self.params.Hbar if warmup_length is None else warmup_length
        )
        self.warmup_seed = s.seed("warmup_seed", warmup_seed)
        self.reset_advance = s.non_negative("reset_advance", reset_advance)
        self.start_mirror = s.choice("start_mirror", start_mirror, START_MIRROR)
        self.tolerance = s.positive("tolerance", tolerance)
        self.target_spacing = s.positive("target_spacing", target_spacing)
        self.weights = np.array([s.non_negative("coverage_weight", coverage_weight),
                                 s.non_negative("precision_weight", precision_weight),
                                 s.non_negative("progress_weight", progress_weight)])  # fmt: skip
        if not self.weights.sum() > 0:
            raise ValueError("at least one reward weight must be > 0")
        self.failure_penalty = s.non_negative("failure_penalty", failure_penalty)
        self.families = s.families_tuple(families, routes.families_of(self.score_mode))
        #: Routes drawn instead of the families (``route_file``), in the file's order.
        self.route_pool: tuple[Route, ...] = ()
        if route_file is not None:
            if self.score_mode != "corridor":
                raise ValueError("route_file needs the route task (score='corridor')")
            self.route_pool = tuple(routes.load_file(route_file).values())
        self.route_width = s.positive("route_width", route_width)
        if self.route_width < routes.MIN_HALF_WIDTH:
            raise ValueError(f"route_width must be >= {routes.MIN_HALF_WIDTH} L_vb")
        self.difficulty = s.difficulty_value(difficulty)
        if trace_window is None and self.score_mode == "corridor":
            trace_window = ROUTE_TRACE_WINDOW
        self.trace_window = None if trace_window is None else s.positive("trace_window",
                                                                         trace_window)  # fmt: skip
        self._reward_keys = _REWARD_KEYS[self.score_mode]
        #: Episode length (control steps) of the current route (score="corridor"; set at
        #: reset from the route's length); None in the thin task (the TimeLimit's).
        self.max_episode_steps: int | None = None
        self.obs_mode = s.choice("obs_mode", obs_mode, OBS_MODES)
        self.image_size = s.count("image_size", image_size, minimum=64)
        self.image_extent = s.positive("image_extent", image_extent)
        self.image_layers = s.choice("image_layers", image_layers, IMAGE_LAYERS)
        self.render_size = s.count("render_size", render_size, minimum=16)
        self.render_style = s.choice("render_style", render_style, RENDER_STYLES)
        self._renderer: Any = None  # plotting.TopViewRenderer of the episode (figure style)
        self.pattern_every = s.count("pattern_every", pattern_every, minimum=0)
        self.cache_dir = s.optional_path("cache_dir", cache_dir)
        self.lean_heights = LEAN_HEIGHTS + tuple(f * self.params.Hbar
                                                 for f in LEAN_HEIGHT_FRACTIONS)  # fmt: skip
        self.layout = ObservationLayout(
            s.count("n_trace_points", n_trace_points), s.count("n_target_points", n_target_points),
            self.lean_heights, route=self.score_mode == "corridor",
        )  # fmt: skip
        self.n_trace_points = self.layout.n_trace_points
        self.n_target_points = self.layout.n_target_points
        self.observation_structure: dict[str, int] = dict(self.layout.structure)
        self.observation_slices: dict[str, slice] = dict(self.layout.slices)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        size = self.image_size
        parts = {"image": spaces.Box(0, 255, shape=(size, size, 3), dtype=np.uint8),
                 "vector": self.layout.space()}  # fmt: skip
        self.observation_space = (spaces.Dict(parts) if self.obs_mode == "dict"
                                  else parts[self.obs_mode])  # fmt: skip

        self._sim: DepositionSim | None = None
        self._episode_index = 0  # successful resets (episode_index)
        self._warm: dict[str, np.ndarray] | None = None
        self.warm_start_source: str | None = None
        self._window = raster.Window(self.metadata["render_fps"])

    def _substeps(self, control_interval: float | None) -> tuple[float, int]:
        """The control interval (tau) and its whole number of physics steps
        (docs/architecture.md rule 4)."""
        if control_interval is None:
            n = max(1, round(CONTROL_INTERVAL_HBAR[self.score_mode] * self.params.Hbar / self.dt))
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
    def episode_index(self) -> int:
        """How many episodes this env has begun (successful resets): a policy that keeps
        per-episode state tells a new episode by it, even on the same route object."""
        return self._episode_index

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
        target = self._resolve_target(target_spec)  # before any state changes
        if self._warm is None:
            snap, self.warm_start_source = warm_state(
                self.config, self.warmup_length, self.warmup_seed, self.cache_dir
            )
            self._warm = flatten_snapshot(snap)
            self._sim = DepositionSim(self.config, seed=self.warmup_seed)
        sim = self._sim
        assert sim is not None
        advance = (
            float(self.np_random.uniform(0.0, 1.0)) * self.reset_advance * self.control_interval
        )
        mirrored = self.start_mirror == "always" or (
            self.start_mirror == "random" and bool(self.np_random.integers(2))
        )  # drawn only for "random": the other settings' streams are unchanged
        warm = unflatten_snapshot(self._warm)
        if mirrored:  # the mirror image in z, an exact symmetry of the simulator
            warm = z_mirrored(warm)
        sim.restore(warm)
        if advance > 0.0:
            try:
                sim.advance(advance)
            except SimulationError:
                sim.restore(warm)  # start from the warm state itself
                advance = 0.0
        if self.flow_gain_range is not None:  # drawn only for a range, as start_mirror
            lo, hi = np.log(self.flow_gain_range)
            self.flow_gain = float(np.exp(self.np_random.uniform(lo, hi)))
        phi = -self.params.phi if mirrored else self.params.phi
        self._flow = (self.params.vbar / self.flow_gain, phi)  # as commanded
        self._begin_episode(target)
        trace = sim.trace()
        metrics = self._last_metrics = self._metrics(trace)
        self._potentials = self._score.potentials(metrics)
        obs = self._observation(trace, metrics)
        info = self._info(metrics, dict.fromkeys(self._reward_keys, 0.0), 0, 0)
        info["reset_advance"] = advance
        info["start_mirrored"] = mirrored
        info["flow_gain"] = self.flow_gain
        if self.render_mode == "human":
            self.render()
        return obs, info

    def set_route_draw(
        self,
        families: Sequence[str] | str | None = None,
        difficulty: float | Sequence[float] | None = None,
    ) -> None:
        """Change how training targets are drawn, from the next reset on (a curriculum:
        training.callbacks.Curriculum calls it through ``VecEnv.env_method``). ``families``
        as the constructor's (None: unchanged), ``difficulty`` in [0, 1] or a range [lo, hi]
        (None: unchanged).
        Both are checked before either changes."""
        known = routes.families_of(self.score_mode)
        fams = self.families if families is None else settings.families_tuple(families, known)
        diff = self.difficulty if difficulty is None else settings.difficulty_value(difficulty)
        self.families, self.difficulty = fams, diff

    def episode_steps_for(self, route: Route) -> int:
        """Episode length (control steps) of ``route`` (:func:`routes.episode_steps`)."""
        return routes.episode_steps(route.length, self.control_interval / self.params.Hbar)

    def _resolve_target(self, spec: Any) -> Route | targets_mod.Target:
        """The episode's target: drawn from ``families`` (spec None) or ``spec``
        (routes.resolve / targets.resolve). Raises ValueError on a bad spec."""
        rng = self.np_random
        if self.score_mode == "thin":
            if spec is None:
                return targets_mod.sample(rng, self.families)
            return targets_mod.resolve(spec, rng)
        if spec is None:
            if self.route_pool:  # route_file: the user's routes instead of the families
                return self.route_pool[int(rng.integers(len(self.route_pool)))]
            return routes.sample(rng, self.families, self.difficulty)
        return routes.resolve(spec, rng, self.difficulty, self.route_width)

    def _begin_episode(self, target: Route | targets_mod.Target) -> None:
        sim = self._sim
        trace = sim.trace()
        self._n0 = sim.n_trace
        self._origin = trace[-1, [0, 2]].copy()
        self._laid0 = float(sim.deposited_length)
        self._t0 = float(sim.time)
        self.target = target
        self._target_abs = target.points + self._origin
        # The score works in the target's own frame (the trace minus the origin), as the
        # offline scores of policies/constant.py do: shifting the target by the origin
        # instead rounds its arc lengths and distances differently, and the two scores of
        # one trace then part in the last bits, by an amount that depends on the origin.
        if isinstance(target, Route):
            _, pads, keepouts = target.translated(self._origin)
            self._pads_abs, self._keepouts_abs = pads, keepouts
            self._score = route_score(target)
            self.max_episode_steps = self.episode_steps_for(target)
        else:
            self._pads_abs, self._keepouts_abs = np.zeros((0, 2, 2)), ()
            self._score = ThinScore(target.points, self.tolerance, self.weights)
        self._target_s = targets_mod.cumulative_length(target.points)  # the score's frame
        self._target_length = float(self._target_s[-1])
        self._steps = 0
        self._episode_index += 1
        self._renderer = None  # a new episode: a new fixed extent
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
            info = self._info(metrics, dict.fromkeys(self._reward_keys, 0.0), 0, 0)
            info["failure"] = self._failure
            return self._observation(trace, metrics), 0.0, True, False, info
        self._flow = flow_from_action(np.clip(a, -1.0, 1.0), self.vbar_max)
        before = sim.stats()
        try:
            sim.set_flow(self.flow_gain * self._flow[0], self._flow[1])
            sim.advance(self.control_interval)
        except SimulationError as exc:
            self._failure = str(exc.reason)
        after = sim.stats()
        self._steps += 1
        trace = sim.trace()
        metrics = self._last_metrics = self._metrics(trace)
        potentials = self._score.potentials(metrics)
        obs = self._observation(trace, metrics)
        parts = obs.values() if isinstance(obs, dict) else (obs,)
        if self._failure is None and not all(np.all(np.isfinite(o)) for o in parts):
            self._failure = "non-finite simulator state"
        if self._failure is not None:
            obs = self._within_space(obs)
            potentials = self._potentials  # a failed state scores nothing new
        delta = potentials - self._potentials
        self._potentials = potentials
        keys = self._reward_keys
        terms = dict(zip(keys[:-1], (float(d) for d in delta), strict=True))
        terms["reward_failure"] = -self.failure_penalty if self._failure is not None else 0.0
        reward = 0.0
        for key in keys:
            reward += terms[key]
        terminated = self._done(metrics) or self._failure is not None
        truncated = (not terminated and self.max_episode_steps is not None
                     and self._steps >= self.max_episode_steps)  # fmt: skip
        info = self._info(metrics, terms, after["steps"] - before["steps"],
                          after["newton_iterations"] - before["newton_iterations"])  # fmt: skip
        if self._failure is not None:
            info["failure"] = self._failure
        limit = self.spec.max_episode_steps if self.spec is not None else None
        if (
            terminated
            or (self.pattern_every and self._steps % self.pattern_every == 0)
            or (limit is not None and self._steps == limit)
            or truncated
        ):
            pattern = pattern_measures(trace[self._n0 - 1 :], self.substrate)
            if pattern is not None:
                info["pattern"] = pattern
        if self.render_mode == "human":
            self.render()
        return obs, reward, terminated, truncated, info

    def _done(self, metrics: dict[str, Any]) -> bool:
        """The target is laid: the route completed, or the thin target's end covered."""
        return bool(metrics["completed" if self.score_mode == "corridor" else "covered_end"])

    # ---- scoring (task/scoring.py) -------------------------------------------------------
    def _metrics(self, trace: np.ndarray) -> dict[str, Any]:
        """The score's metrics of the episode's trace (nodes from ``_n0`` on); the nodes
        that left the solve are frozen."""
        sim = self._sim
        n_frozen = sim.n_trace - sim.n_deposited - self._n0
        return self._score.update(trace[self._n0 :][:, [0, 2]] - self._origin, n_frozen)

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
            is_success=self._score.succeeded(metrics) and self._failure is None,
            physics_steps=int(physics_steps),
            newton_iterations=int(newton_iterations),
        )
        if self.score_mode == "corridor":
            for k in ("inside", "outside", "shorts", "short_length", "pads_crossed", "n_pads",
                      "completed"):  # fmt: skip
                info[k] = metrics[k]
            info["route_width"] = self.target.width
            info["max_episode_steps"] = self.max_episode_steps
        return info

    # ---- observation (task/spaces.py, task/raster.py) -------------------------------------
    def _observation(self, trace: np.ndarray,
                     metrics: dict[str, Any]) -> np.ndarray | dict[str, np.ndarray]:  # fmt: skip
        if self.obs_mode == "image":
            return self._image(trace, metrics)
        if self.obs_mode == "dict":
            return {"image": self._image(trace, metrics), "vector": self._vector(trace, metrics)}
        return self._vector(trace, metrics)

    def _within_space(self, obs: np.ndarray | dict[str, np.ndarray]):
        """``obs`` with any non-finite value zeroed and the vector clipped to its bounds
        (after a failure; the image is uint8, always finite)."""
        if isinstance(obs, dict):
            return {k: self._within_space(o) for k, o in obs.items()}
        if obs.dtype == np.uint8:
            return obs
        return self.layout.clip(np.nan_to_num(obs, nan=0.0, posinf=0.0, neginf=0.0))

    def _image(self, trace: np.ndarray, metrics: dict[str, Any]) -> np.ndarray:
        layers = None
        if self.score_mode == "corridor" and self.image_layers == "route":
            layers = raster.RouteLayers(self.target.width, self._pads_abs,
                                        self.target.pad_width, self._keepouts_abs)  # fmt: skip
        return raster.image_observation(
            self.image_size, self.image_extent, trace[:, [0, 2]], self._n0,
            self._target_abs, self._target_done(metrics), self._sim.suspended_nodes[:, [0, 2]],
            layers,
        )  # fmt: skip

    def _vector(self, trace: np.ndarray, metrics: dict[str, Any]) -> np.ndarray:
        sim = self._sim
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
        route = None
        if self.score_mode == "corridor":
            keep = nearest_on_polygons(trace[-1, [0, 2]], self._keepouts_abs)
            route = np.array([self.target.width, *keep])
        return self.layout.build(trace, ahead, flow, rod, np.array(progress), self.trace_window,
                                 route)  # fmt: skip

    def _target_done(self, metrics: dict[str, Any]) -> np.ndarray | None:
        """The target up to its furthest covered point (None before any)."""
        s = metrics["furthest"]
        return raster.path_head(self._target_abs, self._target_s, s) if s > 0 else None

    def render(self) -> np.ndarray | None:
        """Top view (uint8 (H, W, 3)): ``render_style`` "figure" (the default;
        :class:`cnt_env.plotting.TopViewRenderer`: the extent fixed at the episode's first
        frame, a legend, a scale bar in L_vb and µm, the flow arrow) or "raster"
        (:func:`cnt_env.task.raster.top_view`, refitted to every frame)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode=...")
            return None
        if self._sim is None:
            frame = np.full((self.render_size, self.render_size, 3), 255, dtype=np.uint8)
        elif self.render_style == "figure":
            frame = self._figure_frame()
        else:
            frame = raster.top_view(
                self.render_size, self._sim.trace()[:, [0, 2]], self._n0, self._target_abs,
                self._target_done(self._last_metrics), self._sim.suspended_nodes[:, [0, 2]],
                self._flow, self.vbar_max, 4.0 * self.tolerance, self._route_overlays(),
            )  # fmt: skip
        if self.render_mode == "rgb_array":
            return frame
        self._window.show(frame)
        return None

    def _figure_frame(self) -> np.ndarray:
        from cnt_env import plotting  # matplotlib, only when rendering

        sim = self._sim
        trace = sim.trace()
        rod = sim.suspended_nodes
        width = getattr(self.target, "width", None)
        if self._renderer is None:
            sets = [self._target_abs, trace[max(0, self._n0 - 50) :], rod]
            if width:
                sets += [self._target_abs + d for d in ((width, width), (-width, -width))]
            sets += [*self._pads_abs, *self._keepouts_abs]
            extent = plotting.top_view_extent(*sets, margin=0.12)
            self._renderer = plotting.TopViewRenderer(
                extent, (self.render_size, self.render_size), target=self._target_abs,
                n_start=self._n0, corridor=width, pads=tuple(self._pads_abs),
                keepouts=tuple(self._keepouts_abs), rod=rod, flow=(0.0, 0.0),
                target_done=np.zeros((0, 2)),
                flow_scale=plotting.flow_arrow_scale(self.params.Hbar, self.vbar_max),
                um_per_lvb=plotting.lvb_in_um(self.substrate),
            )  # fmt: skip
        vbar, phi = self._flow
        done = self._target_done(self._last_metrics)
        score = float(np.sum(self._potentials))
        title = f"{self.target.name}: step {self._steps}, score {score:.2f}"
        return self._renderer.render(trace, rod, (vbar * math.cos(phi), vbar * math.sin(phi)),
                                     np.zeros((0, 2)) if done is None else done, title)  # fmt: skip

    def _route_overlays(self) -> raster.Extra:
        """Pads (dark yellow) and keep-outs (orange, closed) for the rendered frame."""
        pads = tuple((p, (200, 160, 0)) for p in self._pads_abs)
        keep = tuple((np.concatenate([k, k[:1]]), (240, 120, 0)) for k in self._keepouts_abs)
        return pads + keep

    def close(self) -> None:
        self._window.close()

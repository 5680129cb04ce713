"""The CNTDeposit-v0 contract (docs/architecture.md rule 11; docs/task.md): checkers,
bit-identical same-seed rollouts, pickling, action clipping and rejection, the reward
decomposition, vector envs, the warm-start cache, and a hypothesis fuzz.

Everything runs on the small rod of tests/smallrod.py (Hbar = 30, 10 physics steps per
control step) with the warm-state cache in a temporary directory. The default
configuration (the paper's serpentine baseline) is only constructed, not stepped.
"""

from __future__ import annotations

import io
import json
import math
import os
import pickle
import signal
import subprocess
import sys
import warnings
import zipfile
from contextlib import contextmanager
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import cnt_env
from cnt_env.sim import warmstart
from cnt_env.sim.stepper import SimulationError
from cnt_env.task import targets as T
from cnt_env.task.env import CNTDepositEnv, flow_from_action
from tests.smallrod import small

ENV_ID = "CNTDeposit-v0"
# the v0 contract runs on the thin task (score="thin"); the route task has its own tests
SMALL = small(pattern_every=10, score="thin")
REWARD_KEYS = ("reward_coverage", "reward_precision", "reward_progress", "reward_failure")

# Warnings the checkers may raise that are not defects of this env, as (message
# fragment, reason) pairs. None is needed today: both checkers run warning-free.
ALLOWED_WARNINGS: tuple[tuple[str, str], ...] = ()


@pytest.fixture(scope="module")
def cache_dir(tmp_path_factory: pytest.TempPathFactory) -> str:
    return str(tmp_path_factory.mktemp("warm_cache"))


# warm states in a temporary cache, whatever a test forgets to pass (tests/conftest.py)
pytestmark = pytest.mark.usefixtures("temp_warm_cache")


@pytest.fixture(scope="module")
def kw(cache_dir: str) -> dict:
    return dict(SMALL, cache_dir=cache_dir)


def make(kw: dict, **extra) -> gymnasium.Env:
    return gymnasium.make(ENV_ID, **{**kw, **extra})


def actions(seed: int, n: int) -> list[np.ndarray]:
    g = np.random.default_rng(seed)
    return [g.uniform(-1, 1, 2).astype(np.float32) for _ in range(n)]


def assert_same(a, b, where: str = "") -> None:
    """Exact equality of nested obs/info data (NaN equals NaN, types must match)."""
    assert type(a) is type(b), f"{where}: {type(a)} != {type(b)}"
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            assert_same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, (tuple, list)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape, where
        assert np.array_equal(a, b, equal_nan=True), where
    elif isinstance(a, float):
        assert a == b or (math.isnan(a) and math.isnan(b)), f"{where}: {a!r} != {b!r}"
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def assert_same_step(s1: tuple, s2: tuple, where: str = "") -> None:
    for name, x, y in zip(("obs", "reward", "terminated", "truncated", "info"), s1, s2,
                          strict=True):  # fmt: skip
        assert_same(x, y, f"{where} {name}")


@contextmanager
def no_unexpected_warnings():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield
    bad = [
        str(w.message) for w in caught
        if not any(pattern in str(w.message) for pattern, _reason in ALLOWED_WARNINGS)
    ]  # fmt: skip
    assert not bad, "unexpected warnings:\n" + "\n".join(bad)


# ---- registration and construction ------------------------------------------------------


def test_import_is_light_and_registers_the_env() -> None:
    code = (
        "import sys, cnt_env, gymnasium;"
        "heavy = [m for m in ('numba', 'rerun', 'torch', 'cnt_env.task.env',"
        " 'cnt_env.sim.deposition')"
        " if m in sys.modules];"
        "spec = gymnasium.spec('CNTDeposit-v0');"
        "print(heavy, spec.entry_point, spec.max_episode_steps)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env=os.environ.copy()).stdout.split("\n")[0]  # fmt: skip
    assert out == "[] cnt_env.task.env:CNTDepositEnv 400"
    assert gymnasium.spec(ENV_ID).max_episode_steps == cnt_env.MAX_EPISODE_STEPS


def test_defaults_are_the_paper_serpentine_baseline() -> None:
    route = CNTDepositEnv()  # the route task: 30 Hbar per step, the corridor's slice
    assert route.score_mode == "corridor"
    assert route.n_substeps * route.dt == pytest.approx(30.0 * 155.0)
    assert route.observation_space.shape == (84,)
    assert list(route.observation_structure)[-1] == "route"
    env = CNTDepositEnv(score="thin")  # construction only: no simulation until reset
    p = env.params
    assert (p.Hbar, p.Ibar, p.kappa_c_bar, p.vbar) == (155.0, 300.0, 0.2, 0.037)
    assert env.substrate == "stepped" and env.vbar_max == 0.13
    # ENV_SIM_DEFAULTS: dt = 0.2 Hbar = 31 tau; 1.5 Hbar rounds to 8 whole steps
    assert env.dt == pytest.approx(0.2 * 155.0)
    assert env.n_substeps == 8 and env.control_interval == pytest.approx(8 * 0.2 * 155.0)
    assert env.config.tail_length == 60.0 and env.config.initial_radius == 3.9
    assert env.warmup_length == 155.0
    assert env.observation_space.shape == (81,) and env.observation_space.dtype == np.float32
    assert np.all(np.isfinite(env.observation_space.low))
    assert np.all(np.isfinite(env.observation_space.high))
    assert env.action_space == gymnasium.spaces.Box(-1, 1, (2,), np.float32)
    assert sum(env.observation_structure.values()) == 81
    assert list(env.observation_structure) == ["trace", "target", "flow", "rod", "progress"]


def test_substrate_keyword_maps_to_kappa_c() -> None:
    assert CNTDepositEnv(substrate="flat").params.kappa_c_bar is None
    assert CNTDepositEnv(substrate="stepped", kappa_c_bar=0.5).params.kappa_c_bar == 0.5
    coil = CNTDepositEnv(preset="coil", substrate="stepped", vbar=0.05)
    assert coil.params.kappa_c_bar == 0.2 and coil.params.Hbar == 253.0
    assert CNTDepositEnv(preset="coil").substrate == "flat"
    with pytest.raises(ValueError, match="stepped"):
        CNTDepositEnv(substrate="flat", kappa_c_bar=0.2)
    with pytest.raises(ValueError):
        CNTDepositEnv(substrate="wavy")


@pytest.mark.parametrize(
    "bad",
    [dict(control_interval=16.0), dict(control_interval=-1.0), dict(control_interval=math.nan),
     dict(vbar=0.2), dict(vbar_max=0.0), dict(tolerance=0.0), dict(n_trace_points=0),
     dict(image_size=32), dict(families=("circle",)), dict(families=("paper_serpentine",)),
     dict(obs_mode="pixels"), dict(Hbar=-3.0), dict(coverage_weight=0.0, precision_weight=0.0,
     progress_weight=0.0), dict(pattern_every=-1), dict(render_mode="ascii"),
     dict(warmup_seed=-1), dict(warmup_seed=1.5), dict(cache_dir=123), dict(drag_law="x"),
     dict(families="line"), dict(families=("straight", 3)), dict(physics=[1, 2]),
     dict(sim_options={"no_such_option": 1}), dict(sim_options={"newton": {"tol": 1e-5}}),
     dict(sim_options={"contact": {"adhesion": "glue"}}),
     dict(sim_options={"contact": {"range": 0.1}}),
     dict(tolerance="wide"), dict(vbar_max=True),
     dict(score="wide"), dict(route_width=0.5), dict(difficulty=1.5), dict(difficulty=[0.2]),
     dict(difficulty=[0.8, 0.2]), dict(difficulty=[0.0, 1.5]), dict(difficulty="hard"),
     dict(difficulty=[0.1, math.nan]), dict(trace_window=0.0),
     dict(score="corridor", families=("zigzag",)), dict(delta_bar=5e-324),
     dict(flow_gain=0.0), dict(flow_gain=math.nan), dict(vbar=0.3, flow_gain=2.0),
     dict(flow_gain=[2.0, 1.0]), dict(flow_gain=[1.0]), dict(flow_gain=[0.0, 1.0]),
     dict(vbar=0.2, flow_gain=[1.0, 2.0])],
)  # fmt: skip
def test_bad_keywords_raise(bad: dict) -> None:
    with pytest.raises(ValueError):
        CNTDepositEnv(**{**SMALL, **bad})


def test_env_speed_settings_by_substrate() -> None:
    """presets.ENV_MESH and ENV_SIM_DEFAULTS: a graded suspended rod (coarse 6 L_vb within
    10 of the contact, snapped to a whole multiple of delta_bar, uniform below 2
    delta_bar) and Newton at 1e-5 on both
    substrates; 4x the validated step on the stepped one, 2x on the flat; sim_options
    overrides, with NewtonOptions fields given as a dict."""
    stepped = CNTDepositEnv().config
    flat = CNTDepositEnv(preset="coil").config
    for cfg in (stepped, flat):
        assert (cfg.coarse_delta, cfg.fine_length, cfg.newton.residual_tol) == (6.0, 10.0, 1e-5)
    assert (stepped.dt_factor, stepped.tail_length, flat.dt_factor) == (0.2, 60.0, 0.1)
    assert CNTDepositEnv(delta_bar=1.5).config.coarse_delta == 6.0
    assert CNTDepositEnv(delta_bar=4.0, initial_radius=8.5).config.coarse_delta == 8.0
    assert CNTDepositEnv(delta_bar=5.0, initial_radius=10.5).config.coarse_delta is None
    own = CNTDepositEnv(sim_options={"coarse_delta": None, "newton": {"residual_tol": 1e-8}})
    assert own.config.coarse_delta is None and own.config.newton.residual_tol == 1e-8


def test_env_runs_the_cohesive_adhesion_given_as_a_dict(tmp_path) -> None:
    """sim_options["contact"] takes ContactOptions fields as a dict (YAML-friendly): the
    cohesive adhesion of docs/model.md §4, on the env's own mesh and step."""
    options = {"dt_factor": 0.05, "contact": {"adhesion": "cohesive"}}
    env = CNTDepositEnv(**{**SMALL, "delta_bar": 0.2, "cache_dir": str(tmp_path),
                           "sim_options": options})  # fmt: skip
    assert env.config.contact.adhesion == "cohesive" and env.config.contact.cohesive_range == 0.05
    env.reset(seed=0)
    laid = env.sim.deposited_length
    for _ in range(3):
        info = env.step(np.array([0.5, 0.0], dtype=np.float32))[-1]
        assert "failure" not in info
    assert env.sim.deposited_length > laid
    env.close()


def test_a_bare_family_name_is_one_family() -> None:
    assert CNTDepositEnv(**SMALL, families="straight").families == ("straight",)


def test_control_interval_derives_substeps() -> None:
    env = CNTDepositEnv(**{**SMALL, "control_interval": 45.0})
    assert env.dt == 1.5 and env.n_substeps == 30
    env = CNTDepositEnv(**{**SMALL, "control_interval": None, "dt": 2.0})
    assert env.n_substeps == round(1.5 * 30 / 2.0) and env.control_interval == 22 * 2.0


def test_flow_from_action_maps_the_square_onto_the_disk() -> None:
    vmax = 0.13
    assert flow_from_action(np.array([0.0, 0.0]), vmax) == (0.0, 0.0)
    for a, phi in [((1, 0), 0.0), ((0, 1), math.pi / 2), ((-1, 0), math.pi),
                   ((1, 1), math.pi / 4), ((-1, -1), -3 * math.pi / 4)]:  # fmt: skip
        v, p = flow_from_action(np.array(a, dtype=float), vmax)
        assert v == pytest.approx(vmax, rel=1e-12) and p == pytest.approx(phi)
    g = np.random.default_rng(0)
    speeds = [flow_from_action(g.uniform(-1, 1, 2), vmax)[0] for _ in range(2000)]
    assert max(speeds) <= vmax


# ---- the checkers -----------------------------------------------------------------------


@pytest.mark.parametrize("obs_mode", ["vector", "image", "dict"])
def test_gymnasium_check_env(kw: dict, obs_mode: str) -> None:
    from gymnasium.utils.env_checker import check_env

    env = make(kw, obs_mode=obs_mode, render_mode="rgb_array")
    with no_unexpected_warnings():
        check_env(env.unwrapped)
    env.close()


@pytest.mark.parametrize("obs_mode", ["vector", "image", "dict"])
def test_sb3_check_env(kw: dict, obs_mode: str) -> None:
    from stable_baselines3.common.env_checker import check_env

    env = make(kw, obs_mode=obs_mode)
    with no_unexpected_warnings():
        check_env(env.unwrapped, warn=True)
    env.close()


# ---- determinism, pickling, actions --------------------------------------------------------


def rollout(env: gymnasium.Env, acts: list[np.ndarray], seed: int | None = None) -> list:
    steps = []
    if seed is not None:
        steps.append(env.reset(seed=seed))
    for a in acts:
        s = env.step(a)
        steps.append(s)
        if s[2] or s[3]:
            steps.append(env.reset())
    return steps


def test_same_seed_same_actions_are_bit_identical(kw: dict) -> None:
    acts = actions(1, 30)
    a, b = make(kw), make(kw)
    ra, rb = rollout(a, acts, seed=42), rollout(b, acts, seed=42)
    assert len(ra) == len(rb) >= 31
    for i, (sa, sb) in enumerate(zip(ra, rb, strict=True)):
        if len(sa) == 2:
            assert_same(sa[0], sb[0], f"reset {i} obs")
            assert_same(sa[1], sb[1], f"reset {i} info")
        else:
            assert_same_step(sa, sb, f"step {i}")
    assert any("pattern" in s[-1] for s in ra)  # info["pattern"] is compared as well
    c = make(kw)
    rc = rollout(c, acts, seed=43)
    assert not np.array_equal(ra[-1][0], rc[-1][0])


def test_flow_gain_scales_the_simulated_flow_only(kw: dict) -> None:
    """flow_gain g: the simulator runs g x the commanded flow, and nothing else changes.
    With powers of two every product is exact, so g = 2 under vbar_max 0.125 is, bit for
    bit, the env of vbar_max 0.25: an action commands half the speed and the simulator
    runs the same flow; the observed flow is normalised by vbar_max either way. Only
    info's flow_vbar (the commanded speed) differs."""
    acts = actions(4, 8)
    gained, wide = make(kw, flow_gain=2.0, vbar_max=0.125), make(kw, vbar_max=0.25)
    ra, rb = rollout(gained, acts, seed=5), rollout(wide, acts, seed=5)
    for i, (sa, sb) in enumerate(zip(ra, rb, strict=True)):
        if len(sa) == 2:
            assert_same(sa[0], sb[0], f"reset {i} obs")
            continue
        assert_same(sa[:4], sb[:4], f"step {i}")
        ia, ib = dict(sa[4]), dict(sb[4])
        assert 2.0 * ia.pop("flow_vbar") == ib.pop("flow_vbar") > 0.0
        assert_same(ia, ib, f"step {i} info")
    np.testing.assert_array_equal(gained.unwrapped.sim.rod.flow, wide.unwrapped.sim.rod.flow)
    # the warm start's vbar is the simulated flow: up to vbar_max x flow_gain
    assert CNTDepositEnv(**{**SMALL, "vbar": 0.2, "flow_gain": 2.0}).params.vbar == 0.2


def test_flow_gain_range_draws_each_episode_its_own_gain(kw: dict) -> None:
    """flow_gain [lo, hi]: each reset draws a gain log-uniformly from np_random (the same
    seed, the same gain), and the episode is, bit for bit, the env of that fixed gain."""
    ranged = make(kw, flow_gain=[1.0, 2.0])
    gains = [ranged.reset(seed=s)[1]["flow_gain"] for s in range(6)]
    assert all(1.0 <= g <= 2.0 for g in gains) and len(set(gains)) == 6
    assert gains == [ranged.reset(seed=s)[1]["flow_gain"] for s in range(6)]
    # a one-point range is the fixed gain, with no draw
    assert make(kw, flow_gain=[1.5, 1.5]).unwrapped.flow_gain_range is None
    acts = actions(3, 6)
    ra = rollout(ranged, acts, seed=3)
    fixed = make(kw, flow_gain=ra[0][1]["flow_gain"])
    rb = rollout(fixed, acts, seed=3)
    for i, (sa, sb) in enumerate(zip(ra, rb, strict=True)):
        if len(sa) == 2:  # the draw comes after the reset's own draws: same start
            assert_same(sa[0], sb[0], f"reset {i} obs")
        else:
            assert_same(sa[:4], sb[:4], f"step {i}")
    ranged.close()
    fixed.close()


def test_pickled_env_continues_identically(kw: dict) -> None:
    env = make(kw)
    rollout(env, actions(2, 5), seed=7)
    copy = pickle.loads(pickle.dumps(env))
    acts = actions(3, 12)
    for i, (sa, sb) in enumerate(zip(rollout(env, acts), rollout(copy, acts), strict=True)):
        if len(sa) == 2:
            assert_same(sa[0], sb[0], f"reset {i}")
        else:
            assert_same_step(sa, sb, f"step {i}")


def test_out_of_bound_action_acts_like_the_bound(kw: dict) -> None:
    a, b = make(kw), make(kw)
    a.reset(seed=5)
    b.reset(seed=5)
    for past, bound in [([7.0, -3.0], [1.0, -1.0]), ([0.25, 1e30], [0.25, 1.0]),
                        ([-1.0000001, 0.0], [-1.0, 0.0])]:  # fmt: skip
        sa = a.step(np.array(past, dtype=np.float64))
        sb = b.step(np.array(bound, dtype=np.float32))
        assert_same_step(sa, sb, str(past))
        assert sa[-1]["flow_vbar"] <= 0.13


@pytest.mark.parametrize(
    "bad", [[math.nan, 0.0], [0.0, math.inf], [-math.inf, 0.5], [0.1, 0.2, 0.3], [[0.1, 0.2]]]
)
def test_non_finite_or_misshaped_action_raises_and_changes_nothing(kw: dict, bad) -> None:
    env, ref = make(kw).unwrapped, make(kw).unwrapped
    env.reset(seed=9)
    ref.reset(seed=9)
    with pytest.raises(ValueError):
        env.step(np.array(bad, dtype=np.float32))
    act = np.array([0.3, -0.4], dtype=np.float32)
    assert_same_step(env.step(act), ref.step(act), "after the rejected action")


# ---- rewards and episode end ----------------------------------------------------------------


def test_reward_is_the_sum_of_its_terms_and_the_return_is_the_final_score(kw: dict) -> None:
    env = make(kw, max_episode_steps=60)
    _obs, info = env.reset(seed=11, options={"target": "zigzag"})
    assert info["score"] == 0.0 and all(info[k] == 0.0 for k in REWARD_KEYS)
    ret, n = 0.0, 0
    while True:
        _obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        n += 1
        parts = [info[k] for k in REWARD_KEYS]
        assert reward == sum(parts)  # exact: the env adds them in this order
        assert sorted(k for k in info if k.startswith("reward_")) == sorted(REWARD_KEYS)
        assert math.isfinite(reward)
        ret += reward
        assert ret == pytest.approx(info["score"], abs=1e-12)
        for key in ("coverage", "precision", "progress"):
            assert 0.0 <= info[key] <= 1.0
        if terminated or truncated:
            break
    assert truncated and n == 60
    assert ret == pytest.approx(info["score"], abs=1e-12)
    assert "pattern" in info  # measured on the last step before the TimeLimit
    assert (
        info["n_laid"] > 0
        and info["laid_length"] > 0
        and info["sim_time"] == pytest.approx(60 * 15.0)
    )


def test_laying_the_target_terminates_with_success(kw: dict) -> None:
    env = make(kw)
    env.reset(seed=1, options={"target": [[0.0, 0.0], [0.6, 0.0]]})
    ret = 0.0
    for _ in range(50):
        _obs, reward, terminated, _truncated, info = env.step(np.zeros(2, dtype=np.float32))
        ret += reward
        if terminated:
            break
    assert terminated and info["is_success"] and "failure" not in info
    assert info["progress"] == 1.0 and info["target"] == "custom"
    assert ret == pytest.approx(info["score"], abs=1e-12)
    assert "pattern" in info or info["n_laid"] < 2


def test_simulation_failure_is_a_clean_penalised_termination(kw: dict) -> None:
    env = make(kw, failure_penalty=0.7)
    env.reset(seed=2)
    ret = 0.0
    for a in actions(4, 3):
        ret += env.step(a)[1]
    sim = env.unwrapped.sim

    def fail(duration: float) -> None:
        sim.step()  # part of the interval happens, then the solver gives up
        raise SimulationError("Newton did not converge within max_iter", 1, sim.time, 1.0, {})

    sim.advance = fail
    obs, reward, terminated, truncated, info = env.step(np.array([1.0, 0.0], np.float32))
    ret += reward
    assert terminated and not truncated and not info["is_success"]
    assert info["failure"] == "Newton did not converge within max_iter"
    assert info["reward_failure"] == -0.7 and reward == sum(info[k] for k in REWARD_KEYS)
    assert reward == pytest.approx(-0.7) and ret == pytest.approx(info["score"], abs=1e-12)
    assert np.all(np.isfinite(obs)) and obs in env.observation_space
    again = env.step(np.array([1.0, 0.0], np.float32))
    assert again[1] == 0.0 and again[2] and again[-1]["failure"] == info["failure"]
    del sim.advance
    env.reset(seed=3)  # a reset recovers
    assert "failure" not in env.step(np.zeros(2, np.float32))[-1]


def test_a_non_finite_state_is_a_reported_failure_not_a_nan_observation(kw: dict) -> None:
    """A simulator state that turns non-finite without raising (here: the top node's
    position poisoned after a step) ends the episode with ``info["failure"]``, a finite
    observation and the failure penalty, never a NaN handed to the agent."""
    env = make(kw, failure_penalty=0.5)
    env.reset(seed=1)
    env.step(np.array([0.5, 0.5], np.float32))
    sim = env.unwrapped.sim
    advance = sim.advance

    def poisoned(duration: float) -> None:
        advance(duration)
        sim.rod.q[4 * (sim.rod.n_nodes - 1)] = np.nan  # x of the top node

    sim.advance = poisoned
    obs, reward, terminated, truncated, info = env.step(np.array([1.0, 0.0], np.float32))
    assert terminated and not truncated and not info["is_success"]
    assert info["failure"] == "non-finite simulator state"
    assert info["reward_failure"] == -0.5 and reward == pytest.approx(-0.5)
    assert reward == sum(info[k] for k in REWARD_KEYS)
    assert np.all(np.isfinite(obs)) and obs in env.observation_space
    assert all(np.isfinite(v) for k, v in info.items() if k.startswith("reward_"))


def test_a_real_newton_failure_ends_the_episode_cleanly(kw: dict) -> None:
    """One Newton iteration and no dt halving: the solver gives up at once (also in the
    random advance at reset, which then starts from the warm state itself)."""
    from cnt_env.sim.stepper import NewtonOptions

    env = make(kw, warmup_length=0.0,
               sim_options={"newton": NewtonOptions(max_iter=1, max_halvings=0),
                            "dt_factor": 0.05})  # fmt: skip
    obs, info = env.reset(seed=0)
    assert info["reset_advance"] == 0.0 and np.all(np.isfinite(obs))
    obs, reward, terminated, truncated, info = env.step(np.zeros(2, np.float32))
    assert terminated and not truncated and not info["is_success"]
    assert info["failure"] == "Newton did not converge within max_iter"
    assert reward == -1.0 == info["score"] and np.all(np.isfinite(obs))


def test_truncation_is_the_time_limits(kw: dict) -> None:
    env = make(kw, max_episode_steps=3)
    env.reset(seed=0, options={"target": "long_diagonal"})
    flags = [env.step(np.zeros(2, np.float32))[2:4] for _ in range(3)]
    assert flags == [(False, False), (False, False), (False, True)]


# ---- reset options, observations, rendering ---------------------------------------------------


def test_target_starts_at_the_contact_point(kw: dict) -> None:
    env = make(kw).unwrapped
    obs, info = env.reset(seed=4, options={"target": "hairpin"})
    assert info["target"] == "hairpin"
    contact = env.sim.trace()[-1][[0, 2]]
    assert env.episode_start == env.sim.n_trace
    np.testing.assert_array_equal(env.target_path[0], contact)
    np.testing.assert_allclose(env.target_path - contact, T.held_out("hairpin").points)
    # the first observed target point is target_spacing along the path from its start
    tgt = obs[env.observation_slices["target"]].reshape(-1, 2)
    assert np.hypot(*tgt[0]) == pytest.approx(env.target_spacing, rel=1e-5)
    # the last observed trace point is the node deposited just before the contact point,
    # an edge (delta_bar) behind it
    past = obs[env.observation_slices["trace"]].reshape(-1, 2)
    assert 0.5 < np.hypot(*past[-1]) / env.params.delta_bar < 1.5
    with pytest.raises(ValueError):
        env.reset(options={"target": "nonsense"})
    with pytest.raises(ValueError):
        env.reset(options={"goal": "arc"})


def test_observation_reports_the_applied_flow(kw: dict) -> None:
    env = make(kw).unwrapped
    obs, _ = env.reset(seed=0)
    flow = obs[env.observation_slices["flow"]]
    np.testing.assert_allclose(flow, [0.037 / 0.13, 0.0], rtol=1e-6)  # the warm-up flow
    obs, *_, info = env.step(np.array([0.0, -1.0], np.float32))
    np.testing.assert_allclose(obs[env.observation_slices["flow"]], [0.0, -1.0], atol=1e-7)
    assert info["flow_vbar"] == pytest.approx(0.13) and info["flow_phi"] == -math.pi / 2


def test_image_observation_draws_trace_target_and_rod(kw: dict) -> None:
    env = make(kw, obs_mode="image")
    obs, _ = env.reset(seed=0, options={"target": "s_curve"})
    assert obs.shape == (64, 64, 3) and obs.dtype == np.uint8
    for _ in range(5):
        obs = env.step(np.array([0.5, 0.5], np.float32))[0]
    for channel in range(3):
        assert obs[..., channel].any(), channel
    assert (obs[..., 0] == 255).any()  # this episode's trace


def test_render_modes(kw: dict) -> None:
    env = make(kw, render_mode="rgb_array", render_size=128)
    env.reset(seed=0)
    env.step(np.zeros(2, np.float32))
    frame = env.render()
    assert frame.shape == (128, 128, 3) and frame.dtype == np.uint8
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) >= 4  # several layers drawn
    human = make(kw, render_mode="human")  # headless: matplotlib's Agg, no window
    human.reset(seed=0)
    human.step(np.zeros(2, np.float32))
    assert human.render() is None
    human.close()
    human.close()


@pytest.mark.parametrize("style", ["figure", "raster"])
def test_render_styles(kw: dict, style: str) -> None:
    env = make(kw, render_mode="rgb_array", render_size=160, render_style=style)
    env.reset(seed=0)
    first = env.render()
    env.step(np.zeros(2, np.float32))
    frame = env.render()
    assert frame.shape == first.shape == (160, 160, 3) and frame.dtype == np.uint8
    assert not np.array_equal(frame, first)  # the trace and rod moved
    env.reset(seed=1)  # a new episode: a new fixed extent, same frame size
    assert env.render().shape == (160, 160, 3)


def test_figure_render_keeps_its_extent_within_an_episode(kw: dict) -> None:
    env = make(kw, render_mode="rgb_array", render_size=160)
    env.reset(seed=0)
    env.render()
    extent = env.unwrapped._renderer.view.ax.get_xlim(), env.unwrapped._renderer.view.ax.get_ylim()
    for _ in range(3):
        env.step(np.ones(2, np.float32))
        env.render()
    view = env.unwrapped._renderer.view
    assert (view.ax.get_xlim(), view.ax.get_ylim()) == extent


# ---- vector envs ---------------------------------------------------------------------------


def test_make_vec_async_runs(kw: dict) -> None:
    envs = gymnasium.make_vec(ENV_ID, num_envs=2, vectorization_mode="async", **kw)
    try:
        obs, info = envs.reset(seed=[0, 1])
        assert obs.shape == (2, 81) and obs.dtype == np.float32
        envs.action_space.seed(0)
        for _ in range(4):
            obs, reward, _terminated, _truncated, info = envs.step(envs.action_space.sample())
            assert np.all(np.isfinite(obs)) and np.all(np.isfinite(reward))
        assert "score" in info and info["score"].shape == (2,)
    finally:
        envs.close()


def test_sb3_subprocvecenv_runs(kw: dict) -> None:
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv

    # "module:id" makes gymnasium import cnt_env (and so register) in the fresh workers
    venv = make_vec_env("cnt_env:CNTDeposit-v0", n_envs=2, seed=0, vec_env_cls=SubprocVecEnv,
                        env_kwargs=kw)  # fmt: skip
    try:
        obs = venv.reset()
        assert obs.shape == (2, 81)
        for _ in range(4):
            obs, reward, _done, infos = venv.step(np.array(actions(5, 2)))
            assert np.all(np.isfinite(obs)) and np.all(np.isfinite(reward))
            assert len(infos) == 2 and "reward_coverage" in infos[0]
    finally:
        venv.close()


# ---- warm-start cache ---------------------------------------------------------------------


def warm_files(directory: str | Path) -> list[Path]:
    return sorted(Path(directory).glob("warm-*.npz"))


def test_warm_state_is_cached_on_disk_and_corruption_is_rebuilt(tmp_path: Path) -> None:
    kw = dict(SMALL, cache_dir=str(tmp_path), warmup_length=2.0, substrate="flat")
    warmstart.clear_memory_cache()
    cold = CNTDepositEnv(**kw)
    obs_cold, info_cold = cold.reset(seed=3)
    assert cold.warm_start_source == "computed"
    (path,) = warm_files(tmp_path)
    # no pickle inside: loads with allow_pickle=False, no object arrays
    with np.load(path, allow_pickle=False) as z:
        assert all(z[name].dtype != object for name in z.files)
    assert CNTDepositEnv(**kw).reset(seed=3) and warmstart._memory  # memory hit
    warmstart.clear_memory_cache()
    disk = CNTDepositEnv(**kw)
    assert_same(disk.reset(seed=3), (obs_cold, info_cold), "from disk")
    assert disk.warm_start_source == "disk"
    a = np.array([0.2, 0.9], np.float32)
    assert_same_step(disk.step(a), cold.step(a), "disk vs computed")

    def flip(b: bytes) -> bytes:
        """One byte flipped inside the positions' data (a flip in a zip header field that
        the reader never checks, like the local header's copy of the CRC, changes no
        data and is rightly loaded)."""
        infos = sorted(zipfile.ZipFile(io.BytesIO(b)).infolist(), key=lambda z: z.header_offset)
        k = next(n for n, z in enumerate(infos) if z.filename == "rod/q.npy")
        i = (infos[k].header_offset + infos[k + 1].header_offset) // 2
        return b[:i] + bytes([b[i] ^ 0xFF]) + b[i + 1 :]

    def tamper(b: bytes) -> bytes:
        """A well-formed archive whose data no longer match the stored checksum."""
        with np.load(io.BytesIO(b), allow_pickle=False) as z:
            arrays = {name: z[name] for name in z.files}
        arrays["rod/q"] = arrays["rod/q"] + 1e-12
        out = io.BytesIO()
        np.savez(out, **arrays)
        return out.getvalue()

    good = path.read_bytes()
    for corrupt in (lambda b: b[: len(b) // 2], lambda b: b[:-100] + bytes(100), lambda b: b"",
                    flip, tamper):  # fmt: skip
        path.write_bytes(corrupt(good))
        warmstart.clear_memory_cache()
        env = CNTDepositEnv(**kw)
        assert_same(env.reset(seed=3), (obs_cold, info_cold), "rebuilt")
        assert env.warm_start_source == "rebuilt"
    # a valid file of another configuration under this name is rebuilt too
    other = dict(kw, warmup_length=1.0)
    warmstart.clear_memory_cache()
    CNTDepositEnv(**other).reset(seed=0)
    files = warm_files(tmp_path)
    assert len(files) == 2
    foreign = next(f for f in files if f != path)
    path.write_bytes(foreign.read_bytes())
    warmstart.clear_memory_cache()
    env = CNTDepositEnv(**kw)
    assert_same(env.reset(seed=3), (obs_cold, info_cold), "foreign file")
    assert env.warm_start_source == "rebuilt"


def test_cache_directory_comes_from_the_environment_variable(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv(warmstart.CACHE_ENV_VAR, str(tmp_path / "from_env"))
    assert warmstart.default_cache_dir() == tmp_path / "from_env"
    warmstart.clear_memory_cache()
    env = CNTDepositEnv(**dict(SMALL, warmup_length=1.5, substrate="flat"))
    env.reset(seed=0)
    assert len(warm_files(tmp_path / "from_env")) == 1


def test_cache_key_changes_with_the_configuration(kw: dict) -> None:
    kw = dict(kw, control_interval=None)  # derived from dt, which follows Hbar
    base = CNTDepositEnv(**kw)
    key = warmstart.config_key(base.config, base.warmup_length, 0)
    assert key == warmstart.config_key(CNTDepositEnv(**kw).config, base.warmup_length, 0)
    for change in (dict(Hbar=31.0), dict(vbar=0.05), dict(substrate="flat"), dict(dt=1.0)):
        env = CNTDepositEnv(**{**kw, **change})
        assert warmstart.config_key(env.config, env.warmup_length, 0) != key, change
    assert warmstart.config_key(base.config, 4.0, 0) != key
    assert warmstart.config_key(base.config, base.warmup_length, 1) != key


def test_snapshot_codec_round_trips_types_and_bits() -> None:
    snap = {
        "a": np.arange(5.0), "b": np.zeros((2, 3), np.uint8), "i": 3, "f": 0.1, "t": True,
        "n": None, "s": "x", "np": np.float64(1.5), "l": [1, 2], "tu": (0.5, 0.25),
        "nest": {"deep": {"q": np.array([1e-300, -0.0, np.pi])}, "k": -7},
    }  # fmt: skip
    back = warmstart.unflatten_snapshot(warmstart.flatten_snapshot(snap))
    assert_same(back, snap)
    with pytest.raises(TypeError):
        warmstart.flatten_snapshot({"o": object()})
    with pytest.raises(TypeError):
        warmstart.flatten_snapshot({"a/b": 1})
    json.dumps(str(warmstart.flatten_snapshot(snap)["__manifest__"]))


# ---- fuzz --------------------------------------------------------------------------------------


@contextmanager
def time_limit(seconds: int):
    def on_alarm(signum, frame):
        raise TimeoutError(f"no answer within {seconds} s: a hang")

    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


TARGETS = st.one_of(
    st.sampled_from(sorted(T.FAMILIES) + list(T.HELD_OUT)),
    st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50)), min_size=2, max_size=6).filter(
        lambda p: T.polyline_length(np.array(p)) > 1e-3
    ),
)
ACTION_VALUES = st.one_of(
    st.floats(-1, 1, width=32),
    st.floats(-1e6, 1e6),
    st.sampled_from([math.nan, math.inf, -math.inf, 1.0000001, -0.0, 5e-324]),
)
KEYWORDS = st.fixed_dictionaries(
    {
        "Hbar": st.sampled_from([20.0, 30.0]),
        "drag_law": st.sampled_from(["linear", "printed"]),
        "substrate": st.sampled_from(["flat", "stepped"]),
        "vbar": st.sampled_from([0.0, 0.037, 0.13]),
        "phi": st.sampled_from([0.0, 2.0]),
        "vbar_max": st.floats(0.13, 0.5),
        "n_substeps": st.integers(1, 20),
        "tolerance": st.floats(0.05, 20.0),
        "n_trace_points": st.integers(1, 8),
        "n_target_points": st.integers(1, 8),
        "target_spacing": st.floats(0.1, 20.0),
        "obs_mode": st.sampled_from(["vector", "image", "dict"]),
        "failure_penalty": st.floats(0.0, 5.0),
        "reset_advance": st.floats(0.0, 3.0),
        "pattern_every": st.integers(0, 3),
    }
)


@settings(max_examples=40, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])  # fmt: skip
@given(
    keywords=KEYWORDS,
    target=TARGETS,
    seed=st.integers(0, 2**31 - 1),
    acts=st.lists(st.tuples(ACTION_VALUES, ACTION_VALUES), min_size=1, max_size=10),
)
def test_fuzz_steps_are_finite_or_fail_cleanly(keywords, target, seed, acts, cache_dir) -> None:
    keywords = dict(keywords)
    n_substeps = keywords.pop("n_substeps")
    dt = 0.05 * keywords["Hbar"]  # DepositionConfig's default physics step
    env = CNTDepositEnv(**{**SMALL, **keywords, "control_interval": n_substeps * dt,
                           "cache_dir": cache_dir})  # fmt: skip
    with time_limit(60):
        obs, info = env.reset(seed=seed, options={"target": target})
        assert obs in env.observation_space
        for a in acts:
            action = np.array(a, dtype=np.float64)
            if not np.all(np.isfinite(action)):
                with pytest.raises(ValueError):
                    env.step(action)
                continue
            obs, reward, terminated, _truncated, info = env.step(action)
            assert obs in env.observation_space
            for part in obs.values() if isinstance(obs, dict) else (obs,):
                assert np.all(np.isfinite(part.astype(np.float64)))
            assert math.isfinite(reward) and math.isfinite(info["score"])
            assert reward == sum(info[k] for k in REWARD_KEYS)
            assert info["flow_vbar"] <= env.vbar_max
            if terminated:
                assert info["is_success"] or isinstance(info.get("failure"), str)
                break


# ---- the route task (score="corridor") ----------------------------------------------------

ROUTE_KEYS = ("reward_progress", "reward_pads", "reward_completion", "reward_outside",
              "reward_short", "reward_failure")  # fmt: skip


@pytest.fixture(scope="module")
def rkw(kw: dict) -> dict:
    return dict(kw, score="corridor")


def test_route_task_spaces_and_reward_terms(rkw: dict) -> None:
    from gymnasium.utils.env_checker import check_env

    env = CNTDepositEnv(**rkw)
    with no_unexpected_warnings():
        check_env(env, skip_render_check=True)
    obs, info = env.reset(seed=1, options={"target": "u_turn"})
    assert obs.shape == (84,) and env.observation_space.contains(obs)
    from cnt_env.task.routes import DEFAULT_HALF_WIDTH

    assert info["route_width"] == DEFAULT_HALF_WIDTH and info["score"] == 0.0
    assert obs[env.observation_slices["route"]][0] == np.float32(DEFAULT_HALF_WIDTH)
    total = 0.0
    for a in actions(3, 12):
        obs, r, _, _, info = env.step(a)
        total += r
        assert set(ROUTE_KEYS) <= set(info)
        assert r == pytest.approx(sum(info[k] for k in ROUTE_KEYS), abs=1e-12)
        assert 0.0 <= info["score"] <= 1.0 and env.observation_space.contains(obs)
    assert total == pytest.approx(info["score"], abs=1e-9)


@pytest.mark.parametrize(
    "target",
    [
        [[0.0, 0.0], [40.0, 0.0]],
        {"waypoints": [[5, 5], [5, 45]], "width": 9.0, "pads": [[[0, 25], [10, 25]]],
         "keepouts": [{"rect": [20, 5, 30, 40]}], "name": "mine"},
        {"waypoints": [[5, 5], [5, 45]], "width": 9.0, "pads": [[[0, 25], [10, 25]]],
         "pad_width": 4.0, "name": "mine"},
        "u_turn",
        "staircase",
    ],
)  # fmt: skip
def test_route_targets_in_every_form(rkw: dict, target) -> None:
    from cnt_env.task import routes

    env = CNTDepositEnv(**rkw)
    _, info = env.reset(seed=0, options={"target": target})
    r = env.target
    assert isinstance(r, routes.Route) and np.array_equal(r.waypoints[0], [0.0, 0.0])
    if isinstance(target, dict):
        assert r.name == "mine" and r.width == 9.0 and len(r.pads) == 1
        assert len(r.keepouts) == len(target.get("keepouts", ()))
        if r.keepouts:
            assert np.allclose(r.keepouts[0].min(axis=0), [15.0, 0.0])  # moved with the route
        assert info["n_pads"] == 1
        # the score counts the pads as strips of the route's pad_width
        assert r.pad_width == target.get("pad_width", 0.0) == 2.0 * env._score.pad_half
    assert env.max_episode_steps == env.episode_steps_for(r) > 10
    same = routes.resolve(r.to_dict(), np.random.default_rng(0))
    assert np.array_equal(same.waypoints, r.waypoints) and same.width == r.width
    assert same.pad_width == r.pad_width


@pytest.mark.parametrize("bad", [[[0, 0], [1e-300, 0]], [[0, 0], [0.5, 0]], "nowhere",
                                 {"waypoints": [[0, 0], [9, 0]], "width": 0.1},
                                 {"points": [[0, 0], [9, 0]]},
                                 {"waypoints": [[0, 0], [80, 0]],
                                  "keepouts": [{"rect": [30, -5, 40, 5]}]}])  # fmt: skip
def test_degenerate_route_raises_and_the_env_stays_usable(rkw: dict, bad) -> None:
    env = CNTDepositEnv(**rkw)
    env.reset(seed=0, options={"target": "u_turn"})
    env.step(np.zeros(2, np.float32))
    with pytest.raises(ValueError):
        env.reset(seed=0, options={"target": bad})
    obs, *_ = env.step(np.zeros(2, np.float32))  # the earlier episode goes on
    assert np.all(np.isfinite(obs))
    env.reset(seed=0, options={"target": [[0, 0], [30, 0]]})


def test_image_observation_shows_the_routes_corridor_keepouts_and_pads(rkw: dict) -> None:
    """The default image layers show what the score counts: a keep-out or a pad changes
    the image; "path" (the image before) shows only the route's line, so it does not."""
    from cnt_env.task import raster

    open_route = {"waypoints": [[0, 0], [40, 0], [40, 30]], "width": 6.0}
    keep = dict(open_route, keepouts=[{"rect": [10, 10, 25, 20]}])
    pads = dict(open_route, pads=[[[30, -8], [30, 8]]], pad_width=4.0)
    obs: dict[tuple[str, str], np.ndarray] = {}
    for layers in ("route", "path"):
        env = CNTDepositEnv(**rkw, obs_mode="image", image_layers=layers)
        for name, route in (("open", open_route), ("keep", keep), ("pads", pads)):
            obs[layers, name] = env.reset(seed=0, options={"target": route})[0]
            assert env.observation_space.contains(obs[layers, name])
    assert np.array_equal(obs["path", "open"], obs["path", "keep"])
    assert np.array_equal(obs["path", "open"], obs["path", "pads"])
    route_open = obs["route", "open"]
    # the view is centred on the route's start; the band: pixel centres within 6 L_vb of
    # the first leg, (0, 0)-(40, 0) (the second, at x = 40, is out of the view)
    k = np.arange(64) + 0.5 - 32
    x, z = np.meshgrid(k, k[::-1])
    band = np.hypot(np.maximum.reduce([-x, np.zeros_like(x), x - 40]), z) <= 6.0
    assert np.array_equal(route_open[..., 1] > 0, band)
    assert np.count_nonzero(route_open[..., 1] == raster.CORRIDOR_VALUE) > 12 * 30
    assert not np.any(route_open[..., 2] == raster.KEEPOUT_VALUE)
    assert np.count_nonzero(obs["route", "keep"][..., 2] == raster.KEEPOUT_VALUE) >= 15 * 10
    assert np.count_nonzero(obs["route", "pads"][..., 2] == raster.PAD_VALUE) >= 4 * 16
    # the trace and the route's line are the same pixels in both layer sets
    for name in ("open", "keep", "pads"):
        assert np.array_equal(obs["route", name][..., 0], obs["path", name][..., 0])
    with pytest.raises(ValueError, match="image_layers"):
        CNTDepositEnv(**rkw, obs_mode="image", image_layers="all")


def test_dict_observation_is_the_image_and_the_vector_of_the_same_episode(rkw: dict) -> None:
    """obs_mode="dict" holds exactly the image and the vector that the "image" and
    "vector" envs give on the same seed, route and actions (one simulation, two views)."""
    route = {"waypoints": [[0, 0], [40, 0], [40, 30]], "width": 6.0,
             "keepouts": [{"rect": [10, 10, 25, 20]}]}  # fmt: skip
    acts = [np.array([1.0, 0.0], np.float32), np.array([0.3, 0.8], np.float32)]
    seen: dict[str, list] = {}
    for mode in ("vector", "image", "dict"):
        env = CNTDepositEnv(**rkw, obs_mode=mode)
        obs = [env.reset(seed=3, options={"target": route})[0]]
        obs += [env.step(a)[0] for a in acts]
        seen[mode] = obs
        assert all(env.observation_space.contains(o) for o in obs)
    for d, image, vector in zip(seen["dict"], seen["image"], seen["vector"], strict=True):
        assert set(d) == {"image", "vector"}
        assert np.array_equal(d["image"], image) and np.array_equal(d["vector"], vector)
    assert not np.array_equal(seen["dict"][0]["image"], seen["dict"][-1]["image"])


def test_route_episode_truncates_at_its_length_and_completes(rkw: dict) -> None:
    env = CNTDepositEnv(**rkw)
    env.reset(seed=0, options={"target": [[0.0, 0.0], [0.0, -400.0]]})
    assert env.max_episode_steps > 1000  # long route, long episode
    env.reset(seed=0, options={"target": [[0.0, 0.0], [1.5, 0.0]]})
    n, k, term, trunc = env.max_episode_steps, 0, False, False
    while not (term or trunc):
        _, _, term, trunc, info = env.step(np.zeros(2, np.float32))
        k += 1
    # a 1.5 L_vb route inside a 15 L_vb corridor is completed by the first nodes laid
    assert term and info["completed"] and info["is_success"] and k < n


def test_a_route_completed_through_a_keep_out_ends_but_is_no_success(rkw: dict) -> None:
    """Completion terminates; ``is_success`` also asks for no short. The small rod lays
    its trace along +x at z = 0; the route goes down 1 and along x = 0..3 at z = -1 (its
    corridor holds the trace), and a keep-out over x in [1, 2] beside the route's leg lies
    on the trace. Without the keep-out the same episode is a success."""
    env = CNTDepositEnv(**rkw)
    route = {"waypoints": [[0.0, 0.0], [0.0, -1.0], [3.0, -1.0]]}
    keep = [[1.0, -0.5], [2.0, -0.5], [2.0, 0.5], [1.0, 0.5]]
    seen = {}
    for name, target in (("clear", route), ("keep-out", dict(route, keepouts=[keep]))):
        env.reset(seed=0, options={"target": target})
        term = trunc = False
        while not (term or trunc):
            _, _, term, trunc, info = env.step(np.array([1.0, 0.0], np.float32))
        assert term and not trunc and info["completed"], name
        seen[name] = info
    assert seen["clear"]["is_success"] and seen["clear"]["short_length"] == 0.0
    bad = seen["keep-out"]
    assert bad["short_length"] > 0 and bad["shorts"] > 0 and not bad["is_success"]
    assert 0.0 < bad["score"] < seen["clear"]["score"]


def test_route_families_draw_deterministically(rkw: dict) -> None:
    from cnt_env.task import routes

    for fam in routes.FAMILIES:
        env = CNTDepositEnv(**dict(rkw, families=fam, difficulty=0.9))
        a = env.reset(seed=5)[1]
        b = env.reset(seed=5)[1]
        assert a["target"] == b["target"] == fam
        assert a["target_length"] == b["target_length"]


def test_route_task_is_deterministic_and_pickles(rkw: dict) -> None:
    a, b = make(rkw), make(rkw)
    acts = actions(4, 10)
    for i, (sa, sb) in enumerate(zip(rollout(a, acts, seed=11), rollout(b, acts, seed=11),
                                     strict=True)):  # fmt: skip
        if len(sa) == 2:
            assert_same(sa, sb, f"reset {i}")
        else:
            assert_same_step(sa, sb, f"step {i}")
    copy = pickle.loads(pickle.dumps(a))
    more = actions(5, 6)
    for i, (sa, sb) in enumerate(zip(rollout(a, more), rollout(copy, more), strict=True)):
        if len(sa) == 5:
            assert_same_step(sa, sb, f"after pickling, step {i}")


def test_record_video_writes_an_mp4(kw: dict, tmp_path) -> None:
    pytest.importorskip("moviepy", reason="the video extra (pip install -e '.[video]')")
    from gymnasium.wrappers import RecordVideo

    folder = tmp_path / "videos"  # a new folder: RecordVideo warns when it exists
    env = RecordVideo(make(kw, render_mode="rgb_array", render_size=128), str(folder),
                      episode_trigger=lambda i: True, disable_logger=True)  # fmt: skip
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.zeros(2, np.float32))
    env.close()
    videos = list(folder.glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000


def test_a_difficulty_range_gives_each_drawn_route_its_own() -> None:
    """difficulty=[lo, hi]: each drawn route takes a difficulty uniform in the range, so
    the corridor half-width (20 at difficulty 0 down to 13 at 1, +-1, x ROUTE_SCALE)
    spreads over the range's widths, not one value's +-1; the same seed draws the same
    route; [d, d] is the number d, stream and all."""
    from cnt_env.task import routes

    small = {k: v for k, v in SMALL.items() if k != "score"}  # the route task

    def widths(difficulty: object, seeds: range) -> list[float]:
        env = CNTDepositEnv(**small, families="straight", difficulty=difficulty)
        out = []
        for seed in seeds:
            env.reset(seed=seed)
            out.append(env.target.width / routes.ROUTE_SCALE)
        return out

    ranged = widths([0.0, 1.0], range(12))
    assert min(ranged) >= 12.0 and max(ranged) <= 21.0
    assert max(ranged) - min(ranged) > 3.0  # one difficulty spreads over 2 at most
    fixed = widths(0.5, range(12))
    assert max(fixed) - min(fixed) <= 2.0
    assert widths([0.0, 1.0], range(3)) == ranged[:3]
    assert widths([0.5, 0.5], range(3)) == fixed[:3]


def test_set_route_draw_changes_the_next_routes_and_refuses_bad_values() -> None:
    """CNTDeposit-v0.set_route_draw (a curriculum's hook): the next reset draws from the
    new families at the new difficulty; None keeps a value; a bad value raises before
    either changes."""
    small = {k: v for k, v in SMALL.items() if k != "score"}  # the route task
    env = CNTDepositEnv(**small, families=["straight", "detour"], difficulty=0.5)
    env.set_route_draw(families="arc")
    assert env.families == ("arc",) and env.difficulty == 0.5
    _, info = env.reset(seed=0)
    assert info["target"] == "arc"
    env.set_route_draw(difficulty=0.1)
    assert env.families == ("arc",) and env.difficulty == 0.1
    for bad in ({"families": ["arc", "spiral"], "difficulty": 0.9}, {"families": "pads",
                                                                      "difficulty": -0.1},
                {"families": [], "difficulty": 0.9}, {"difficulty": float("nan")}):  # fmt: skip
        with pytest.raises(ValueError):
            env.set_route_draw(**bad)
        assert env.families == ("arc",) and env.difficulty == 0.1


def test_route_file_draws_your_own_routes(tmp_path) -> None:
    """route_file: a reset without a target draws one of the file's routes with
    np_random (the same seed, the same route); an explicit target still wins; a bad file
    or the thin task is refused at construction."""
    import json

    from cnt_env.task.env import CNTDepositEnv

    mine = {"jog": {"waypoints": [[0, 0], [30, 0], [30, 20]], "width": 15.0},
            "run": {"waypoints": [[0, 0], [0, 40]]}}  # fmt: skip
    path = tmp_path / "mine.json"
    path.write_text(json.dumps(mine))
    env = CNTDepositEnv(**{**SMALL, "score": "corridor", "route_file": str(path)})
    names = []
    for seed in range(8):
        env.reset(seed=seed)
        names.append(env.target.name)
    assert set(names) == {"jog", "run"}
    again = []
    for seed in range(8):
        env.reset(seed=seed)
        again.append(env.target.name)
    assert again == names
    env.reset(seed=0, options={"target": "u_turn"})
    assert env.target.name == "u_turn"
    env.close()
    path.write_text('[{"waypoints": [[0, 0], [9, 0]]}]')
    with pytest.raises(ValueError, match="give every route a 'name'"):
        CNTDepositEnv(**{**SMALL, "score": "corridor", "route_file": str(path)})
    with pytest.raises(ValueError, match="route_file needs the route task"):
        CNTDepositEnv(**SMALL, route_file=str(path))


def test_a_mirrored_start_lays_the_mirror_image_of_the_episode(kw) -> None:
    """``start_mirror="always"`` starts from the warm state's mirror image in z: with the
    route and every action mirrored too, the episode is the mirror image of the original
    one, to the last bit: the observation is ``z_mirror`` of the original's (the route
    task's observation, keep-out point included, and one with no keep-out) and the rewards
    are equal."""
    from cnt_env.task.spaces import ACTION_Z_MIRROR

    keep = [{"rect": [10.0, 4.0, 20.0, 12.0]}]
    route = {"waypoints": [[0.0, 0.0], [30.0, 0.0], [30.0, 20.0]], "keepouts": keep}
    mirrored_keep = [{"rect": [10.0, -12.0, 20.0, -4.0]}]
    mirrored = {"waypoints": [[0.0, 0.0], [30.0, 0.0], [30.0, -20.0]],
                "keepouts": mirrored_keep}  # fmt: skip
    for pair in ((route, mirrored), ({"waypoints": route["waypoints"]},
                                     {"waypoints": mirrored["waypoints"]})):  # fmt: skip
        plain = make(kw, score="corridor")
        mirror = make(kw, score="corridor", start_mirror="always")
        z_mirror = plain.unwrapped.layout.z_mirror
        o1, i1 = plain.reset(seed=4, options={"target": pair[0]})
        o2, i2 = mirror.reset(seed=4, options={"target": pair[1]})
        assert not i1["start_mirrored"] and i2["start_mirrored"]
        assert np.array_equal(o2, z_mirror(o1)) and not np.array_equal(o2, o1)
        for a in actions(2, 4):
            o1, r1, *_ = plain.step(a)
            o2, r2, *_ = mirror.step(a * ACTION_Z_MIRROR)
            assert np.array_equal(o2, z_mirror(o1)) and r1 == r2
        plain.close()
        mirror.close()


def test_start_mirror_random_draws_from_np_random_and_is_checked(kw) -> None:
    env = make(kw, start_mirror="random")
    drawn = [env.reset(seed=s)[1]["start_mirrored"] for s in range(8)]
    assert set(drawn) == {True, False}
    assert drawn == [env.reset(seed=s)[1]["start_mirrored"] for s in range(8)]
    env.close()
    with pytest.raises(ValueError, match="start_mirror"):
        make(kw, start_mirror="sometimes")

"""Baseline policies: the shared interface, the flow <-> action inverse, the offline
score of the constant-flow search against the env's own, the scripted heuristic's
direction and speed rule, and the SB3 loader on the pretrained models."""

from __future__ import annotations

import math

import gymnasium
import numpy as np
import pytest

from cnt_env.sim import warmstart
from cnt_env.task import targets as T
from cnt_env.task.env import flow_from_action
from policies import (
    PRETRAINED_DIR,
    ConstantPolicy,
    Policy,
    RandomPolicy,
    ScriptedPolicy,
    action_from_flow,
    load_policy,
)
from policies.constant import record_constant, score_trace
from policies.scripted import amplitude_curve

SMALL = dict(Hbar=30.0, Ibar=200.0, initial_radius=4.0, warmup_length=3.0,
             control_interval=15.0, reset_advance=2.0, pattern_every=0,
             sim_options={"dt_factor": 0.05}, score="thin")  # fmt: skip


@pytest.fixture(scope="module", autouse=True)
def _cache(tmp_path_factory: pytest.TempPathFactory):
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(warmstart.CACHE_ENV_VAR, str(tmp_path_factory.mktemp("warm_cache")))
        yield


@pytest.mark.parametrize("vbar", [0.0, 0.02, 0.065, 0.13])
@pytest.mark.parametrize("phi", np.linspace(-math.pi, math.pi, 9)[:-1].tolist())
def test_action_from_flow_inverts_the_env_map(vbar: float, phi: float) -> None:
    a = action_from_flow(vbar, phi, 0.13)
    assert a.dtype == np.float32 and np.all(np.abs(a) <= 1.0)
    v, p = flow_from_action(a, 0.13)
    assert v == pytest.approx(vbar, abs=1e-6)
    if vbar > 0:
        assert math.remainder(p - phi, 2 * math.pi) == pytest.approx(0.0, abs=1e-5)


def test_interface_and_random_seeding() -> None:
    obs = np.zeros(81, dtype=np.float32)
    rnd = RandomPolicy()
    for pol in (rnd, ConstantPolicy(0.05, 1.0, 0.13), ScriptedPolicy(slice(32, 64), 0.13)):
        assert isinstance(pol, Policy)
        pol.reset(0)
        assert pol.act(obs).shape == (2,)
    rnd.reset(5)
    first = [rnd.act(obs) for _ in range(3)]
    rnd.reset(5)
    assert np.array_equal(first, [rnd.act(obs) for _ in range(3)])


def test_scripted_points_along_the_target_and_slows_for_wide_targets() -> None:
    pol = ScriptedPolicy(slice(0, 32), 0.13)
    ahead = np.column_stack([np.zeros(16), 2.0 * np.arange(1, 17)])  # straight along +z
    vbar, phi = flow_from_action(pol.act(ahead.ravel()), 0.13)
    assert phi == pytest.approx(math.pi / 2, abs=1e-5)
    v, a, _ = amplitude_curve()
    assert vbar == pytest.approx(v[np.argmin(a)], rel=1e-4)  # straight: smallest amplitude
    assert pol.speed_for(float(a.max())) <= pol.speed_for(float(a.min()))


def test_offline_score_matches_the_env() -> None:
    env = gymnasium.make("CNTDeposit-v0", max_episode_steps=30, **SMALL)
    ct = record_constant(env, 0.1, 0.7, seed=2, max_steps=30)
    base = env.unwrapped
    for name in ("jog", "s_curve"):
        off = score_trace(ct.trace, T.held_out(name).points, base.tolerance,
                          tuple(base.weights), ct.n_after_step)  # fmt: skip
        env.reset(seed=2, options={"target": name})
        pol = ConstantPolicy(0.1, 0.7, base.vbar_max)
        for _ in range(30):
            _, _, term, trunc, info = env.step(pol.act(None))
            if term or trunc:
                break
        assert off["score"] == pytest.approx(info["score"], abs=0.02)
        assert off["precision"] == pytest.approx(info["precision"], abs=0.02)
    env.close()


@pytest.mark.skipif(not (PRETRAINED_DIR / "ppo.zip").is_file(), reason="no pretrained models")
@pytest.mark.parametrize("name", ["ppo", "sac", "ppo_residual"])
def test_pretrained_models_load_with_their_normalisation(name: str) -> None:
    pol = load_policy(PRETRAINED_DIR / f"{name}.zip")
    assert pol.vecnormalize is not None and pol.vecnormalize.obs_rms.mean.shape == (81,)
    assert (pol.base is not None) == (name == "ppo_residual")
    obs = np.zeros(81, dtype=np.float32)
    obs[32:64] = np.column_stack([2.0 * np.arange(1, 17), np.zeros(16)]).ravel()
    a = pol.act(obs)
    assert a.shape == (2,) and np.all(np.abs(a) <= 1.0)

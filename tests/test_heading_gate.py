"""keepout_headings (policies/residual.py HeadingGate): the routes with a keep-out that a
residual agent hands to the route follower, read off an episode's first observation; at
inference (SB3Policy) and in the training wrapper (training.common.ResidualAction) alike."""

from __future__ import annotations

import numpy as np
import pytest

from policies import PRETRAINED_DIR, RouteFollower, load_policy
from policies.opening import axis_of
from policies.residual import HeadingGate, has_keepout

pytestmark = pytest.mark.usefixtures("temp_warm_cache")
AGENT = PRETRAINED_DIR / "ppo_residual.zip"
BLOCK = [{"rect": [-40.0, -90.0, -10.0, -70.0]}]  # beside the second leg of DOWN
DOWN = {"waypoints": [[0.0, 0.0], [0.0, -60.0], [40.0, -60.0]], "keepouts": BLOCK}
DOWN_OPEN = {"waypoints": [[0.0, 0.0], [0.0, -60.0], [40.0, -60.0]]}
OUT = {"waypoints": [[0.0, 0.0], [60.0, 0.0], [60.0, 40.0]], "keepouts": BLOCK}


@pytest.mark.parametrize(
    ("d", "axis"),
    [((3, 1), "+x"), ((-3, 1), "-x"), ((1, 3), "+z"), ((1, -3), "-z"), ((2, -2), "+x"),
     ((-2, 2), "-x"), ((0, 0), "+x")],
)  # fmt: skip
def test_axis_of_is_the_nearest_axis_x_on_a_tie(d, axis) -> None:
    assert axis_of(*d) == axis


@pytest.mark.parametrize("headings", ["-z", ["z"], ["-y"], ["-z", "down"]])
def test_a_bad_heading_is_refused(headings, agent_env) -> None:
    with pytest.raises(ValueError, match="keepout_headings"):
        HeadingGate(headings, {}, agent_env)


def _actions(policy, env, route, n: int = 2) -> list[np.ndarray]:
    obs, _ = env.reset(seed=3, options={"target": route})
    policy.reset(3)
    out = []
    for _ in range(n):
        a = policy.act(obs)
        out.append(a)
        obs, *_ = env.step(a)
    return out


@pytest.mark.skipif(not AGENT.is_file(), reason="no pretrained models")
def test_the_agent_hands_a_gated_route_to_the_follower_only(agent_env) -> None:
    env = agent_env
    gated = load_policy(AGENT, env=env, keepout_headings=("-z",))
    plain = load_policy(AGENT, env=env, keepout_headings=())
    follower = RouteFollower.from_env(env)  # the follower with its defaults, not the base
    on_down = _actions(gated, env, DOWN)
    assert gated.gate.deferred
    assert np.array_equal(on_down, _actions(follower, env, DOWN))
    assert not np.array_equal(on_down, _actions(plain, env, DOWN))
    for route in (OUT, DOWN_OPEN):  # another heading; no keep-out: the agent as it is
        on_route = _actions(gated, env, route)
        assert not gated.gate.deferred
        assert np.array_equal(on_route, _actions(plain, env, route))


@pytest.mark.skipif(not AGENT.is_file(), reason="no pretrained models")
def test_keepout_headings_needs_a_residual_agent() -> None:
    with pytest.raises(ValueError, match="residual agent"):
        load_policy(PRETRAINED_DIR / "ppo.zip", keepout_headings=("-z",))


def test_the_training_wrapper_ignores_the_action_on_a_gated_route(agent_env) -> None:
    from training.common import ResidualAction

    env = agent_env

    def first_obs(headings, route, action) -> np.ndarray:
        w = ResidualAction(env, scale=1.0, keepout_headings=headings)
        w.reset(seed=3, options={"target": route})
        return w.step(np.asarray(action, dtype=np.float32))[0]

    down = [first_obs(("-z",), DOWN, a) for a in ([1.0, 1.0], [-1.0, -1.0])]
    assert np.array_equal(*down)  # the follower plays: the agent's action has no effect
    for route in (OUT, DOWN_OPEN):
        other = [first_obs(("-z",), route, a) for a in ([1.0, 1.0], [-1.0, -1.0])]
        assert not np.array_equal(*other)


def test_has_keepout_reads_the_far_point_as_none(agent_env) -> None:
    env = agent_env
    slices = env.unwrapped.observation_slices
    with_one = env.reset(seed=0, options={"target": DOWN})[0]
    without = env.reset(seed=0, options={"target": DOWN_OPEN})[0]
    assert has_keepout(with_one, slices) and not has_keepout(without, slices)
    assert not has_keepout(with_one, {"trace": slice(0, 2)})  # the thin task: no route slice


def test_a_gate_needs_the_route_tasks_env() -> None:
    with pytest.raises(ValueError, match="route task"):
        HeadingGate(["-z"], {}, None)
    assert HeadingGate([], {}, None).fallback is None  # no headings: nothing to hand over


@pytest.mark.skipif(not AGENT.is_file(), reason="no pretrained models")
def test_the_shipped_gate_hands_over_no_held_out_route(agent_env) -> None:
    """The committed held-out scores of the shipped agent were measured before its gate."""
    from cnt_env.task import routes

    env = agent_env
    agent = load_policy(AGENT, env=env)
    assert agent.gate.headings == ("-z",)
    for seed in (0, 1, 2):
        for name in routes.HELD_OUT:
            obs, _ = env.reset(seed=seed, options={"target": name})
            agent.reset(seed)
            agent.act(obs)
            assert not agent.gate.deferred, name

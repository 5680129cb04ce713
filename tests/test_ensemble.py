"""Agents combined (policies/ensemble.py): ``a+b`` (MeanPolicy) plays the mean of its
members' actions; ``a|b`` (KeepoutSplit) plays agent a on routes without a keep-out and
agent b on routes with one, chosen at an episode's first observation, and in
cnt-evaluate lays each member's own traces bit for bit."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from policies import PRETRAINED_DIR
from policies.ensemble import KeepoutSplit, MeanPolicy

pytestmark = pytest.mark.usefixtures("temp_warm_cache")
BLOCK = [{"rect": [-40.0, -90.0, -10.0, -70.0]}]
WITH = {"waypoints": [[0.0, 0.0], [60.0, 0.0], [60.0, 40.0]], "keepouts": BLOCK}
WITHOUT = {"waypoints": [[0.0, 0.0], [60.0, 0.0], [60.0, 40.0]]}


class Fixed:
    """An agent that plays one action and records its resets."""

    def __init__(self, a: list[float]) -> None:
        self.a, self.seeds = np.asarray(a, dtype=np.float32), []

    def reset(self, seed=None) -> None:
        self.seeds.append(seed)

    def act(self, obs):
        return self.a


def test_mean_policy_plays_the_mean_of_its_members() -> None:
    """The members' mean, in [-1, 1]; reset reaches every member; one member is not an
    ensemble."""
    members = [Fixed([1.0, -1.0]), Fixed([0.0, -1.0]), Fixed([-0.5, 0.25])]
    ens = MeanPolicy(members)
    ens.reset(7)
    assert all(m.seeds == [7] for m in members)
    out = ens.act(np.zeros(3))
    assert out.dtype == np.float32
    np.testing.assert_allclose(out, [1.0 / 6.0, -0.5833333], rtol=1e-6)
    with pytest.raises(ValueError, match="at least two"):
        MeanPolicy(members[:1])


def test_the_split_plays_one_agent_per_route_kind_for_the_whole_episode(agent_env) -> None:
    env = agent_env
    a, b = Fixed([0.5, 0.0]), Fixed([-0.5, 0.25])
    split = KeepoutSplit(a, b, env.unwrapped.observation_slices)
    for route, agent in ((WITH, b), (WITHOUT, a), (WITH, b)):
        obs, _ = env.reset(seed=4, options={"target": route})
        split.reset(4)
        for _ in range(2):  # later observations do not switch agents
            act = split.act(obs)
            assert act.dtype == np.float32 and np.array_equal(act, agent.a)
            obs, *_ = env.step(act)
    assert a.seeds == [4] and b.seeds == [4, 4]  # only the chosen agent is reset
    with pytest.raises(ValueError, match="route"):
        KeepoutSplit(a, b, {})


@pytest.mark.parametrize("name", ["a|b|c", "a|", "|b", "a+b|c"])
def test_a_malformed_split_is_refused(name: str) -> None:
    from training.evaluate import ensemble_members

    with pytest.raises(ValueError, match="two model names"):
        ensemble_members(name)


@pytest.mark.skipif(not (PRETRAINED_DIR / "ppo.zip").is_file(), reason="no pretrained models")
def test_evaluate_plays_a_split_named_a_bar_b(tmp_path: Path) -> None:
    """On an open route ``ppo_residual|ppo`` lays ppo_residual's trace, on a route with a
    keep-out ppo's, bit for bit."""
    from training.common import load_config
    from training.evaluate import evaluate

    config = load_config(PRETRAINED_DIR / "ppo_residual.yml")
    config["env_kwargs"]["max_episode_steps"] = 3
    names = ["ppo_residual", "ppo", "ppo_residual|ppo"]
    evaluate(names, ["u_turn", "detour_block"], [0], config, tmp_path, jobs=1)
    rows = json.loads((tmp_path / "episodes.json").read_text())
    traces = np.load(tmp_path / "traces.npz")
    by = {(r["policy"], r["target"]): traces[f"trace_{i}"] for i, r in enumerate(rows)}
    np.testing.assert_array_equal(by["ppo_residual|ppo", "u_turn"], by["ppo_residual", "u_turn"])
    np.testing.assert_array_equal(by["ppo_residual|ppo", "detour_block"], by["ppo", "detour_block"])
    assert not np.array_equal(by["ppo", "detour_block"], by["ppo_residual", "detour_block"])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["models"]["ppo_residual|ppo"].count("|") == 1


def test_cnt_evaluate_refuses_a_malformed_split_before_any_run(tmp_path: Path) -> None:
    from training.evaluate import main

    with pytest.raises(SystemExit) as exc:
        main(["--policies", "ppo_residual|ppo|sac", "--out", str(tmp_path / "x")])
    assert exc.value.code == 2 and not (tmp_path / "x").exists()

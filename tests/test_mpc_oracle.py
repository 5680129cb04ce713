"""benchmarks/mpc_oracle.py plays the env the held-out scores are measured on.

The oracle judges the goal's margin (follower + half its gap) against the physics, so its
env must be ``cnt-evaluate``'s. Until 2026-12-02 it read the training config, which has
pinned the fast surrogate since 2026-11-26, and measured the wrong model.
"""

from __future__ import annotations

import pytest

from benchmarks import mpc_oracle  # the repo root is on pytest's pythonpath
from training.common import env_settings, load_config
from training.evaluate import build_parser


def _oracle_config(argv: list[str]) -> str:
    _, jobs = mpc_oracle.parse_jobs(argv)
    assert {job["config"] for job in jobs} == {jobs[0]["config"]}
    return jobs[0]["config"]


def test_the_oracle_plays_the_evaluation_env_by_default() -> None:
    oracle = _oracle_config(["--targets", "u_turn"])
    evaluation = build_parser().parse_args([]).config
    assert env_settings(load_config(oracle)) == env_settings(load_config(evaluation))
    # and the training config, which pins the surrogate, is another env
    training = mpc_oracle.ROOT / "training/configs/ppo.yml"
    assert env_settings(load_config(training)) != env_settings(load_config(evaluation))


def test_the_oracle_takes_another_config() -> None:
    other = mpc_oracle.ROOT / "training/configs/ppo.yml"
    assert _oracle_config(["--targets", "u_turn", "--config", str(other)]) == str(other)


def test_the_follower_study_plays_the_evaluation_env_by_default() -> None:
    """The follower is scored on cnt-evaluate's env, so its options are studied there."""
    from benchmarks import follower_study

    study = follower_study.build_parser().parse_args([]).config
    evaluation = build_parser().parse_args([]).config
    assert env_settings(load_config(study)) == env_settings(load_config(evaluation))


def test_the_oracle_takes_a_horizon_and_one_mode() -> None:
    _, jobs = mpc_oracle.parse_jobs(["--targets", "u_turn", "--horizon", "3", "--modes", "oracle"])
    assert [(j["mode"], j["horizon"]) for j in jobs] == [("oracle", 3)]
    _, jobs = mpc_oracle.parse_jobs(["--targets", "u_turn"])
    assert [(j["mode"], j["horizon"]) for j in jobs] == [("oracle", None), ("follower", None)]
    assert not any(j["confirm"] for j in jobs)
    _, jobs = mpc_oracle.parse_jobs(["--targets", "u_turn", "--horizon", "5", "--confirm"])
    assert all(j["confirm"] and j["horizon"] == 5 for j in jobs)


@pytest.mark.parametrize(
    "argv", [["--horizon", "-1"], ["--horizon", "x"], ["--modes", "planner"], ["--confirm"]]
)
def test_the_oracle_refuses_a_bad_horizon_or_mode(argv: list[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        mpc_oracle.parse_jobs(["--targets", "u_turn", *argv])
    assert exc.value.code == 2

"""benchmarks/mpc_oracle.py plays the env the held-out scores are measured on.

The oracle judges the goal's margin (follower + half its gap) against the physics, so its
env must be ``cnt-evaluate``'s. Until 2026-12-02 it read the training config, which has
pinned the fast surrogate since 2026-11-26, and measured the wrong model.
"""

from __future__ import annotations

from typing import ClassVar

from benchmarks import mpc_oracle  # the repo root is on pytest's pythonpath
from training.common import env_settings, load_config
from training.evaluate import build_parser


class _Stop(Exception):
    pass


class _Pool:
    """Stands in for the process pool: records the first job and runs nothing."""

    seen: ClassVar[dict] = {}

    def __init__(self, *args, **kwargs) -> None:
        pass

    def __enter__(self) -> _Pool:
        return self

    def __exit__(self, *exc) -> None:
        return None

    def map(self, fn, jobs):
        _Pool.seen = next(iter(jobs))
        raise _Stop


def _oracle_config(argv: list[str], monkeypatch) -> str:
    monkeypatch.setattr(mpc_oracle, "ProcessPoolExecutor", _Pool)
    try:
        mpc_oracle.main(argv)
    except _Stop:
        pass
    return _Pool.seen["config"]


def test_the_oracle_plays_the_evaluation_env_by_default(tmp_path, monkeypatch) -> None:
    argv = ["--targets", "u_turn", "--out", str(tmp_path / "o.jsonl")]
    oracle = _oracle_config(argv, monkeypatch)
    evaluation = build_parser().parse_args([]).config
    assert env_settings(load_config(oracle)) == env_settings(load_config(evaluation))
    # and the training config, which pins the surrogate, is another env
    training = mpc_oracle.ROOT / "training/configs/ppo.yml"
    assert env_settings(load_config(training)) != env_settings(load_config(evaluation))


def test_the_oracle_takes_another_config(tmp_path, monkeypatch) -> None:
    other = mpc_oracle.ROOT / "training/configs/ppo.yml"
    argv = ["--targets", "u_turn", "--config", str(other), "--out", str(tmp_path / "o.jsonl")]
    assert _oracle_config(argv, monkeypatch) == str(other)

"""The RLlib path (training/rllib.py): a local Ray with 2 env runners trains for a few
iterations, writes a checkpoint, and the checkpoint acts through the policy interface.
Slow (Ray start-up and worker compile) and skipped without the ``[ray]`` extra."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("ray.rllib")

pytestmark = pytest.mark.slow


def test_rllib_trains_on_two_env_runners_and_the_checkpoint_acts(tmp_path: Path) -> None:
    import gymnasium as gym

    import cnt_env  # noqa: F401
    from training.common import CONFIG_DIR
    from training.rllib import RLlibPolicy, train_rllib

    out = tmp_path / "run"
    summary = train_rllib(CONFIG_DIR / "ppo.yml", timesteps=1, env_runners=2, out=out)
    assert summary["env_runners"] == 2 and summary["env_steps"] > 0
    assert (out / "summary.json").exists()
    policy = RLlibPolicy(out / "checkpoint")
    env = gym.make("CNTDeposit-v0", max_episode_steps=3)
    obs, _ = env.reset(seed=0)
    action = policy.act(obs)
    assert action.shape == (2,) and env.action_space.contains(action)
    assert np.all(np.isfinite(action))
    # a run directory is never overwritten
    with pytest.raises(FileExistsError, match="not empty"):
        train_rllib(CONFIG_DIR / "ppo.yml", timesteps=1, env_runners=1, out=out)

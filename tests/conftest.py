"""Shared fixtures."""

from __future__ import annotations

import pytest

from cnt_env.sim import warmstart


@pytest.fixture(scope="module")
def temp_warm_cache(tmp_path_factory: pytest.TempPathFactory):
    """The warm-state cache of a test module: a temporary directory (through the
    environment, so subprocess workers inherit it), never the user's cache. Use it with
    ``pytestmark = pytest.mark.usefixtures("temp_warm_cache")``."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(warmstart.CACHE_ENV_VAR, str(tmp_path_factory.mktemp("warm_cache")))
        yield


@pytest.fixture
def agent_env():
    """CNTDeposit-v0 with the shipped residual agent's env settings
    (policies/pretrained/ppo_residual.yml), closed after the test."""
    import gymnasium as gym

    from policies import PRETRAINED_DIR
    from training.common import env_settings, load_config

    env_kwargs, _ = env_settings(load_config(PRETRAINED_DIR / "ppo_residual.yml"))
    env = gym.make("CNTDeposit-v0", **env_kwargs)
    yield env
    env.close()

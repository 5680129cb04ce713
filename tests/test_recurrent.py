"""A recurrent policy (sb3-contrib's RecurrentPPO, ``--algo ppo_lstm``): it trains through
cnt-train, loads without unpickling, and at inference carries its LSTM state through an
episode and starts each episode from a zero state, as SB3's own evaluation loop does."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from policies import load_policy
from policies.sb3 import (
    ALGOS,
    UntrustedModelError,
    algo_class,
    algo_of,
    safe_custom_objects,
)
from tests.smallrod import play, tiny_config

pytestmark = pytest.mark.usefixtures("temp_warm_cache")


def _lstm_config() -> dict:
    return {**tiny_config(), "n_timesteps": 64, "policy": "MlpLstmPolicy",
            "policy_kwargs": {"net_arch": [16], "lstm_hidden_size": 8}}  # fmt: skip


@pytest.fixture(scope="module")
def lstm_model(tmp_path_factory: pytest.TempPathFactory, temp_warm_cache) -> Path:
    from training.train import train

    out = tmp_path_factory.mktemp("lstm")
    return train("ppo_lstm", _lstm_config(), out / "run", seed=5, progress_bar=False)


def test_the_algorithm_is_read_from_the_name_longest_first(tmp_path: Path) -> None:
    assert algo_of(tmp_path / "ppo_lstm.zip") == "ppo_lstm"
    assert algo_of(tmp_path / "best_ppo_lstm_model.zip") == "ppo_lstm"
    assert algo_of(tmp_path / "ppo.zip") == "ppo"
    assert algo_class("ppo_lstm").__name__ == "RecurrentPPO"
    with pytest.raises(ValueError, match="unknown algorithm"):
        algo_class("a2c")


def test_every_algorithm_has_a_default_config() -> None:
    """cnt-train --algo A without --config reads a config that exists; ppo_lstm's is the
    recurrent recipe, whose policy is an LSTM one."""
    from training.common import CONFIG_DIR, load_config
    from training.train import DEFAULT_CONFIG

    for algo in ALGOS:
        config = load_config(CONFIG_DIR / DEFAULT_CONFIG.get(algo, f"{algo}.yml"))
        assert ("Lstm" in config["policy"]) == (algo == "ppo_lstm"), algo


def test_a_recurrent_run_saves_a_model_that_loads_safely_and_as_trusted(lstm_model: Path) -> None:
    assert lstm_model.name == "ppo_lstm.zip"
    custom = safe_custom_objects(lstm_model, "ppo_lstm")  # nothing is unpickled
    assert custom["policy_class"].__name__ == "RecurrentActorCriticPolicy"
    # read as a plain PPO zip, its policy class is not on PPO's allowlist
    with pytest.raises(UntrustedModelError, match="policy_class"):
        safe_custom_objects(lstm_model, "ppo")
    safe, trusted = load_policy(lstm_model), load_policy(lstm_model, trust=True)
    assert safe.recurrent and trusted.recurrent
    assert np.array_equal(np.array(play(safe, 3, 6)[1]), np.array(play(trusted, 3, 6)[1]))


def test_the_lstm_state_is_carried_within_an_episode_and_reset_between(lstm_model: Path) -> None:
    """The policy's actions are SB3's own predict with the state carried and
    ``episode_start`` true at the first step only; the same observation gives another
    action once the state has moved; a new episode (reset) starts from a zero state."""
    policy = load_policy(lstm_model)
    observations, actions = play(policy, 3, 6)
    model, stats = policy.model, policy.vecnormalize
    state, ref = None, []
    for i, o in enumerate(observations):
        a, state = model.predict(stats.normalize_obs(o[None].astype(np.float32)), state=state,
                                 episode_start=np.array([i == 0]), deterministic=True)  # fmt: skip
        ref.append(np.asarray(a, dtype=np.float32).reshape(-1))
    assert np.array_equal(np.array(actions), np.array(ref))

    # the first observation acted on again mid-episode, with the state it has by then
    again = policy.act(observations[0])
    assert not np.array_equal(again, actions[0]), "the LSTM state should change the action"
    # and after reset the episode is played again bit for bit
    assert np.array_equal(np.array(play(policy, 3, 6)[1]), np.array(actions))


def test_a_recurrent_run_is_deterministic_in_its_seed(tmp_path: Path, lstm_model: Path) -> None:
    from training.train import train

    again = train("ppo_lstm", _lstm_config(), tmp_path / "again", seed=5, progress_bar=False)
    a = np.array(play(load_policy(lstm_model), 4, 6)[1])
    b = np.array(play(load_policy(again), 4, 6)[1])
    assert np.array_equal(a, b)

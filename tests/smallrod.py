"""The small rod the env, policy, replay and training tests run on, and helpers to train
and play on it: Hbar = 30, a 3 L_vb warm-up, and dt = 0.05 Hbar = 1.5 tau, so a control
interval of 15 tau is 10 physics steps. An episode of it takes milliseconds; the default
configuration (the paper's serpentine baseline) is only constructed in those tests."""

from __future__ import annotations

from typing import Any

import numpy as np


def small(pattern_every: int = 0, score: str | None = None, **sim_options: Any) -> dict:
    """The small rod's env keywords: pattern classification every ``pattern_every``
    control steps (0: never), the route task unless ``score`` is given, and the
    simulator's ``sim_options`` over dt_factor 0.05."""
    kwargs: dict[str, Any] = dict(
        Hbar=30.0, Ibar=200.0, initial_radius=4.0, warmup_length=3.0, control_interval=15.0,
        reset_advance=2.0, pattern_every=pattern_every,
        sim_options={"dt_factor": 0.05, **sim_options},
    )  # fmt: skip
    if score is not None:
        kwargs["score"] = score
    return kwargs


#: the training tests' env: the route task, no pattern classification
SMALL = small()


def tiny_config() -> dict:
    """A cnt-train config of a few seconds on the small rod (128 steps, one env)."""
    return {
        "n_timesteps": 128, "policy": "MlpPolicy", "n_envs": 1, "vec_env": "dummy",
        "normalize": {"norm_obs": True, "norm_reward": True}, "max_episode_steps": 30,
        "env_kwargs": SMALL, "n_steps": 64, "batch_size": 32, "n_epochs": 1,
        "policy_kwargs": {"net_arch": [16, 16]},
    }  # fmt: skip


def play(policy, seed: int, steps: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The observations and actions of ``policy`` (reset first) over ``steps`` control
    steps of the small rod's "jog" target from reset seed ``seed``."""
    from training.common import make_env

    env = make_env(SMALL, 30)
    obs, _ = env.reset(seed=seed, options={"target": "jog"})
    policy.reset(seed)
    observations, actions = [], []
    for _ in range(steps):
        a = policy.act(obs)
        observations.append(obs)
        actions.append(a)
        obs, *_ = env.step(a)
    env.close()
    return observations, actions

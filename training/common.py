"""Pieces shared by training and evaluation: configs, env construction, held-out cycling."""

from __future__ import annotations

import copy
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml

from cnt_env.task import targets as targets_mod
from policies.residual import combine, make_base_policy

__all__ = [
    "CONFIG_DIR",
    "ENV_ID",
    "HeldOutCycle",
    "ResidualAction",
    "env_settings",
    "limit_threads",
    "load_config",
    "make_env",
]

ENV_ID = "CNTDeposit-v0"
CONFIG_DIR = Path(__file__).resolve().parent / "configs"
#: Keys of a config entry that are not hyperparameters of the algorithm (rl-zoo style).
NON_ALGO_KEYS = frozenset({
    "n_timesteps", "policy", "n_envs", "normalize", "env_kwargs", "max_episode_steps",
    "eval_freq", "n_eval_episodes", "eval_targets", "save_freq", "vec_env", "residual",
})  # fmt: skip


def limit_threads() -> None:
    """One thread per process: the env is serial and the machine has 2 cores."""
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # pragma: no cover
        pass


def load_config(path: str | Path, env_id: str = ENV_ID) -> dict[str, Any]:
    """The entry ``env_id`` of an rl-zoo style YAML file (a deep copy)."""
    with Path(path).open() as fh:
        data = yaml.safe_load(fh)
    if env_id not in data:
        raise ValueError(f"{path} has no entry {env_id!r}; it has {sorted(data)}")
    return copy.deepcopy(data[env_id])


def env_settings(config: dict[str, Any]) -> tuple[dict[str, Any], int]:
    """``(env_kwargs, max_episode_steps)`` of a config."""
    return dict(config.get("env_kwargs") or {}), int(config["max_episode_steps"])


def make_env(env_kwargs: dict[str, Any], max_episode_steps: int, **extra) -> gym.Env:
    """``gymnasium.make(CNTDeposit-v0)`` with the config's settings."""
    return gym.make(ENV_ID, max_episode_steps=max_episode_steps, **{**env_kwargs, **extra})


class ResidualAction(gym.Wrapper):
    """Residual policy learning (policies/residual.py): the env receives
    clip(base(obs) + scale * a, -1, 1). The base is the scripted heuristic
    (policies/scripted.py), so a barely trained agent already acts like it.

    The wrapper sits below VecNormalize: the base sees the raw observation."""

    def __init__(self, env: gym.Env, base: str = "scripted", scale: float = 0.5) -> None:
        super().__init__(env)
        self.base_name, self.scale = base, float(scale)
        base_env = env.unwrapped
        self.base = make_base_policy(base, base_env.observation_slices["target"],
                                     base_env.vbar_max)  # fmt: skip
        self._obs: np.ndarray | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self.base.reset(seed)
        self._obs = obs
        return obs, info

    def step(self, action):
        a = combine(self.base.act(self._obs), action, self.scale)
        obs, reward, terminated, truncated, info = self.env.step(a)
        self._obs = obs
        return obs, reward, terminated, truncated, info


class HeldOutCycle(gym.Wrapper):
    """Every reset uses the next of ``targets`` (held-out names), in turn: EvalCallback
    episodes then run over the held-out set. Reset seeds are ``seed0 + k``."""

    def __init__(self, env: gym.Env, targets: Sequence[str], seed0: int = 1000) -> None:
        super().__init__(env)
        for t in targets:
            if t not in targets_mod.HELD_OUT:
                raise ValueError(
                    f"{t!r} is not a held-out target; choose from {targets_mod.HELD_OUT}"
                )
        self.targets = tuple(targets)
        self.seed0 = int(seed0)
        self._k = 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        target = self.targets[self._k % len(self.targets)]
        seed = self.seed0 + (self._k // len(self.targets))
        self._k += 1
        return self.env.reset(seed=seed, options={"target": target})

"""Bit digests of a short rollout, a training update or two matrix products, printed as
one JSON line for tests/test_numerics.py's subprocesses (each under its own kernels).

* ``python -m tests.portable_rollout``: the shipped residual agent (its follower base,
  the default env, torch) on held-out ``detour_block``, seed 0, from a cold warm-state
  cache (``$CNT_ENV_CACHE_DIR``) for a few control steps: the digest of every
  observation and action, and the canaries;
* ``python -m tests.portable_rollout train DIR``: the demo's residual PPO recipe for one
  update (512 samples, seed 0) into DIR: the digest of the trained weights;
* ``python -m tests.portable_rollout canary``: the canaries alone, the digests of a NumPy
  and a torch matrix product, which show the BLAS and MKL code paths the process runs."""

from __future__ import annotations

import hashlib
import json
import sys

import numpy as np

import policies  # first: pins MKL's code path (policies/mkl.py)

STEPS = 3


def digest(a: np.ndarray | bytes) -> str:
    data = a if isinstance(a, bytes) else np.ascontiguousarray(a).tobytes()
    return hashlib.sha1(data).hexdigest()[:16]


def canaries() -> dict[str, str]:
    import torch

    x = np.random.default_rng(0).standard_normal((64, 84))
    t = torch.from_numpy(x.astype(np.float32))
    return {"blas": digest(x @ x[0]), "mkl": digest((t @ t.T).numpy())}


def rollout() -> dict[str, object]:
    import gymnasium as gym

    import cnt_env  # noqa: F401

    env = gym.make("CNTDeposit-v0")
    obs, _ = env.reset(seed=0, options={"target": "detour_block"})
    pol = policies.load_policy(policies.PRETRAINED_DIR / "ppo_residual.zip", env=env)
    pol.reset(0)
    rows = [digest(obs)]
    for _ in range(STEPS):
        a = pol.act(obs)
        obs, _, _, _, _ = env.step(a)
        rows += [digest(a), digest(obs)]
    env.close()
    return {"rollout": rows, **canaries()}


def train_one_update(out: str) -> dict[str, object]:
    import zipfile
    from pathlib import Path

    from training.common import CONFIG_DIR, load_config
    from training.demo import DEMO_CONFIG, short_run_config
    from training.train import train

    config = short_run_config(load_config(CONFIG_DIR / DEMO_CONFIG), 512)
    train("ppo", config, Path(out), seed=0, max_wall_seconds=600)
    with zipfile.ZipFile(Path(out) / "ppo.zip") as z:
        return {"weights": digest(z.read("policy.pth"))}


if __name__ == "__main__":
    mode = sys.argv[1] if len(sys.argv) > 1 else "rollout"
    if mode == "train":
        result = train_one_update(sys.argv[2])
    elif mode == "canary":
        result = canaries()
    else:
        result = rollout()
    print(json.dumps(result))

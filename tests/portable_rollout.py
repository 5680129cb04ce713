"""A short rollout or training run printed as bit digests, for tests/test_numerics.py.

``python -m tests.portable_rollout [agent]``: the default env, held-out ``detour_block``,
seed 0, from a cold warm-state cache (``$CNT_ENV_CACHE_DIR``), played by the route follower
or by the shipped residual agent for a few control steps. Prints one JSON line: the
digest of every observation and action, and two canaries that show which BLAS and MKL
code paths the process runs (the digests of a NumPy and a torch matrix product).

``python -m tests.portable_rollout train DIR``: the demo's residual PPO recipe for one
update (512 samples, seed 0) into DIR; prints the digest of the trained weights."""

from __future__ import annotations

import hashlib
import json
import sys

import numpy as np

import policies  # first: pins MKL's code path (policies/mkl.py)

STEPS = 3


def digest(a: np.ndarray) -> str:
    return hashlib.sha1(np.ascontiguousarray(a).tobytes()).hexdigest()[:16]


def canaries() -> dict[str, str]:
    x = np.random.default_rng(0).standard_normal((64, 84))
    out = {"blas": digest(x @ x[0])}
    if len(sys.argv) > 1 and sys.argv[1] == "agent":
        import torch

        t = torch.from_numpy(x.astype(np.float32))
        out["mkl"] = digest((t @ t.T).numpy())
    return out


def main() -> None:
    import gymnasium as gym

    import cnt_env  # noqa: F401

    agent = len(sys.argv) > 1 and sys.argv[1] == "agent"
    env = gym.make("CNTDeposit-v0")
    obs, _ = env.reset(seed=0, options={"target": "detour_block"})
    if agent:
        pol = policies.load_policy(policies.PRETRAINED_DIR / "ppo_residual.zip", env=env)
    else:
        pol = policies.RouteFollower.from_env(env)
    pol.reset(0)
    rows = [digest(obs)]
    for _ in range(STEPS):
        a = pol.act(obs)
        obs, _, _, _, _ = env.step(a)
        rows += [digest(a), digest(obs)]
    env.close()
    print(json.dumps({"rollout": rows, **canaries()}))


def train_one_update(out: str) -> None:
    import zipfile
    from pathlib import Path

    from training.common import CONFIG_DIR, load_config
    from training.demo import DEMO_CONFIG, short_run_config
    from training.train import train

    config = short_run_config(load_config(CONFIG_DIR / DEMO_CONFIG), 512)
    train("ppo", config, Path(out), seed=0, max_wall_seconds=600)
    with zipfile.ZipFile(Path(out) / "ppo.zip") as z:
        weights = z.read("policy.pth")
    print(json.dumps({"weights": hashlib.sha1(weights).hexdigest()[:16]}))


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "train":
        train_one_update(sys.argv[2])
    else:
        main()

"""Training on a Ray cluster with RLlib (optional extra ``[ray]``).

The SB3 path (``cnt-train``) runs on one machine. At a few hundred env steps per second
per core the sample budget limits learning, so this path spreads RLlib's env runners over
a Ray cluster. It reads the same rl-zoo style YAML as ``cnt-train`` (``env_kwargs``,
``max_episode_steps`` and the PPO hyperparameters that RLlib shares: ``gamma``,
``gae_lambda``, ``clip_range``, ``learning_rate``, ``n_epochs``, ``batch_size``,
``policy_kwargs.net_arch``), so both train on the same task, and ``cnt-evaluate --rllib
CHECKPOINT`` scores the result with the same evaluation (:class:`RLlibPolicy`).

Where it runs (``--address``):

* nothing: ``$RAY_ADDRESS`` if set, else a local Ray instance on this machine;
* ``auto``: the cluster this machine belongs to (after ``ray start``);
* ``ray://HEAD:10001`` or ``HEAD:6379``: a given cluster.

On a cluster: ``ray start --head`` on the head node, ``ray start --address=HEAD:6379`` on
each worker (every node needs this package installed with ``[ray]``), then
``cnt-train-rllib --address auto --env-runners N`` anywhere in the cluster. Each env
runner is one process holding one env (``--envs-per-runner`` more); sampling scales with
the runners as long as each has a core (``benchmarks/rllib_throughput.py``).

Ray 2.60's ``ray[rllib]`` extra pins ``gymnasium==1.2.2``; this project uses gymnasium
1.4, with which RLlib 2.60 runs (tested). The ``[ray]`` extra therefore lists ray and
RLlib's other dependencies without that pin.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from training.callbacks import policy_kwargs
from training.common import (
    CONFIG_DIR,
    ENV_ID,
    DefaultsHelp,
    env_settings,
    load_config,
    parse_cli,
)

__all__ = ["RLlibPolicy", "build_config", "main", "train_rllib"]

RLLIB_ENV = "cnt_env_rllib"


def _import_ray() -> Any:
    try:
        import ray
    except ImportError as exc:  # pragma: no cover - exercised only without the extra
        raise SystemExit(
            "cnt-train-rllib needs Ray: pip install -e '.[ray]' (see training/rllib.py)"
        ) from exc
    return ray


def _make_env(env_config: dict[str, Any]) -> Any:
    """The env creator every env runner calls (module-level, so Ray can pickle it)."""
    import gymnasium as gym

    import cnt_env  # noqa: F401  (registers the env in this worker)

    kwargs = dict(env_config)
    steps = kwargs.pop("max_episode_steps", None)
    return gym.make(ENV_ID, max_episode_steps=steps, **kwargs)


def build_config(
    zoo: dict[str, Any], env_runners: int, envs_per_runner: int = 1, seed: int = 0
) -> Any:
    """An RLlib ``PPOConfig`` from an rl-zoo style entry (see the module docstring)."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.tune.registry import register_env

    register_env(RLLIB_ENV, _make_env)
    env_kwargs, max_steps = env_settings(zoo)
    env_config = {**env_kwargs, "max_episode_steps": max_steps}
    n_steps = int(zoo.get("n_steps", 512))
    net = list(policy_kwargs(zoo.get("policy_kwargs")).get("net_arch", [64, 64]))
    lr = zoo.get("learning_rate", 3e-4)
    if isinstance(lr, str):  # "lin_3e-4": RLlib takes a schedule of (timestep, value)
        lr0 = float(lr.split("_", 1)[1])
        lr = [[0, lr0], [int(zoo.get("n_timesteps", 1e5)), 0.0]]
    fragment = max(1, n_steps // max(1, envs_per_runner))
    return (
        PPOConfig()
        .environment(RLLIB_ENV, env_config=env_config)
        .env_runners(
            num_env_runners=env_runners,
            num_envs_per_env_runner=envs_per_runner,
            rollout_fragment_length=fragment,
            num_cpus_per_env_runner=1,
        )
        .training(
            train_batch_size=n_steps * max(1, env_runners) * envs_per_runner,
            minibatch_size=int(zoo.get("batch_size", 128)),
            num_epochs=int(zoo.get("n_epochs", 10)),
            gamma=float(zoo.get("gamma", 0.99)),
            lambda_=float(zoo.get("gae_lambda", 0.95)),
            clip_param=float(zoo.get("clip_range", 0.2)),
            lr=lr,
        )
        .rl_module(model_config={"fcnet_hiddens": net, "fcnet_activation": "tanh"})
        .debugging(seed=seed)
    )


def train_rllib(
    config_path: Path,
    timesteps: int,
    env_runners: int,
    out: Path,
    address: str | None = None,
    envs_per_runner: int = 1,
    seed: int = 0,
) -> dict[str, Any]:
    """Train PPO with RLlib until ``timesteps`` env steps are sampled; save a checkpoint
    under ``out`` (a new directory) and return a summary."""
    ray = _import_ray()
    if out.exists() and any(out.iterdir()):
        raise FileExistsError(f"{out} exists and is not empty; runs never overwrite (choose --out)")
    zoo = load_config(config_path)
    address = address or os.environ.get("RAY_ADDRESS")
    if address:
        ray.init(address=address, log_to_driver=False)
    else:
        ray.init(num_cpus=max(2, env_runners + 1), include_dashboard=False, log_to_driver=False)
    try:
        algo = build_config(zoo, env_runners, envs_per_runner, seed).build_algo()
        history = []
        sampled = 0
        t0 = time.perf_counter()
        while sampled < timesteps:
            result = algo.train()
            runners = result.get("env_runners", {})
            sampled = int(result.get("num_env_steps_sampled_lifetime", sampled))
            history.append({
                "env_steps": sampled,
                "wall_s": round(time.perf_counter() - t0, 2),
                "episode_return_mean": runners.get("episode_return_mean"),
            })  # fmt: skip
            print(json.dumps(history[-1]), flush=True)
        out.mkdir(parents=True, exist_ok=True)
        algo.save_to_path(str((out / "checkpoint").resolve()))
        algo.stop()
    finally:
        ray.shutdown()
    summary = {
        "config": str(config_path),
        "env_runners": env_runners,
        "envs_per_runner": envs_per_runner,
        "env_steps": sampled,
        "wall_s": history[-1]["wall_s"] if history else 0.0,
        "history": history,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


class RLlibPolicy:
    """A trained RLlib checkpoint behind the project's policy interface (``act(obs)``).

    Loads only the RL module (torch); no Ray cluster is started. The action is the mean
    of the Gaussian the module outputs (deterministic evaluation), clipped to [-1, 1].
    """

    def __init__(self, checkpoint: str | os.PathLike[str], name: str = "rllib_ppo") -> None:
        from ray.rllib.core.rl_module.rl_module import RLModule

        path = Path(checkpoint)
        module_dir = path / "learner_group" / "learner" / "rl_module" / "default_policy"
        if not module_dir.is_dir():
            raise ValueError(
                f"{path} is not an RLlib checkpoint of cnt-train-rllib (no {module_dir})"
            )
        self.module = RLModule.from_checkpoint(str(module_dir))
        self.name = name

    def reset(self, seed: int | None = None) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        import torch

        with torch.no_grad():
            out = self.module.forward_inference(
                {"obs": torch.as_tensor(obs[None], dtype=torch.float32)}
            )
        logits = out["action_dist_inputs"][0].numpy()
        mean = logits[: logits.shape[0] // 2]
        return np.clip(mean, -1.0, 1.0).astype(np.float32)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="cnt-train-rllib",
        description="Train PPO on CNTDeposit-v0 with RLlib, locally or on a Ray cluster.",
        formatter_class=DefaultsHelp,
    )
    ap.add_argument("--config", type=Path, default=CONFIG_DIR / "ppo.yml", help="rl-zoo YAML")
    ap.add_argument("--timesteps", type=int, default=20000, help="env steps to sample")
    ap.add_argument("--env-runners", type=int, default=2, help="sampling processes")
    ap.add_argument("--envs-per-runner", type=int, default=1)
    ap.add_argument(
        "--address", default=None, help="Ray address (default: $RAY_ADDRESS, else local)"
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--out", type=Path, default=None, help="run directory (default: runs/rllib/<time>)"
    )
    args = parse_cli(ap, argv)
    if args.env_runners < 0 or args.envs_per_runner < 1 or args.timesteps < 1:
        ap.error("--env-runners >= 0, --envs-per-runner >= 1 and --timesteps >= 1 are required")
    out = args.out or Path("runs") / "rllib" / time.strftime("%Y%m%d-%H%M%S")
    try:
        summary = train_rllib(
            args.config, args.timesteps, args.env_runners, out, args.address,
            args.envs_per_runner, args.seed,
        )  # fmt: skip
    except FileExistsError as exc:
        ap.error(str(exc))
    print(
        f"checkpoint: {out / 'checkpoint'}  ({summary['env_steps']} steps, {summary['wall_s']} s)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

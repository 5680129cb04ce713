"""Trained SB3 models as policies: the model zip and the VecNormalize statistics saved
beside it (training/train.py): ``<name>_vecnormalize.npz`` + ``.json`` (arrays and
settings, read without pickle; :func:`save_vecnormalize`, :func:`load_vecnormalize`),
and VecNormalize's own ``<name>_vecnormalize.pkl`` (``VecNormalize.load``), used when the
npz is absent (models trained before it)."""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np

from .residual import combine, make_base_policy, residual_settings

__all__ = [
    "ALGOS",
    "NormalizerStats",
    "SB3Policy",
    "load_policy",
    "load_vecnormalize",
    "save_vecnormalize",
    "vecnormalize_path",
]

ALGOS = ("ppo", "sac")


def vecnormalize_path(model_path: str | Path) -> Path:
    """Where the VecNormalize statistics of ``model_path`` (a ``.zip``) live."""
    p = Path(model_path)
    return p.with_name(p.name.removesuffix(".zip") + "_vecnormalize.pkl")


class SB3Policy:
    """A trained PPO/SAC model, deterministic, with its observation normalisation.

    The VecNormalize object is unpickled without a venv: only its ``obs_rms`` and
    ``normalize_obs`` are used (rewards are not normalised at inference)."""

    def __init__(self, model, vecnormalize=None, name: str = "sb3", base=None,
                 scale: float = 0.0) -> None:  # fmt: skip
        self.model = model
        self.vecnormalize = vecnormalize
        self.name = name
        #: residual agents (policies/residual.py): action = clip(base + scale * a)
        self.base = base
        self.scale = float(scale)

    def reset(self, seed: int | None = None) -> None:
        if self.base is not None:
            self.base.reset(seed)

    def act(self, obs: np.ndarray) -> np.ndarray:
        o = np.asarray(obs, dtype=np.float32)[None]
        if self.vecnormalize is not None:
            o = self.vecnormalize.normalize_obs(o)
        action, _ = self.model.predict(o, deterministic=True)
        a = np.asarray(action, dtype=np.float32).reshape(-1)
        if self.base is not None:
            return combine(self.base.act(obs), a, self.scale)
        return a


def load_policy(model_path: str | Path, algo: str | None = None, device: str = "cpu") -> SB3Policy:
    """Load ``model_path`` (``.zip``; ``algo`` from the file name if not given), the
    VecNormalize statistics beside it, if any, and, if the resolved config beside it
    (``<name>.yml``) says the agent is residual, its base policy."""
    from stable_baselines3 import PPO, SAC

    model_path = Path(model_path)
    if algo is None:
        algo = next((a for a in ALGOS if a in model_path.name.lower()), None)
    if algo not in ALGOS:
        raise ValueError(f"cannot tell the algorithm of {model_path}; pass algo in {ALGOS}")
    cls = {"ppo": PPO, "sac": SAC}[algo]
    model = cls.load(str(model_path), device=device)
    vn = None
    vn_path = vecnormalize_path(model_path)
    if vn_path.with_suffix(".npz").is_file() and vn_path.with_suffix(".json").is_file():
        vn = load_vecnormalize(vn_path)
    elif vn_path.is_file():
        with vn_path.open("rb") as fh:
            vn = pickle.load(fh)
        vn.training = False
    base, scale = None, 0.0
    cfg_path = model_path.with_suffix(".yml")
    if cfg_path.is_file():
        import yaml

        cfg = yaml.safe_load(cfg_path.read_text()) or {}
        entry = cfg.get("CNTDeposit-v0") or {}
        residual = residual_settings(entry)
        if residual is not None:
            from cnt_env.task import CNTDepositEnv

            env_kwargs = dict(entry.get("env_kwargs") or {})
            env_kwargs.pop("max_episode_steps", None)  # gymnasium.make's, not the env's
            base = make_base_policy(residual.get("base", "scripted"), CNTDepositEnv(**env_kwargs))
            scale = float(residual.get("scale", 0.5))
    return SB3Policy(model, vn, name=algo, base=base, scale=scale)


class NormalizerStats:
    """The observation normalisation of a saved VecNormalize, without a venv or pickle:
    ``normalize_obs`` as VecNormalize's (clip((obs - mean) / sqrt(var + eps)))."""

    def __init__(self, mean: np.ndarray, var: np.ndarray, count: float, clip_obs: float,
                 epsilon: float, norm_obs: bool) -> None:  # fmt: skip
        from stable_baselines3.common.running_mean_std import RunningMeanStd

        self.obs_rms = RunningMeanStd(shape=mean.shape)
        self.obs_rms.mean, self.obs_rms.var, self.obs_rms.count = mean, var, count
        self.clip_obs, self.epsilon, self.norm_obs = clip_obs, epsilon, norm_obs
        self.training = False

    def normalize_obs(self, obs: np.ndarray) -> np.ndarray:
        if not self.norm_obs:
            return obs
        o = (obs - self.obs_rms.mean) / np.sqrt(self.obs_rms.var + self.epsilon)
        return np.clip(o, -self.clip_obs, self.clip_obs).astype(np.float32)


def save_vecnormalize(venv, stem: Path) -> tuple[Path, Path]:
    """Write ``<stem>.npz`` (obs and return running statistics) and ``<stem>.json``
    (settings) for the VecNormalize ``venv``."""
    stem = Path(stem)
    arrays = {"obs_mean": venv.obs_rms.mean, "obs_var": venv.obs_rms.var,
              "obs_count": np.array(venv.obs_rms.count), "ret_mean": venv.ret_rms.mean,
              "ret_var": venv.ret_rms.var, "ret_count": np.array(venv.ret_rms.count)}  # fmt: skip
    npz = stem.with_suffix(".npz")
    np.savez(npz, **arrays)
    meta = {"clip_obs": venv.clip_obs, "clip_reward": venv.clip_reward, "gamma": venv.gamma,
            "epsilon": venv.epsilon, "norm_obs": venv.norm_obs, "norm_reward": venv.norm_reward,
            "format": "cnt_env vecnormalize 1"}  # fmt: skip
    js = stem.with_suffix(".json")
    js.write_text(json.dumps(meta, indent=2) + "\n")
    return npz, js


def load_vecnormalize(stem: Path) -> NormalizerStats:
    """The statistics written by :func:`save_vecnormalize` (for inference)."""
    stem = Path(stem)
    meta = json.loads(stem.with_suffix(".json").read_text())
    with np.load(stem.with_suffix(".npz")) as d:
        return NormalizerStats(d["obs_mean"], d["obs_var"], float(d["obs_count"]),
                               meta["clip_obs"], meta["epsilon"], meta["norm_obs"])  # fmt: skip

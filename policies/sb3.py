"""Trained SB3 models as policies: the model zip and the VecNormalize statistics saved
beside it (``<name>.zip`` + ``<name>_vecnormalize.pkl``, training/train.py)."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np

from .residual import combine, make_base_policy

__all__ = ["ALGOS", "SB3Policy", "load_policy", "vecnormalize_path"]

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
    if vn_path.is_file():
        with vn_path.open("rb") as fh:
            vn = pickle.load(fh)
        vn.training = False
    base, scale = None, 0.0
    cfg_path = model_path.with_suffix(".yml")
    if cfg_path.is_file():
        import yaml

        cfg = yaml.safe_load(cfg_path.read_text()) or {}
        residual = (cfg.get("CNTDeposit-v0") or {}).get("residual")
        if residual:
            from cnt_env.task import CNTDepositEnv

            env = CNTDepositEnv(**(cfg["CNTDeposit-v0"].get("env_kwargs") or {}))
            base = make_base_policy(residual.get("base", "scripted"),
                                    env.observation_slices["target"], env.vbar_max)  # fmt: skip
            scale = float(residual.get("scale", 0.5))
    return SB3Policy(model, vn, name=algo, base=base, scale=scale)

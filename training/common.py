"""Pieces shared by training and evaluation: configs, env construction, held-out cycling."""

from __future__ import annotations

import argparse
import copy
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml

from cnt_env.cli.common import (
    csv_list,
    double_dash_option,
    positive_float,
    positive_int,
    seed_int,
    seed_list,
)
from cnt_env.task import routes, settings
from cnt_env.task import targets as targets_mod
from policies.residual import (
    HeadingGate,
    combine,
    make_base_policy,
    observe,
    observed_space,
    residual_settings,
    zoo_entry,
    zoo_names,
)

__all__ = [
    "CONFIG_DIR",
    "DEFAULT_N_ENVS",
    "ENV_ID",
    "VALIDATION",
    "HeldOutCycle",
    "ResidualAction",
    "algo_kwargs",
    "callback_settings",
    "check_callbacks",
    "check_run_config",
    "csv_list",
    "curriculum_settings",
    "env_settings",
    "eval_env_settings",
    "eval_settings",
    "fresh_dir",
    "held_out_names",
    "held_out_targets",
    "limit_threads",
    "load_config",
    "make_env",
    "normalize_settings",
    "observation_mode",
    "positive_float",
    "positive_int",
    "score_mode",
    "seed_int",
    "seed_list",
]

ENV_ID = "CNTDeposit-v0"
CONFIG_DIR = Path(__file__).resolve().parent / "configs"
#: The env the held-out scores are measured on (the env's default physics, the model):
#: cnt-evaluate's default, and the default of every benchmark that judges against them.
EVAL_CONFIG = CONFIG_DIR / "eval.yml"
#: Keys of a config entry that are not hyperparameters of the algorithm (rl-zoo style).
NON_ALGO_KEYS = frozenset({
    "n_timesteps", "policy", "n_envs", "normalize", "env_kwargs", "max_episode_steps",
    "eval_freq", "n_eval_episodes", "eval_targets", "save_freq", "vec_env", "residual",
    "env_wrapper", "callback", "frame_stack",
})  # fmt: skip
#: Registered episode cap (TimeLimit) when a config gives none: the env's own.
DEFAULT_MAX_EPISODE_STEPS = 400
#: Parallel envs when a config gives no ``n_envs`` (one per core of the 2-core machine).
DEFAULT_N_ENVS = 2
#: The project's callbacks in a config's ``callback`` list (rl-zoo style: a name, or a
#: one-key dict name -> kwargs).
EVAL_CALLBACK = "training.callbacks.HeldOutEval"
CHECKPOINT_CALLBACK = "training.callbacks.Checkpoint"
CURRICULUM_CALLBACK = "training.callbacks.Curriculum"


def limit_threads() -> None:
    """One thread per process: the env is serial and the machine has 2 cores."""
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # pragma: no cover
        pass


def shown_path(path: str | Path, base: str | Path | None = None) -> str:
    """``path`` relative to ``base`` (the working directory by default) when under it, so
    a results file names the repository's file, not one machine's absolute path."""
    p, b = Path(path).resolve(), Path(base if base is not None else Path.cwd()).resolve()
    return str(p.relative_to(b)) if p.is_relative_to(b) else str(p)


def load_config(path: str | Path, env_id: str = ENV_ID) -> dict[str, Any]:
    """The entry ``env_id`` of an rl-zoo style YAML file (a deep copy). A file that cannot
    be read, is not YAML or has no such mapping raises ValueError naming the file."""
    try:
        data = yaml.safe_load(Path(path).read_text())
    except OSError as exc:
        raise ValueError(f"cannot read the config {path}: {exc.strerror or exc}") from exc
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValueError(f"the config {path} is not valid YAML ({first})") from exc
    if not isinstance(data, dict) or env_id not in data:
        has = sorted(map(str, data)) if isinstance(data, dict) else type(data).__name__
        raise ValueError(f"{path} has no entry {env_id!r} (rl-zoo style); it has {has}")
    if not isinstance(data[env_id], dict):
        raise ValueError(f"{path}: the entry {env_id!r} must be a mapping of settings")
    return copy.deepcopy(data[env_id])


def check_run_config(config: dict[str, Any]) -> None:
    """Refuse a config whose run cannot start: ``n_timesteps`` and ``n_envs`` positive
    integers, an episode cap (``env_kwargs.max_episode_steps``) of at least 1, and no
    normalised image observation nor residual agent on the image."""
    env_settings(config)  # the episode cap
    mode = observation_mode(config)
    normalize_settings(config, obs_mode=mode)
    if mode == "image" and residual_settings(config) is not None:
        raise ValueError("a residual agent (env_wrapper ResidualAction) acts over the route "
                         "follower, which reads the vector observation: use obs_mode: "
                         "dict (the image and the vector), or train a plain agent on the "
                         "image")  # fmt: skip
    _positive_int_setting("n_timesteps", config.get("n_timesteps"))
    _positive_int_setting("n_envs", config.get("n_envs", DEFAULT_N_ENVS))


def _positive_int_setting(key: str, value: Any) -> int:
    """``value`` of config setting ``key`` if it is a positive integer as written (not
    true, 2.9 or "300", which int() would take), else ValueError naming the key."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{key} must be a positive integer, got {value!r}")
    return int(value)


def held_out_targets(text: str, names: Sequence[str]) -> list[str]:
    """The held-out targets ``text`` names (comma separated, or ``all``: every one of
    ``names``); ValueError naming any that is not one of ``names``."""
    targets = list(names) if text == "all" else csv_list(text)
    unknown = [t for t in targets if t not in names]
    if unknown or not targets:
        raise ValueError(f"{unknown or 'none given'}: not held-out targets of this task; "
                         f"choose from {list(names)} or all")  # fmt: skip
    return targets


def env_settings(config: dict[str, Any]) -> tuple[dict[str, Any], int]:
    """``(env_kwargs, max_episode_steps)`` of a config: the TimeLimit from
    ``env_kwargs.max_episode_steps`` (rl-zoo: env_kwargs go to ``gymnasium.make``) or the
    older top-level key; the env's kwargs without it."""
    env_kwargs = dict(config.get("env_kwargs") or {})
    steps = env_kwargs.pop("max_episode_steps", None)
    if steps is None:
        steps = config.get("max_episode_steps", DEFAULT_MAX_EPISODE_STEPS)
    return env_kwargs, _positive_int_setting("max_episode_steps", steps)


def callback_settings(config: dict[str, Any], name: str) -> dict[str, Any] | None:
    """The kwargs of callback ``name`` in the config's ``callback`` list (None if absent)."""
    return zoo_entry(config.get("callback"), name)


def eval_env_settings(config: dict[str, Any]) -> tuple[dict[str, Any], int]:
    """``(env_kwargs, max_episode_steps)`` of a config's evaluation env: the training
    env's (:func:`env_settings`), with HeldOutEval's own ``env_kwargs`` over them (say a
    fixed ``flow_gain`` where training draws one per episode, so that every evaluation
    scores the same envs)."""
    env_kwargs, steps = env_settings(config)
    ev = callback_settings(config, EVAL_CALLBACK) or {}
    over = dict(ev.get("env_kwargs") or {})
    if "max_episode_steps" in over:
        raise ValueError("HeldOutEval's env_kwargs set the env, not max_episode_steps")
    return {**env_kwargs, **over}, steps


def eval_settings(config: dict[str, Any]) -> dict[str, Any]:
    """``{"eval_targets", "eval_freq", "n_eval_episodes", "save_freq"}``: from the
    ``callback`` entries HeldOutEval and Checkpoint, else the older top-level keys."""
    ev = callback_settings(config, EVAL_CALLBACK)
    ev = {k: config[k] for k in ("eval_targets", "eval_freq", "n_eval_episodes")
          if k in config} if ev is None else ev  # fmt: skip
    ck = callback_settings(config, CHECKPOINT_CALLBACK) or {}
    targets = list(ev.get("eval_targets") or [])
    return {
        "eval_targets": targets,
        "eval_freq": int(ev.get("eval_freq", 0)),
        "n_eval_episodes": int(ev.get("n_eval_episodes", len(targets))),
        "save_freq": int(ck.get("save_freq", config.get("save_freq", 0))),
    }


def check_callbacks(config: dict[str, Any]) -> None:
    """Refuse a ``callback`` entry that is not one of the project's (HeldOutEval,
    Checkpoint, Curriculum): a misspelt name would otherwise train without it."""
    known = (EVAL_CALLBACK, CHECKPOINT_CALLBACK, CURRICULUM_CALLBACK)
    for name in zoo_names(config.get("callback")):
        if name not in known:
            raise ValueError(f"unknown callback {name!r}; choose from {list(known)}")


def curriculum_settings(config: dict[str, Any]) -> list[tuple[float, dict[str, Any]]]:
    """The stages of the ``training.callbacks.Curriculum`` callback, checked before training
    starts: ``[(at, {"families": ..., "difficulty": ...}), ...]``, ``at`` the fraction of
    ``n_timesteps`` from which the training envs draw their routes so (``env_kwargs``
    hold the draw before the first stage). [] without the callback.

    YAML: ``{training.callbacks.Curriculum: {stages: [{at: 0.5, families: [...],
    difficulty: 0.7}, ...]}}``; ``at`` strictly increasing in (0, 1); each stage sets
    ``families``, ``difficulty`` or both."""
    entry = callback_settings(config, CURRICULUM_CALLBACK)
    if entry is None:
        return []
    if set(entry) != {"stages"} or not isinstance(entry["stages"], list) or not entry["stages"]:
        raise ValueError(f"{CURRICULUM_CALLBACK} takes one key, stages: a non-empty list of "
                         f"{{at, families, difficulty}}; got {entry!r}")  # fmt: skip
    env_kwargs, _ = env_settings(config)
    known = routes.families_of(score_mode(env_kwargs))
    out: list[tuple[float, dict[str, Any]]] = []
    for stage in entry["stages"]:
        keys = set(stage) if isinstance(stage, dict) else set()
        if "at" not in keys or not keys - {"at"} or not keys <= {"at", "families", "difficulty"}:
            raise ValueError(f"a curriculum stage is {{at, families and/or difficulty}}, "
                             f"got {stage!r}")  # fmt: skip
        at = stage["at"]
        if not isinstance(at, int | float) or not 0.0 < at < 1.0 or (out and at <= out[-1][0]):
            raise ValueError(f"curriculum stages need 0 < at < 1, strictly increasing; got "
                             f"{[a for a, _ in out] + [at]}")  # fmt: skip
        draw: dict[str, Any] = {}
        if "families" in stage:
            draw["families"] = list(settings.families_tuple(stage["families"], known))
        if "difficulty" in stage:
            draw["difficulty"] = settings.difficulty_value(stage["difficulty"])
        out.append((float(at), draw))
    return out


def observation_mode(config: dict[str, Any]) -> str:
    """The config's ``env_kwargs.obs_mode``: "vector" (the env's default), "image" or
    "dict" (both; SB3's MultiInputPolicy)."""
    return str(env_settings(config)[0].get("obs_mode", "vector"))


def normalize_settings(config: dict[str, Any], obs_mode: str = "vector") -> dict[str, Any]:
    """VecNormalize kwargs of ``normalize`` (rl-zoo: ``true``, a dict, or a string
    ``"dict(norm_obs=True, norm_reward=False)"``); {} for none.

    An image is never normalised (SB3's CNN policies scale the uint8 pixels by 1/255
    themselves and reject the floats VecNormalize would give them): on ``obs_mode``
    "image" only the reward is, and on "dict" the reward and the "vector" part
    (``norm_obs_keys: [vector]``). Asking to normalise an image raises ValueError."""
    from .callbacks import policy_kwargs

    value = config.get("normalize")
    if not value:
        return {}
    extra = {} if value is True else policy_kwargs(value)
    default = {"image": {"norm_obs": False}, "dict": {"norm_obs": True,
               "norm_obs_keys": ["vector"]}}.get(obs_mode, {"norm_obs": True})  # fmt: skip
    out = {**default, "norm_reward": True, **extra}
    keys = out.get("norm_obs_keys")  # None: every key (VecNormalize's default)
    if out["norm_obs"] and (obs_mode == "image" or (obs_mode == "dict" and (
            keys is None or "image" in keys))):  # fmt: skip
        raise ValueError("normalize: norm_obs on an image observation: VecNormalize would "
                         "turn the uint8 image into floats, which SB3's CNN policies "
                         "reject; drop norm_obs on an image (the policy scales the pixels), "
                         "or on obs_mode dict set norm_obs_keys: [vector]")  # fmt: skip
    return out


def algo_kwargs(config: dict[str, Any]) -> dict[str, Any]:
    """The algorithm's keyword arguments: ``lin_`` schedules and string
    ``policy_kwargs`` resolved (training/callbacks.py)."""
    from .callbacks import policy_kwargs, schedule

    out = {k: schedule(v) for k, v in config.items() if k not in NON_ALGO_KEYS}
    if "policy_kwargs" in out:
        out["policy_kwargs"] = policy_kwargs(out["policy_kwargs"])
    return out


def score_mode(env_kwargs: dict[str, Any]) -> str:
    """The task of ``env_kwargs``: "corridor" (routes, the env's default) or "thin"."""
    return str(env_kwargs.get("score", "corridor"))


def held_out_names(env_kwargs: dict[str, Any]) -> tuple[str, ...]:
    """The held-out targets of the task of ``env_kwargs``."""
    return routes.HELD_OUT if score_mode(env_kwargs) == "corridor" else targets_mod.HELD_OUT


class DefaultsHelp(argparse.ArgumentDefaultsHelpFormatter):
    """argparse's defaults in the help, but not after a help that states its own default
    or for a default of None (it printed "(default: ...) (default: None)")."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        if action.default is None or "(default" in text:
            return text
        return super()._get_help_string(action)


def check_dir_option(parser: argparse.ArgumentParser, dest: str, path: Path | None) -> None:
    """A usage error (exit 2) when the directory option ``dest`` names an existing file,
    before anything is made (a directory that does not exist yet is created later)."""
    if path is not None and Path(path).exists() and not Path(path).is_dir():
        flag = "--" + dest.replace("_", "-")
        parser.error(f"{flag}: {path} is a file; give a directory (made if missing)")


def fresh_dir(path: str | Path) -> Path:
    """``path`` if it does not exist or is empty, else the first free ``path_2``,
    ``path_3``, ...: a run never overwrites an earlier one. The directory is created."""
    path = Path(path)
    candidate, k = path, 1
    while candidate.exists() and any(candidate.iterdir()):
        k += 1
        candidate = path.with_name(f"{path.name}_{k}")
    candidate.mkdir(parents=True, exist_ok=True)
    return candidate


def make_env(env_kwargs: dict[str, Any], max_episode_steps: int, **extra) -> gym.Env:
    """``gymnasium.make(CNTDeposit-v0)`` with the config's settings."""
    return gym.make(ENV_ID, max_episode_steps=max_episode_steps, **{**env_kwargs, **extra})


class ResidualAction(gym.Wrapper):
    """Residual policy learning (policies/residual.py): the env receives
    clip(base(obs) + scale * a, -1, 1). The base is the scripted heuristic
    (policies/scripted.py), so a barely trained agent already acts like it.

    The wrapper sits below VecNormalize: the base sees the raw observation.
    ``base_kwargs`` are the base's options (policies/residual.py ``base_options``; its
    defaults when omitted); the trained model's config pins them. ``observe_base``
    appends the base's action to the observation (policies/residual.py ``observe``).
    ``keepout_headings``: the route follower plays, the action ignored, episodes whose
    route has a keep-out and starts along one of these axes (policies/residual.py
    ``HeadingGate``). ``mirror_average`` is an option of the trained agent at inference
    (policies/sb3.py ``SB3Policy``), accepted here so that its config trains on (with
    ``--trained-agent``); training acts through the model alone, unaveraged."""

    def __init__(self, env: gym.Env, base: str = "scripted", scale: float = 0.5,
                 base_kwargs: dict[str, Any] | None = None,
                 observe_base: bool = False,
                 keepout_headings: Sequence[str] = (),
                 mirror_average: bool = False) -> None:  # fmt: skip
        super().__init__(env)
        self.base_name, self.scale = base, float(scale)
        self.base = make_base_policy(base, env, base_kwargs)
        self.observe_base = bool(observe_base)
        self.gate = HeadingGate(keepout_headings, env.unwrapped.observation_slices, env)
        if self.observe_base:
            self.observation_space = observed_space(env.observation_space, env.action_space)
        self._base_action: np.ndarray | None = None

    def _observe(self, obs: np.ndarray) -> np.ndarray:
        """The base (or, on a route ``keepout_headings`` hands over, the follower) acts on
        ``obs`` now (its action is played at the next step)."""
        policy = self.gate.fallback if self.gate.defers(obs) else self.base
        self._base_action = policy.act(obs)
        return observe(obs, self._base_action) if self.observe_base else obs

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self.base.reset(seed)
        self.gate.reset(seed)
        return self._observe(obs), info

    def step(self, action):
        if self.gate.deferred:  # keepout_headings: the follower plays this route
            a = np.asarray(self._base_action, dtype=np.float32)
        else:
            a = combine(self._base_action, action, self.scale)
        obs, reward, terminated, truncated, info = self.env.step(a)
        return self._observe(obs), reward, terminated, truncated, info


#: An eval target that stands for a route drawn from the training families (a validation
#: route, never a held-out test route); see :class:`HeldOutCycle`.
VALIDATION = "validation"
#: Reset seeds of the validation routes, far from the training and evaluation seeds.
VALIDATION_SEED0 = 50_000


class HeldOutCycle(gym.Wrapper):
    """Every reset uses the next of ``targets``, in turn: EvalCallback episodes then run
    over them. A target is a held-out name (reset seed ``seed0 + k``, k counting passes
    over the list) or :data:`VALIDATION`: a route drawn from the env's families with the
    fixed reset seed ``VALIDATION_SEED0 + i`` (i its place in the list), so every
    evaluation sees the same validation routes and none of the held-out test set."""

    def __init__(self, env: gym.Env, targets: Sequence[str], seed0: int = 1000) -> None:
        super().__init__(env)
        known = held_out_names({"score": env.unwrapped.score_mode})
        for t in targets:
            if t not in known and t != VALIDATION:
                raise ValueError(
                    f"{t!r} is not a held-out target or {VALIDATION!r}; choose from {known}"
                )
        if not targets:
            raise ValueError("HeldOutCycle needs at least one target")
        self.targets = tuple(targets)
        self.seed0 = int(seed0)
        self._k = 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        i = self._k % len(self.targets)
        target = self.targets[i]
        seed = self.seed0 + (self._k // len(self.targets))
        self._k += 1
        if target == VALIDATION:
            return self.env.reset(seed=VALIDATION_SEED0 + i)
        return self.env.reset(seed=seed, options={"target": target})


def parse_cli(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> argparse.Namespace:
    """``parser.parse_args(argv)`` with ``--opt=--`` a usage error (exit 2): argparse reads
    ``--`` as the end of options and stores [] for a single-valued option, which crashed
    further on (cnt_env.cli.common.double_dash_option)."""
    args = parser.parse_args(argv)
    flag = double_dash_option(parser, args, list(sys.argv[1:] if argv is None else argv))
    if flag is not None:
        parser.error(f"{flag} got '--' as its value; give the value itself")
    return args

"""Trained SB3 models as policies, loaded without running code from the model's folder.

A model is ``<name>.zip`` (SB3), its VecNormalize statistics ``<name>_vecnormalize.npz``
+ ``.json`` (arrays and settings, read without pickle; :func:`save_vecnormalize`,
:func:`load_vecnormalize`) and, for residual agents, ``<name>.yml`` (read with
``yaml.safe_load``). See docs/security.md.

By default (``trust=False``) :func:`load_policy`

* reads the zip's ``data`` JSON itself and replaces EVERY cloudpickled entry (those with
  a ``:serialized:`` key: policy class, spaces, schedules, buffers...) through SB3's
  ``custom_objects``, so ``save_util.json_to_data`` never calls ``cloudpickle.loads``;
  the replacements are rebuilt from the plain-text fields beside each blob and an
  allowlist of SB3 classes; an entry it cannot rebuild makes it refuse the zip. The
  weights are read by SB3 with ``torch.load(weights_only=True)``;
* refuses a VecNormalize pickle (``<name>_vecnormalize.pkl``);
* checks the files of the model against ``MANIFEST.json`` (sha256 per file) when the
  model's folder has one (``policies/pretrained`` does; training writes one per run).

``trust=True`` (``cnt-evaluate --trust``) loads with SB3's own (pickle) path, reads a
VecNormalize pickle and turns a manifest mismatch into a warning: only for files you
made yourself or got from someone you trust.
"""

from __future__ import annotations

import hashlib
import json
import re
import warnings
import zipfile
from collections import deque
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cnt_env.task.spaces import ACTION_Z_MIRROR

from .mkl import check as check_mkl
from .residual import HeadingGate, combine, make_base_policy, observe, residual_settings

__all__ = [
    "ALGOS",
    "MANIFEST_NAME",
    "NormalizerStats",
    "SB3Policy",
    "UntrustedModelError",
    "algo_class",
    "check_manifest",
    "convert_vecnormalize_pickle",
    "file_sha256",
    "load_policy",
    "load_vecnormalize",
    "model_files",
    "restore_vecnormalize",
    "safe_custom_objects",
    "save_vecnormalize",
    "vecnormalize_path",
    "write_manifest",
]

#: The algorithms of cnt-train: SB3's PPO and SAC, and sb3-contrib's RecurrentPPO as
#: rl-zoo names it (``ppo_lstm``: PPO with an LSTM in the policy and the value function).
ALGOS = ("ppo", "sac", "ppo_lstm")
MANIFEST_NAME = "MANIFEST.json"
MANIFEST_FORMAT = "cnt_env manifest 1"
TRUST_HINT = ("pass --trust (cnt-evaluate) or trust=True (policies.load_policy) only if "
              "you made these files or trust who did; see docs/security.md")  # fmt: skip


class UntrustedModelError(ValueError):
    """A model file that cannot be loaded without the risk of running code from it
    (a pickle, a zip entry that cannot be rebuilt from data, a manifest mismatch)."""


def vecnormalize_path(model_path: str | Path) -> Path:
    """The stem of the VecNormalize statistics of ``model_path`` (a ``.zip``):
    ``<name>_vecnormalize`` + ``.npz`` / ``.json`` (``.pkl``: the old pickle)."""
    p = Path(model_path)
    return p.with_name(p.name.removesuffix(".zip") + "_vecnormalize.pkl")


def model_files(model_path: str | Path) -> list[Path]:
    """The files that make up the model ``model_path`` (those that exist or not):
    the zip, its VecNormalize npz/json/pkl, and its ``.yml``."""
    p = Path(model_path)
    vn = vecnormalize_path(p)
    return [p, vn.with_suffix(".npz"), vn.with_suffix(".json"), vn, p.with_suffix(".yml")]


# ---- checksum manifest --------------------------------------------------------------------


def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def write_manifest(directory: str | Path, names: list[str] | None = None) -> Path:
    """Write ``<directory>/MANIFEST.json``: the sha256 of ``names`` (default: every
    regular file of the folder but the manifest itself)."""
    d = Path(directory)
    if names is None:
        names = sorted(p.name for p in d.iterdir() if p.is_file() and p.name != MANIFEST_NAME)
    files = {n: file_sha256(d / n) for n in sorted(names)}
    path = d / MANIFEST_NAME
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps({"format": MANIFEST_FORMAT, "sha256": files}, indent=2) + "\n")
    tmp.replace(path)
    return path


def check_manifest(model_path: str | Path, trust: bool = False) -> bool:
    """Check the files of ``model_path`` (:func:`model_files`) against the
    ``MANIFEST.json`` of its folder. Returns False if there is no manifest, True if
    every file matches; raises :class:`UntrustedModelError` on a mismatch (a file that
    differs, is missing, or is not listed), or warns instead if ``trust``."""
    model_path = Path(model_path)
    manifest = model_path.parent / MANIFEST_NAME
    if not manifest.is_file():
        return False
    try:
        listed = json.loads(manifest.read_text())["sha256"]
        if not isinstance(listed, dict):
            raise TypeError("sha256 is not an object")
    except (OSError, ValueError, KeyError, TypeError) as exc:
        problems = [f"{manifest} is unreadable ({exc})"]
    else:
        problems = []
        for f in model_files(model_path):
            if f.name in listed and not f.is_file():
                problems.append(f"{f.name} is listed but missing")
            elif f.is_file() and f.name not in listed:
                problems.append(f"{f.name} is not listed")
            elif f.is_file() and file_sha256(f) != listed[f.name]:
                problems.append(f"{f.name} does not match its sha256")
    if problems:
        msg = f"{model_path}: checksum manifest {manifest} check failed: " + "; ".join(problems)
        if not trust:
            raise UntrustedModelError(f"{msg}. Refusing to load it; {TRUST_HINT}")
        warnings.warn(f"{msg} (loading anyway: trusted)", stacklevel=2)
    return True


# ---- SB3 zips without cloudpickle ---------------------------------------------------------

#: Policy classes a zip may name, per algorithm: (module, class names).
_POLICY_CLASSES = {
    "ppo": ("stable_baselines3.common.policies",
            ("ActorCriticPolicy", "ActorCriticCnnPolicy", "MultiInputActorCriticPolicy")),
    "sac": ("stable_baselines3.sac.policies", ("SACPolicy", "CnnPolicy", "MultiInputPolicy")),
    "ppo_lstm": ("sb3_contrib.common.recurrent.policies",
                 ("RecurrentActorCriticPolicy", "RecurrentActorCriticCnnPolicy",
                  "RecurrentMultiInputActorCriticPolicy")),
}  # fmt: skip
_FLOAT = re.compile(r"[-+]?(?:\d+\.?\d*(?:[eE][-+]?\d+)?|\.\d+(?:[eE][-+]?\d+)?|inf|nan)")


def _class_name(item: dict[str, Any]) -> str | None:
    """The name of a serialized class, from the text of its ``__init__`` entry."""
    m = re.fullmatch(r"<function (\w+)\.__init__ at 0x[0-9a-f]+>", str(item.get("__init__", "")))
    return m.group(1) if m else None


def _policy_class(item: dict[str, Any], algo: str):
    import importlib

    module, allowed = _POLICY_CLASSES[algo]
    name = _class_name(item)
    if item.get("__module__") != module or name not in allowed:
        raise UntrustedModelError(f"policy_class {item.get('__module__')}.{name} is not one of "
                                  f"{module}.{allowed}")  # fmt: skip
    return getattr(importlib.import_module(module), name)


def _bound(text: Any, shape: tuple[int, ...], dtype: np.dtype) -> np.ndarray:
    """A Box bound from its ``str(ndarray)`` text; a summarised text ("...") only if
    every value shown is the same."""
    s = str(text)
    if not re.fullmatch(r"[\[\]\s\d.eE+\-infa]*(\.\.\.[\[\]\s\d.eE+\-infa]*)*", s):
        raise UntrustedModelError(f"cannot read a Box bound from {s[:60]!r}")
    values = [float(v) for v in _FLOAT.findall(s.replace("...", " "))]
    if "..." in s:
        if not values or len(set(values)) != 1:
            raise UntrustedModelError("a summarised Box bound with different values")
        return np.full(shape, values[0], dtype=dtype)
    if len(values) != int(np.prod(shape)):
        raise UntrustedModelError(f"a Box bound with {len(values)} values for shape {shape}")
    return np.array(values, dtype=dtype).reshape(shape)


def _box(item: dict[str, Any]):
    from gymnasium import spaces

    if item.get(":type:") != "<class 'gymnasium.spaces.box.Box'>":
        raise UntrustedModelError(f"space of type {item.get(':type:')} (only Box is rebuilt)")
    try:
        shape = tuple(int(n) for n in item["_shape"])
        dtype = np.dtype(str(item["dtype"]))
    except (KeyError, TypeError, ValueError) as exc:
        raise UntrustedModelError(f"cannot read a Box from {sorted(item)}") from exc
    if dtype.kind not in "fiu":
        raise UntrustedModelError(f"a Box of dtype {dtype}")
    low, high = _bound(item.get("low"), shape, dtype), _bound(item.get("high"), shape, dtype)
    return spaces.Box(low=low, high=high, shape=shape, dtype=dtype)


#: One Box of a Dict space's text: ``'key': Box(low, high, (shape), dtype)`` (numpy
#: prints an array bound without commas; a bound that is one value is printed as it).
_DICT_BOX = re.compile(r"'(\w+)': Box\(([^,()]+), ([^,()]+), \(([\d, ]*)\), (\w+)\)")


def _space(item: dict[str, Any]):
    """A Box, or a Dict of Boxes (``obs_mode="dict"``) from the text of its spaces."""
    from gymnasium import spaces

    if item.get(":type:") != "<class 'gymnasium.spaces.dict.Dict'>":
        return _box(item)
    text = str(item.get("spaces", ""))
    entries = _DICT_BOX.findall(text)
    if not entries or _DICT_BOX.sub("", text) != "{" + ", " * (len(entries) - 1) + "}":
        raise UntrustedModelError(f"cannot read a Dict of Boxes from {text[:60]!r}")
    boxes = {}
    for key, low, high, shape_text, dtype_text in entries:
        shape = tuple(int(n) for n in shape_text.replace(",", " ").split())
        dtype = np.dtype(dtype_text)
        if dtype.kind not in "fiu":
            raise UntrustedModelError(f"a Box of dtype {dtype}")
        bounds = [np.full(shape, _bound(b, (1,), dtype)[0], dtype=dtype) if "[" not in b
                  else _bound(b, shape, dtype) for b in (low, high)]  # fmt: skip
        boxes[key] = spaces.Box(low=bounds[0], high=bounds[1], shape=shape, dtype=dtype)
    return spaces.Dict(boxes)


def _schedule_value(item: dict[str, Any], default: float) -> float:
    m = re.fullmatch(r"ConstantSchedule\(val=([-+0-9.eE]+)\)", str(item.get("value_schedule")))
    return float(m.group(1)) if m else default


def _train_freq(item: dict[str, Any]):
    from stable_baselines3.common.type_aliases import TrainFreq, TrainFrequencyUnit

    return TrainFreq(1, TrainFrequencyUnit.STEP)


#: How each serialized entry is rebuilt (inference needs only the policy class and the
#: spaces; the others are training state, replaced by neutral values).
_REBUILD = {
    "policy_class": _policy_class,
    "observation_space": lambda item, algo: _space(item),
    "action_space": lambda item, algo: _box(item),
    "lr_schedule": lambda item, algo: _schedule_value(item, 0.0),
    "learning_rate": lambda item, algo: 0.0,
    "clip_range": lambda item, algo: _schedule_value(item, 0.2),
    "clip_range_vf": lambda item, algo: None,
    "_last_obs": lambda item, algo: None,
    "_last_episode_starts": lambda item, algo: None,
    "_last_original_obs": lambda item, algo: None,
    "ep_info_buffer": lambda item, algo: deque(maxlen=100),
    "ep_success_buffer": lambda item, algo: deque(maxlen=100),
    "rollout_buffer_class": lambda item, algo: None,
    "replay_buffer_class": lambda item, algo: None,
    "train_freq": lambda item, algo: _train_freq(item),
    "action_noise": lambda item, algo: None,
}


def safe_custom_objects(model_path: str | Path, algo: str) -> dict[str, Any]:
    """The ``custom_objects`` that replace every cloudpickled entry of the zip's ``data``
    (so SB3's ``json_to_data`` unpickles nothing). Raises :class:`UntrustedModelError`
    if an entry cannot be rebuilt from data."""
    model_path = Path(model_path)
    try:
        with zipfile.ZipFile(model_path) as z:
            data = json.loads(z.read("data"))
    except (OSError, zipfile.BadZipFile, KeyError, ValueError) as exc:
        raise UntrustedModelError(f"{model_path} is not an SB3 model zip ({exc})") from exc
    if not isinstance(data, dict):
        raise UntrustedModelError(f"{model_path}: its data entry is not a JSON object")
    custom: dict[str, Any] = {}
    for key, item in data.items():
        if not (isinstance(item, dict) and ":serialized:" in item):
            continue
        if key == "lr_schedule" and isinstance(data.get("learning_rate"), (int, float)):
            custom[key] = float(data["learning_rate"])
            continue
        rebuild = _REBUILD.get(key)
        if rebuild is None:
            raise UntrustedModelError(f"{model_path}: the pickled entry {key!r} cannot be "
                                      f"rebuilt without unpickling it; {TRUST_HINT}")  # fmt: skip
        try:
            custom[key] = rebuild(item, algo)
        except UntrustedModelError as exc:
            raise UntrustedModelError(f"{model_path}: entry {key!r}: {exc}; {TRUST_HINT}") from exc
    # everything SB3 would unpickle is replaced: check it once more
    left = [k for k, v in data.items()
            if isinstance(v, dict) and ":serialized:" in v and k not in custom]  # fmt: skip
    assert not left, left
    return custom


# ---- the policy ---------------------------------------------------------------------------


def frame_stack(config: dict[str, Any]) -> int:
    """rl-zoo's ``frame_stack``: the number of observations the agent sees, the newest
    last (SB3 ``VecFrameStack`` over the normalised observation); 1 when absent, false
    or 0 (no stack, as in rl-zoo)."""
    n = config.get("frame_stack")
    if n is None or n is False or (type(n) is int and n == 0):
        return 1
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"frame_stack must be an integer >= 1, got {n!r}")
    return n


class SB3Policy:
    """A trained PPO/SAC model, deterministic, with its observation normalisation
    (``normalize_obs`` of :class:`NormalizerStats`; rewards are not normalised at
    inference)."""

    def __init__(self, model, vecnormalize=None, name: str = "sb3", base=None,
                 scale: float = 0.0, frame_stack: int = 1,
                 observe_base: bool = False,
                 keepout_headings: Sequence[str] = (),
                 mirror: Callable[[np.ndarray], np.ndarray] | None = None) -> None:  # fmt: skip
        self.model = model
        self.vecnormalize = vecnormalize
        self.name = name
        #: residual agents (policies/residual.py): action = clip(base + scale * a)
        self.base = base
        self.scale = float(scale)
        #: the agent also sees the base's action (policies/residual.py ``observe``)
        self.observe_base = bool(observe_base)
        #: rl-zoo ``frame_stack``: the model sees the last n normalised observations,
        #: newest last, zeros before the episode's first (SB3 VecFrameStack)
        self.frame_stack = int(frame_stack)
        #: one stack per view: the observation, and with ``mirror`` its mirror image
        self._stacks: dict[bool, np.ndarray] = {}
        #: a recurrent model's (RecurrentPPO, ``ppo_lstm``) LSTM states, one per view;
        #: absent at an episode's start (SB3's ``episode_start``, which zeroes them)
        self.recurrent = hasattr(getattr(model, "policy", None), "lstm_actor")
        self._lstm: dict[bool, Any] = {}
        #: ``mirror_average``: the model's action is the mean of its action for the
        #: observation and, mirrored back, for the observation's mirror image in z
        #: (``mirror``: the env's ``ObservationLayout.z_mirror``; with ``observe_base``
        #: the base's action follows, its z mirrored too)
        self.mirror = mirror
        #: residual agents: the routes handed to the route follower (policies/residual.py
        #: ``HeadingGate``), decided at the first observation after :meth:`reset`
        self.gate = None
        if base is not None:
            self.gate = HeadingGate(keepout_headings, base.slices, getattr(base, "_env", None))
        elif keepout_headings:
            raise ValueError("keepout_headings needs a residual agent (its base reads the env)")
        from gymnasium import spaces

        #: a Dict observation (``obs_mode="dict"``): its parts pass to the model as they are
        self.multi_input = isinstance(getattr(model, "observation_space", None), spaces.Dict)
        if self.multi_input and (self.frame_stack > 1 or observe_base or mirror is not None):
            raise ValueError("a model of a Dict observation (obs_mode dict) takes no "
                             "frame_stack, observe_base or mirror_average")  # fmt: skip

    def reset(self, seed: int | None = None) -> None:
        self._stacks = {}
        self._lstm = {}
        if self.base is not None:
            self.base.reset(seed)
        if self.gate is not None:
            self.gate.reset(seed)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """The action for ``obs``; call :meth:`reset` at each episode's start (with
        ``frame_stack`` the stack restarts there, a recurrent model's memory too; with
        ``keepout_headings`` the route's heading is read off the observation after it)."""
        if self.gate is not None and self.gate.defers(obs):
            return np.asarray(self.gate.fallback.act(obs), dtype=np.float32)
        b = self.base.act(obs) if self.base is not None else None  # the vector's reader
        o = obs if self.multi_input else np.asarray(observe(obs, b) if self.observe_base
                                                    else obs, dtype=np.float32)  # fmt: skip
        a = self._model_action(o, mirrored=False)
        if self.mirror is not None:
            om = self.mirror(obs)
            if self.observe_base:
                om = observe(om, b * ACTION_Z_MIRROR)
            mirrored = self._model_action(om, mirrored=True) * ACTION_Z_MIRROR
            a = (0.5 * (a.astype(np.float64) + mirrored)).astype(np.float32)
        if b is not None:
            return combine(b, a, self.scale)
        return a

    def _model_action(self, o: np.ndarray | dict[str, np.ndarray],
                      mirrored: bool) -> np.ndarray:  # fmt: skip
        """The model's deterministic action for the raw observation ``o`` ((d,), or a dict
        of its parts), through its normalisation and its frame stack (one per view)."""
        o = {k: np.asarray(v)[None] for k, v in o.items()} if isinstance(o, dict) else o[None]
        if self.vecnormalize is not None:
            o = self.vecnormalize.normalize_obs(o)
        if self.frame_stack > 1:
            d = o.shape[-1]
            stack = self._stacks.get(mirrored)
            if stack is None:
                stack = np.zeros((1, d * self.frame_stack), dtype=o.dtype)
            stack = np.roll(stack, -d, axis=-1)
            stack[:, -d:] = o
            self._stacks[mirrored] = o = stack
        if self.recurrent:
            state = self._lstm.get(mirrored)
            action, self._lstm[mirrored] = self.model.predict(
                o, state=state, episode_start=np.array([state is None]), deterministic=True
            )
        else:
            action, _ = self.model.predict(o, deterministic=True)
        return np.asarray(action, dtype=np.float32).reshape(-1)


def algo_class(algo: str):
    """The SB3 class of ``algo`` (one of :data:`ALGOS`); ``ppo_lstm`` needs sb3-contrib."""
    if algo == "ppo_lstm":
        try:
            from sb3_contrib import RecurrentPPO
        except ImportError as exc:
            raise ImportError("ppo_lstm (RecurrentPPO) needs sb3-contrib: "
                              "pip install 'sb3-contrib~=2.9.0'") from exc  # fmt: skip
        return RecurrentPPO
    from stable_baselines3 import PPO, SAC

    classes = {"ppo": PPO, "sac": SAC}
    if algo not in classes:
        raise ValueError(f"unknown algorithm {algo!r}; one of {ALGOS}")
    return classes[algo]


def model_config(model_path: Path) -> Any:
    """The resolved config beside a model (``<name>.yml``, written by cnt-train), parsed
    with ``yaml.safe_load``; {} without one (or an empty one)."""
    path = model_path.with_suffix(".yml")
    if not path.is_file():
        return {}
    import yaml

    return yaml.safe_load(path.read_text()) or {}


def algo_of(model_path: str | Path, algo: str | None = None) -> str:
    """``algo`` if given, else the one the file name contains, else the ``run: algo`` of
    the resolved config beside the model (:func:`model_config`)."""
    model_path = Path(model_path)
    cfg_path = model_path.with_suffix(".yml")
    if algo is None:
        # the longest name first: "ppo_lstm.zip" also contains "ppo"
        names = sorted(ALGOS, key=len, reverse=True)
        algo = next((a for a in names if a in model_path.name.lower()), None)
    if algo is None:
        import yaml

        try:
            cfg = model_config(model_path)
        except yaml.YAMLError:
            cfg = None
        run = cfg.get("run") if isinstance(cfg, dict) else None
        algo = run.get("algo") if isinstance(run, dict) else None
    if algo not in ALGOS:
        raise ValueError(f"cannot tell the algorithm of {model_path}: neither its name nor "
                         f"a 'run: algo:' in {cfg_path.name} beside it names one of {ALGOS}; "
                         "pass the algorithm, or name the file with it (e.g. ppo.zip)")  # fmt: skip
    return algo


def check_model(model_path: str | Path, algo: str | None = None, trust: bool = False) -> None:
    """Everything :func:`load_policy` refuses, checked without loading the model (so a
    command can fail before it starts workers)."""
    model_path = Path(model_path)
    if not model_path.is_file():
        raise FileNotFoundError(f"no model at {model_path}")
    algo = algo_of(model_path, algo)
    check_manifest(model_path, trust)
    if trust:
        return
    safe_custom_objects(model_path, algo)
    vn = vecnormalize_path(model_path)
    has_data = vn.with_suffix(".npz").is_file() and vn.with_suffix(".json").is_file()
    if not has_data and vn.is_file():
        raise UntrustedModelError(
            f"{vn} is a pickle (loading it can run any code) and there is no "
            f"{vn.with_suffix('.npz').name} + .json beside it; convert it once with "
            f"policies.sb3.convert_vecnormalize_pickle if you trust it, or {TRUST_HINT}"
        )


def load_policy(model_path: str | Path, algo: str | None = None, device: str = "cpu",
                trust: bool = False, env=None,
                keepout_headings: Sequence[str] | None = None,
                mirror_average: bool | None = None) -> SB3Policy:  # fmt: skip
    """Load ``model_path`` (``.zip``; ``algo`` from the file name if not given), the
    VecNormalize statistics beside it, if any, and, if the resolved config beside it
    (``<name>.yml``) says the agent is residual, its base policy with the options that
    config pins (``base_kwargs``; a config without them gets today's defaults, and a
    warning).

    ``env`` is the env the policy will act in. A residual agent's base (the route
    follower) reads the episode's route from it, as it did in training (its plan around
    keep-outs and its memory of the band); without ``env`` the base sees only the
    observation, a weaker follower than the one the agent was trained on, and a warning
    says so.

    ``keepout_headings`` overrides the config's (a residual agent's routes with a keep-out
    handed to the route follower, :class:`policies.residual.HeadingGate`; ``()``: none).
    ``mirror_average`` overrides the config's (the residual's ``mirror_average``, default
    false): the model's action averaged with its action for the observation's mirror
    image in z, mirrored back (:class:`SB3Policy`; needs ``env``, whose observation layout
    gives the mirror image, ``ObservationLayout.z_mirror``).

    Without ``trust`` nothing is unpickled (module doc); a pickle, a zip entry that
    cannot be rebuilt from data or a manifest mismatch raise :class:`UntrustedModelError`."""
    check_mkl()
    model_path = Path(model_path)
    algo = algo_of(model_path, algo)
    check_model(model_path, algo, trust)
    cls = algo_class(algo)
    if trust:
        model = cls.load(str(model_path), device=device)
    else:
        model = cls.load(str(model_path), device=device,
                         custom_objects=safe_custom_objects(model_path, algo))  # fmt: skip
    vn = None
    vn_path = vecnormalize_path(model_path)
    if vn_path.with_suffix(".npz").is_file() and vn_path.with_suffix(".json").is_file():
        vn = load_vecnormalize(vn_path)
    elif vn_path.is_file():  # only with trust (check_model)
        vn = _load_vecnormalize_pickle(vn_path)
    base, scale, n_stack, observe_base, headings, mirror = None, 0.0, 1, False, (), False
    cfg_path = model_path.with_suffix(".yml")
    if cfg_path.is_file():
        cfg = model_config(model_path)
        entry = cfg.get("CNTDeposit-v0") or {}
        n_stack = frame_stack(entry)
        residual = residual_settings(entry)
        if residual is not None:
            from cnt_env.task import CNTDepositEnv

            if env is None:
                warnings.warn(f"{model_path.name} is a residual agent: pass env= (the env it "
                              "acts in) to load_policy, or its base follower cannot see the "
                              "route it was trained to read", stacklevel=2)  # fmt: skip
                env_kwargs = dict(entry.get("env_kwargs") or {})
                env_kwargs.pop("max_episode_steps", None)  # gymnasium.make's, not the env's
                env = CNTDepositEnv(**env_kwargs)
            if "base_kwargs" not in residual:
                warnings.warn(f"{cfg_path.name} does not pin the options of the residual "
                              "agent's base (a config written before they were pinned): it "
                              "gets today's defaults, which may differ from those it was "
                              "trained on", stacklevel=2)  # fmt: skip
            base = make_base_policy(residual.get("base", "scripted"), env,
                                    residual.get("base_kwargs"))  # fmt: skip
            scale = float(residual.get("scale", 0.5))
            observe_base = bool(residual.get("observe_base", False))
            headings = tuple(residual.get("keepout_headings") or ())
            mirror = bool(residual.get("mirror_average", False))
    if keepout_headings is not None:
        headings = tuple(keepout_headings)
    if mirror_average is not None:
        mirror = bool(mirror_average)
    mirror_of = None
    if mirror:
        layout = getattr(getattr(env, "unwrapped", None), "layout", None)
        if layout is None or getattr(env.unwrapped, "obs_mode", None) != "vector":
            raise ValueError(
                "mirror_average needs env=, a CNTDeposit-v0 with the vector "
                "observation (its layout gives the mirror image)"
            )
        mirror_of = layout.z_mirror
    return SB3Policy(model, vn, name=algo, base=base, scale=scale, frame_stack=n_stack,
                     observe_base=observe_base, keepout_headings=headings,
                     mirror=mirror_of)  # fmt: skip


# ---- VecNormalize statistics as data ------------------------------------------------------


class NormalizerStats:
    """The observation normalisation of a saved VecNormalize, without a venv or pickle:
    ``normalize_obs`` as VecNormalize's (clip((obs - mean) / sqrt(var + eps))). A Dict
    observation (``obs_mode="dict"``) has one set of statistics per normalised key
    (``norm_obs_keys``; the image is not normalised): ``obs_rms`` is then a dict."""

    def __init__(self, stats: dict[str | None, tuple[np.ndarray, np.ndarray, float]],
                 clip_obs: float, epsilon: float, norm_obs: bool) -> None:  # fmt: skip
        """``stats``: key -> (mean, var, count); the key None for a Box observation."""
        from stable_baselines3.common.running_mean_std import RunningMeanStd

        rms = {}
        for key, (mean, var, count) in stats.items():
            rms[key] = RunningMeanStd(shape=mean.shape)
            rms[key].mean, rms[key].var, rms[key].count = mean, var, count
        # one RunningMeanStd for a Box (an empty one when not normalised), a dict for a Dict
        self.obs_rms: Any = rms if rms and None not in rms else rms.get(None, RunningMeanStd((0,)))
        self.clip_obs, self.epsilon, self.norm_obs = clip_obs, epsilon, norm_obs
        self.training = False

    def _normalize(self, obs: np.ndarray, rms) -> np.ndarray:
        o = (obs - rms.mean) / np.sqrt(rms.var + self.epsilon)
        return np.clip(o, -self.clip_obs, self.clip_obs).astype(np.float32)

    def normalize_obs(self, obs: np.ndarray | dict[str, np.ndarray]):
        if not self.norm_obs:
            return obs
        if isinstance(self.obs_rms, dict):
            return {k: self._normalize(o, self.obs_rms[k]) if k in self.obs_rms else o
                    for k, o in obs.items()}  # fmt: skip
        return self._normalize(obs, self.obs_rms)


def _obs_statistics(venv) -> dict[str, Any]:
    """A VecNormalize's observation statistics by key (None for a Box observation)."""
    if not venv.norm_obs:  # VecNormalize keeps no observation statistics without norm_obs
        return {}
    return dict(venv.obs_rms) if isinstance(venv.obs_rms, dict) else {None: venv.obs_rms}


def _suffix(key: str | None) -> str:
    return "" if key is None else f".{key}"  # npz names: obs_mean, or obs_mean.<key>


def _keys_meta(stats: dict[str | None, Any]) -> dict[str, Any]:
    """The settings that name a normaliser's statistics: ``norm_obs``, and for a Dict
    observation its ``norm_obs_keys`` (what :func:`_saved_obs_statistics` reads)."""
    meta: dict[str, Any] = {"norm_obs": bool(stats)}
    if stats and None not in stats:
        meta["norm_obs_keys"] = sorted(stats)
    return meta


def save_vecnormalize(venv, stem: Path) -> tuple[Path, Path]:
    """Write ``<stem>.npz`` (obs and return running statistics; per key, ``obs_mean.<key>``,
    for a Dict observation) and ``<stem>.json`` (settings) for the VecNormalize ``venv``."""
    stem = Path(stem)
    arrays = {"ret_mean": venv.ret_rms.mean, "ret_var": venv.ret_rms.var,
              "ret_count": np.array(venv.ret_rms.count)}  # fmt: skip
    stats = _obs_statistics(venv)
    for key, rms in stats.items():
        x = _suffix(key)
        arrays |= {f"obs_mean{x}": rms.mean, f"obs_var{x}": rms.var,
                   f"obs_count{x}": np.array(rms.count)}  # fmt: skip
    npz = stem.with_suffix(".npz")
    np.savez(npz, **arrays)
    meta = {"clip_obs": venv.clip_obs, "clip_reward": venv.clip_reward, "gamma": venv.gamma,
            "epsilon": venv.epsilon, "norm_reward": venv.norm_reward,
            "format": "cnt_env vecnormalize 1", **_keys_meta(stats)}  # fmt: skip
    js = stem.with_suffix(".json")
    js.write_text(json.dumps(meta, indent=2) + "\n")
    return npz, js


def _statistics_arrays(stem: Path) -> dict[str, np.ndarray]:
    """The arrays of ``<stem>.npz`` (:func:`save_vecnormalize`) as float64, unpickling
    nothing."""
    with np.load(stem.with_suffix(".npz"), allow_pickle=False) as d:
        return {k: np.asarray(d[k], dtype=np.float64) for k in d.files}


def _saved_obs_statistics(meta: dict[str, Any], arrays: dict[str, np.ndarray]
                          ) -> dict[str | None, tuple[np.ndarray, np.ndarray, float]]:  # fmt: skip
    """key -> (mean, var, count) of a saved normaliser (none without ``norm_obs``)."""
    if not meta["norm_obs"]:  # an image observation: the reward's statistics alone
        return {}
    keys = [str(k) for k in meta["norm_obs_keys"]] if "norm_obs_keys" in meta else [None]
    return {k: (arrays[f"obs_mean{_suffix(k)}"], arrays[f"obs_var{_suffix(k)}"],
                float(arrays[f"obs_count{_suffix(k)}"])) for k in keys}  # fmt: skip


def load_vecnormalize(stem: Path) -> NormalizerStats:
    """The statistics written by :func:`save_vecnormalize` (for inference)."""
    stem = Path(stem)
    try:
        meta = json.loads(stem.with_suffix(".json").read_text())
        stats = _saved_obs_statistics(meta, _statistics_arrays(stem))
        return NormalizerStats(stats, float(meta["clip_obs"]), float(meta["epsilon"]),
                               bool(meta["norm_obs"]))  # fmt: skip
    except (OSError, ValueError, KeyError, TypeError) as exc:
        msg = f"cannot read the VecNormalize statistics {stem}.npz/.json: {exc}"
        raise ValueError(msg) from exc


def restore_vecnormalize(venv, stem: Path) -> None:
    """Set the running statistics of the VecNormalize ``venv`` (training goes on updating
    them) to those written by :func:`save_vecnormalize` at ``stem``: to continue training a
    saved agent. Its settings (clip, gamma, ...) stay the venv's (the config's)."""
    stem = Path(stem)
    now = _obs_statistics(venv)
    try:
        arrays = _statistics_arrays(stem)
        ret_mean, ret_var = arrays["ret_mean"], arrays["ret_var"]
        ret_count = float(arrays["ret_count"])
        saved = _saved_obs_statistics(_keys_meta(now), arrays)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        msg = f"cannot read the VecNormalize statistics {stem}.npz: {exc}"
        raise ValueError(msg) from exc
    for key, rms in now.items():
        mean, var, count = saved[key]
        if mean.shape != rms.mean.shape:
            part = "observations" if key is None else f"the observation's {key!r}"
            raise ValueError(f"the VecNormalize statistics {stem}.npz are for {part} of "
                             f"shape {mean.shape}, the env gives {rms.mean.shape}: the agent "
                             "was trained on another observation")  # fmt: skip
        rms.mean, rms.var, rms.count = mean, var, count
    if ret_mean.shape != venv.ret_rms.mean.shape:
        raise ValueError(f"the VecNormalize statistics {stem}.npz hold a return of shape "
                         f"{ret_mean.shape}, the env's is {venv.ret_rms.mean.shape}")  # fmt: skip
    venv.ret_rms.mean, venv.ret_rms.var, venv.ret_rms.count = ret_mean, ret_var, ret_count


def _load_vecnormalize_pickle(path: Path):
    import pickle

    with Path(path).open("rb") as fh:
        vn = pickle.load(fh)  # only with trust=True (check_model)
    vn.training = False
    return vn


def convert_vecnormalize_pickle(pkl_path: str | Path) -> tuple[Path, Path]:
    """TRUSTED step: unpickle ``<name>_vecnormalize.pkl`` (this runs whatever code it
    holds) and write its statistics as ``.npz`` + ``.json`` beside it."""
    pkl_path = Path(pkl_path)
    return save_vecnormalize(_load_vecnormalize_pickle(pkl_path), pkl_path.with_suffix(""))

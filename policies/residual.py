"""Residual actions (Silver et al. 2018; Johannink et al. 2019): the agent's action ``a``
corrects a base policy's, and the env receives ``clip(base(obs) + scale * a, -1, 1)``.

With ``observe_base`` the agent also sees the base's action: its observation is the env's
followed by ``base(obs)`` (:func:`observe`). The route follower acts on a memory of the
band (its last control steps and its one-step lead) that the env's observation does not
hold, so without it the agent cannot tell what it is correcting.

With ``keepout_headings`` the route follower plays, the agent and its base idle, every
episode whose route has a keep-out and a first leg along one of those axes
(:class:`HeadingGate`): the routes on which the agent was measured to lose to it.

The one implementation, used by the training wrapper (``training/common.py``
``ResidualAction``) and by trained residual agents at inference (``policies/sb3.py``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = [
    "BASES",
    "WRAPPER",
    "HeadingGate",
    "base_options",
    "combine",
    "has_keepout",
    "make_base_policy",
    "observe",
    "observed_space",
    "pin_base",
    "residual_settings",
    "zoo_entry",
    "zoo_names",
]

#: Base policies a residual agent can correct.
BASES = ("scripted",)
#: The rl-zoo ``env_wrapper`` entry of a residual agent (training/common.py).
WRAPPER = "training.common.ResidualAction"


def residual_settings(entry: dict) -> dict | None:
    """The residual settings ``{"base", "scale"}`` of an rl-zoo config entry: its
    ``env_wrapper`` ``training.common.ResidualAction`` (with its kwargs), or the older
    ``residual`` key; None for a plain agent."""
    if entry.get("residual"):
        return dict(entry["residual"])
    return zoo_entry(entry.get("env_wrapper"), WRAPPER)


def _zoo_list(entries: Any) -> list:
    """An rl-zoo list (``env_wrapper``, ``callback``) as a list: a single entry may stand
    alone, and an absent one is empty."""
    return entries if isinstance(entries, list) else [entries] if entries else []


def _names(entry: Any, name: str) -> bool:
    """Whether an rl-zoo list entry (a name, or a one-key dict name -> kwargs) is ``name``."""
    return entry == name or (isinstance(entry, dict) and name in entry)


def zoo_entry(entries: Any, name: str) -> dict[str, Any] | None:
    """The kwargs of ``name`` in an rl-zoo list (``env_wrapper``, ``callback``): entries
    are a name, or a one-key dict name -> kwargs; a single entry may stand alone.
    None when ``name`` is absent."""
    for e in _zoo_list(entries):
        if _names(e, name):
            return dict(e[name] or {}) if isinstance(e, dict) else {}
    return None


def zoo_names(entries: Any) -> list[Any]:
    """The names in an rl-zoo list (``env_wrapper``, ``callback``), in order."""
    return [n for e in _zoo_list(entries) for n in (list(e) if isinstance(e, dict) else [e])]


def pin_base(entry: dict, score_mode: str) -> dict:
    """A copy of the rl-zoo config entry ``entry`` whose residual settings (if any) hold
    every option of the base (:func:`base_options`) under ``base_kwargs``: written beside
    a trained model, so it loads with the base it was trained on."""
    residual = residual_settings(entry)
    if residual is None:
        return dict(entry)
    pinned = {
        **residual,
        "base_kwargs": base_options(
            residual.get("base", "scripted"), score_mode, residual.get("base_kwargs")
        ),
    }
    out = dict(entry)
    if entry.get("residual"):
        out["residual"] = pinned
        return out
    out["env_wrapper"] = [
        {WRAPPER: pinned} if _names(w, WRAPPER) else w for w in _zoo_list(entry["env_wrapper"])
    ]
    return out


def combine(base_action: np.ndarray, residual: np.ndarray, scale: float) -> np.ndarray:
    """clip(base + scale * residual, -1, 1) as float32."""
    a = np.asarray(base_action, dtype=np.float64) + scale * np.asarray(residual, dtype=np.float64)
    return np.clip(a, -1.0, 1.0).astype(np.float32)


class HeadingGate:
    """Which episodes a residual agent hands to the route follower (``keepout_headings``):
    those whose route has a keep-out and runs, at the episode's first observation,
    nearest to one of the axes ``headings`` ("+x", "+z", "-x", "-z";
    :func:`policies.opening.route_axis`). Empty: none. The follower (``fallback``) is the
    scripted baseline with its defaults (policies/route_follower.py), not the agent's
    pinned base: the shipped agent's base predates the follower's steering of runs along
    the steps (``run_centre``), and lays those detours no better than the agent.

    Why an option: the shipped agent shorts the keep-out at the first corner of most drawn
    detours whose first leg runs down the steps' axis (-z), where the follower does not
    (12 of 19 against 1 over three sets: two on the model, one on the surrogate it was
    trained on), while on routes without a keep-out that start along -z it is ahead of the
    follower (benchmarks/RESULTS.md, issue 10, "Drawn detours"). An agent whose first
    stage drew mirrored starts (``start_mirror``; one run) shorts the mirror images,
    detours that start along +z (5-6 of 14 against the follower's 0), and needs
    ``["-z", "+z"]`` (same file, "Mirrored starts in the first stage only")."""

    def __init__(self, headings: Any, slices: dict[str, slice], env: Any = None) -> None:
        from .opening import AXES

        if isinstance(headings, str) or not all(h in AXES for h in headings):
            raise ValueError(f"keepout_headings must be a list of {list(AXES)}, got {headings!r}")
        self.headings: tuple[str, ...] = tuple(headings)
        self.slices = slices
        self.fallback = None
        if self.headings:
            if env is None or getattr(env.unwrapped, "score_mode", None) != "corridor":
                raise ValueError(
                    "keepout_headings needs the route task's env (score 'corridor'): "
                    "the follower it hands routes to reads it"
                )
            from .route_follower import RouteFollower

            self.fallback = RouteFollower.from_env(env)
        #: whether the follower plays this episode (decided by :meth:`defers`)
        self.deferred = False
        self._pending = True  # the next observation is an episode's first

    def reset(self, seed: int | None = None) -> None:
        """A new episode: the next observation decides it."""
        self.deferred, self._pending = False, True
        if self.fallback is not None:
            self.fallback.reset(seed)

    def defers(self, obs: np.ndarray) -> bool:
        """Whether the follower plays the episode ``obs`` belongs to, decided at its first
        observation (the first after :meth:`reset`)."""
        if self._pending:
            from .base import vector_part
            from .opening import route_axis

            obs = vector_part(obs)
            self.deferred = (bool(self.headings) and has_keepout(obs, self.slices)
                             and route_axis(obs, self.slices) in self.headings)  # fmt: skip
            self._pending = False
        return self.deferred


def has_keepout(obs: np.ndarray, slices: dict[str, slice]) -> bool:
    """Whether the observation's route has a keep-out: its nearest keep-out point (the last
    two values of the ``route`` slice) is in view (cnt_env/task/spaces.py
    ``keepout_in_view``), not the far point that stands for none."""
    from cnt_env.task.spaces import keepout_in_view

    if "route" not in slices:
        return False
    return keepout_in_view(*(float(v) for v in obs[slices["route"]][1:3]))


def observe(obs: np.ndarray, base_action: np.ndarray) -> np.ndarray:
    """The observation of a residual agent with ``observe_base``: the env's observation
    followed by the base's action for it, as float32."""
    return np.concatenate([np.asarray(obs, dtype=np.float32).reshape(-1),
                           np.asarray(base_action, dtype=np.float32).reshape(-1)])  # fmt: skip


def observed_space(observation_space, action_space):
    """The observation space of :func:`observe`: the env's (a flat Box) followed by the
    action space's bounds."""
    from gymnasium import spaces

    if not isinstance(observation_space, spaces.Box) or len(observation_space.shape) != 1:
        raise ValueError("observe_base needs a flat Box observation (the vector observation "
                         f"of CNTDeposit-v0), got {observation_space}")  # fmt: skip
    low = np.concatenate([observation_space.low, action_space.low]).astype(np.float32)
    high = np.concatenate([observation_space.high, action_space.high]).astype(np.float32)
    return spaces.Box(low, high, dtype=np.float32)


def _base_class(name: str, score_mode: str):
    from .route_follower import RouteFollower
    from .scripted import ScriptedPolicy

    if name not in BASES:
        raise ValueError(f"unknown residual base {name!r}; choose one of {BASES}")
    return RouteFollower if score_mode == "corridor" else ScriptedPolicy


def base_options(name: str, score_mode: str, base_kwargs: dict | None = None) -> dict:
    """Every option of the base policy ``name`` for the task ``score_mode``: its
    defaults, overridden by ``base_kwargs``. The training run writes them into the
    model's config (``env_wrapper`` ``base_kwargs``), so a model keeps the base it was
    trained on when the base's defaults change later. A config that pins every option
    but some the base gained since (``cls.ADDED``: each with the value that reproduces the
    base before it) was written before them: those take that value, not today's default.
    An unknown option raises."""
    cls = _base_class(name, score_mode)
    defaults = cls.OPTIONS
    given = dict(base_kwargs or {})
    unknown = set(given) - set(defaults)
    if unknown:
        raise ValueError(f"unknown option(s) {sorted(unknown)} of the {cls.__name__} base; "
                         f"its options are {sorted(defaults)}")  # fmt: skip
    added = getattr(cls, "ADDED", {})
    if given and set(defaults) - set(added) <= set(given):  # pinned before ``added``
        given = {**{k: v for k, v in added.items() if k not in given}, **given}
    return {**defaults, **given}


def make_base_policy(name: str, env, base_kwargs: dict | None = None):
    """The base policy ``name`` for ``env`` (a CNTDeposit-v0, wrapped or not): "scripted"
    is the scripted baseline of its task (the route follower for ``score="corridor"``,
    the tangent heuristic for ``"thin"``), with ``base_kwargs`` (:func:`base_options`)."""
    score_mode = env.unwrapped.score_mode
    cls = _base_class(name, score_mode)
    return cls.from_env(env, **base_options(name, score_mode, base_kwargs))

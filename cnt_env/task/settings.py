"""Validation of the keyword arguments of ``CNTDeposit-v0`` and the simulator settings they
resolve to: the preset's groups and mesh (:mod:`cnt_env.presets`), the env's speed
settings, then the caller's keywords. Every check raises ``ValueError`` in ``__init__``
with a message that says what to pass instead.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from cnt_env.presets import (
    DEFAULT_KAPPA_C,
    ENV_MESH,
    ENV_SIM_DEFAULTS,
    NEWTON,
    graded_coarse,
    mesh_for,
)
from cnt_env.sim.deposition import ContactOptions, DepositionConfig
from cnt_env.sim.stepper import NewtonOptions
from cnt_env.units import DimensionlessParams, paper_groups

__all__ = [
    "SUBSTRATES",
    "choice",
    "count",
    "deposition_config",
    "difficulty_value",
    "families_tuple",
    "gain_value",
    "mapping_or_none",
    "non_negative",
    "optional_path",
    "physics_params",
    "positive",
    "seed",
]

SUBSTRATES = ("flat", "stepped")


def positive(name: str, value: Any) -> float:
    v = _float(name, value)
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return v


def non_negative(name: str, value: Any) -> float:
    v = _float(name, value)
    if not (math.isfinite(v) and v >= 0):
        raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
    return v


def _float(name: str, value: Any) -> float:
    if isinstance(value, bool):
        raise ValueError(f"{name} must be a number, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a number, got {value!r}") from exc


def count(name: str, value: Any, minimum: int = 1) -> int:
    """An int >= ``minimum`` (bools rejected)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an int >= {minimum}, got {value!r}")
    return int(value)


def seed(name: str, value: Any) -> int:
    """A seed: an int >= 0."""
    return count(name, value, minimum=0)


def choice(name: str, value: Any, options: Sequence[Any]) -> Any:
    if not isinstance(value, str) or value not in options:
        raise ValueError(f"{name} must be one of {tuple(options)}, got {value!r}")
    return value


def optional_path(name: str, value: Any) -> str | None:
    """None or a path (str or os.PathLike), as str."""
    if value is None:
        return None
    if isinstance(value, (str, os.PathLike)):
        return os.fspath(value)
    raise ValueError(f"{name} must be a path (str or os.PathLike) or None, got {value!r}")


def mapping_or_none(name: str, value: Any) -> dict[str, Any]:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise ValueError(f"{name} must be a dict of keyword arguments or None, got {value!r}")
    return dict(value)


def families_tuple(value: Any, known: Mapping[str, Any]) -> tuple[str, ...]:
    """Training families: None (all of ``known``), one name, or a sequence of names."""
    if value is None:
        return tuple(known)
    names = (value,) if isinstance(value, str) else value
    try:
        names = tuple(names)
    except TypeError as exc:
        msg = f"families must be a family name or a list of them, got {value!r}"
        raise ValueError(msg) from exc
    for f in names:
        if not isinstance(f, str) or f not in known:
            raise ValueError(f"unknown training family {f!r}; choose from {sorted(known)}")
    if not names:
        raise ValueError("families must name at least one family")
    return names


def difficulty_value(value: Any) -> float | tuple[float, float]:
    """Route difficulty: a number in [0, 1], or a range ``[lo, hi]`` in [0, 1] (lo <= hi)
    from which each drawn route takes its own difficulty, uniformly (``np_random``)."""
    return _number_or_range("difficulty", value, lambda v: _difficulty_number(v, value))


def gain_value(value: Any) -> float | tuple[float, float]:
    """Flow gain: a number > 0, or a range ``[lo, hi]`` (0 < lo <= hi) from which each
    episode draws its own gain, log-uniformly (``np_random``): domain randomization of a
    surrogate's kinematics, whose drift per commanded flow then differs episode to episode."""
    return _number_or_range("flow_gain", value, lambda v: positive("flow_gain", v))


def _number_or_range(
    name: str, value: Any, number: Callable[[Any], float]
) -> float | tuple[float, float]:
    """``number(value)``, or for a list/tuple a range ``(lo, hi)`` of two such numbers with
    lo <= hi; a range of one point is that number."""
    if isinstance(value, (list, tuple)):
        if len(value) != 2:
            raise ValueError(f"a {name} range is [lo, hi], got {value!r}")
        lo, hi = (number(v) for v in value)
        if lo > hi:
            raise ValueError(f"a {name} range [lo, hi] needs lo <= hi, got {value!r}")
        return (lo, hi) if lo < hi else lo
    return number(value)


def _difficulty_number(value: Any, given: Any) -> float:
    try:
        d = float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"difficulty must be a number in [0, 1] or a range [lo, hi], "
                         f"got {given!r}") from exc  # fmt: skip
    if not 0.0 <= d <= 1.0:  # NaN fails here too
        raise ValueError(f"difficulty must be in [0, 1], got {given!r}")
    return d


def physics_params(
    preset: str,
    substrate: str | None,
    Hbar: float | None,
    Ibar: float | None,
    kappa_c_bar: float | None,
    delta_bar: float | None,
    vbar: float | None,
    phi: float | None,
    physics: Mapping[str, Any] | None,
) -> DimensionlessParams:
    """The dimensionless groups: the preset's, on the model's mesh (``presets.MESH``
    delta_bar), with the keywords on top."""
    base = paper_groups(preset)
    if substrate is None:
        substrate = "flat" if base.kappa_c_bar is None else "stepped"
    if substrate not in SUBSTRATES:
        raise ValueError(f"substrate must be one of {SUBSTRATES}, got {substrate!r}")
    overrides: dict[str, Any] = {"delta_bar": mesh_for(preset)["delta_bar"]}
    overrides.update(mapping_or_none("physics", physics))
    for name, value in (("Hbar", Hbar), ("Ibar", Ibar), ("delta_bar", delta_bar),
                        ("vbar", vbar), ("phi", phi)):  # fmt: skip
        if value is not None:
            overrides[name] = value
    if substrate == "flat":
        if kappa_c_bar is not None:
            raise ValueError("kappa_c_bar applies to the stepped substrate; pass "
                             "substrate='stepped' or drop kappa_c_bar")  # fmt: skip
        overrides["kappa_c_bar"] = None
    else:
        default = base.kappa_c_bar if base.kappa_c_bar is not None else DEFAULT_KAPPA_C
        overrides["kappa_c_bar"] = default if kappa_c_bar is None else kappa_c_bar
    return paper_groups(preset, **overrides)


def deposition_config(
    preset: str,
    params: DimensionlessParams,
    drag_law: str,
    sim_options: Mapping[str, Any] | None,
    **explicit: float | None,
) -> DepositionConfig:
    """The simulator config: the preset's start-up radius (``presets.MESH``), the env's
    graded rod (``presets.ENV_MESH``, snapped to a whole multiple of delta_bar), then the
    env's speed settings (``ENV_SIM_DEFAULTS`` of the substrate), then ``sim_options``,
    then the ``explicit`` keywords that are not None (dt, coarse_delta, initial_radius)."""
    mesh = mesh_for(preset)
    cfg: dict[str, Any] = {
        "initial_radius": mesh["initial_radius"],
        "coarse_delta": graded_coarse(ENV_MESH["coarse_delta"], params.delta_bar),
        "fine_length": ENV_MESH["fine_length"],
    }
    cfg.update(ENV_SIM_DEFAULTS["flat" if params.kappa_c_bar is None else "stepped"])
    cfg.update(mapping_or_none("sim_options", sim_options))
    cfg.update({k: v for k, v in explicit.items() if v is not None})
    if isinstance(cfg.get("newton"), Mapping):  # NewtonOptions fields over the model's
        try:
            cfg["newton"] = NewtonOptions(**{**NEWTON, **cfg["newton"]})
        except TypeError as exc:
            raise ValueError(f"sim_options['newton']: {exc}") from exc
    if isinstance(cfg.get("contact"), Mapping):  # ContactOptions fields, e.g. adhesion
        try:
            cfg["contact"] = ContactOptions(**cfg["contact"])
        except TypeError as exc:
            raise ValueError(f"sim_options['contact']: {exc}") from exc
    try:
        return DepositionConfig(params=params, drag_law=drag_law, **cfg)
    except TypeError as exc:  # an unknown field in sim_options
        raise ValueError(f"sim_options: {exc}") from exc

"""benchmarks/validation.py reuses a cached case only if it ran with today's settings."""

from __future__ import annotations

import argparse

from benchmarks import validation as v  # the repo root is on pytest's pythonpath


def _cached(suite: str, name: str, deposit: float, transient: float) -> dict:
    """What run_case records about its settings, for the current defaults."""
    return {**v.case_settings(suite, name), "deposit": deposit, "transient": transient,
            "amplitude": 30.0}  # fmt: skip


def test_a_case_cached_with_other_settings_is_run_again(capsys) -> None:
    args = argparse.Namespace(suite="serpentine", deposit=1500.0, transient=150.0)
    fresh = _cached("serpentine", "dt_half", 1500.0, 150.0)
    assert v._same_settings(args, "dt_half", fresh)
    assert not v._same_settings(args, "dt_half", None)
    # an older model default (another drag law) under the same case name
    other = "linear" if fresh["drag_law"] != "linear" else "printed"
    assert not v._same_settings(args, "dt_half", {**fresh, "drag_law": other})
    assert "drag_law" in capsys.readouterr().out
    # another run length, and a case that sets vbar against a record without it
    assert not v._same_settings(args, "dt_half", {**fresh, "deposit": 700.0}, quiet=True)
    no_vbar = {k: x for k, x in _cached("serpentine", "vbar_0.12", 1500.0, 150.0).items()
               if k != "vbar"}  # fmt: skip
    assert not v._same_settings(args, "vbar_0.12", no_vbar, quiet=True)
    # a record from before vbar was a setting ran at the preset's vbar: still fresh
    old_default = _cached("serpentine", "default", 1500.0, 150.0)
    del old_default["vbar"]
    assert v._same_settings(args, "default", old_default, quiet=True)


def test_cases_run_with_the_models_newton_options(capsys) -> None:
    """A case solves as the model does (presets.NEWTON: residual 1e-5, length projection,
    edge-rotation check, lagged Jacobian), not with the stepper's generic Newton; a
    record cached before those options were recorded is run again."""
    from cnt_env.sim.deposition import DepositionConfig

    for suite, name in (("coil", "default"), ("serpentine", "default"), ("serpentine", "dt_half")):
        case = v.case_config(suite, v.case_settings(suite, name))
        assert case.newton == DepositionConfig(params=case.params).newton
    args = argparse.Namespace(suite="serpentine", deposit=1500.0, transient=150.0)
    fresh = _cached("serpentine", "default", 1500.0, 150.0)
    before = {k: x for k, x in fresh.items() if k not in ("length_projection", "lagged_jacobian")}
    assert not v._same_settings(args, "default", before)
    assert "length_projection" in capsys.readouterr().out

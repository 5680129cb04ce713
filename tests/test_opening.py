"""policies/opening.py (the learned opening) and training/opening.py (its paired fit)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cnt_env.task.spaces import ObservationLayout, flow_from_action
from policies.opening import OpenedPolicy, Opening, context_of
from training.opening import fit

LAYOUT = ObservationLayout(16, 16, (2.0, 8.0, 77.5, 155.0), route=True)
VBAR_MAX = 0.13


def _obs(heading: float, contact_dir: tuple[float, float]) -> np.ndarray:
    obs = np.zeros(LAYOUT.size, dtype=np.float32)
    pts = np.array([[5.0 * i * math.cos(heading), 5.0 * i * math.sin(heading)]
                    for i in range(16)])  # fmt: skip
    obs[LAYOUT.slices["target"]] = pts.ravel()
    rod = LAYOUT.slices["rod"]
    obs[rod.start + 1 : rod.start + 3] = contact_dir
    return obs


@pytest.mark.parametrize("heading, sector", [
    (0.0, 0), (0.3, 0), (math.pi / 4, 1), (math.pi / 2, 2), (math.pi, 4),
    (-math.pi / 2, 6), (-0.3, 0), (-math.pi / 4 - 0.1, 7),
])  # fmt: skip
def test_the_context_is_the_heading_sector_centred_on_the_axes(heading, sector) -> None:
    assert context_of(_obs(heading, (0.0, 1.0)), LAYOUT.slices, 8).split(":")[0] == str(sector)


def test_the_context_side_is_where_the_contact_edge_points_across_the_route() -> None:
    # heading +x: an edge pointing +z is on the left (+), -z on the right (-)
    assert context_of(_obs(0.0, (0.0, 1.0)), LAYOUT.slices, 8) == "0:+"
    assert context_of(_obs(0.0, (0.0, -1.0)), LAYOUT.slices, 8) == "0:-"
    # heading +z: an edge pointing -x is on the left
    assert context_of(_obs(math.pi / 2, (-1.0, 0.0)), LAYOUT.slices, 8) == "2:+"


class _Constant:
    name = "const"

    def __init__(self) -> None:
        self.resets = 0

    def reset(self, seed=None) -> None:
        self.resets += 1

    def act(self, obs):
        return np.array([1.0, 0.0], dtype=np.float32)  # v̄_max along +x


def _phis(policy: OpenedPolicy, obs: np.ndarray, n: int) -> list[float]:
    return [flow_from_action(policy.act(obs), VBAR_MAX)[1] for _ in range(n)]


def test_the_opening_turns_the_flow_at_its_steps_for_its_context_only() -> None:
    obs = _obs(0.0, (0.0, 1.0))  # context "0:+"
    opened = OpenedPolicy(_Constant(), Opening({"0:+": 0.4}, (1, 2)), VBAR_MAX, LAYOUT.slices)
    assert _phis(opened, obs, 5) == pytest.approx([0.0, 0.4, 0.4, 0.0, 0.0], abs=1e-6)
    assert opened.context == "0:+"
    opened.reset(3)  # a new episode starts the steps again
    assert opened.base.resets == 1 and opened.context is None
    assert _phis(opened, obs, 2) == pytest.approx([0.0, 0.4], abs=1e-6)
    other = OpenedPolicy(_Constant(), Opening({"0:-": 0.4}, (1, 2)), VBAR_MAX, LAYOUT.slices)
    assert _phis(other, obs, 3) == pytest.approx([0.0, 0.0, 0.0], abs=1e-9)


def test_the_opening_reads_its_context_once_per_episode() -> None:
    opened = OpenedPolicy(_Constant(), Opening({"0:+": -0.4}, (1,)), VBAR_MAX, LAYOUT.slices)
    first, later = _obs(0.0, (0.0, 1.0)), _obs(math.pi, (0.0, 1.0))
    assert _phis(opened, first, 1) + _phis(opened, later, 1) == pytest.approx([0.0, -0.4])


def test_an_opening_round_trips_and_refuses_bad_values(tmp_path: Path) -> None:
    op = Opening({"0:+": 0.4, "4:-": -0.4}, (1, 2, 3), 8)
    assert Opening.from_dict(op.to_dict()) == op
    with pytest.raises(ValueError, match="finite"):
        Opening({"0:+": math.nan})
    with pytest.raises(ValueError, match="sectors"):
        Opening({}, (1,), 0)
    with pytest.raises(ValueError, match="steps"):
        Opening({}, (-1,))
    bad = tmp_path / "opening.json"
    bad.write_text("{not json")
    with pytest.raises(ValueError, match=r"not an opening file.*training/opening\.py"):
        Opening.load(bad)


def _rows(ctx: str, seed: int, scores: dict[float, float]) -> list[dict]:
    return [{"seed": seed, "context": ctx, "turn": t, "score": s} for t, s in scores.items()]


def test_the_fit_takes_a_turn_only_on_a_consistent_paired_gain() -> None:
    turns = [-0.4, 0.0, 0.4]
    rows = []
    for i, seed in enumerate(range(10, 15)):  # "0:+": +0.4 gains 0.02 +- 0.005 over 5 pairs
        base = 0.9 + 0.01 * i
        rows += _rows("0:+", seed, {0.0: base, 0.4: base + 0.02 + 0.005 * (-1) ** i,
                                    -0.4: base - 0.01})  # fmt: skip
    for i, seed in enumerate(range(20, 25)):  # "4:-": a gain as large as its noise
        rows += _rows("4:-", seed, {0.0: 0.9, 0.4: 0.9 + (0.05 if i % 2 else -0.04),
                                    -0.4: 0.89})  # fmt: skip
    rows += _rows("2:+", 30, {0.0: 0.5, 0.4: 0.9, -0.4: 0.5})  # one pair: too few
    rows += _rows("2:+", 31, {0.0: 0.5, 0.4: 0.9})  # incomplete: not a pair
    table, stats = fit(rows, turns, t_min=2.0, n_min=3)
    assert table == {"0:+": 0.4}
    assert stats["0:+"]["0.4"]["n"] == 5 and stats["0:+"]["0.4"]["mean"] == pytest.approx(0.021)
    assert stats["2:+"]["0.4"]["n"] == 1

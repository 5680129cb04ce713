"""benchmarks/label_predictability.py: the AUC in closed form."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.label_predictability import auc


def test_auc_closed_forms() -> None:
    y = np.array([False, False, True, True])
    assert auc(np.array([0.1, 0.2, 0.3, 0.4]), y) == 1.0  # every departure ranked above
    assert auc(np.array([0.4, 0.3, 0.2, 0.1]), y) == 0.0
    # one of the four (departure, follow) pairs misordered
    assert auc(np.array([0.1, 0.35, 0.3, 0.4]), y) == pytest.approx(0.75)
    rng = np.random.default_rng(0)
    y = rng.random(20000) < 0.2
    assert auc(rng.random(20000), y) == pytest.approx(0.5, abs=0.02)  # an uninformed score


def test_auc_needs_both_classes() -> None:
    with pytest.raises(ValueError, match="both"):
        auc(np.array([0.1, 0.2]), np.array([True, True]))

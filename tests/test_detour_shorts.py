"""benchmarks/detour_shorts.py: its command line."""

from __future__ import annotations

import pytest

from benchmarks import detour_shorts  # the repo root is on pytest's pythonpath


@pytest.mark.parametrize(
    "argv",
    [
        ["--policies", "oracle"],
        ["--count", "0"],
        ["--first", "-1"],
        ["--config", "no/such/config.yml"],
    ],
)
def test_bad_arguments_exit_with_a_usage_error(argv: list[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        detour_shorts.main([*argv])
    assert exc.value.code == 2

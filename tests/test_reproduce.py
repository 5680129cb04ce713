"""benchmarks/reproduce.py: the --quick table runs, writes its summary and traces, and a
second call resumes (runs nothing); with Ray (slow) the same points come out the same."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))  # the spawned workers import it by name
import reproduce  # noqa: E402

QUICK = ["--quick", "--deposit", "40", "--jobs", "2", "--only", "coil", "--only", "vbar"]


def _records(out: Path) -> dict[str, dict]:
    lines = (out / "results.jsonl").read_text().splitlines()
    return {r["key"]: r for r in map(json.loads, lines)}


def test_quick_table_runs_and_resumes(tmp_path: Path, capsys) -> None:
    assert reproduce.main([*QUICK, "--out", str(tmp_path)]) == 0
    recs = _records(tmp_path)
    assert len(recs) == 3  # the coil and two vbar points
    assert all("coarse=4,fine=20,tol=1e-05" in key for key in recs)  # the model's mesh
    assert all(r["error"] is None and r["deposit"] == 40.0 for r in recs.values())
    assert len(list((tmp_path / "traces").glob("*.npy"))) == 3
    assert "Model against paper" in (tmp_path / "summary_default.md").read_text()
    capsys.readouterr()
    assert reproduce.main([*QUICK, "--out", str(tmp_path)]) == 0
    assert "0 points to run (3 already" in capsys.readouterr().out
    assert _records(tmp_path) == recs


@pytest.mark.slow
def test_ray_backend_gives_the_same_points(tmp_path: Path) -> None:
    pytest.importorskip("ray")
    local, ray = tmp_path / "local", tmp_path / "ray"
    assert reproduce.main([*QUICK, "--out", str(local)]) == 0
    assert reproduce.main([*QUICK, "--backend", "ray", "--out", str(ray)]) == 0
    a, b = _records(local), _records(ray)
    assert a.keys() == b.keys()
    for key in a:  # deterministic: the same figures whatever ran them
        for field in ("amplitude", "wavelength_x", "coil_radius", "steps", "pattern"):
            assert a[key][field] == b[key][field], (key, field)

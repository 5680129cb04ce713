"""The ``cnt-sim`` command line and the trace file format (cnt_env.cli, cnt_env.io).

One tiny simulation (``--deposit 5 --Hbar 40``) is shared by the module; the numba
compile on first use dominates the time. Everything else runs without simulating.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import cnt_env.sim.deposition
from cnt_env import cli, units
from cnt_env.io import TraceFileError, load_trace, save_trace, to_jsonable

REPO = Path(__file__).resolve().parents[1]
RUN_KEYS = {
    "pattern",
    "coil_radius",
    "amplitude",
    "wavelength",
    "deposited_length",
    "sim_time",
    "steps",
    "newton_iterations",
    "wall_time_s",
    "params",
    "coil_radius_spread",
    "measure",
    "config",
    "version",
}
CONFIG_KEYS = {"dt", "drag_law", "sliding", "contact_mode", "seed", "initial_radius"}
TINY = ["--deposit", "5", "--Hbar", "40", "--transient", "0", "--delta", "1"]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _strict_json(text: str) -> dict:
    """Parse one JSON object, rejecting NaN/Infinity (Python's json accepts them)."""

    def no_constants(name: str) -> None:
        raise AssertionError(f"invalid JSON constant {name}")

    value = json.loads(text, parse_constant=no_constants)
    assert isinstance(value, dict)
    return value


def _call(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli.main(argv)
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The module's one simulation: --json with --out and --png."""
    tmp = tmp_path_factory.mktemp("run")
    out, png = tmp / "trace.npz", tmp / "trace.png"
    code, stdout, stderr = _call(["run", *TINY, "--json", "--out", str(out), "--png", str(png)])
    return {"code": code, "stdout": stdout, "stderr": stderr, "out": out, "png": png}


@pytest.fixture
def no_simulation(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fail the test if a DepositionSim is built."""

    def forbidden(*args: object, **kwargs: object) -> None:
        raise AssertionError("a simulation was started")

    monkeypatch.setattr(cnt_env.sim.deposition, "DepositionSim", forbidden)


# --------------------------------------------------------------------------- run


def test_run_json_prints_one_object_with_every_key(tiny_run: dict) -> None:
    assert tiny_run["code"] == 0, tiny_run["stderr"]
    lines = tiny_run["stdout"].splitlines()
    assert len(lines) == 1
    result = _strict_json(lines[0])
    assert RUN_KEYS <= set(result)
    assert CONFIG_KEYS <= set(result["config"])
    assert result["deposited_length"] >= 5.0
    assert result["steps"] > 0 and result["newton_iterations"] >= result["steps"]
    assert result["sim_time"] > 0 and result["wall_time_s"] > 0
    assert result["version"] == cli.package_version()
    # a 5 L_vb trace has no coil: NaN is written as null
    assert result["coil_radius"] is None and result["coil_radius_spread"] == [None, None]
    assert result["measure"]["pattern"] == result["pattern"]


def test_run_json_params_round_trip(tiny_run: dict) -> None:
    result = _strict_json(tiny_run["stdout"])
    assert units.DimensionlessParams(**result["params"]) == units.paper_groups("coil", Hbar=40.0)


def test_out_then_measure_reproduces_the_measurement(
    tiny_run: dict, capsys: pytest.CaptureFixture[str], no_simulation: None
) -> None:
    run = _strict_json(tiny_run["stdout"])
    assert cli.main(["measure", str(tiny_run["out"]), "--json"]) == 0
    captured = capsys.readouterr()
    measured = _strict_json(captured.out)
    assert RUN_KEYS <= set(measured)
    for key in RUN_KEYS - {"version"}:
        assert measured[key] == run[key], key


def test_trace_file_holds_the_run(tiny_run: dict) -> None:
    saved = load_trace(tiny_run["out"])
    run = _strict_json(tiny_run["stdout"])
    assert saved["format_version"] == 1
    assert saved["trace"].ndim == 2 and saved["trace"].shape[1] == 3
    assert saved["suspended"].shape[1] == 3 and saved["suspended"][-1, 1] > 30.0
    assert saved["params"] == run["params"] and saved["config"] == run["config"]
    sidecar = _strict_json(Path(f"{tiny_run['out']}.json").read_text())
    assert sidecar["params"] == run["params"] and sidecar["config"] == run["config"]
    assert sidecar["output"] == str(tiny_run["out"])


def test_png_is_written_with_its_config(tiny_run: dict) -> None:
    png = tiny_run["png"]
    assert png.stat().st_size > 1000
    assert png.read_bytes()[:8] == PNG_MAGIC
    assert _strict_json(Path(f"{png}.json").read_text())["params"]["Hbar"] == 40.0


def test_human_summary_and_demo(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The module's second (tiny) simulation: ``demo`` writes its figure under --outdir."""
    assert cli.main(["demo", "--deposit", "3", "--outdir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "deposited" in out and "pattern" in out
    assert (tmp_path / "coil.png").read_bytes()[:8] == PNG_MAGIC
    assert (tmp_path / "coil.png.json").exists() and (tmp_path / "coil.npz").exists()


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    ("args", "names"),
    [
        (["--Hbar", "nan"], ["--Hbar", "Hbar"]),
        (["--Hbar", "-1"], ["--Hbar", "Hbar"]),
        (["--Hbar", "inf"], ["--Hbar", "Hbar"]),
        (["--delta", "0"], ["--delta", "delta_bar"]),
        (["--kb", "-1"], ["--kb", "k_b"]),
        (["--ev", "nan"], ["--ev", "e_v"]),
        (["--deposit", "nan"], ["--deposit"]),
        (["--dt", "-1"], ["--dt"]),
        (["--transient", "-5"], ["--transient"]),
    ],
)
def test_unphysical_input_is_rejected_before_any_work(
    args: list[str], names: list[str], tmp_path: Path, no_simulation: None
) -> None:
    out = tmp_path / "trace.npz"
    code, stdout, stderr = _call(["run", *args, "--json", "--out", str(out)])
    assert code == 2  # (no_simulation makes any simulation attempt fail the test)
    assert stdout == ""
    assert stderr.startswith("cnt-sim: error: ")
    for name in names:
        assert name in stderr
    assert not out.exists()


def test_substrate_flag_overrides_the_preset() -> None:
    flat = cli.apply_substrate(units.paper_groups("serpentine"), "flat")
    assert flat.kappa_c_bar is None and flat.Hbar == 155.0
    stepped = cli.apply_substrate(units.paper_groups("coil"), "stepped")
    assert stepped.kappa_c_bar == cli.DEFAULT_KAPPA_C
    kept = cli.apply_substrate(units.paper_groups("serpentine", kappa_c_bar=0.5), "stepped")
    assert kept.kappa_c_bar == 0.5
    assert cli.apply_substrate(units.paper_groups("coil"), None).kappa_c_bar is None


def test_si_values_win_over_groups() -> None:
    params, physical, ignored = cli.resolve_params(
        "coil", {"Hbar": 40.0, "delta_bar": 0.5}, {"k_b": units.PAPER_K_B}
    )
    expected = units.preset("coil").to_dimensionless()
    assert physical is not None and ignored == ["Hbar"]
    assert params.Hbar == expected.Hbar and params.Ibar == expected.Ibar
    assert params.delta_bar == 0.5 and params.kt_over_kb == 1.0


# --------------------------------------------------------------------------- measure


def test_measure_a_corrupt_file(tmp_path: Path) -> None:
    bad = tmp_path / "random.npz"
    bad.write_bytes(np.random.default_rng(0).bytes(4096))
    code, stdout, stderr = _call(["measure", str(bad)])
    assert code == 2 and stdout == ""
    assert stderr.startswith("cnt-sim: error: ") and "not an .npz" in stderr
    assert "cnt-sim run --out" in stderr  # says what to do


def test_measure_a_truncated_trace(tiny_run: dict, tmp_path: Path) -> None:
    bad = tmp_path / "truncated.npz"
    data = tiny_run["out"].read_bytes()
    bad.write_bytes(data[: len(data) // 2])
    code, _, stderr = _call(["measure", str(bad)])
    assert code == 2 and "corrupt or truncated" in stderr


def test_measure_a_foreign_npz(tmp_path: Path) -> None:
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, positions=np.zeros((4, 3)), velocity=np.ones(3))
    code, stdout, stderr = _call(["measure", str(foreign), "--json"])
    assert code == 2 and stdout == ""
    assert "not a cnt_env trace" in stderr and "positions" in stderr


def test_measure_a_missing_file(tmp_path: Path) -> None:
    code, _, stderr = _call(["measure", str(tmp_path / "nope.npz")])
    assert code == 2 and "no such file" in stderr


def test_measure_a_trace_too_short_for_the_transient(tiny_run: dict) -> None:
    code, stdout, stderr = _call(["measure", str(tiny_run["out"]), "--json", "--transient", "1e3"])
    assert code == 1
    result = _strict_json(stdout)
    assert result["pattern"] is None and "too short" in result["measure"]["error"]
    assert "too short" in stderr


# --------------------------------------------------------------------------- io


def test_trace_file_rejects_bad_contents(tmp_path: Path) -> None:
    params = units.paper_groups("coil")
    with pytest.raises(ValueError, match="NaN"):
        save_trace(tmp_path / "x.npz", np.full((3, 3), np.nan), params, {}, {})
    with pytest.raises(ValueError, match="shape"):
        save_trace(tmp_path / "x.npz", np.zeros((3, 2)), params, {}, {})
    damaged = tmp_path / "damaged.npz"
    np.savez(damaged, format=np.array("cnt_env.trace"), format_version=np.array(1))
    with pytest.raises(TraceFileError, match="missing"):
        load_trace(damaged)
    newer = tmp_path / "newer.npz"
    save_trace(newer, np.zeros((3, 3)), params, {}, {})
    with np.load(newer) as npz:
        entries = dict(npz)
    entries["format_version"] = np.array(2)
    np.savez(newer, **entries)
    with pytest.raises(TraceFileError, match="upgrade"):
        load_trace(newer)


def test_trace_file_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "no_suffix"
    trace = np.arange(12.0).reshape(4, 3)
    params = units.paper_groups("coil")
    save_trace(path, trace, params, {"seed": 3}, {"steps": np.int64(7), "x": np.nan})
    assert path.exists()  # no .npz appended
    saved = load_trace(path)
    np.testing.assert_array_equal(saved["trace"], trace)
    assert saved["suspended"] is None
    assert units.DimensionlessParams(**saved["params"]) == params
    assert saved["config"] == {"seed": 3} and saved["stats"] == {"steps": 7, "x": None}


def test_to_jsonable_makes_valid_json() -> None:
    value = {"a": np.float64("nan"), "b": (np.int32(2), np.inf), "c": np.array([1.0, np.nan])}
    assert to_jsonable(value) == {"a": None, "b": [2, None], "c": [1.0, None]}
    json.dumps(to_jsonable(value), allow_nan=False)


def test_progress_bar_draws_on_stderr(capsys: pytest.CaptureFixture[str]) -> None:
    with cli.progress_bar(True, 10.0) as update:
        for done in (2.5, 5.0, 10.0):
            update(done, 10.0)
    assert "L_vb" in capsys.readouterr().err
    with cli.progress_bar(False, 10.0) as update:
        assert update is None


# --------------------------------------------------------------------------- entry points


def test_python_dash_m_version() -> None:
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]),
    }
    proc = subprocess.run(
        [sys.executable, "-m", "cnt_env", "--version"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
        check=False,
    )
    assert proc.returncode == 0
    assert proc.stdout.strip() == f"cnt-sim {cli.package_version()}"


def test_usage_errors_return_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["run", "--drag-law", "nonsense"]) == 2
    assert "invalid choice" in capsys.readouterr().err
    assert cli.main([]) == 2

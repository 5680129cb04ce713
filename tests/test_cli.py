"""The ``cnt-sim`` command line and the trace file format (cnt_env.cli, cnt_env.io).

One tiny simulation (``--deposit 5 --Hbar 40``) is shared by the module; the numba
compile on first use dominates the time. Everything else runs without simulating.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import cnt_env.runs
import cnt_env.sim.deposition
from cnt_env import cli, units
from cnt_env.io import load_trace

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
CONFIG_KEYS = {"dt", "drag_law", "sliding", "contact_mode", "seed", "initial_radius",
               "settled_fraction", "flow_profile"}  # fmt: skip
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


def test_run_with_the_cohesive_adhesion_records_it(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["run", *TINY, "--adhesion", "cohesive", "--cohesive-range", "1.5",
                     "--json"]) == 0  # fmt: skip
    config = _strict_json(capsys.readouterr().out)["config"]
    assert config["adhesion"] == "cohesive" and config["cohesive_range"] == 1.5


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
        (["--cohesive-range", "0"], ["--cohesive-range"]),
        (["--cohesive-range", "nan"], ["--cohesive-range"]),
        (["--adhesion", "cohesive", "--cohesive-range", "0.01"], ["cohesive range", "delta_bar"]),
        (["--dt", "-1"], ["--dt"]),
        (["--transient", "-5"], ["--transient"]),
        # metres typed as if micrometres: the group out of range names the SI flag given
        (["--H", "20"], ["--Hbar", "--H 20", "check their units"]),
        (["--png", "fig.jpg"], ["--png", "name it <file>.png"]),  # it held PNG bytes
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


def test_si_values_that_move_the_groups_say_so() -> None:
    """One SI value re-derives every group from the preset's SI values, which round the
    paper's groups (H̄ 155.9, Ī 309 for the serpentine's 155, 300): a warning says what
    the run now uses (it changed them silently)."""
    said: list[str] = []
    cnt_env.runs.resolve(cnt_env.runs.RunOptions(preset="serpentine", si={"v": 1.0}),
                         warn=said.append)  # fmt: skip
    assert len(said) == 1 and "Hbar 155.9 (preset 155)" in said[0]
    assert "Ibar 309 (preset 300)" in said[0]
    said.clear()
    cnt_env.runs.resolve(cnt_env.runs.RunOptions(preset="serpentine"), warn=said.append)
    assert said == []  # the preset's groups as they are: nothing to say


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


def test_an_entry_name_with_a_newline_keeps_the_error_on_one_line(tmp_path: Path) -> None:
    """Found by the 10 000-example fuzz: a zip entry named "\\normat.npy" (a newline in
    it) split the error over two lines."""
    import zipfile

    buf = io.BytesIO()
    np.save(buf, np.zeros(3))
    bad = tmp_path / "newline.npz"
    with zipfile.ZipFile(bad, "w") as zf:
        zf.writestr("\normat.npy", buf.getvalue())
        zf.writestr("trace\t.npy", buf.getvalue())
    code, stdout, stderr = _call(["measure", str(bad)])
    assert code == 2 and stdout == ""
    assert stderr.count("\n") == 1 and stderr.startswith("cnt-sim: error: ")
    assert "not a cnt_env trace" in stderr and "\\normat" in stderr and "\\t" in stderr


def test_measure_a_missing_file(tmp_path: Path) -> None:
    code, _, stderr = _call(["measure", str(tmp_path / "nope.npz")])
    assert code == 2 and "no such file" in stderr


def test_measure_a_trace_too_short_for_the_transient(tiny_run: dict) -> None:
    code, stdout, stderr = _call(["measure", str(tiny_run["out"]), "--json", "--transient", "1e3"])
    assert code == 1
    result = _strict_json(stdout)
    assert result["pattern"] is None and "too short" in result["measure"]["error"]
    assert "too short" in stderr


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


# --------------------------------------------------------------------------- hostile input
# (issue 14: outputs that must not destroy what is not the user's result, inputs that must
# not run forever, and clear errors instead of tracebacks; the exit codes of docs/cli.md)


def _assert_clean_error(code: int, stdout: str, stderr: str, expected: int, *names: str) -> None:
    assert code == expected, stderr
    assert stdout == ""
    assert stderr.startswith("cnt-sim: error: ") and "Traceback" not in stderr
    assert len(stderr.splitlines()) == 1
    for name in names:
        assert name in stderr


@pytest.mark.parametrize("device", ["/dev/full", "/dev/null"])
def test_run_never_replaces_a_device(device: str, no_simulation: None) -> None:
    """Defect 2: a device is not a regular file; nothing runs, nothing is replaced."""
    before = os.stat(device)
    code, stdout, stderr = _call(["run", *TINY, "--json", "--out", device])
    _assert_clean_error(code, stdout, stderr, 2, "--out", "not a regular file")
    after = os.stat(device)
    assert (after.st_ino, after.st_rdev) == (before.st_ino, before.st_rdev)


def test_run_never_replaces_a_fifo(tmp_path: Path, no_simulation: None) -> None:
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    code, stdout, stderr = _call(["run", *TINY, "--png", str(fifo)])
    _assert_clean_error(code, stdout, stderr, 2, "--png", "not a regular file")
    assert fifo.is_fifo()


def test_run_never_writes_through_a_symlink(tmp_path: Path, no_simulation: None) -> None:
    """Defect 3: a symlink at <out>.json is refused before any work; its target is kept."""
    target = tmp_path / "precious.txt"
    target.write_text("keep me")
    out = tmp_path / "trace.npz"
    Path(f"{out}.json").symlink_to(target)
    code, stdout, stderr = _call(["run", *TINY, "--out", str(out)])
    _assert_clean_error(code, stdout, stderr, 2, "--out", "symbolic link")
    assert target.read_text() == "keep me" and not out.exists()


def test_run_outputs_are_checked_as_a_unit(tmp_path: Path, no_simulation: None) -> None:
    """Defect 5: <out>.json a directory, or --png naming the trace's config, fails before
    any work and leaves the existing trace as it was."""
    out = tmp_path / "a"
    out.write_bytes(b"old trace")
    Path(f"{out}.json").mkdir()
    code, stdout, stderr = _call(["run", *TINY, "--out", str(out)])
    _assert_clean_error(code, stdout, stderr, 2, "--out", "directory")
    assert out.read_bytes() == b"old trace"
    Path(f"{out}.json").rmdir()
    code, stdout, stderr = _call(["run", *TINY, "--out", str(out), "--png", f"{out}.json"])
    _assert_clean_error(code, stdout, stderr, 2, "same file")
    assert out.read_bytes() == b"old trace" and not Path(f"{out}.json").exists()


def test_a_failed_run_keeps_the_old_outputs(tmp_path: Path, monkeypatch) -> None:
    """Defect 5: a run that fails after its outputs were checked writes none of them."""
    from cnt_env.sim.stepper import SimulationError

    def failing(*args: object, **kwargs: object) -> None:
        raise SimulationError("Newton did not converge", 3, 1.0, 0.1, {})

    monkeypatch.setattr(cnt_env.runs, "deposit", failing)
    out, png = tmp_path / "t.npz", tmp_path / "t.png"
    out.write_bytes(b"old")
    code, stdout, stderr = _call(["run", *TINY, "--out", str(out), "--png", str(png)])
    _assert_clean_error(code, stdout, stderr, 1, "Newton")
    assert out.read_bytes() == b"old" and not png.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.npz"]  # no temporaries


@pytest.mark.parametrize(
    ("args", "names"),
    [
        (["--Hbar", "1e300"], ["--Hbar", "meaningful range"]),  # defect 6
        (["--delta", "1e-9"], ["--delta"]),
        (["--delta", "5e-324"], ["--delta", "meaningful range"]),  # coarse/delta overflowed
        (["--deposit", "1e12"], ["--max-nodes"]),
        (["--deposit=3.595386269724632e+307"], ["--max-nodes"]),  # the node count overflowed
        (["--coarse-delta=3.595386269724632e+307"], ["--coarse-delta", "longer than the rod"]),
        (["--Ibar", "1e300"], ["--Ibar", "meaningful range"]),  # defect 7
        (["--kappa-c", "0"], ["--kappa-c"]),  # defect 9
        (["--substrate", "flat", "--kappa-c", "0.2"], ["--kappa-c", "--substrate flat"]),
        (["--max-nodes", "0"], ["--max-nodes"]),
        (["--max-steps", "0"], ["--max-steps"]),
        (["--max-wall-time", "-1"], ["--max-wall-time"]),
        (["--out", "x" * 300], ["--out", "longer than 255"]),  # defect 13
        (["--out", "/proc/x/y.npz"], ["--out"]),
    ],
)
def test_hostile_run_input_is_a_clear_error(
    args: list[str], names: list[str], no_simulation: None
) -> None:
    code, stdout, stderr = _call(["run", *TINY, "--json", *args])
    _assert_clean_error(code, stdout, stderr, 2, *names)


def test_a_run_that_makes_no_progress_stops_at_the_step_limit() -> None:
    """Defect 7: physics steps without deposited length stop with exit 3."""
    code, stdout, stderr = _call(["run", *TINY, "--json", "--max-steps", "2"])
    _assert_clean_error(code, stdout, stderr, 3, "--max-steps", "no progress")


def test_a_run_stops_at_the_wall_time_limit() -> None:
    code, stdout, stderr = _call(["run", *TINY, "--json", "--max-wall-time", "1e-6"])
    _assert_clean_error(code, stdout, stderr, 3, "--max-wall-time")


def test_measure_rejects_a_long_png_name_and_a_bad_trace(tiny_run: dict, tmp_path: Path) -> None:
    """Defect 13: a 300-character output name, a trace whose stats have the wrong type."""
    code, stdout, stderr = _call(["measure", str(tiny_run["out"]), "--png", "p" * 300])
    _assert_clean_error(code, stdout, stderr, 2, "--png")
    with np.load(tiny_run["out"]) as npz:
        entries = dict(npz)
    entries["stats"] = np.array(json.dumps({"steps": "many"}))
    bad = tmp_path / "bad.npz"
    np.savez(bad, **entries)
    code, stdout, stderr = _call(["measure", str(bad), "--json"])
    _assert_clean_error(code, stdout, stderr, 2, "steps")


def test_exit_code_table_is_documented() -> None:
    text = (REPO / "docs" / "cli.md").read_text()
    for code in cli.EXIT_CODES:
        assert f"| {code} " in text


def test_run_config_file_round_trips_and_flags_win(tmp_path: Path) -> None:
    first = tmp_path / "a.npz"
    argv = ["run", "--preset", "serpentine", "--vbar", "0.05", "--seed", "3", *TINY]
    assert _call([*argv, "--out", str(first)])[0] == 0
    again = tmp_path / "b.npz"  # the <out>.json of the first run as the config
    assert _call(["run", "--config", f"{first}.json", "--out", str(again)])[0] == 0
    a, b = load_trace(first), load_trace(again)
    np.testing.assert_array_equal(a["trace"], b["trace"])
    assert a["config"] == b["config"] and a["params"] == b["params"]
    assert a["config"]["coarse_delta"] == 4.0  # the preset's graded rod
    uniform = tmp_path / "u.npz"  # a uniform rod (coarse_delta None) stays uniform
    assert _call([*argv, "--coarse-delta", "0", "--out", str(uniform)])[0] == 0
    assert _call(["run", "--config", f"{uniform}.json", "--out", str(again)])[0] == 0
    u, b = load_trace(uniform), load_trace(again)
    assert u["config"]["coarse_delta"] is None and u["config"] == b["config"]
    np.testing.assert_array_equal(u["trace"], b["trace"])
    layer = tmp_path / "l.npz"  # a boundary layer stays one, and lays another trace
    assert _call([*argv, "--flow-profile", "linear", "--out", str(layer)])[0] == 0
    assert _call(["run", "--config", f"{layer}.json", "--out", str(again)])[0] == 0
    lay, b = load_trace(layer), load_trace(again)
    assert lay["config"]["flow_profile"] == "linear" and lay["config"] == b["config"]
    np.testing.assert_array_equal(lay["trace"], b["trace"])
    assert a["config"]["flow_profile"] == "uniform"
    assert not np.array_equal(lay["trace"], a["trace"])
    flat = tmp_path / "c.yaml"  # flag names as keys; a flag on the command line wins
    flat.write_text("preset: serpentine\nvbar: 0.05\nseed: 3\ndeposit: 5\nHbar: 40\n"
                    "transient: 0\ndelta: 1\n")  # fmt: skip
    third = tmp_path / "c.npz"
    assert _call(["run", "--config", str(flat), "--seed", "4", "--out", str(third)])[0] == 0
    c = load_trace(third)
    assert c["config"]["seed"] == 4 and c["params"] == a["params"]
    assert not np.array_equal(c["trace"], a["trace"])
    bad = tmp_path / "bad.yaml"
    bad.write_text("vbarr: 0.05\n")
    code, _, err = _call(["run", "--config", str(bad)])
    assert code == 2 and "vbarr" in err and "unknown settings" in err
    code, _, err = _call(["run", "--config", str(tmp_path / "missing.yaml")])
    assert code == 2 and "cannot read" in err


@pytest.mark.parametrize(
    ("text", "extra", "named"),
    [
        ("vbar: abc\n", [], "--vbar 'abc' is not a valid value"),  # argparse's type
        ("preset: serp\n", [], "--preset must be one of coil, serpentine"),  # its choices
        ("vbar: -1\n", [], "(set in --config"),  # the model's range
        ("seed: 2.5\n", [], "(set in --config"),
        ("vbar: 0.05\n", ["--vbar", "-1"], None),  # the bad value is the command line's
    ],
)
def test_a_bad_value_in_the_config_file_names_the_file(
    tmp_path: Path, text: str, extra: list[str], named: str | None
) -> None:
    """A bad value from --config names the file (where it must be fixed) and the setting;
    one given on the command line does not blame the file."""
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    code, out, err = _call(["run", "--config", str(path), *TINY, *extra])
    assert code == 2 and out == "" and err.count("\n") == 1, err
    if named is None:
        assert "--config" not in err and "--vbar" in err
    else:
        assert str(path) in err and named in err


@pytest.mark.parametrize(
    "argv",
    [
        ["sweep", "--Hbar=30", "--deposit=3", "--no-plots", "--param=--", "--range=", "--out=x"],
        ["run", "--preset=--"],
        ["run", "--kappa-c=--", "--deposit=3"],
    ],
)
def test_an_option_given_double_dash_as_its_value_is_a_usage_error(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    """argparse reads ``--opt=--`` as the end of options and stores [] (found by the slow
    CLI fuzz: ``sweep --param=--`` crashed with an AttributeError). No work is done."""
    assert cli.main(argv) == cli.EXIT_USAGE
    err = capsys.readouterr().err
    flag = next(a for a in argv if a.endswith("=--")).split("=")[0]
    assert f"{flag} got '--' as its value" in err
    assert "unexpected" not in err


@pytest.mark.parametrize(
    ("kind", "text", "expected"),
    [
        ("seed_list", "0, 1,2", [0, 1, 2]),
        ("int_list", "250,500", [250, 500]),
        ("float_list", "1,0.5,2e-1", [1.0, 0.5, 0.2]),
        ("name_list", "u_turn,,l_up", ["u_turn", "l_up"]),
        ("positive_float", "3.5", 3.5),
    ],
)
def test_list_types_parse(kind: str, text: str, expected: object) -> None:
    from cnt_env.cli import common

    assert getattr(common, kind)(text) == expected


@pytest.mark.parametrize(
    ("kind", "text", "message"),
    [
        ("seed_list", "0,x", "'x' is not an integer"),
        ("seed_list", "0,-1", "a seed must be ≥ 0"),
        ("seed_list", ",", "at least one seed"),
        ("int_list", "0", "positive integer"),
        ("float_list", "1,nan", "finite"),
        ("float_list", "1,a", "'a' is not a number"),
        ("name_list", " , ", "at least one name"),
        ("positive_float", "inf", "finite number > 0"),
    ],
)
def test_list_types_refuse_with_a_message(kind: str, text: str, message: str) -> None:
    import argparse

    from cnt_env.cli import common

    with pytest.raises(argparse.ArgumentTypeError, match=message):
        getattr(common, kind)(text)


@pytest.mark.parametrize(
    ("script", "argv"),
    [
        ("follower_study", ["--seeds", "0,x"]),
        ("power_budget", ["--delta", "1,nan"]),
        ("newton_iteration", ["--sizes", "0"]),
        ("reproduce", ["--seeds", "a"]),
        ("route_breadth", ["--seeds", ""]),
    ],
)
def test_a_benchmark_list_flag_is_a_usage_error(
    script: str, argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    """A bad comma-separated value stops a benchmark with argparse's one-line error."""
    import importlib

    module = importlib.import_module(f"benchmarks.{script}")
    with pytest.raises(SystemExit) as exc:
        module.main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {argv[0]}" in err and "Traceback" not in err


def test_measure_judges_the_class_on_the_settled_fraction_given(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--settled-fraction``: a serpentine whose start-up decays over its first cycles
    is periodic on its settled half (the default) and irregular judged whole (1.0); the
    run's own fraction is used when the flag is absent, and the measure reports it."""
    from cnt_env.io import save_trace
    from tests.traces import A_BAR, LAMBDA_BAR, serpentine_curve

    steady = 2 * A_BAR - LAMBDA_BAR / 2
    xz = serpentine_curve([steady * (1.0 + 0.8 * math.exp(-k / 5.0)) for k in range(44)],
                          LAMBDA_BAR, 0.5)  # fmt: skip
    trace = np.column_stack([xz[:, 0], np.zeros(len(xz)), xz[:, 1]])
    params = units.paper_groups("serpentine")
    config = {"substrate": "stepped", "transient_length": 0.0, "settled_fraction": 1.0}
    path = save_trace(tmp_path / "t.npz", trace, params, config, {"steps": 1})

    def measured(*flags: str) -> dict:
        assert cli.main(["measure", str(path), "--json", *flags]) == 0
        return _strict_json(capsys.readouterr().out)

    whole = measured()  # the run's fraction, 1.0
    assert whole["pattern"] == "irregular-serpentine"
    assert whole["measure"]["settled_fraction"] == 1.0
    settled = measured("--settled-fraction", "0.5")
    assert settled["pattern"] == "periodic-serpentine"
    assert settled["measure"]["settled_amplitude_cv"] < 0.02 < whole["measure"]["amplitude_cv"]
    assert cli.main(["measure", str(path), "--settled-fraction", "0"]) == 2
    assert "--settled-fraction" in capsys.readouterr().err


def test_no_output_replaces_an_input_and_a_directory_name_is_refused(
    tiny_run: dict, tmp_path: Path
) -> None:  # fmt: skip
    """An output that names the command's own input (the trace measured or replayed, the
    --config file) would replace it: exit 2, the input untouched (they were overwritten
    with exit 0). An output ending in '/' names a directory, not a file (it made a file
    of that name)."""
    import shutil

    trace = tmp_path / "t.npz"
    shutil.copy(tiny_run["out"], trace)
    shutil.copy(f"{tiny_run['out']}.json", f"{trace}.json")
    before = trace.read_bytes(), Path(f"{trace}.json").read_bytes()
    for argv, what in (
        (["measure", str(trace), "--png", str(trace)], "the trace measured"),
        (["replay", str(trace), "--video", str(trace)], "the file replayed"),
        (["run", "--config", f"{trace}.json", "--out", str(trace)], "the --config file"),
    ):
        code, _, stderr = _call(argv)
        assert code == 2 and what in stderr and "would replace it" in stderr, argv
    assert (trace.read_bytes(), Path(f"{trace}.json").read_bytes()) == before
    code, _, stderr = _call(["run", *TINY, "--out", f"{tmp_path}/results/"])
    assert code == 2 and "ends in '/'" in stderr
    assert not (tmp_path / "results").exists()


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["run", "--Hbr", "40"], "did you mean --Hbar?"),
        (["run", "--Hbar", "abc"], "argument --Hbar: invalid float value"),
        (["sweep", "--param"], "argument --param: expected one argument"),
        (["nosuch"], "invalid choice: 'nosuch'"),
    ],
)
def test_argparse_errors_are_one_line_too(argv: list[str], says: str) -> None:
    """docs/cli.md: every error is one line, ``cnt-sim: error: ...`` (argparse's own
    printed the usage first), an unknown flag with the closest known one."""
    code, stdout, stderr = _call(argv)
    assert code == 2 and stdout == ""
    assert stderr.startswith("cnt-sim: error: ") and stderr.count("\n") == 1
    assert says in stderr and "--help" in stderr

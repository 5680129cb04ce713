"""``cnt-sim sweep`` (cnt_env.sweep) and the U-turn markers of ``plot_run``.

The sweeps are tiny (coil preset, H = 30 L_vb, 6 L_vb deposited, no transient): about
a second each once numba has compiled. ``run_point`` is wrapped to count (or fail)
the points that run in this process (``--jobs 1``).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

from cnt_env import cli, sweep
from cnt_env.plotting import plot_run, uturn_markers
from cnt_env.sim.stepper import SimulationError

TINY = ["--preset", "coil", "--Hbar", "30", "--deposit", "6", "--transient", "0"]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _call(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli.main(argv)
    return code, out.getvalue(), err.getvalue()


def _summary(stdout: str) -> dict:
    lines = stdout.splitlines()
    assert len(lines) == 1, stdout
    return json.loads(lines[0])


@pytest.fixture
def counted(monkeypatch: pytest.MonkeyPatch) -> list:
    """Points run in this process, in order: ``run_point`` records each one."""
    calls: list = []
    original = sweep.run_point

    def counting(point: sweep.SweepPoint) -> dict:
        calls.append(dict(point.values))
        return original(point)

    monkeypatch.setattr(sweep, "run_point", counting)
    return calls


# --------------------------------------------------------------------------- grid input


def test_param_names_map_to_groups() -> None:
    assert sweep.resolve_param("kappa-c") == "kappa_c_bar"
    assert sweep.resolve_param("kappa_c_bar") == "kappa_c_bar"
    assert sweep.resolve_param("delta") == "delta_bar"
    assert sweep.resolve_param("hbar") == "Hbar"
    assert sweep.resolve_param("ks-over-ev") == "ks_over_ev"
    assert sweep.parse_range("0.01:0.13:3", "--range") == pytest.approx([0.01, 0.07, 0.13])
    assert sweep.parse_range("1:100:3:log", "--range") == pytest.approx([1.0, 10.0, 100.0])


@pytest.mark.parametrize(
    ("grid", "names"),
    [
        (["--param", "vbar", "--values", "nan"], ["point 1 of 1", "--vbar", "vbar"]),
        (["--param", "Hbar", "--values=100,-5"], ["point 2 of 2", "--Hbar", "Hbar"]),
        (["--param", "Ibar", "--values", "100", "--Hbar=-5"], ["point 1 of 1", "Hbar"]),
        (["--param", "foo", "--values", "1"], ["unknown sweep parameter", "foo"]),
        (["--param", "vbar", "--values", "0.1,,0.2"], ["--values"]),
        (["--param", "vbar", "--values", "0.1,x"], ["--values", "'x'"]),
        (["--param", "vbar", "--range", "0:1:0"], ["--range", "n must be >= 1"]),
        (["--param", "vbar"], ["--values or --range"]),
        (["--values", "1,2"], ["without --param"]),
        (
            ["--param", "vbar", "--values", "0.1", "--param2", "vbar", "--values2", "1"],
            ["both vbar"],
        ),
        (
            ["--param", "Ibar", "--values", "100", "--param2", "sigma", "--values2", "0"],
            ["point 1 of 1", "sigma"],
        ),
    ],
)
def test_invalid_grid_exits_2_before_running(
    grid: list[str], names: list[str], tmp_path: Path, counted: list
) -> None:
    out = tmp_path / "sweep.csv"
    code, stdout, stderr = _call(["sweep", *TINY, *grid, "--out", str(out), "--json"])
    assert code == 2, stderr
    assert stdout == ""
    assert "cnt-sim: error: " in stderr
    for name in names:
        assert name in stderr
    assert counted == []
    assert not out.exists()


# --------------------------------------------------------------------------- sweeps


def test_1d_sweep_in_parallel_then_resumes(tmp_path: Path, counted: list) -> None:
    out = tmp_path / "res" / "sweep.csv"
    grid = ["--param", "Ibar", "--values", "100,200"]
    code, stdout, stderr = _call(
        ["sweep", *TINY, *grid, "--jobs", "2", "--out", str(out), "--json"]
    )
    assert code == 0, stderr
    summary = _summary(stdout)
    assert summary["n_run"] == 2 and summary["n_skipped"] == 0 and summary["n_failed"] == 0
    assert counted == []  # --jobs 2: the points ran in worker processes

    header, rows = sweep.read_rows(out)
    assert header is not None
    assert header[:2] == ["Ibar", "seed"] and header[-1] == "config_hash"
    assert set(sweep.RESULT_COLUMNS) <= set(header)
    assert sorted(r["Ibar"] for r in rows) == [100.0, 200.0]
    for row in rows:
        assert row["failure"] == "" and row["pattern"]
        assert row["seed"] == 0 and row["deposited_length"] >= 6.0
        assert row["steps"] > 0 and row["wall_time_s"] > 0
        assert row["config_hash"] == summary["config_hash"]
    resolved = json.loads(Path(f"{out}.json").read_text())
    assert resolved["sweep"]["params"] == ["Ibar"] and resolved["params"]["Hbar"] == 30.0
    assert resolved["config_hash"] == summary["config_hash"]
    curves = out.parent / "sweep_curves.png"
    assert curves.read_bytes()[:8] == PNG_MAGIC

    # the same sweep again: nothing runs, the CSV is unchanged
    before = out.read_bytes()
    code, stdout, stderr = _call(
        ["sweep", *TINY, *grid, "--jobs", "2", "--out", str(out), "--json"]
    )
    assert code == 0, stderr
    again = _summary(stdout)
    assert again["n_run"] == 0 and again["n_skipped"] == 2
    assert out.read_bytes() == before
    assert [r["wall_time_s"] for r in again["rows"]] == [r["wall_time_s"] for r in summary["rows"]]

    # a grown grid runs only the new point (in this process, --jobs 1)
    grown = ["--param", "Ibar", "--values", "100,200,400"]
    code, stdout, stderr = _call(["sweep", *TINY, *grown, "--out", str(out), "--json"])
    assert code == 0, stderr
    assert counted == [{"Ibar": 400.0}]
    assert len(sweep.read_rows(out)[1]) == 3

    # a changed base config is a different sweep: its points run again
    counted.clear()
    code, stdout, stderr = _call(
        ["sweep", *TINY, "--Ibar", "1", *grid, "--dt", "1.0", "--out", str(out), "--json"]
    )
    assert code == 0, stderr
    assert len(counted) == 2
    assert len({r["config_hash"] for r in sweep.read_rows(out)[1]}) == 2
    assert "also holds rows of 1 other configuration" in stderr  # said, not silent


def test_2d_grid_writes_a_phase_diagram(tmp_path: Path) -> None:
    out = tmp_path / "grid.csv"
    plots = tmp_path / "plots"
    grid = ["--param", "Ibar", "--values", "100,300", "--param2", "vbar", "--values2", "0,0.05"]
    code, stdout, stderr = _call(
        ["sweep", *TINY, *grid, "--out", str(out), "--plots", str(plots), "--seed-per-point"]
    )
    assert code == 0, stderr
    assert "4 points over Ibar x vbar" in stdout
    _, rows = sweep.read_rows(out)
    assert {(r["Ibar"], r["vbar"]) for r in rows} == {
        (100.0, 0.0),
        (100.0, 0.05),
        (300.0, 0.0),
        (300.0, 0.05),
    }
    assert sorted(r["seed"] for r in rows) == [0, 1, 2, 3]
    for name in ("grid_curves.png", "grid_phase.png"):
        assert (plots / name).read_bytes()[:8] == PNG_MAGIC


def test_failed_point_is_recorded_not_fatal(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls: list[float] = []
    original = sweep.run_point

    def flaky(point: sweep.SweepPoint) -> dict:
        ibar = dict(point.values)["Ibar"]
        calls.append(ibar)
        if ibar == 200.0:
            raise SimulationError("Newton did not converge", 12, 3.5, 0.1, {})
        return original(point)

    monkeypatch.setattr(sweep, "run_point", flaky)
    out = tmp_path / "sweep.csv"
    argv = ["sweep", *TINY, "--param", "Ibar", "--values", "100,200", "--out", str(out)]
    code, stdout, stderr = _call([*argv, "--json"])
    assert code == 1, stderr
    summary = _summary(stdout)
    assert summary["n_run"] == 2 and summary["n_failed"] == 1
    _, rows = sweep.read_rows(out)
    by_ibar = {r["Ibar"]: r for r in rows}
    assert by_ibar[100.0]["failure"] == "" and by_ibar[100.0]["pattern"]
    failed = by_ibar[200.0]
    assert failed["failure"].startswith("SimulationError: ")
    assert "Newton did not converge" in failed["failure"]
    assert failed["pattern"] == "" and math.isnan(failed["amplitude"])
    assert (tmp_path / "sweep_curves.png").exists()

    # resumed: the failure is kept, not re-run; --retry-failed runs it again
    calls.clear()
    assert _call([*argv, "--json"])[0] == 1
    assert calls == []
    assert _call([*argv, "--json", "--retry-failed"])[0] == 1
    assert calls == [200.0]


def test_ray_backend_runs_the_same_points(tmp_path: Path) -> None:
    pytest.importorskip("ray")
    out = tmp_path / "ray.csv"
    argv = ["sweep", *TINY, "--param", "Ibar", "--values", "100,200", "--out", str(out)]
    code, stdout, stderr = _call([*argv, "--backend", "ray", "--jobs", "2", "--json"])
    assert code == 0, stderr
    summary = _summary(stdout)
    assert summary["n_run"] == 2 and summary["n_failed"] == 0
    _, rows = sweep.read_rows(out)
    assert sorted(r["Ibar"] for r in rows) == [100.0, 200.0]
    assert all(r["pattern"] and r["steps"] > 0 for r in rows)
    # the same points in this process give the same rows: the backend changes nothing
    local = tmp_path / "local.csv"
    local_argv = ["sweep", *TINY, "--param", "Ibar", "--values", "100,200", "--out", str(local)]
    assert _call([*local_argv, "--json"])[0] == 0
    _, local_rows = sweep.read_rows(local)
    key = ("Ibar", "pattern", "steps", "newton_iterations", "sim_time", "config_hash")
    assert sorted(tuple(r[k] for k in key) for r in rows) == sorted(
        tuple(r[k] for k in key) for r in local_rows
    )


# --------------------------------------------------------------------------- U-turns


def test_stepped_run_figure_marks_the_uturns(tmp_path: Path) -> None:
    # a meander along x with amplitude 10 and wavelength 8: U-turns at z = +-10
    s = np.linspace(0.0, 6.0 * 2.0 * math.pi, 1200)
    trace = np.column_stack([8.0 * s / (2.0 * math.pi), np.zeros_like(s), 10.0 * np.sin(s)])
    measurement = {"substrate": "stepped", "transient_length": 0.0, "pattern": "x"}
    marks = uturn_markers(trace, measurement)
    assert marks is not None
    assert len(marks["indices"]) == 12
    assert np.allclose(np.abs(trace[marks["indices"], 2]), 10.0, atol=0.01)
    assert uturn_markers(trace, {**measurement, "substrate": "flat"}) is None
    png = plot_run(trace, None, measurement, tmp_path / "meander.png")
    assert png.read_bytes()[:8] == PNG_MAGIC


# --------------------------------------------------------------------------- hostile input
# (issue 14: sweep size, FIFO and /proc outputs, damaged CSVs; docs/cli.md)


@pytest.fixture
def fake_points(monkeypatch: pytest.MonkeyPatch) -> list:
    """``run_point`` without a simulation: a row with a pattern, recorded in order."""
    calls: list = []

    def fake(point: sweep.SweepPoint) -> dict:
        calls.append(dict(point.values))
        row = {name: math.nan for name in sweep.RESULT_COLUMNS}
        row.update(dict(point.values), seed=point.seed, pattern="coil", failure="")
        row.update(config_hash=point.config_hash, wall_time_s=0.0)
        return row

    monkeypatch.setattr(sweep, "run_point", fake)
    return calls


def _clean(code: int, stdout: str, stderr: str, expected: int, *names: str) -> None:
    assert code == expected, stderr
    assert stdout == "" and "Traceback" not in stderr
    assert stderr.startswith("cnt-sim: error: ")
    for name in names:
        assert name in stderr


@pytest.mark.parametrize(
    ("args", "names"),
    [
        (["--param", "Ibar", "--values", "1", "--repeats", "100000000"], ["--max-points"]),
        (["--param", "Ibar", "--range", "1:2:100000000"], ["--range", "--max-points"]),
        (["--param", "Ibar", "--values", "1,2", "--max-points", "1"], ["--max-points"]),
        # a raised limit has a ceiling: 1e9 points of a range took 24 GB before the check
        (
            ["--param", "Ibar", "--range", "1:2:1000000000", "--max-points", "1000000000"],
            ["--max-points", "ceiling"],
        ),
        (["--param", "Ibar", "--values", "100", "--kappa-c", "0"], ["--kappa-c"]),
        (["--param", "kappa-c", "--values", "0"], ["--kappa-c"]),
        (["--param", "Ibar", "--values", "1e300"], ["--Ibar", "meaningful range"]),
    ],
)
def test_hostile_sweep_input_is_a_clear_error(
    args: list[str], names: list[str], tmp_path: Path, fake_points: list
) -> None:
    """Defects 8, 9: a huge sweep and kappa_c = 0 are refused before any point runs."""
    out = tmp_path / "s.csv"
    code, stdout, stderr = _call(["sweep", *TINY, *args, "--out", str(out), "--json"])
    _clean(code, stdout, stderr, 2, *names)
    assert fake_points == [] and not out.exists()


@pytest.mark.parametrize("kind", ["fifo", "proc", "long", "symlink"])
def test_sweep_out_must_be_a_writable_regular_file(
    kind: str, tmp_path: Path, fake_points: list
) -> None:
    """Defects 8, 13: --out on a FIFO does not hang; /proc and long names are errors."""
    target = tmp_path / "target.csv"
    target.write_text("keep")
    out = {
        "fifo": tmp_path / "fifo.csv",
        "proc": Path("/proc/x.csv"),
        "long": tmp_path / ("s" * 300),
        "symlink": tmp_path / "link.csv",
    }[kind]
    if kind == "fifo":
        os.mkfifo(out)
    if kind == "symlink":
        out.symlink_to(target)
    grid = ["--param", "Ibar", "--values", "100"]
    code, stdout, stderr = _call(["sweep", *TINY, *grid, "--out", str(out), "--json"])
    _clean(code, stdout, stderr, 2, "--out")
    assert fake_points == [] and target.read_text() == "keep"


def test_sweep_csv_with_an_unclosed_quote_resumes_once(tmp_path: Path, fake_points: list) -> None:
    """Defect 12: a last row ending in an unclosed quote is cut off; the point runs once
    and its row is read back, so the next resume runs nothing."""
    out = tmp_path / "s.csv"
    argv = ["sweep", *TINY, "--param", "Ibar", "--values", "100,200", "--out", str(out)]
    assert _call([*argv, "--json", "--no-plots"])[0] == 0
    lines = out.read_text().splitlines(keepends=True)
    out.write_text("".join(lines[:-1]) + '200.0,0,"coil')  # the last row cut in a quote
    assert len(sweep.read_rows(out)[1]) == 1
    fake_points.clear()
    code, _, stderr = _call([*argv, "--json", "--no-plots"])
    assert code == 0, stderr
    assert fake_points == [{"Ibar": 200.0}]
    assert len(sweep.read_rows(out)[1]) == 2
    fake_points.clear()
    assert _call([*argv, "--json", "--no-plots"])[0] == 0
    assert fake_points == []


def test_sweep_csv_with_random_bytes_is_a_clear_error(tmp_path: Path, fake_points: list) -> None:
    """Defect 12: random bytes appended to the CSV: exit 2 naming --out, file unchanged."""
    out = tmp_path / "s.csv"
    argv = ["sweep", *TINY, "--param", "Ibar", "--values", "100", "--out", str(out), "--json"]
    assert _call([*argv, "--no-plots"])[0] == 0
    with out.open("ab") as f:
        f.write(np.random.default_rng(1).bytes(64) + b"\xff\xfe")
    before = out.read_bytes()
    fake_points.clear()
    code, stdout, stderr = _call([*argv, "--no-plots"])
    _clean(code, stdout, stderr, 2, "--out", "UTF-8")
    assert fake_points == [] and out.read_bytes() == before


def test_a_row_carries_the_settled_measures_that_decide_the_class(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The serpentine classes are decided on the settled pattern (patterns.classify): its
    CVs and loop events are columns of the CSV; a coil, which has none, leaves NaN."""
    from types import SimpleNamespace

    from cnt_env import runs

    spec = runs.resolve_run("coil", groups={"Hbar": 30.0}, deposit=6.0, transient=0.0)
    point = sweep.SweepPoint(0, (("Ibar", 100.0),), spec, "h", None)
    measure = {"amplitude_cv": 0.3, "wavelength_cv": 0.2, "settled_amplitude_cv": 0.04,
               "settled_wavelength_cv": 0.05, "settled_loop_events": 2}  # fmt: skip
    report = {"measure": measure, "pattern": "periodic", "amplitude": 30.0,
              "wavelength": 7.0, "coil_radius": None, "deposited_length": 6.0,
              "sim_time": 1.0, "steps": 3, "newton_iterations": 9, "wall_time_s": 0.1}  # fmt: skip
    outcome = SimpleNamespace(trace=None, stats=None, measurement=measure, report=lambda: report)
    monkeypatch.setattr(runs, "simulate", lambda _spec: outcome)
    row = sweep.run_point(point)
    assert (row["settled_amplitude_cv"], row["settled_wavelength_cv"]) == (0.04, 0.05)
    assert row["settled_loop_events"] == 2 and row["amplitude_cv"] == 0.3
    report["measure"] = {}  # a coil's measure: no U-turn statistics
    row = sweep.run_point(point)
    assert all(math.isnan(row[c]) for c in sweep.LATER_RESULT_COLUMNS)


def test_a_csv_from_before_the_settled_columns_resumes(tmp_path: Path, fake_points: list) -> None:
    """A sweep CSV written before the settled-pattern columns is resumed with its own
    header (a warning names them); a header with a column no sweep writes is refused."""
    out = tmp_path / "s.csv"
    argv = ["sweep", *TINY, "--param", "Ibar", "--values", "100", "--out", str(out), "--no-plots"]
    assert _call([*argv, "--json"])[0] == 0
    header, _ = sweep.read_rows(out)
    assert header is not None
    keep = [i for i, c in enumerate(header) if c not in sweep.LATER_RESULT_COLUMNS]
    lines = [line.split(",") for line in out.read_text().splitlines()]
    out.write_text("".join(",".join(line[i] for i in keep) + "\n" for line in lines))
    fake_points.clear()
    grown = ["sweep", *TINY, "--param", "Ibar", "--values", "100,200", "--out", str(out)]
    code, _, stderr = _call([*grown, "--no-plots", "--json"])
    assert code == 0, stderr
    assert fake_points == [{"Ibar": 200.0}]  # the old row counts as done
    assert "predates the columns" in stderr and "settled_amplitude_cv" in stderr
    header2, rows = sweep.read_rows(out)
    assert header2 == [header[i] for i in keep] and len(rows) == 2

    out.write_text(out.read_text().replace("config_hash", "config_hash,extra", 1))
    record = Path(f"{out}.json").read_bytes()
    code, stdout, stderr = _call([*grown[:-4], "--values", "100,300", "--out", str(out),
                                  "--no-plots", "--json"])  # fmt: skip
    _clean(code, stdout, stderr, 2, "--out", "different sweep")
    # refused before any work: the CSV's record still describes the sweep it holds
    assert Path(f"{out}.json").read_bytes() == record


def test_kappa_c_swept_on_the_coil_preset_says_it_turns_the_steps_on(
    tmp_path: Path, fake_points: list
) -> None:
    """Sweeping kappa_c on a flat preset runs stepped points: said once, not per point."""
    argv = ["sweep", *TINY, "--param", "kappa-c", "--values", "0.1,0.2", "--json", "--no-plots"]
    code, _, stderr = _call([*argv, "--out", str(tmp_path / "a.csv")])
    assert code == 0, stderr
    assert stderr.count("turns the steps on") == 1 and "--substrate stepped" in stderr
    assert len(fake_points) == 2
    code, _, stderr = _call([*argv, "--substrate", "stepped", "--out", str(tmp_path / "b.csv")])
    assert code == 0, stderr
    assert "turns the steps on" not in stderr

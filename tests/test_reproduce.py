"""benchmarks/reproduce.py: the --quick table runs, writes its summary and traces, and a
second call resumes (runs nothing); with Ray (slow) the same points come out the same."""

from __future__ import annotations

import dataclasses
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
    # the deposition speed in units of its scale e_v / (sigma mu H): of order 1 (0.4-0.8
    # on the model's mesh), not per unit of internal time (~1 / Hbar)
    assert all(0.2 < r["deposition_speed"] < 1.5 for r in recs.values())
    assert all(r["flow_profile"] == "uniform" for r in recs.values())
    assert len(list((tmp_path / "traces").glob("*.npy"))) == 3
    assert "Model against paper" in (tmp_path / "summary_default.md").read_text()
    capsys.readouterr()
    assert reproduce.main([*QUICK, "--out", str(tmp_path)]) == 0
    assert "0 points to run (3 already" in capsys.readouterr().out
    assert _records(tmp_path) == recs
    # only the invocation that ran points is logged, and the summary lists it
    logged = (tmp_path / "invocations.jsonl").read_text().splitlines()
    assert len(logged) == 1 and json.loads(logged[0])["points"] == 3
    text = (tmp_path / "summary_default.md").read_text()
    assert "## Invocations that ran points" in text and "| 3 | default | 2 |" in text


def test_a_record_cut_by_a_crash_is_run_again(tmp_path: Path, capsys) -> None:
    args = [*QUICK[:-2], "--out", str(tmp_path)]  # the coil point only
    assert reproduce.main(args) == 0
    path = tmp_path / "results.jsonl"
    whole = path.read_text()
    before = _records(tmp_path)
    path.write_text(whole[: len(whole) // 2])  # killed while writing its record
    capsys.readouterr()
    assert reproduce.main(args) == 0
    out = capsys.readouterr()
    assert "1 points to run (0 already" in out.out
    assert "dropped" in out.err and "incomplete last line" in out.err
    after = _records(tmp_path)  # the same point, run again, bit for bit (but its wall time)
    assert after.keys() == before.keys()
    for key, rec in after.items():
        assert {**rec, "wall_s": 0} == {**before[key], "wall_s": 0}


def test_a_results_file_it_did_not_write_is_refused(tmp_path: Path, capsys) -> None:
    text = '{"key": "a"}\nnot a record\n{"key": "b"}\n'
    (tmp_path / "results.jsonl").write_text(text)
    with pytest.raises(SystemExit) as exc:
        reproduce.main([*QUICK, "--out", str(tmp_path)])
    assert exc.value.code == 2
    assert "results.jsonl, line 2: not a JSON line" in capsys.readouterr().err
    assert (tmp_path / "results.jsonl").read_text() == text


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


def test_summary_compares_other_time_steps_with_the_default_point() -> None:
    """A point re-run at another dt_factor is listed with its relative change."""
    lines = (ROOT / "benchmarks/results/reproduce_surrogate/results.jsonl").read_text().splitlines()
    recs = [json.loads(x) for x in lines]
    serp = next(r for r in recs if r["preset"] == "serpentine" and r["wavelength_x"])
    coil = next(r for r in recs if r["preset"] == "coil" and r["coil_radius"])
    half = [
        {**serp, "key": serp["key"] + "|dt=0.025", "dt_factor": 0.025,
         "amplitude": 1.02 * serp["amplitude"], "wavelength_x": 0.97 * serp["wavelength_x"]},
        {**coil, "key": coil["key"] + "|dt=0.025", "dt_factor": 0.025,
         "coil_radius": 1.004 * coil["coil_radius"]},
    ]  # fmt: skip
    text = reproduce.summary([serp, coil, *half], serp["candidate"])
    table = text.split("## Other time steps")[1]
    assert "| +2.0% | -3.0% |" in table
    assert "+0.4% |" in table
    assert (
        "Largest change at dt_factor 0.025 (A and lambda_x of serpentines, R0 of coils): 3.0%"
        in table
    )
    coil_row = next(x for x in table.splitlines() if x.startswith("| coil | coil"))
    assert coil_row.endswith("|  |  | +0.4% |")  # a coil's A and lambda_x are not compared


def test_seeds_section_judges_the_step_against_the_seeds_spread() -> None:
    """Several seeds of a point: mean +- sd per step, and the change of the mean is
    'within' only when it is below two standard errors of the difference."""
    lines = (ROOT / "benchmarks/results/reproduce_surrogate/results.jsonl").read_text().splitlines()
    real = next(r for r in map(json.loads, lines) if r["groups"] == {"Hbar": 250.0})
    key = real["key"]  # default|serpentine|Hbar=250|coarse=...

    def rec(seed: int, dt: float | None, a: float, lam: float) -> dict:
        k = key.replace("|coarse", ("" if dt is None else f"|dt={dt:g}")
                        + (f"|seed={seed}" if seed else "") + "|coarse")  # fmt: skip
        return {**real, "key": k, "dt_factor": dt or 0.05, "amplitude": a,
                "wavelength_x": lam, "pattern": "periodic"}  # fmt: skip

    # A: means 40 and 41, sd 1.63 over 4 seeds: 2 SE = 2.31, within; lambda_x: means 8
    # and 10, sd 0.12: far outside
    amps, wiggle = (38.0, 40.0, 42.0, 40.0), (0.1, -0.1, 0.1, -0.1)
    recs = [rec(s, None, amps[s], 8.0 + wiggle[s]) for s in range(4)]
    recs += [rec(s, 0.025, amps[s] + 1.0, 10.0 + wiggle[s]) for s in range(4)]
    lines = reproduce.seeds_section(recs)
    rows = [x for x in lines if x.startswith("| Hbar |")]
    assert len(rows) == 2
    default = next(x for x in rows if "| 0.05 |" in x)
    half = next(x for x in rows if "| 0.025 |" in x)
    assert "| 4 | periodic 4 | 40.00 +- 1.63 (4) | 8.00 +- 0.12 (4) |" in default
    assert "amplitude +2.5%; wavelength_x +25.0% | yes, no |" in half
    # the main tables see seed 0 at the default step alone
    text = reproduce.summary(recs, "default")
    assert "## Seeds" in text and "(1 points)" in text


def test_default_keys_name_the_model_so_the_previous_default_is_never_reused() -> None:
    """The "default" candidate follows presets.py: its keys name the model fields that
    differ from the previous default (LEGACY_DEFAULT_MODEL, the printed law at delta_bar
    1), so none of the previous default's records (benchmarks/results/reproduce_surrogate)
    is taken for a point of today's; a named candidate fixes its model and its keys name
    none."""
    from cnt_env.presets import MESH, MODEL

    table = reproduce.rows(False)
    points = [p for row in table.values() for p in row]
    old = set(_records(ROOT / "benchmarks/results/reproduce_surrogate"))
    now = {reproduce.point_key(p, "default", None) for p in points}
    assert len(now) == len(points) and not now & old
    suffix = f"|drag_law={MODEL['drag_law']}|delta_bar={MESH['serpentine']['delta_bar']:g}"
    assert all(key.endswith(suffix) for key in now)
    # the same model under its candidate name: the name fixes it, the key does not list it
    assert all("drag_law" not in reproduce.point_key(p, "C_fine", None) for p in points)
    # a default equal to the previous one names nothing: its old records stay its own
    legacy = {k: v for k, v in reproduce.LEGACY_DEFAULT_MODEL.items() if k != "delta_bar"}
    cfg = reproduce.point_config(points[0], "default", None)
    cfg = dataclasses.replace(cfg, params=dataclasses.replace(cfg.params, delta_bar=1.0),
                              **legacy)  # fmt: skip
    assert reproduce._default_model_fields(cfg) == ""


def test_capped_points_name_the_cap_and_uncapped_records_leave_the_tables() -> None:
    """A stepped point above presets.STEP_HBAR_CAP runs at the capped step and its key says
    so, so the uncapped record of the same point is never reused; such a record stays in
    results.jsonl but out of the tables. Points at or below the cap, and coils, keep their
    keys (their step did not change)."""
    from cnt_env.presets import STEP_HBAR_CAP

    cap = STEP_HBAR_CAP["stepped"]
    table = reproduce.rows(False)
    points = {(p["row"], tuple(sorted(p["groups"].items()))): p
              for row in table.values() for p in row}  # fmt: skip
    high = points[("Hbar", (("Hbar", 400.0),))]
    low = points[("Hbar", (("Hbar", 100.0),))]
    coil = points[("coil_groups", (("Hbar", 400.0),))]
    assert f"|dtcap={cap:g}" in reproduce.point_key(high, "default", None)
    assert f"|dtcap={cap:g}" in reproduce.point_key(high, "default", 0.025)
    assert "|dtcap=" not in reproduce.point_key(low, "default", None)
    assert "|dtcap=" not in reproduce.point_key(coil, "default", None)
    assert reproduce.point_config(high, "default", None).time_step == pytest.approx(0.05 * cap)
    old = {"key": "default|serpentine|Hbar=400|x", "Hbar": 400.0, "kappa_c_bar": 0.2}
    assert reproduce._before_cap(old)
    assert not reproduce._before_cap({**old, "key": old["key"] + "|dtcap=155"})
    assert not reproduce._before_cap({**old, "Hbar": cap})
    assert not reproduce._before_cap({**old, "kappa_c_bar": None})  # a coil: no cap


def test_every_candidate_makes_a_valid_config_at_every_point() -> None:
    """Each named candidate of the study (a dict of DepositionConfig fields) builds and
    validates at every point of the table, and it fixes what it names: its drag law and
    contact on both substrates, its sliding rule on the stepped one."""
    points = [p for row in reproduce.rows(False).values() for p in row]
    for name, changes in reproduce.CANDIDATES.items():
        for p in points:
            cfg = reproduce.point_config(p, name, None)
            stepped = p["preset"] != reproduce.COIL
            for field in ("drag_law", "sliding", "adhesion"):
                if field not in changes or (field == "sliding" and not stepped):
                    continue
                got = cfg.contact.adhesion if field == "adhesion" else getattr(cfg, field)
                assert got == changes[field], (name, p["row"], field)


def test_si_section_converts_with_each_substrates_length() -> None:
    """The paper's SI ranges are checked in micrometres: a stepped point's lengths times
    L_vb of the stepped substrate, a coil's times the flat one's, and the count inside."""
    from cnt_env import units

    l_serp = units.preset("serpentine").L_vb * 1e6
    l_coil = units.preset("coil").L_vb * 1e6
    recs = [
        {"row": "vbar", "preset": "serpentine", "amplitude": 4.0 / l_serp,
         "wavelength_x": 1.0 / l_serp},
        {"row": "vbar", "preset": "serpentine", "amplitude": 20.0 / l_serp,
         "wavelength_x": 0.4 / l_serp},
        {"row": "phi", "preset": "serpentine", "amplitude": 99.0, "wavelength_x": 99.0},
        {"row": "coil_groups", "preset": "coil", "coil_radius": 0.6 / l_coil},
    ]  # fmt: skip
    text = "\n".join(reproduce.si_section(recs))
    amplitude = "| 3-13 | 4.00-20.00 (peak to peak 8.00-40.00) | 2 | 1 of 2 |"
    assert f"| serpentine amplitude A, vbar row {amplitude}" in text
    assert "| serpentine wavelength lambda_x, vbar row | 0.5-3 | 0.40-1.00 | 2 | 1 of 2 |" in text
    assert "| coil radius R0, coil rows (experiments) | 0.5-5 | 0.60-0.60 | 1 | 1 of 1 |" in text


def test_a_point_off_the_table_lists_the_table_points_it_could_mean(tmp_path: Path, capsys) -> None:
    """--point takes only the table's points: an off-table value is refused before any
    run, listing the table's points with that group and naming `cnt-sim run`."""
    with pytest.raises(SystemExit) as stop:
        reproduce.main(["--point", "vbar=0.02", "--out", str(tmp_path)])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "vbar=0.019" in err and "vbar=0.037" in err and "cnt-sim run" in err
    assert not (tmp_path / "results.jsonl").exists()


@pytest.mark.parametrize("ratio", reproduce.LVB_RATIOS)
def test_the_lvb_row_is_the_si_conversion_of_a_changed_adhesion(ratio: float) -> None:
    """The coil_Lvb row changes L_vb by the adhesion e_v alone: its groups are the SI
    conversion of the paper's coil with e_v / ratio^2 (the paper's tube, H and gas), each
    in the ratio to the SI baseline's groups, and the row reads its L_vb back from Hbar."""
    from cnt_env import units

    si = units.preset("coil")
    base = si.to_dimensionless()
    changed = dataclasses.replace(si, e_v=si.e_v / ratio**2, delta=None).to_dimensionless()
    groups = reproduce.lvb_groups(ratio)
    paper = units.paper_groups("coil")
    for name in ("Hbar", "Ibar", "ks_over_ev", "r0_bar"):
        want = getattr(changed, name) / getattr(base, name)
        assert groups[name] / getattr(paper, name) == pytest.approx(want, rel=1e-12), name
    rec = {"row": "coil_Lvb", "Hbar": groups["Hbar"]}
    assert reproduce.lvb_ratio(rec) == pytest.approx(ratio, rel=1e-12)
    assert reproduce.lvb_ratio({"row": "coil_groups", "Hbar": 100.0}) == 1.0

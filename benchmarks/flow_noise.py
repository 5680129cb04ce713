"""Is the model's serpentine near an instability? Its class under a fluctuating flow.

Issue 12's phase sequence (serpentine-coil, periodic, irregular as v̄ rises) is the one
row no candidate reproduces: the model lays periodic serpentines from v̄ 0.019 to 0.12
(settled CV of Ā <= 2%, benchmarks/RESULTS.md, "Goals of issue 12"). The paper's model is
deterministic too, so its irregular serpentines at high flow come from the dynamics. One
reading is that the paper's high-flow pattern is close to an instability that its
simulations cross and ours do not. This probe asks how far ours is from one: it lays the
v̄ row's serpentine (the model's defaults, ``reproduce.py``'s point) under a flow whose
speed and direction fluctuate, and measures the classes and the CVs.

The fluctuation is an AR(1) (discrete Ornstein-Uhlenbeck) process in the trace laid,
refreshed every ``every`` L_vb of deposited trace:

    xi_{k+1} = a xi_k + sqrt(1 - a^2) n_k,  a = exp(-every / corr),  n_k ~ N(0, 1)

(stationary variance 1, correlation exp(-s / corr) over s L_vb of trace), one process for
the speed and one for the direction: vbar (1 + sigma xi_v) (clipped at 0) and
phi + sigma xi_phi rad. It is not a model option: the paper names no fluctuation, and
none is in the env. It is a measurement of the deterministic model's margin.

    python benchmarks/flow_noise.py --jobs 2          # ~25 min on 2 cores
    python benchmarks/flow_noise.py --vbar 0.12 --sigma 0.05 --seeds 0,1
    python benchmarks/flow_noise.py --vbar                # the table alone (no point)

Results append to benchmarks/results/flow_noise.jsonl (resumable: a point already there
is not run again) and the table prints.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks import reproduce  # noqa: E402
from cnt_env.jsonl import append_row  # noqa: E402

OUT = ROOT / "benchmarks" / "results" / "flow_noise.jsonl"
VBARS = (0.019, 0.037, 0.12)
SIGMAS = (0.05, 0.15)
EVERY = 2.0  # L_vb of trace between refreshes of the flow
CORR = 20.0  # L_vb of trace: the correlation length (a cycle is ~150 L_vb at v̄ 0.037)


def ar1(rng: np.random.Generator, n: int, every: float, corr: float) -> np.ndarray:
    """``n`` steps of the stationary AR(1) process above (x_0 ~ N(0, 1))."""
    if not (every > 0 and corr > 0):
        raise ValueError(f"every and corr must be > 0, got {every}, {corr}")
    a = math.exp(-every / corr)
    b = math.sqrt(1.0 - a * a)
    x = np.empty(n)
    x[0] = rng.standard_normal()
    for k in range(1, n):
        x[k] = a * x[k - 1] + b * rng.standard_normal()
    return x


def point_key(vbar: float, sigma: float, corr: float, seed: int, deposit: float) -> str:
    """The point's name in the results file."""
    return f"vbar={vbar:g}|sigma={sigma:g}|corr={corr:g}|every={EVERY:g}|seed={seed}|" + (
        f"run={deposit:g}"
    )


def run_point(vbar: float, sigma: float, corr: float, seed: int, deposit: float) -> dict[str, Any]:
    """Lay ``deposit`` L_vb at ``vbar`` under the fluctuating flow and measure it as
    ``reproduce.py`` measures its points (the preset's transient dropped)."""
    from cnt_env.patterns import MeasureOptions, measure
    from cnt_env.presets import RUN_TRANSIENT
    from cnt_env.sim.deposition import DepositionSim

    point = reproduce._point("vbar", reproduce.SERP, vbar=vbar)
    cfg = reproduce.point_config(point, "default", None)
    sim = DepositionSim(cfg, seed=0)  # the start-up of the table's point; noise seeded apart
    n = math.ceil(deposit / EVERY) + 1
    rng = np.random.default_rng(seed)
    xi_v, xi_phi = ar1(rng, n, EVERY, corr), ar1(rng, n, EVERY, corr)
    phi0 = cfg.params.phi
    t0 = time.time()
    error = None
    try:
        for k in range(n):
            if sigma > 0:
                sim.set_flow(max(0.0, vbar * (1.0 + sigma * xi_v[k])), phi0 + sigma * xi_phi[k])
            sim.run(min(deposit, (k + 1) * EVERY))
            if sim.deposited_length >= deposit:
                break
    except Exception as exc:  # a failed solve is reported with the record, not hidden
        error = f"{type(exc).__name__}: {exc}"[:300]
    wall = time.time() - t0
    opts = MeasureOptions(transient_length=min(RUN_TRANSIENT[reproduce.SERP], 0.3 * deposit))
    m = measure(sim.trace(), opts, "stepped", flow_direction=(1.0, 0.0))
    return {
        "key": point_key(vbar, sigma, corr, seed, deposit),
        "vbar": vbar, "sigma": sigma, "corr": corr, "every": EVERY, "seed": seed,
        "deposit": deposit, "error": error, **reproduce._measured(m),
        "wall_s": round(wall, 1),
        "deposition_speed": sim.deposited_length / sim.time * cfg.params.Hbar,
    }  # fmt: skip


def _row(r: dict[str, Any]) -> str:
    f = reproduce._fmt
    cells = [f"{r['vbar']:g}", f"{r['sigma']:g}", f"{r['corr']:g}", str(r["seed"]), r["pattern"],
             f(r["amplitude"]), f(r["wavelength_x"]), f(r["settled_amplitude_cv"], 3),
             f(r["settled_wavelength_cv"], 3), str(r["n_loops"]), f"{r['wall_s']:.0f}"]  # fmt: skip
    return "| " + " | ".join(cells) + " |"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--vbar", type=float, nargs="*", default=list(VBARS))
    p.add_argument("--sigma", type=float, nargs="*", default=list(SIGMAS))
    p.add_argument("--corr", type=float, default=CORR)
    p.add_argument("--seeds", default="0", help="comma separated noise seeds")
    p.add_argument("--deposit", type=float, default=reproduce.SERPENTINE_RUN,
                   help="L_vb per point (the table's)")  # fmt: skip
    p.add_argument("--jobs", type=int, default=1)
    p.add_argument("--out", type=Path, default=OUT)
    a = p.parse_args(argv)
    seeds = [int(s) for s in a.seeds.split(",")]
    done = reproduce.load_done(a.out)
    todo = [(v, s, a.corr, sd, a.deposit) for v in a.vbar for s in a.sigma for sd in seeds
            if point_key(v, s, a.corr, sd, a.deposit) not in done]  # fmt: skip
    print(f"{len(todo)} points to run, {len(done)} in {a.out}", flush=True)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    with ProcessPoolExecutor(max_workers=max(1, a.jobs)) as pool:
        for rec in pool.map(run_point, *zip(*todo, strict=True)) if todo else []:
            append_row(a.out, rec)
            done[rec["key"]] = rec
            print(_row(rec), flush=True)
    print("| v̄ | sigma | corr | seed | class | Ā | λ̄_x | CV Ā | CV λ̄ | loops | wall s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for rec in sorted(done.values(), key=lambda r: (r["vbar"], r["sigma"], r["corr"], r["seed"])):
        print(_row(rec))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

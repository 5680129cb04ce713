"""Learning curves of route_runs/resid_drange_s1 from its learning_curve CSVs (its
evaluations.npz were not kept), beside the shipped run's (resid_two40_s1), with the
follower (today's defaults, which the runs' base did not yet have: start flow, band_memory 8)
and random scored on each run's and stage's validation routes as dashed and dotted lines
(each run draws its validation routes from its own training families). Run from the repo:
``.venv/bin/python training/results/route_runs/resid_drange_s1/plot_curves.py`` (~2 min;
the baselines are cached under /tmp/lc)."""

import shutil
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

ROOT = Path(__file__).resolve().parents[4]
sys.path.insert(0, str(ROOT))
from training.evaluate import eval_set_baselines  # noqa: E402

R = ROOT / "training/results/route_runs"
runs = {
    "difficulty [0.25, 1] (resid_drange_s1)": R / "resid_drange_s1",
    "shipped recipe, difficulty 0.5 (resid_two40_s1)": R / "resid_two40_s1",
}
stages = (
    ("stage 1", "stage1_learning_curve.csv", ("stage1_run_config.yml", "stage1_config.yml")),
    ("stage 2", "learning_curve.csv", ("config.yml",)),
)
NAMES = {"scripted": "follower", "random": "random"}
fig, axes = plt.subplots(1, 2, figsize=(12, 4))
for ax, (stage, csv, cfg) in zip(axes, stages, strict=True):
    for (label, run), color in zip(runs.items(), ("C0", "C1"), strict=True):
        # each run draws its validation routes from its own training families
        cfgfile = next(run / c for c in cfg if (run / c).is_file())
        tmp = Path(f"/tmp/lc/base_{run.name}_{stage.replace(' ', '')}")
        tmp.mkdir(parents=True, exist_ok=True)
        shutil.copy(cfgfile, tmp / "config.yml")
        base = eval_set_baselines(tmp)
        print(stage, run.name, base)
        for (name, v), ls in zip(base.items(), ("--", ":"), strict=True):
            ax.axhline(v, ls=ls, color=color, lw=1, label=f"{NAMES[name]}, same routes ({v:.3f})")
        d = np.genfromtxt(run / csv, delimiter=",", names=True)
        ax.plot(
            d["timesteps"],
            d["return_mean"],
            marker="o",
            ms=3,
            color=color,
            label=f"{label}: {int(d['timesteps'][-1])} steps",
        )
        ax.fill_between(
            d["timesteps"],
            d["return_mean"] - d["return_std"],
            d["return_mean"] + d["return_std"],
            alpha=0.15,
            color=color,
        )
    ax.set_xlabel("training steps of the stage")
    ax.set_ylabel("EvalCallback return = final score")
    ax.set_title(f"{stage}: EvalCallback on its four validation routes", fontsize=9)
    ax.legend(fontsize=7)
fig.tight_layout()
fig.savefig(R / "resid_drange_s1" / "learning_curves.png", dpi=90)

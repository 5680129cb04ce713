#!/bin/bash
# Two stages inside one hour: the shipped recipe (uncalibrated) ~35 min, then the
# shipped agent's second stage (calibrated, detour 3 in 10) ~24 min from its final model.
set -e
cd /work/main
date -u +%s > /tmp/runs/two/t0
.venv/bin/cnt-train --algo ppo --config training/configs/ppo_residual_recipe_shipped.yml --seed 0 --vec-env subproc --n-timesteps 54000 --max-wall-seconds 2100 --out /tmp/runs/two/s1 --no-progress
S1=$(ls -d /tmp/runs/two/s1/*/ | head -1)
.venv/bin/python - "$S1" <<'PY'
import sys, yaml
from pathlib import Path
from policies.sb3 import write_manifest, model_files
run = Path(sys.argv[1])
ft = yaml.safe_load(open("training/configs/ppo_residual_shipped_detour_finetune.yml"))["CNTDeposit-v0"]
want = ft["env_wrapper"][0]["training.common.ResidualAction"]["base_kwargs"]
for name in ("ppo.yml", "config.yml"):
    p = run / name
    cfg = yaml.safe_load(p.read_text())
    cfg["CNTDeposit-v0"]["env_wrapper"][0]["training.common.ResidualAction"]["base_kwargs"] = dict(want)
    cfg["run"]["base_set_after_training"] = "the second stage's base (unhook as the shipped agent's)"
    p.write_text(yaml.safe_dump(cfg, sort_keys=False))
models = [run / "ppo.zip", run / "best_model.zip"]
write_manifest(run, [f.name for m in models for f in model_files(m) if f.is_file()])
PY
date -u +%s > /tmp/runs/two/t1
.venv/bin/cnt-train --algo ppo --config training/configs/ppo_residual_shipped_detour_finetune.yml --trained-agent ${S1}ppo.zip --seed 0 --vec-env subproc --n-timesteps 75000 --max-wall-seconds 1380 --out /tmp/runs/two/s2 --no-progress
date -u +%s > /tmp/runs/two/t2

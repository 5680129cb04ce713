#!/bin/bash
# (A record of the run as made: its paths are the machine's; set R and the repo path for yours.)
# One hour, two stages, each route drawn at a difficulty uniform in [0.25, 1.0]: the shipped recipe with the shipped agent's seed (1) for 40 min
# (its lin_3e-4 schedule over 100k steps, stopped by the wall as the shipped run was), then
# the shipped agent's second stage (calibrated, detour 3 in 10) for the rest of the hour,
# with n_timesteps set so that its lin_1e-4 schedule anneals within the time left.
set -e
cd /work/main
R=${R:-/work/runs/drange}; mkdir -p $R
T0=$(date -u +%s); echo $T0 > $R/t0
.venv/bin/cnt-train --algo ppo --config training/configs/ppo_residual_difficulty_range.yml --seed 1 --vec-env subproc --max-wall-seconds 2400 --out $R/s1 --no-progress
S1=$(ls -d $R/s1/*/ | head -1)
.venv/bin/python - "$S1" <<'PY'
import sys, yaml
from pathlib import Path
from policies.sb3 import write_manifest, model_files
run = Path(sys.argv[1])
ft = yaml.safe_load(open("training/configs/ppo_residual_difficulty_range_stage2.yml"))["CNTDeposit-v0"]
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
T1=$(date -u +%s); echo $T1 > $R/t1
LEFT=$(( 3600 - (T1 - T0) - 45 ))
NSTEPS=$(( LEFT * 50 ))
echo "stage 2: $LEFT s, $NSTEPS steps" > $R/stage2_plan
.venv/bin/cnt-train --algo ppo --config training/configs/ppo_residual_difficulty_range_stage2.yml --trained-agent ${S1}ppo.zip --seed 0 --vec-env subproc --n-timesteps $NSTEPS --max-wall-seconds $LEFT --out $R/s2 --no-progress
date -u +%s > $R/t2

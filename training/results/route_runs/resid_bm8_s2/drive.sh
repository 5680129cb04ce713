#!/bin/bash
# (A record of the run as made: its paths are the machine's; set R and the repo path for yours.)
# The shipped agent's one-hour, two-stage run (route_runs/resid_two40_s1/drive.sh) with
# today's follower options of the shipped agent's base in it throughout: the start flow
# (start_swing: true) and the plan for the recent band (band_memory: 8); the shipped agent
# got both only after training. Otherwise as route_runs/resid_start_s1/drive.sh (start
# flow only): stage 1 is ppo_residual_recipe_shipped.yml with those keys, seed 1, 40 min;
# stage 2 is ppo_residual_shipped_detour_finetune.yml with those keys, seed 0, for the
# rest of the hour.
# route_runs/resid_bm8_s2: the same with stage 1 at seed 2 (resid_bm8_s1 had seed 1).
set -e
cd /work/main
R=/tmp/runs/bm8s2
mkdir -p $R
T0=$(date -u +%s); echo $T0 > $R/t0
.venv/bin/python - "$R" <<'PY'
import sys, yaml
for src, dst in (("ppo_residual_recipe_shipped", "stage1_config"),
                 ("ppo_residual_shipped_detour_finetune", "stage2_config")):
    cfg = yaml.safe_load(open(f"training/configs/{src}.yml"))
    cfg["CNTDeposit-v0"]["env_wrapper"][0]["training.common.ResidualAction"]["base_kwargs"]["start_swing"] = True
    cfg["CNTDeposit-v0"]["env_wrapper"][0]["training.common.ResidualAction"]["base_kwargs"]["band_memory"] = 8
    open(f"{sys.argv[1]}/{dst}.yml", "w").write(yaml.safe_dump(cfg, sort_keys=False))
PY
.venv/bin/cnt-train --algo ppo --config $R/stage1_config.yml --seed 2 --vec-env subproc --max-wall-seconds 2400 --out $R/s1 --no-progress
S1=$(ls -d $R/s1/*/ | head -1)
.venv/bin/python - "$S1" "$R/stage2_config.yml" <<'PY'
import sys, yaml
from pathlib import Path
from policies.sb3 import write_manifest, model_files
run = Path(sys.argv[1])
ft = yaml.safe_load(open(sys.argv[2]))["CNTDeposit-v0"]
want = ft["env_wrapper"][0]["training.common.ResidualAction"]["base_kwargs"]
for name in ("ppo.yml", "config.yml"):
    p = run / name
    cfg = yaml.safe_load(p.read_text())
    cfg["CNTDeposit-v0"]["env_wrapper"][0]["training.common.ResidualAction"]["base_kwargs"] = dict(want)
    cfg["run"]["base_set_after_training"] = "the second stage's base (unhook as the shipped agent's, start flow, band_memory 8)"
    p.write_text(yaml.safe_dump(cfg, sort_keys=False))
models = [run / "ppo.zip", run / "best_model.zip"]
write_manifest(run, [f.name for m in models for f in model_files(m) if f.is_file()])
PY
T1=$(date -u +%s); echo $T1 > $R/t1
LEFT=$(( 3600 - (T1 - T0) - 45 ))
NSTEPS=$(( LEFT * 50 ))
echo "stage 2: $LEFT s, $NSTEPS steps" > $R/stage2_plan
.venv/bin/cnt-train --algo ppo --config $R/stage2_config.yml --trained-agent ${S1}ppo.zip --seed 0 --vec-env subproc --n-timesteps $NSTEPS --max-wall-seconds $LEFT --out $R/s2 --no-progress
date -u +%s > $R/t2

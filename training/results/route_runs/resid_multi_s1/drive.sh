#!/bin/bash
# (A record of the run as made: its paths are the machine's; set R and the repo path for yours.)
# The residual agent's one-hour, two-stage run of route_runs/resid_bm8_s1/drive.sh (the
# shipped recipe with today's base options, start_swing and band_memory 8, throughout),
# on the Dict observation: obs_mode dict and policy MultiInputPolicy (NatureCNN on the
# image with its corridor, pads and keep-outs, beside the vector), nothing else changed.
# Stage 1: ppo_residual_recipe_shipped.yml with those keys, seed 1, 40 min; stage 2:
# ppo_residual_shipped_detour_finetune.yml with those keys, seed 0, the rest of the hour,
# its n_timesteps set from the Dict's step rate (~28 steps/s alone) so that its lin_
# schedule anneals within the time left.
set -e
cd /work/main
R=/tmp/s16/rm
mkdir -p $R
T0=$(date -u +%s); echo $T0 > $R/t0
.venv/bin/python - "$R" <<'PY'
import sys, yaml
for src, dst in (("ppo_residual_recipe_shipped", "stage1_config"),
                 ("ppo_residual_shipped_detour_finetune", "stage2_config")):
    cfg = yaml.safe_load(open(f"training/configs/{src}.yml"))
    e = cfg["CNTDeposit-v0"]
    e["env_wrapper"][0]["training.common.ResidualAction"]["base_kwargs"]["start_swing"] = True
    e["env_wrapper"][0]["training.common.ResidualAction"]["base_kwargs"]["band_memory"] = 8
    e["policy"] = "MultiInputPolicy"
    e["env_kwargs"]["obs_mode"] = "dict"
    open(f"{sys.argv[1]}/{dst}.yml", "w").write(yaml.safe_dump(cfg, sort_keys=False))
PY
.venv/bin/cnt-train --algo ppo --config $R/stage1_config.yml --seed 1 --vec-env subproc --max-wall-seconds 2400 --out $R/s1 --no-progress
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
NSTEPS=$(( LEFT * 28 ))
echo "stage 2: $LEFT s, $NSTEPS steps" > $R/stage2_plan
.venv/bin/cnt-train --algo ppo --config $R/stage2_config.yml --trained-agent ${S1}ppo.zip --seed 0 --vec-env subproc --n-timesteps $NSTEPS --max-wall-seconds $LEFT --out $R/s2 --no-progress
date -u +%s > $R/t2

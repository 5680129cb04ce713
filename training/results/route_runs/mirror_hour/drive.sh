#!/bin/bash
# One hour, two stages, with mirrored starts throughout (2026-12-06): the shipped agent's
# recipe (route_runs/resid_two40_s1/drive.sh: 40 min of the recipe, seed 1, then its
# detour stage for the rest of the hour) with start_mirror: random in both stages. Then
# the shipped agent's base at inference (start flow, band_memory 8, the -z keep-out gate:
# policies/pretrained/ppo_residual.yml), the selection rule (12 validation routes) over
# the final and best models, each as trained and mirror-averaged, and held out.
# R: the run directory.
set -e
cd "$(dirname "$0")/../../../.."
O=training/results/route_runs/mirror_hour
R=${R:-/tmp/runs/mirror_hour}
mkdir -p $R
T0=$(date -u +%s); echo $T0 > $R/t0
.venv/bin/cnt-train --algo ppo --config training/configs/ppo_residual_recipe_mirror.yml --seed 1 \
  --vec-env subproc --max-wall-seconds 2400 --out $R/s1 --no-progress
S1=$(ls -d $R/s1/*/ | head -1)
.venv/bin/python - "$S1" <<'PY'
import sys, yaml
from pathlib import Path
from policies.sb3 import write_manifest, model_files
run = Path(sys.argv[1])
ft = yaml.safe_load(open("training/configs/ppo_residual_detour_mirror_finetune.yml"))["CNTDeposit-v0"]
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
.venv/bin/cnt-train --algo ppo --config training/configs/ppo_residual_detour_mirror_finetune.yml \
  --trained-agent ${S1}ppo.zip --seed 0 --vec-env subproc --n-timesteps $NSTEPS \
  --max-wall-seconds $LEFT --out $R/s2 --no-progress
date -u +%s > $R/t2
S2=$(ls -d $R/s2/*/ | head -1)
cp ${S1}learning_curve.csv $O/stage1_learning_curve.csv
cp ${S1}config.yml $O/stage1_config.yml
cp ${S2}learning_curve.csv $O/learning_curve.csv
cp ${S2}config.yml $O/config.yml
cp $R/t0 $R/t1 $R/t2 $R/stage2_plan $O/
# The four candidates, each over the shipped agent's base as it is evaluated.
M=$R/models; mkdir -p $M
for pair in "ppo:mh_final" "best_model:mh_best"; do
  src=${pair%%:*}; dst=${pair##*:}
  for v in "$dst" "${dst}_avg"; do
    cp ${S2}$src.zip $M/$v.zip
    cp ${S2}${src}_vecnormalize.json $M/${v}_vecnormalize.json
    cp ${S2}${src}_vecnormalize.npz $M/${v}_vecnormalize.npz
    .venv/bin/python - ${S2}config.yml policies/pretrained/ppo_residual.yml $M/$v.yml $v <<'PY'
import sys, yaml
run, shipped, out, name = sys.argv[1:]
c = yaml.safe_load(open(run))
wrap = yaml.safe_load(open(shipped))["CNTDeposit-v0"]["env_wrapper"][0]["training.common.ResidualAction"]
if name.endswith("_avg"):
    wrap = dict(wrap, mirror_average=True)
c["CNTDeposit-v0"]["env_wrapper"][0]["training.common.ResidualAction"] = wrap
c["run"]["base_set_after_training"] = "the shipped agent's base (policies/pretrained/ppo_residual.yml)"
open(out, "w").write(yaml.safe_dump(c, sort_keys=False))
PY
  done
done
.venv/bin/python -c "import sys; from policies.sb3 import write_manifest; write_manifest(sys.argv[1])" "$M"
.venv/bin/python benchmarks/checkpoint_selection.py --models "$M" policies/pretrained \
  --names ppo_residual,mh_final,mh_best,mh_final_avg,mh_best_avg --routes 12 \
  --jobs 2 --config training/configs/eval.yml --out $O/validation.json > $O/validation.log 2>&1
.venv/bin/cnt-evaluate --policies random,scripted,ppo_residual,mh_final,mh_best,mh_final_avg,mh_best_avg \
  --models "$M" policies/pretrained --reuse training/results --out $O/seeds_0-2 \
  --jobs 2 > $O/seeds_0-2.log 2>&1
# Afterwards (as run): seeds 3-8 of the final model, as trained and averaged; only each
# evaluation's episodes.csv is kept; the final model and the first stage's model are kept in
# model/ (the first stage over the second stage's base, as stage 2 started from it).
.venv/bin/cnt-evaluate --policies mh_final,mh_final_avg --models "$M" policies/pretrained \
  --seeds 3,4,5,6,7,8 --out $O/seeds_3-8 --jobs 2 > $O/seeds_3-8.log 2>&1

#!/bin/bash
# One hour, two stages: mirrored starts in the first stage only (2026-12-06). Stage 1 is
# route_runs/mirror_hour's (40 min of configs/ppo_residual_recipe_mirror.yml, seed 1; its
# final model kept as ../mirror_hour/model/mh_stage1, already over the second stage's
# base; 2 406 s with start-up, ../mirror_hour/t0, t1). Stage 2 here is the shipped agent's
# own detour stage (configs/ppo_residual_shipped_detour_finetune.yml, seed 0, unmirrored
# starts) for the rest of the hour. Then the shipped agent's base at inference, the
# selection rule (12 validation routes) over the final and best models, each as trained
# and mirror-averaged, and held out (seeds 0-2).
# R: the run directory.
set -e
cd "$(dirname "$0")/../../../.."
O=training/results/route_runs/mirror_stage1
H=training/results/route_runs/mirror_hour
R=${R:-/tmp/runs/mirror_stage1}
mkdir -p $R
STAGE1=$(( $(cat $H/t1) - $(cat $H/t0) ))
LEFT=$(( 3600 - STAGE1 - 45 ))
NSTEPS=$(( LEFT * 50 ))
echo "stage 1: $STAGE1 s (mirror_hour); stage 2: $LEFT s, $NSTEPS steps" > $R/stage2_plan
date -u +%s > $R/t1
.venv/bin/cnt-train --algo ppo --config training/configs/ppo_residual_shipped_detour_finetune.yml \
  --trained-agent $H/model/mh_stage1.zip --seed 0 --vec-env subproc --n-timesteps $NSTEPS \
  --max-wall-seconds $LEFT --out $R/s2 --no-progress
date -u +%s > $R/t2
S2=$(ls -d $R/s2/*/ | head -1)
cp ${S2}learning_curve.csv $O/learning_curve.csv
cp ${S2}config.yml $O/config.yml
cp $R/t1 $R/t2 $R/stage2_plan $O/
# The four candidates, each over the shipped agent's base as it is evaluated.
M=$R/models; mkdir -p $M
for pair in "ppo:ms_final" "best_model:ms_best"; do
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
  --names ppo_residual,ms_final,ms_best,ms_final_avg,ms_best_avg --routes 12 \
  --jobs 2 --config training/configs/eval.yml --out $O/validation.json > $O/validation.log 2>&1
.venv/bin/cnt-evaluate --policies random,scripted,ppo_residual,ms_final,ms_best,ms_final_avg,ms_best_avg \
  --models "$M" policies/pretrained --reuse training/results --out $O/seeds_0-2 \
  --jobs 2 > $O/seeds_0-2.log 2>&1
# Afterwards (as run): seeds 3-8 of the two averaged models; only episodes.csv is kept.
.venv/bin/cnt-evaluate --policies ms_final_avg,ms_best_avg --models "$M" policies/pretrained \
  --seeds 3,4,5,6,7,8 --out $O/seeds_3-8 --jobs 2 > $O/seeds_3-8.log 2>&1

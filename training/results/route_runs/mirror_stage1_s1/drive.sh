#!/bin/bash
# mirror_stage1's hour with its second stage's other seed (2026-12-06): is that run's
# held-out lead (the averaged final model, 0.977 on seeds 0-2) the recipe's or its seed's?
# Stage 1 is ../mirror_hour's (model/mh_stage1, 2 406 s with start-up); stage 2 the
# shipped detour stage (configs/ppo_residual_shipped_detour_finetune.yml), unmirrored
# starts, seed 1 (../mirror_stage1 ran seed 0). Then the four candidates over the shipped
# agent's base and gate (python -m training.candidate), the 12 validation routes, and
# held out (seeds 0-2, then 3-8 for every candidate). Training is skipped when $R/t2 is
# there (the run is resumable after it). R: the run directory.
set -e
cd "$(dirname "$0")/../../../.."
O=training/results/route_runs/mirror_stage1_s1
H=training/results/route_runs/mirror_hour
R=${R:-/tmp/runs/mirror_stage1_s1}
mkdir -p $R
if [ ! -f $R/t2 ]; then
  STAGE1=$(( $(cat $H/t1) - $(cat $H/t0) ))
  LEFT=$(( 3600 - STAGE1 - 45 ))
  NSTEPS=$(( LEFT * 50 ))
  echo "stage 1: $STAGE1 s (mirror_hour); stage 2: $LEFT s, $NSTEPS steps" > $R/stage2_plan
  date -u +%s > $R/t1
  .venv/bin/cnt-train --algo ppo --config training/configs/ppo_residual_shipped_detour_finetune.yml \
    --trained-agent $H/model/mh_stage1.zip --seed 1 --vec-env subproc --n-timesteps $NSTEPS \
    --max-wall-seconds $LEFT --out $R/s2 --no-progress
  date -u +%s > $R/t2
fi
S2=$(ls -d $R/s2/*/ | head -1)
cp ${S2}learning_curve.csv ${S2}config.yml $R/t1 $R/t2 $R/stage2_plan $O/
M=$R/models
for pair in "ppo:m1_final" "best_model:m1_best"; do
  src=${pair%%:*}; dst=${pair##*:}
  .venv/bin/python -m training.candidate ${S2}$src.zip --like policies/pretrained/ppo_residual.yml \
    --name $dst --out $M
  .venv/bin/python -m training.candidate ${S2}$src.zip --like policies/pretrained/ppo_residual.yml \
    --name ${dst}_avg --out $M --mirror-average
done
.venv/bin/python benchmarks/checkpoint_selection.py --models "$M" \
  --names m1_final,m1_best,m1_final_avg,m1_best_avg --routes 12 --jobs 2 \
  --config training/configs/eval.yml --out $O/validation.json > $O/validation.log 2>&1
.venv/bin/cnt-evaluate --policies m1_final,m1_best,m1_final_avg,m1_best_avg \
  --models "$M" policies/pretrained --out $O/seeds_0-2 --jobs 2 > $O/seeds_0-2.log 2>&1
# Afterwards (as run): the +z drawn detours of ../mirror_stage1 (14 routes), the final
# model as trained and averaged, ungated (benchmarks/results/plus_z_detours_m1_*.jsonl).
for v in m1_final_avg m1_final; do
  .venv/bin/python benchmarks/detour_shorts.py --first 6000 --count 400 --heading=+z \
    --policies ungated --agent $M/$v.zip --jobs 2 --out benchmarks/results/plus_z_detours_$v.jsonl
done

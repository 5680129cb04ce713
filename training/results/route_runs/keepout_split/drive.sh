#!/bin/bash
# A split agent inside one hour (2026-12-06): route_runs/mirror_hour's first stage
# (model/mh_stage1, 2 406 s with start-up) plays routes without a keep-out; a copy of it
# trained for the rest of the hour on detours only
# (configs/ppo_residual_detour_only_finetune.yml, seed 0) plays routes with one
# (policies/ensemble.py KeepoutSplit, `a|b` in cnt-evaluate). Then the candidates over the
# shipped agent's base and gate (python -m training.candidate), the 12 validation routes,
# the +z drawn detours, and held out. Training is skipped when its run directory is there.
# R: the run directory. (Run before 2026-12-06's rename of training.two_stage's directory
# over a given first stage: the runs were made as two_stage_s0 and two_stage_s0_2, named
# then by the unused --seed; today they are stage2_s0 and stage2_s1.)
set -e
cd "$(dirname "$0")/../../../.."
O=training/results/route_runs/keepout_split
H=training/results/route_runs/mirror_hour
R=${R:-/tmp/runs/kosplit}
mkdir -p $R
if [ ! -d $R/runs/stage2_s0 ]; then
  .venv/bin/python -m training.two_stage --stage1-model $H/model/mh_stage1.zip \
    --stage1-spent 2406 --stage2 training/configs/ppo_residual_detour_only_finetune.yml \
    --stage2-seed 0 --out $R/runs > $R/train.log 2>&1
fi
S2=$R/runs/stage2_s0/stage2/
cp ${S2}learning_curve.csv ${S2}config.yml $R/runs/stage2_s0/timing.json $O/
M=$R/models
LIKE=policies/pretrained/ppo_residual.yml
.venv/bin/python -m training.candidate $H/model/mh_stage1.zip --like $LIKE --name s1 --out $M
for pair in "ppo:ks_final" "best_model:ks_best"; do
  src=${pair%%:*}; dst=${pair##*:}
  .venv/bin/python -m training.candidate ${S2}$src.zip --like $LIKE --name $dst --out $M
  .venv/bin/python -m training.candidate ${S2}$src.zip --like $LIKE --name ${dst}_z --out $M \
    --keepout-headings=-z,+z
done
.venv/bin/python benchmarks/checkpoint_selection.py --models "$M" \
  --names "s1|ks_final,s1|ks_best,s1|ks_final_z,s1|ks_best_z" --routes 12 --jobs 2 \
  --config training/configs/eval.yml --out $O/validation.json > $O/validation.log 2>&1
# Afterwards (as run): held out, seeds 0-2, the two splits with the symmetric gate (on the
# held-out routes, which have no keep-out route starting along z, the same as without it).
.venv/bin/cnt-evaluate --policies "random,scripted,ppo_residual,s1|ks_final_z,s1|ks_best_z" \
  --models "$M" policies/pretrained --reuse training/results --out $O/seeds_0-2 \
  --jobs 2 > $O/seeds_0-2.log 2>&1
# Afterwards (as run, looked at after the decision): the specialist on the drawn detours,
# ungated (on the surrogate it trained on, on the model, and the +z set).
.venv/bin/python benchmarks/detour_shorts.py --first 1000 --count 124 --policies ungated \
  --agent $M/ks_final.zip --config policies/pretrained/ppo_residual.yml --jobs 2 \
  --out benchmarks/results/detour_shorts_surrogate_ks_final.jsonl
.venv/bin/python benchmarks/detour_shorts.py --first 1000 --count 124 --policies ungated \
  --agent $M/ks_final.zip --jobs 2 --out benchmarks/results/detour_shorts_ks_final.jsonl
.venv/bin/python benchmarks/detour_shorts.py --first 6000 --count 400 --heading=+z \
  --policies ungated --agent $M/ks_final.zip --jobs 2 \
  --out benchmarks/results/plus_z_detours_ks_final.jsonl
# Then held out, seeds 3-8, the validation pick (only episodes.csv and results.md kept).
.venv/bin/cnt-evaluate --policies "s1|ks_final_z" --models "$M" policies/pretrained \
  --seeds 3,4,5,6,7,8 --out $O/seeds_3-8 --jobs 2 > $O/seeds_3-8.log 2>&1
# Then (as run) stage 2 again with seed 1, and its final model on the same drawn detours.
.venv/bin/python -m training.two_stage --stage1-model $H/model/mh_stage1.zip \
  --stage1-spent 2406 --stage2 training/configs/ppo_residual_detour_only_finetune.yml \
  --stage2-seed 1 --out $R/runs > $R/train_s1.log 2>&1
.venv/bin/python -m training.candidate $R/runs/stage2_s1/stage2/ppo.zip --like $LIKE \
  --name ks1_final --out $M
.venv/bin/python benchmarks/detour_shorts.py --first 1000 --count 124 --policies ungated \
  --agent $M/ks1_final.zip --jobs 2 --out benchmarks/results/detour_shorts_ks1_final.jsonl
.venv/bin/python benchmarks/detour_shorts.py --first 6000 --count 400 --heading=+z \
  --policies ungated --agent $M/ks1_final.zip --jobs 2 \
  --out benchmarks/results/plus_z_detours_ks1_final.jsonl

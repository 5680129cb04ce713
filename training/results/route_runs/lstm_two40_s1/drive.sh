#!/bin/bash
# A recurrent policy in the shipped agent's hour (2026-12-06, ninth session): the shipped
# recipe's two stages (40 min of ppo_residual_recipe_shipped.yml, seed 1, then its detour
# stage for the rest of the hour) with sb3-contrib's RecurrentPPO (an LSTM of 64 units
# under the same [64, 64] heads) in place of the MLP; nothing else differs. Then the
# candidates over the shipped agent's base and gate (python -m training.candidate), the
# 12 validation routes and held out. Training is skipped when its run directory is there.
# R: the run directory.
set -e
cd "$(dirname "$0")/../../../.."
O=training/results/route_runs/lstm_two40_s1
R=${R:-/tmp/runs/lstm}
mkdir -p $R
if [ ! -d $R/runs/two_stage_s1 ]; then
  .venv/bin/python -m training.two_stage --algo ppo_lstm \
    --stage1 training/configs/ppo_lstm_residual_recipe.yml \
    --stage2 training/configs/ppo_lstm_residual_detour_finetune.yml \
    --seed 1 --out $R/runs > $R/train.log 2>&1
fi
S2=$R/runs/two_stage_s1/stage2/
cp $R/runs/two_stage_s1/stage1/learning_curve.csv $O/stage1_learning_curve.csv
cp ${S2}learning_curve.csv $O/stage2_learning_curve.csv
cp ${S2}config.yml $R/runs/two_stage_s1/timing.json $O/
cp $R/runs/two_stage_s1/stage1/config.yml $O/stage1_config.yml
# The candidates over the shipped agent's base and gate, then the rule written before any
# evaluation (README.md): validation on 12 routes of the model picks one; it is shipped
# only if it leads the shipped agent there by >= 0.005 and shorts no more drawn detours.
M=$R/models
LIKE=policies/pretrained/ppo_residual.yml
for pair in "ppo_lstm:lstm_final" "best_model:lstm_best"; do
  src=${pair%%:*}; dst=${pair##*:}
  .venv/bin/python -m training.candidate ${S2}$src.zip --like $LIKE --name $dst --out $M
done
.venv/bin/python benchmarks/checkpoint_selection.py --models "$M" policies/pretrained \
  --names lstm_final,lstm_best,ppo_residual --routes 12 --jobs 2 \
  --config training/configs/eval.yml --out $O/validation.json > $O/validation.log 2>&1
# Held out, seeds 0-2, for the record whatever validation says.
.venv/bin/cnt-evaluate --policies "random,constant,scripted,ppo_residual,lstm_final,lstm_best" \
  --models "$M" policies/pretrained --reuse training/results --out $O/seeds_0-2 \
  --jobs 2 > $O/seeds_0-2.log 2>&1
# Afterwards (as run): the candidate of the final model on the two surrogates it trained on
# (the calibrated one of stage 2, the agent's own config; the plain one of stage 1), the
# shipped agent's and the follower's committed episodes reused.
.venv/bin/cnt-evaluate --config policies/pretrained/ppo_residual.yml \
  --policies scripted,ppo_residual,lstm_final --models "$M" policies/pretrained \
  --reuse training/results/surrogate_calibrated --out $O/surrogate_calibrated --jobs 2 \
  > $O/surrogate_calibrated.log 2>&1
.venv/bin/cnt-evaluate --config training/configs/ppo.yml \
  --policies scripted,ppo_residual,lstm_final --models "$M" policies/pretrained \
  --reuse training/results/surrogate --out $O/surrogate --jobs 2 > $O/surrogate.log 2>&1
# Kept: each evaluation's episodes.csv and results.md; model/ holds lstm_final, so its rows
# play again: cnt-evaluate --models training/results/route_runs/lstm_two40_s1/model ...
# Then (as run) a third physics neither network trained on: the model's law on a rod of
# delta_bar 0.33 (81 episodes in 302 s).
.venv/bin/cnt-evaluate --config training/configs/ppo_residual_linear033.yml \
  --policies scripted,ppo_residual,lstm_final --models $O/model policies/pretrained \
  --out $O/linear033 --jobs 2 > $O/linear033.log 2>&1

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

#!/bin/bash
# Both phases of the start (2026-12-06): the shipped agent + 20 min with half the episodes
# starting mirrored (start_mirror: random), then the selection rule (12 validation routes)
# over its final and best models, each as trained and mirror-averaged, then held out.
# Outside the goal's hour (the shipped agent's 3 458 s + 1 203 s). R: the run directory.
set -e
cd "$(dirname "$0")/../../../.."
O=training/results/route_runs/mirror
R=${R:-/tmp/runs/mirror_ft}
.venv/bin/cnt-train --algo ppo --config training/configs/ppo_residual_start_mirror_finetune.yml \
  --trained-agent policies/pretrained/ppo_residual.zip --seed 0 --vec-env subproc \
  --max-wall-seconds 1200 --out $R --no-progress
M=$(mktemp -d)
for pair in "ppo:mirror_ft" "best_model:mirror_ftbest"; do
  src=${pair%%:*}; dst=${pair##*:}
  for v in "$dst" "${dst}_avg"; do
    cp $R/ppo_s0/$src.zip $M/$v.zip
    cp $R/ppo_s0/${src}_vecnormalize.json $M/${v}_vecnormalize.json
    cp $R/ppo_s0/${src}_vecnormalize.npz $M/${v}_vecnormalize.npz
  done
  cp $R/ppo_s0/config.yml $M/$dst.yml
  .venv/bin/python -c "import sys, yaml; c = yaml.safe_load(open(sys.argv[1])); c['CNTDeposit-v0']['env_wrapper'][0]['training.common.ResidualAction']['mirror_average'] = True; open(sys.argv[2], 'w').write(yaml.safe_dump(c, sort_keys=False))" $R/ppo_s0/config.yml $M/${dst}_avg.yml
done
.venv/bin/python -c "import sys; from policies.sb3 import write_manifest; write_manifest(sys.argv[1])" "$M"
cp $R/ppo_s0/learning_curve.csv $O/ft_learning_curve.csv
cp $R/ppo_s0/config.yml $O/ft_config.yml
.venv/bin/python benchmarks/checkpoint_selection.py --models "$M" policies/pretrained \
  --names ppo_residual,mirror_ft,mirror_ftbest,mirror_ft_avg,mirror_ftbest_avg --routes 12 \
  --jobs 2 --config training/configs/eval.yml --out $O/validation_ft.json > $O/validation_ft.log 2>&1
.venv/bin/cnt-evaluate --policies random,scripted,ppo_residual,mirror_ft,mirror_ft_avg \
  --models "$M" policies/pretrained --reuse training/results --out $O/ft_seeds_0-2 \
  --jobs 2 > $O/ft_seeds_0-2.log 2>&1
.venv/bin/cnt-evaluate --policies mirror_ft_avg --models "$M" policies/pretrained \
  --seeds 3,4,5,6,7,8 --out $O/ft_seeds_3-8 --jobs 2 > $O/ft_seeds_3-8.log 2>&1

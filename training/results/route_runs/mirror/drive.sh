#!/bin/bash
# mirror_average probe (2026-12-06): the shipped agent with its action averaged with its
# action for the observation's mirror image in z. No training. Validation (12 routes of
# the model, the selection rule), then held out on seeds 0-2.
set -e
cd "$(dirname "$0")/../../../.."
O=training/results/route_runs/mirror
M=$(mktemp -d)
# the shipped agent under another name, its config with mirror_average: true
for f in ppo_residual.zip ppo_residual_vecnormalize.json ppo_residual_vecnormalize.npz; do
  cp policies/pretrained/$f "$M/${f/ppo_residual/ppo_residual_mirror}"
done
sed 's/^      keepout_headings: \[-z\]$/&\n      mirror_average: true/' policies/pretrained/ppo_residual.yml \
  > "$M/ppo_residual_mirror.yml"
grep -q 'mirror_average: true' "$M/ppo_residual_mirror.yml"
.venv/bin/python -c "import sys; from policies.sb3 import write_manifest; write_manifest(sys.argv[1])" "$M"
.venv/bin/python benchmarks/checkpoint_selection.py --models "$M" policies/pretrained \
  --names ppo_residual,ppo_residual_mirror --routes 12 --jobs 2 \
  --config training/configs/eval.yml --out $O/validation.json > $O/validation.log 2>&1
.venv/bin/cnt-evaluate --policies random,scripted,ppo_residual,ppo_residual_mirror \
  --models "$M" policies/pretrained --reuse training/results --out $O/seeds_0-2 \
  --jobs 2 > $O/seeds_0-2.log 2>&1

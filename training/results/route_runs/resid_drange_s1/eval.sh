#!/bin/bash
# The evaluation of resid_drange_s1 as run (2026-12-02, after drive.sh, alone on the 2
# cores): the run's two models renamed into $R/models, then the selection rule's 24
# validation routes, the held-out routes (seeds 0-2) and the difficulty-1.0 routes, the
# follower and the shipped agent measured again on this machine beside them.
set -e
cd /work/main
R=${R:-/work/runs/drange}
while [ ! -f $R/t2 ]; do sleep 30; done
S2=$(ls -d $R/s2/*/ | head -1)
M=$R/models; mkdir -p $M
for pair in "ppo:dr_final" "best_model:dr_best"; do
  src=${pair%%:*}; dst=${pair##*:}
  for f in $S2/${src}.zip $S2/${src}.yml $S2/${src}_vecnormalize.*; do
    [ -f "$f" ] && cp "$f" "$M/$(basename "$f" | sed "s/^${src}/${dst}/")"
  done
done
.venv/bin/python -c "from policies.sb3 import write_manifest; write_manifest('$M')"
ls -l $M
for d in 0.5 1.0; do
  .venv/bin/python benchmarks/checkpoint_selection.py --models $M policies/pretrained \
    --names dr_final,dr_best,ppo_residual --routes 12 --jobs 2 \
    --config training/configs/eval.yml --difficulty $d --out $R/selection_d$d.json
done
# As first written, the held-out step below named only $M in --models and stopped
# (ppo_residual is in policies/pretrained); it was run by hand as below. The
# difficulty-1.0 evaluation this script then ran was dropped: the selection's 12 routes
# at difficulty 1.0 had already put both models below the follower (README.md).
.venv/bin/cnt-evaluate --policies random,constant,scripted,ppo_residual,dr_final \
  --models $M policies/pretrained --reuse training/results --redo scripted,ppo_residual \
  --out $R/heldout --jobs 2
date -u +%s > $R/t3

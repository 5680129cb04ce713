#!/bin/bash
# The ensemble probe through the project's tools: validation (12 routes of the model), then held out.
set -e
cd /work/main
O=training/results/route_runs/ensemble
M="policies/pretrained training/results/route_runs/resid_shipft_s0/model training/results/route_runs/resid_2core_s1/model"
T0=$(date +%s)
.venv/bin/python benchmarks/checkpoint_selection.py --models $M --names ppo_residual,ppo_residual+ft_final,ppo_residual+ppo_residual_r5+ft_final --routes 12 --jobs 2 --config training/configs/eval.yml --out $O/validation.json > $O/validation.log 2>&1
T1=$(date +%s); echo "validation $((T1-T0)) s" >> $O/walls.txt
.venv/bin/cnt-evaluate --policies random,scripted,ppo_residual,ppo_residual+ft_final --models $M --reuse training/results --out $O/seeds_0-2 --jobs 2 > $O/seeds_0-2.log 2>&1
T2=$(date +%s); echo "seeds 0-2 $((T2-T1)) s" >> $O/walls.txt
.venv/bin/cnt-evaluate --policies random,scripted,ppo_residual,ppo_residual+ft_final --models $M --reuse training/results/seeds_3-5 --seeds 3,4,5 --out $O/seeds_3-5 --jobs 2 > $O/seeds_3-5.log 2>&1
T3=$(date +%s); echo "seeds 3-5 $((T3-T2)) s" >> $O/walls.txt
.venv/bin/cnt-evaluate --policies random,scripted,ppo_residual,ppo_residual+ft_final --models $M --reuse training/results/seeds_6-8 --seeds 6,7,8 --out $O/seeds_6-8 --jobs 2 > $O/seeds_6-8.log 2>&1
T4=$(date +%s); echo "seeds 6-8 $((T4-T3)) s" >> $O/walls.txt
echo done >> $O/walls.txt

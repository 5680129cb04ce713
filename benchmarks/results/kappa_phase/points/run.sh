#!/bin/sh
# The κ̄_c phase probe's single points (benchmarks/RESULTS.md, issue 12, "The model's
# phase diagram past κ̄_c 0.1-0.2"): the irregular boundary, a second seed and half the
# step at the irregular point, half the step at a serpentine-coil. Two at a time.
set -e
cd "$(dirname "$0")/../../../.."
D=benchmarks/results/kappa_phase/points
S=".venv/bin/cnt-sim run --preset serpentine --deposit 3000 --transient 150 --json"
$S --kappa-c 0.4 --vbar 0.07 --out $D/k0.4_v0.07.npz > $D/k0.4_v0.07.json &
$S --kappa-c 0.4 --vbar 0.12 --seed 1 --out $D/k0.4_v0.12_seed1.npz > $D/k0.4_v0.12_seed1.json &
wait
$S --kappa-c 0.4 --vbar 0.12 --dt 3.875 --out $D/k0.4_v0.12_dt_half.npz > $D/k0.4_v0.12_dt_half.json &
$S --kappa-c 0.05 --vbar 0.037 --dt 3.875 --out $D/k0.05_v0.037_dt_half.npz > $D/k0.05_v0.037_dt_half.json &
wait
# then: where the loops stop below κ̄_c 0.1, and the irregular boundary at κ̄_c 0.3
$S --kappa-c 0.075 --vbar 0.019 --out $D/k0.075_v0.019.npz > $D/k0.075_v0.019.json &
$S --kappa-c 0.3 --vbar 0.07 --out $D/k0.3_v0.07.npz > $D/k0.3_v0.07.json &
wait

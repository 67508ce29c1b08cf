#!/bin/bash
# SPDX-License-Identifier: Apache-2.0
# The loop in the open world, on ball-bar data: Kim's plane errors, backlash
# of 4 µm on axis 2 (a library effect) and a lead-screw pitch error on axis 1
# growing along its stroke to 8 µm (no library effect describes it). Ball-bar
# lengths at 192 poses; calibrate; `cpm loop` without --allow (it names the
# backlash, stops at the pitch error and prints it as a pitch_table ready to
# paste), then with --allow pitch_table (it adds it, recalibrates the planes
# beside it and goes on); the circular test of each model on the true machine.
#
#   bash identification/demo/open_world_loop.sh [OUT_DIR]
set -euo pipefail
CPM=${CPM:-build/bin/cpm}
OUT=${1:-/tmp/cpm-demo-open-world}
mkdir -p "$OUT"

echo "== 1. the true machine: Kim's errors, backlash on axis 2, a pitch error on axis 1"
"$CPM" kim-experiment --kinematic --truth-out "$OUT/kim_truth.yaml" > /dev/null
awk '$1 == "limb2:" { inlimb = 1 }
  inlimb && $1 == "effects:" { sub(/effects: \{\}/, "effects: {backlash: {b: 4.0e-6}}"); inlimb = 0 }
  { print }' "$OUT/kim_truth.yaml" > "$OUT/truth.yaml"
cat >> "$OUT/truth.yaml" <<'YAML'
user_effects:
  - kind: pitch_table
    axis: 1
    nodes: [0.05, 0.10, 0.15, 0.20, 0.25, 0.30, 0.35]
    values: [0, 2.2e-07, 8.9e-07, 2.0e-06, 3.56e-06, 5.56e-06, 8.0e-06]
YAML
"$CPM" model check "$OUT/truth.yaml"

echo "== 2. ball-bar lengths at 192 poses, calibrate"
"$CPM" plan-poses --kind ballbar --layout optimal --count 192 --out "$OUT/poses.csv"
"$CPM" simulate-measurement --truth "$OUT/truth.yaml" --poses "$OUT/poses.csv" \
  --pivot-error=-0.000018,0.000017,-0.00103 --seed 3 --dwell 20 --order shuffled --out "$OUT/ballbar.csv"
"$CPM" calibrate --data "$OUT/ballbar.csv" --out "$OUT/calibrated.yaml" | tail -n 1

echo "== 3. the loop, library effects only"
"$CPM" loop --model "$OUT/calibrated.yaml" --data "$OUT/ballbar.csv" --out "$OUT/library.yaml"

echo "== 4. the loop, allowed to add a pitch_table"
"$CPM" loop --model "$OUT/calibrated.yaml" --data "$OUT/ballbar.csv" --allow pitch_table \
  --out "$OUT/better.yaml" --json "$OUT/loop.json" --report "$OUT/loop.html"

echo "== 5. the circular test of each model on the true machine"
for m in calibrated library better; do
  echo "-- $m.yaml"
  "$CPM" circular-test --kinematic --truth "$OUT/truth.yaml" --model "$OUT/$m.yaml" | grep 'circular deviation'
done

#!/bin/bash
# SPDX-License-Identifier: Apache-2.0
# The identification loop in one command: a true machine with planted dynamic
# effects; the nominal controller tracks a circle; the motion log goes
# through `cpm loop` (diagnose, add what is missing, refit, diagnose again
# until nothing is, printing the waterfall); the controller with the model it
# leaves tracks the same circle; the tracking RMSE before and after is printed.
#
#   bash identification/demo/dynamic_loop.sh [OUT_DIR]
#   EFFECTS="cogging:1:1.5,0.012,0.3" bash identification/demo/dynamic_loop.sh
#
# Environment: CPM (the cpm binary, default build/bin/cpm), EFFECTS (planted,
# space separated, NAME:AXIS:VALUES as for `cpm sim --truth-effect`; default
# Coulomb friction of 2 N on axis 2 and viscous friction of 3 N s/m on axis 1).
set -euo pipefail
CPM=${CPM:-build/bin/cpm}
OUT=${1:-/tmp/cpm-demo-dynamic}
EFFECTS=${EFFECTS:-${EFFECT:-coulomb_friction:2:2.0 viscous_friction:1:3.0}}
mkdir -p "$OUT"
COMMON=(--trajectory circle --time 8 --ramp 0.5 --encoder-noise 1e-6 --velocity-noise 2e-4 --seed 7)
TRUTH=()
for e in $EFFECTS; do TRUTH+=(--truth-effect "$e"); done

echo "== 1. the nominal controller on a machine with $EFFECTS"
"$CPM" sim "${COMMON[@]}" "${TRUTH[@]}" --log "$OUT/run_nominal.csv" --json "$OUT/sim_nominal.json"

echo "== 2. the loop: diagnose, add, refit, diagnose again"
"$CPM" loop --data "$OUT/run_nominal.csv" --out "$OUT/fitted.yaml" --json "$OUT/loop.json" --report "$OUT/loop.html"

echo "== 3. the controller with the model the loop left, same circle, same machine"
"$CPM" sim "${COMMON[@]}" "${TRUTH[@]}" --model "$OUT/fitted.yaml" --log "$OUT/run_fitted.csv" \
  --json "$OUT/sim_fitted.json"

# The JSON read by a JSON parser (Python's), not by its layout.
rmse() { python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["position_rmse"])' "$1"; }
before=$(rmse "$OUT/sim_nominal.json")
after=$(rmse "$OUT/sim_fitted.json")
awk -v b="$before" -v a="$after" 'BEGIN { printf "\ntracking RMSE: %.4f mm with the nominal model, %.4f mm with the fitted one (%.0f %% less)\n", b*1e3, a*1e3, 100*(1-a/b) }'
echo "waterfall: $OUT/loop.html   new model: $OUT/fitted.yaml"

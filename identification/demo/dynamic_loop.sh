#!/bin/bash
# Issue 4, point 6(a), in one command: a true machine with a planted dynamic
# effect; the nominal controller tracks a circle; the motion log goes through
# `cpm diagnose` and `cpm fit`; the controller with the fitted model tracks the
# same circle; the tracking RMSE before and after is printed.
#
#   bash identification/demo/dynamic_loop.sh [OUT_DIR]
#   EFFECT=cogging:1:1.5,0.012,0.3 bash identification/demo/dynamic_loop.sh
#
# Environment: CPM (the cpm binary, default build/bin/cpm), EFFECT (planted,
# NAME:AXIS:VALUES as for `cpm sim --truth-effect`, default Coulomb friction
# of 2 N on axis 2).
set -euo pipefail
CPM=${CPM:-build/bin/cpm}
OUT=${1:-/tmp/cpm-demo-dynamic}
EFFECT=${EFFECT:-coulomb_friction:2:2.0}
mkdir -p "$OUT"
COMMON=(--trajectory circle --time 8 --ramp 0.5 --encoder-noise 1e-6 --velocity-noise 2e-4 --seed 7)

echo "== 1. the nominal controller on a machine with $EFFECT"
"$CPM" sim "${COMMON[@]}" --truth-effect "$EFFECT" --log "$OUT/run_nominal.csv" --json "$OUT/sim_nominal.json"

echo "== 2. diagnose the log"
"$CPM" diagnose --data "$OUT/run_nominal.csv" --json "$OUT/diagnose.json" --report "$OUT/diagnose.html" |
  sed -n '/^VERDICT/,$p'
missing=$(sed -n 's/.*"verdict": {"missing": "\([a-z_]*\)", "axis": \([0-9null]*\).*/\1 \2/p' "$OUT/diagnose.json")
name=${missing% *}
axis=${missing#* }
if [ -z "$name" ]; then echo "diagnose found nothing missing: nothing to fit"; exit 1; fi
spec=$name
[ "$axis" != null ] && spec="$name:$axis"

echo "== 3. fit $spec"
"$CPM" fit --data "$OUT/run_nominal.csv" --add "$spec" --out "$OUT/fitted.yaml" --json "$OUT/fit.json"

echo "== 4. the controller with the fitted model, same circle, same machine"
"$CPM" sim "${COMMON[@]}" --truth-effect "$EFFECT" --model "$OUT/fitted.yaml" --log "$OUT/run_fitted.csv" \
  --json "$OUT/sim_fitted.json"

rmse() { sed -n 's/.*"position_rmse": \([0-9.eE+-]*\).*/\1/p' "$1"; }
before=$(rmse "$OUT/sim_nominal.json")
after=$(rmse "$OUT/sim_fitted.json")
awk -v b="$before" -v a="$after" 'BEGIN { printf "\ntracking RMSE: %.4f mm with the nominal model, %.4f mm with the fitted one (%.0f %% less)\n", b*1e3, a*1e3, 100*(1-a/b) }'
echo "report: $OUT/diagnose.html   new model: $OUT/fitted.yaml"

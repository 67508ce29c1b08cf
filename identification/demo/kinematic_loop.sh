#!/bin/bash
# SPDX-License-Identifier: Apache-2.0
# Issue 4, point 6(b), in one command: ball-bar data from a true machine that
# carries Kim's plane errors (and his pivot error) plus a planted kinematic
# effect; calibrate; diagnose; fit the effect named; the circular test's G
# (ISO 230-4, simulated ball-bar, 150 mm in XY) before and after is printed.
#
#   bash identification/demo/kinematic_loop.sh [OUT_DIR]
#   LIMB=1 EFFECT='backlash: {b: 4.0e-6}' bash identification/demo/kinematic_loop.sh
#
# Environment: CPM (the cpm binary, default build/bin/cpm); LIMB (1..3) and
# EFFECT (the planted effect as in a model file's `effects:` mapping, default
# a 4 µm cyclic error of 16 mm wavelength on limb 2). The ball-bar poses are
# 192 points on two hemispheres (100 and 150 mm) about Kim's pivot: denser
# than Kim's 32, because a periodic error needs several samples per period.
# They are visited in a shuffled order, 20 s apart, and the file carries the
# t and dir columns, so backlash and thermal drift can be planted too:
#   LIMB=1 EFFECT='backlash: {b: 4.0e-6}' ...
#   LIMB=3 EFFECT='thermal_drift: {e: 2.0e-5, tau: 1200}' ...
set -euo pipefail
CPM=${CPM:-build/bin/cpm}
OUT=${1:-/tmp/cpm-demo-kinematic}
LIMB=${LIMB:-2}
EFFECT=${EFFECT:-'cyclic_error: {a: 4.0e-6, lambda: 0.016, phi: 0.3}'}
mkdir -p "$OUT"

echo "== 1. the true machine: Kim's plane errors + limb $LIMB: $EFFECT"
"$CPM" kim-experiment --kinematic --truth-out "$OUT/kim_truth.yaml" > /dev/null
awk -v limb="limb$LIMB:" -v eff="$EFFECT" '
  $1 == limb { inlimb = 1 }
  inlimb && $1 == "effects:" { sub(/effects: \{\}/, "effects: {" eff "}"); inlimb = 0 }
  { print }' "$OUT/kim_truth.yaml" > "$OUT/truth.yaml"
"$CPM" model check "$OUT/truth.yaml"

echo "== 2. ball-bar lengths (QC10: +-0.5 µm) at 192 poses about the pivot, commanded through the nominal model"
awk 'BEGIN {
  pi = atan2(0, -1); print "# kind = poses"; print "px,py,pz"
  split("0.100 0.150", R, " ")
  for (ri = 1; ri <= 2; ++ri) for (k = 0; k < 6; ++k) {
    th = (15 + 65 * k / 5) * pi / 180
    for (a = 0; a < 16; ++a) {
      ph = 2 * pi * (a + 0.5 * (k % 2) + 0.25 * (ri - 1)) / 16
      printf "%.9f,%.9f,%.9f\n", 0.430 + R[ri] * sin(th) * cos(ph), 0.430 + R[ri] * sin(th) * sin(ph), 0.530 - R[ri] * cos(th)
    }
  } }' > "$OUT/poses.csv"
"$CPM" simulate-measurement --truth "$OUT/truth.yaml" --poses "$OUT/poses.csv" \
  --pivot-error=-0.000018,0.000017,-0.00103 --seed 3 --dwell 20 --order shuffled --out "$OUT/ballbar.csv"

echo "== 3. calibrate (Kim's ball-bar method)"
"$CPM" calibrate --data "$OUT/ballbar.csv" --out "$OUT/calibrated.yaml" --json "$OUT/calibrate.json" | tail -n 3
"$CPM" circular-test --kinematic --truth "$OUT/truth.yaml" --model "$OUT/calibrated.yaml" \
  --svg "$OUT/circle_calibrated.svg" --json "$OUT/circle_calibrated.json" > /dev/null

echo "== 4. diagnose the calibrated model on the same data"
"$CPM" diagnose --model "$OUT/calibrated.yaml" --data "$OUT/ballbar.csv" --json "$OUT/diagnose.json" \
  --report "$OUT/diagnose.html" | sed -n '/^VERDICT/,/^$/p'
# The JSON read by a JSON parser (Python's), not by its layout.
json_get() { python3 -c 'import json, sys; v = json.load(open(sys.argv[1]))
for k in sys.argv[2:]: v = v[k]
print("null" if v is None else v)' "$@"; }
missing="$(json_get "$OUT/diagnose.json" verdict missing) $(json_get "$OUT/diagnose.json" verdict axis)"
name=${missing% *}
axis=${missing#* }
if [ "$name" = null ]; then echo "diagnose found nothing missing: nothing to fit"; exit 1; fi

echo "== 5. fit $name:$axis (the planes are recalibrated with it)"
"$CPM" fit --model "$OUT/calibrated.yaml" --data "$OUT/ballbar.csv" --add "$name:$axis" \
  --out "$OUT/fitted.yaml" --json "$OUT/fit.json"
"$CPM" circular-test --kinematic --truth "$OUT/truth.yaml" --model "$OUT/fitted.yaml" \
  --svg "$OUT/circle_fitted.svg" --json "$OUT/circle_fitted.json" > /dev/null

before=$(json_get "$OUT/circle_calibrated.json" G)
after=$(json_get "$OUT/circle_fitted.json" G)
awk -v b="$before" -v a="$after" 'BEGIN { printf "\ncircular test G (150 mm, XY, both directions): %.2f µm calibrated, %.2f µm with the fitted effect (%.0f %% less)\n", b*1e6, a*1e6, 100*(1-a/b) }'
echo "reports: $OUT/diagnose.html, $OUT/circle_calibrated.svg, $OUT/circle_fitted.svg   new model: $OUT/fitted.yaml"

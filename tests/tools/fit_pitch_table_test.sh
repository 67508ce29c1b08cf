#!/bin/bash
# SPDX-License-Identifier: Apache-2.0
# cpm fit --add pitch_table:AXIS on kinematic data, end to end through the
# command line: Kim's true machine with a lead-screw pitch error planted by
# `cpm simulate-measurement --truth-effect pitch_table:...` (a curve growing
# along the stroke), ball-bar lengths (192 poses, 0.289 µm) on axis 1 and
# positions (120 poses, 2 µm) on axis 2; calibrate, fit the table, then:
#   - the fitted values follow the planted curve (both less their straight
#     line, which the calibration holds): RMS off it < 10 % of its curved part;
#   - the residual falls to the bar's / instrument's noise (<= 1.1 sigma) from
#     above 1.3 sigma, and `cpm diagnose` of the new model finds nothing outside
#     the library (the planted curve was outside_library on the calibrated model).
#   fit_pitch_table_test.sh CPM
set -euo pipefail
CPM=$1
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
cd "$OUT"
NODES=0,0.075,0.15,0.225,0.30,0.375,0.45  # m: over the whole stroke (a pitch error does not stop growing)
BAR=0,5.556e-07,2.222e-06,5e-06,8.889e-06,1.389e-05,2e-05   # m: 20 µm (d/450 mm)^2
POS=0,4.167e-06,1.667e-05,3.75e-05,6.667e-05,0.0001042,0.00015   # m: 150 µm (d/450 mm)^2

"$CPM" kim-experiment --kinematic --truth-out truth.yaml > /dev/null
run() {  # KIND AXIS VALUES SIGMA POSES
  "$CPM" plan-poses --kind "$1" --layout optimal --count "$5" --out "$1.poses.csv" > /dev/null
  local noise=()
  [ "$1" = position ] && noise=(--noise "$4")
  "$CPM" simulate-measurement --kind "$1" "${noise[@]}" --truth truth.yaml --poses "$1.poses.csv" \
    --truth-effect "pitch_table:$2:$NODES:$3" --pivot-error=-0.000018,0.000017,-0.00103 --seed 3 --dwell 20 \
    --order shuffled --out "$1.csv" > /dev/null
  "$CPM" calibrate --data "$1.csv" --out "$1.cal.yaml" > /dev/null
  "$CPM" diagnose --model "$1.cal.yaml" --data "$1.csv" --json "$1.before.json" > /dev/null
  "$CPM" fit --model "$1.cal.yaml" --data "$1.csv" --add "pitch_table:$2" --out "$1.fit.yaml" --json "$1.fit.json"
  "$CPM" model check "$1.fit.yaml" | grep -q '1 user effect' || { echo "FAIL: $1.fit.yaml holds no pitch_table"; exit 1; }
  "$CPM" diagnose --model "$1.fit.yaml" --data "$1.csv" --json "$1.after.json" > /dev/null
  python3 - "$1" "$2" "$NODES" "$3" "$4" <<'PY'
import json, sys
kind, axis, sigma = sys.argv[1], int(sys.argv[2]), float(sys.argv[5])
pn = [float(a) for a in sys.argv[3].split(',')]
pv = [float(a) for a in sys.argv[4].split(',')]
fit = json.load(open(f"{kind}.fit.json"))
before, after = (json.load(open(f"{kind}.{w}.json")) for w in ("before", "after"))
t = fit["user_effect"]
assert t["kind"] == "pitch_table" and t["axis"] == axis, t
x, v = t["nodes"], t["values"]
def planted(d):  # the truth's table: linear between nodes, held beyond the ends
    if d <= pn[0]: return pv[0]
    for k in range(1, len(pn)):
        if d <= pn[k]: return pv[k - 1] + (pv[k] - pv[k - 1]) * (d - pn[k - 1]) / (pn[k] - pn[k - 1])
    return pv[-1]
def curved(y):  # less its least-squares line over the nodes
    n = len(x); mx, my = sum(x) / n, sum(y) / n
    b = sum((a - mx) * (c - my) for a, c in zip(x, y)) / sum((a - mx) ** 2 for a in x)
    return [c - my - b * (a - mx) for a, c in zip(x, y)]
e, f = curved([planted(d) for d in x]), curved(v)
off = (sum((a - b) ** 2 for a, b in zip(f, e)) / len(e)) ** 0.5
ptp = max(e) - min(e)
r0, r1 = fit["base_only"]["rms"], fit["after"]["rms"]
print(f"{kind}, pitch_table on axis {axis}: {len(x)} nodes, RMS off the planted curve {off*1e6:.3f} µm of "
      f"{ptp*1e6:.3f} µm peak to peak; residual {r0*1e6:.3f} -> {r1*1e6:.3f} µm (sigma {sigma*1e6:.3f}); "
      f"before: {before['verdict'].get('missing')}, after: {after['verdict'].get('missing')}")
assert off < 0.10 * ptp, off
assert r0 > 1.3 * sigma and r1 <= 1.1 * sigma, (r0, r1)
assert before["verdict"].get("missing") == "outside_library", before["verdict"]
assert not after["verdict"].get("outside_library"), after["verdict"]
PY
}
run ballbar 1 "$BAR" 2.887e-7 192
run position 2 "$POS" 2e-6 120
echo "PASS"

#!/bin/bash
# SPDX-License-Identifier: Apache-2.0
# cpm loop in the open world, end to end through the command line
# (identification/demo/open_world_loop.sh: ball-bar data with backlash on axis 2
# and a pitch error on axis 1 planted in truth.yaml's user_effects):
#   - without --allow the loop stops at the pitch error above 1.2x the floor and
#     prints it as a pitch_table ready to paste, with the --allow command;
#   - with --allow pitch_table it adds backlash then the pitch_table and ends
#     within 20 % of the floor; the model it writes passes `cpm model check`
#     and holds the table; its circular test beats the library-only model's.
#   open_world_loop_test.sh CPM SOURCE_DIR
set -euo pipefail
CPM=$1
SRC=$2
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
cd "$SRC"
CPM="$CPM" bash identification/demo/open_world_loop.sh "$OUT" > "$OUT/demo.txt" 2>&1 || { cat "$OUT/demo.txt"; exit 1; }
fail() { echo "FAIL: $*"; cat "$OUT/demo.txt"; exit 1; }

"$CPM" loop --model "$OUT/calibrated.yaml" --data "$OUT/ballbar.csv" --out "$OUT/lib2.yaml" \
  --json "$OUT/lib.json" > "$OUT/lib.txt"
grep -q '^  - kind: pitch_table' "$OUT/lib.txt" || fail "no pitch_table YAML printed without --allow"
grep -q -- '--allow pitch_table' "$OUT/lib.txt" || fail "no --allow command printed"

python3 - "$OUT/lib.json" "$OUT/loop.json" <<'PY' || fail "waterfall figures"
import json, sys
lib, full = (json.load(open(p)) for p in sys.argv[1:3])
last = lambda j: j["waterfall"][-1]
r_lib = last(lib)["rms"] / last(lib)["noise_floor"]
r_full = last(full)["rms"] / last(full)["noise_floor"]
added = [w["added"] for w in full["waterfall"]]
print(f"without --allow: {r_lib:.3f} x the floor; with: {r_full:.3f} x; steps {added}")
assert lib["outside_library"] and lib["suggested_user_effect"]["kind"] == "pitch_table", lib["stop"]
assert lib["suggested_user_effect"]["axis"] == 1
assert r_lib > 1.2, r_lib
assert "backlash[axis 2]" in added and added[-1] == "pitch_table[axis 1]", added
assert r_full <= 1.2, r_full
assert not full["outside_library"]
PY
"$CPM" model check "$OUT/better.yaml" | grep -q '1 user effect' || fail "better.yaml: no user effect read back"
g() { grep 'circular deviation' "$OUT/demo.txt" | sed -n "$1p" | sed 's/.*both \([0-9.]*\) µm.*/\1/'; }
awk -v l="$(g 2)" -v b="$(g 3)" 'BEGIN { printf "circular test G: %s µm library only, %s µm with the pitch table\n", l, b; exit !(b < 0.5 * l) }' \
  || fail "the pitch table does not improve the circular test"
echo "PASS"

#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# A compensation file written by `cpm export-comp` read by LinuxCNC itself:
# its loader (usrmotLoadComp) and motion module (the screw compensation of
# joint 0) in the bench's linear-delta config, not real-time
# (bench/linuxcnc/comp/comp-check.sh). At each pose the trim LinuxCNC adds
# to joint 0 (joint.0.backlash-corr) must be -e(d) of the model's
# pitch_table at that joint position, in mm, for COMP_FILE_TYPE 0 and 1.
#
#   tests/tools/linuxcnc_comp_test.sh CPM SOURCE_DIR
# Exit 77 (skipped) without linuxcnc-uspace.
set -euo pipefail
cpm=$1 src=$2
command -v linuxcnc >/dev/null || { echo "linuxcnc-uspace is not installed: skipped"; exit 77; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# A pitch error growing along joint 0's travel, 0 to 31 um over 400 mm.
nodes="0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4"
errors="0, 2e-06, 5e-06, 7.5e-06, 1.1e-05, 1.4e-05, 1.9e-05, 2.4e-05, 3.1e-05"
{ cat "$src/config/machine.yaml"
  printf '\nuser_effects:\n  - kind: pitch_table\n    axis: 1\n    nodes: [%s]\n    values: [%s]\n' "$nodes" "$errors"
} >"$work/model.yaml"
"$cpm" model check "$work/model.yaml" >/dev/null
fails=0
for type in 0 1; do
  "$cpm" export-comp --model "$work/model.yaml" --axis 1 --type "$type" "$work/j0_$type.comp" >/dev/null
  timeout 180 bash "$src/bench/linuxcnc/comp/comp-check.sh" "$work/j0_$type.comp" "$type" >"$work/lc_$type.log" 2>&1 || {
    cat "$work/lc_$type.log"; echo "FAIL: LinuxCNC did not run (type $type)"; exit 1; }
  grep -q "^COMP " "$work/lc_$type.log" || { cat "$work/lc_$type.log"; echo "FAIL: no pose reached"; exit 1; }
  python3 - "$work/lc_$type.log" "$nodes" "$errors" "$type" <<'PY' || fails=$((fails + 1))
import sys
log, nodes, errors, ftype = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4]
x = [float(v) * 1e3 for v in nodes.split(",")]          # mm
e = [float(v) * 1e3 for v in errors.split(",")]         # mm
def err(d):
    if d <= x[0]: return e[0]
    if d >= x[-1]: return e[-1]
    k = next(i for i in range(1, len(x)) if x[i] >= d)
    return e[k - 1] + (d - x[k - 1]) / (x[k] - x[k - 1]) * (e[k] - e[k - 1])
worst, n, seen = 0.0, 0, set()
for line in open(log):
    if not line.startswith("COMP "): continue
    _, pos, trim, _motor = line.split()
    pos, trim = float(pos), float(trim)
    seen.add(round(pos, 6))
    worst = max(worst, abs(trim - (-err(pos))))
    n += 1
print(f"COMP_FILE_TYPE {ftype}: {n} poses ({len(seen)} distinct joint-0 positions), "
      f"LinuxCNC's trim against -e(d): worst difference {worst * 1e6:.4f} nm")
sys.exit(0 if n > 0 and len(seen) >= 2 and worst < 1e-6 else 1)
PY
done
[ $fails -eq 0 ] && echo "ok: LinuxCNC applies cpm's compensation files as the pitch_table says" || { echo "FAIL"; exit 1; }

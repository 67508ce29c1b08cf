#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# compare, diagnose, fit and calibrate (and plan-poses, simulate-measurement)
# without --model, from a folder outside the source tree: each takes the
# default model, here the build tree's config/machine.yaml (build/bin/cpm ->
# config/machine.yaml; the installed /etc/cpmd/machine.yaml is tested with the
# package). A cpm outside any tree, with no model anywhere, says where it looked.
#   default_model_test.sh CPM SOURCE_DIR
set -u
cpm=$(realpath "$1")
model=$(realpath "$2/config/machine.yaml")
failures=0
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cd "$tmp" || exit 1
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }
run() {  # run WANT-IN-OUTPUT ARGS...
  local want=$1
  shift
  local out rc
  out=$("$cpm" "$@" 2>&1) rc=$?
  if [ $rc -eq 0 ] && [[ $out == *"$want"* ]]; then echo "ok   cpm $* (in $tmp)"
  else fail "cpm $*: exit $rc, '$want' not in: $out"; fi
}
run "$model" plan-poses --out poses.csv
run "$model" simulate-measurement --poses poses.csv --out ballbar.csv
run "$model" compare --data ballbar.csv
run "" diagnose --data ballbar.csv --json diagnose.json --quiet
names() { sed 's/": "/":"/g' "$1"; }  # the JSON with or without a space after the colon
names diagnose.json | grep -qF "\"model_file\":\"$model\"" && echo "ok   diagnose used $model" ||
  fail "diagnose.json does not name $model: $(grep -o '"model_file[^,]*' diagnose.json)"
run "" fit --data ballbar.csv --add cyclic_error:1 --out fitted.yaml --json fit.json
names fit.json | grep -qF "\"model\":\"$model\"" && echo "ok   fit used $model" || fail "fit.json does not name $model"
run "wrote calibrated.yaml" calibrate --data ballbar.csv --out calibrated.yaml --quiet
grep -qF "$model" calibrated.yaml && echo "ok   calibrate used $model" || fail "calibrated.yaml's history does not name $model"

# A cpm with no tree around it, in a folder without config/: the installed
# model when there is one, else an error that says where it looked.
cp "$cpm" "$tmp/cpm-alone"
mkdir empty && cd empty || exit 1
out=$("$tmp/cpm-alone" diagnose --data ../ballbar.csv --json d.json --quiet 2>&1) rc=$?
if [ -e /etc/cpmd/machine.yaml ]; then
  [ $rc -eq 0 ] && names d.json | grep -qF '"model_file":"/etc/cpmd/machine.yaml"' && echo "ok   alone: /etc/cpmd/machine.yaml" ||
    fail "alone, with /etc/cpmd/machine.yaml: exit $rc, $out"
elif [ $rc -eq 1 ] && [[ $out == *"no default model found"*"/etc/cpmd/machine.yaml"*"--model"* ]]; then
  echo "ok   alone: $out"
else
  fail "alone, no model anywhere: exit $rc, '$out'"
fi
[ $failures -eq 0 ] && echo "default model: all passed" && exit 0
echo "default model: $failures failed"
exit 1

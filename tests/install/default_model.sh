# SPDX-License-Identifier: Apache-2.0
# Sourced by staged.sh and package.sh: `cpm compare`, `diagnose`, `fit` and
# `calibrate` without --model, in the current folder (outside the tree), must
# use the installed default model MODEL; each names the model it read (its
# output, its JSON, or the new model's history).
#   check_default_model CPM MOTION_LOG.csv FIT_EFFECT MODEL
check_default_model() {
  local cpm=$1 data=$2 effect=$3 m=$4
  "$cpm" compare --data "$data" >compare.txt
  grep -qF "model $m on $data" compare.txt || fail "compare did not use $m: $(head -n 3 compare.txt)"
  "$cpm" diagnose --data "$data" --json diagnose.json >diagnose.txt
  grep -qF "\"$m\"" diagnose.json || fail "diagnose did not use $m"
  "$cpm" fit --data "$data" --add "$effect" --out fitted.yaml --json fit.json >fit.txt
  grep -qF "\"model\": \"$m\"" fit.json || fail "fit did not use $m"
  "$cpm" plan-poses --out poses.csv >/dev/null
  "$cpm" simulate-measurement --poses poses.csv --out ballbar.csv >/dev/null
  "$cpm" calibrate --data ballbar.csv --out calibrated.yaml >calibrate.txt
  grep -qF "$m" calibrated.yaml || fail "calibrate did not use $m (the new model's history names it)"
  echo "compare, diagnose, fit and calibrate used $m"
}

#!/bin/bash
# SPDX-License-Identifier: Apache-2.0
# sil.daemon.identify's host side: the emulated CPU of the SIL guest runs the
# loop's fit some 100x slower than the host (docs/sil.md), so the experiment
# is designed here (cpm excite), recorded in the guest (cpm identify
# --record-only on vcan0), fitted here (cpm loop) on that log, and the new
# model loaded and checked in the guest. The folder OUT is shared with the
# guest: the guest writes log.csv then log.done; this writes better.yaml
# then better.done (cpm loop's exit status).
#   identify-host-fit.sh CPM CONFIG MODEL OUT RUNNER-COMMAND...
set -u
cpm=$1 config=$2 model=$3 out=$4
shift 4
rm -rf "$out"
mkdir -p "$out"
# The design for the model cpmd starts from, within config/sil.yaml's limits, a row per cycle.
rate=$(sed -n 's/^ *rate_hz: *\([0-9.]*\).*/\1/p' "$config" | head -1)
"$cpm" excite --config "$config" --model "$model" --rate "$rate" --out "$out/exc.csv" \
  --period 4 --periods 2 --harmonics 4 --iterations 40 >"$out/excite.out" 2>&1 \
  || { cat "$out/excite.out"; exit 1; }
(
  for _ in $(seq 1 6000); do  # 20 min at most: the runner's own limit ends the guest before
    if [ -e "$out/log.done" ]; then
      start=$(date +%s%N)
      "$cpm" loop --model "$model" --data "$out/log.csv" --out "$out/better.yaml" >"$out/loop.out" 2>&1
      rc=$?
      echo "cpm loop on the host: exit $rc, $((($(date +%s%N) - start) / 1000000)) ms" >>"$out/loop.out"
      echo $rc >"$out/better.done"
      exit 0
    fi
    sleep 0.2
  done
) &
fitter=$!
"$@"
rc=$?
kill "$fitter" 2>/dev/null
wait "$fitter" 2>/dev/null
[ -e "$out/loop.out" ] && { echo "---- the host's cpm loop ($out/loop.out)"; cat "$out/loop.out"; }
exit $rc

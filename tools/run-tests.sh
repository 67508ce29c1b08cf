#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# Set up, build and run every test.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/build.sh
cd build
# A first run (a clean clone) has no cost data, and ctest -j would start the
# slowest tests last, in the order they are declared: tests/ctest-cost.txt
# holds their measured seconds so that they start first. ctest keeps the
# file up to date from then on.
if [ ! -s Testing/Temporary/CTestCostData.txt ]; then
  mkdir -p Testing/Temporary
  cp ../tests/ctest-cost.txt Testing/Temporary/CTestCostData.txt
fi
# Every test in one ctest, two at a time: the SIL tests (one emulated CPU each)
# run beside the others instead of after them. A SIL test runs against a real
# kernel CAN stack: the host's vcan, or Debian's kernel in a software-emulated
# VM whose timing a loaded host can stall for seconds, so a failing SIL test is
# run once more; failing twice fails the run. Any other failure fails it at once.
if ctest --output-on-failure -j"$(nproc)" --timeout 900; then
  exit 0
fi
failed=$(sed 's/^[0-9]*://' Testing/Temporary/LastTestsFailed.log)
sil=$(ctest -N -L sil | sed -n 's/^ *Test *#[0-9]*: //p')
others=$(comm -23 <(sort <<<"$failed") <(sort <<<"$sil"))
if [ -n "$others" ]; then
  echo "run-tests: failed: $(tr '\n' ' ' <<<"$others")" >&2
  exit 1
fi
echo "run-tests: SIL test(s) failed, run once more: $(tr '\n' ' ' <<<"$failed")"
ctest --output-on-failure --timeout 900 -L sil --rerun-failed

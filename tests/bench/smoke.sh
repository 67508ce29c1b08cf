#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# Smoke test of the benchmark command: bench/run.sh --quick runs every step
# (in seconds) and writes a JSON with every figure of docs/performance.md.
# It checks the JSON's shape and that each figure is a number, never how
# fast anything was: timing is reported by bench/run.sh, not asserted in CI.
#   usage: tests/bench/smoke.sh BUILD_DIR
set -euo pipefail
cd "$(dirname "$0")/../.."
B=$1
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
bash bench/run.sh --quick --no-build --build-dir "$B" --json "$tmp/perf.json" >"$tmp/table.txt"
cat "$tmp/table.txt"
/usr/bin/python3 tests/bench/check_perf_json.py "$tmp/perf.json"

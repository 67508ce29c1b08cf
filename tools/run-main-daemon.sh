#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# The main job on the product: set up, build, start cpmd on its simulator
# backend, run the paper's circle through `cpm`, print the tracking error, stop.
# LCM stays on this machine: a private network namespace when root, else
# loopback with ttl=0 (config/sim.yaml). Commands are signed with a throw-away
# operator key made for this run (tools/throwaway-operator.sh, docs/security.md).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -z "${CPMD_IN_NETNS:-}" ]; then
  bash tools/build.sh >/dev/null
  if [ "$(id -u)" -eq 0 ] && unshare -n true 2>/dev/null; then
    exec unshare -n env CPMD_IN_NETNS=1 bash -c 'ip link set lo up; ip route add 224.0.0.0/4 dev lo; exec bash "$0"' "$0"
  fi
fi
B=${CPMD_BUILD_DIR:-build}/bin
. tools/throwaway-operator.sh "$B"
log=$(mktemp /tmp/cpmd.XXXXXX.log)
"$B/cpmd" --config config/sim.yaml --operators "$CPMD_OPERATORS" 2>"$log" &
pid=$!
trap 'kill $pid 2>/dev/null; wait $pid 2>/dev/null || true; rm -rf "$CPMD_THROWAWAY"' EXIT
for _ in $(seq 50); do "$B/cpm" status >/dev/null 2>&1 && break; sleep 0.1; done
"$B/cpm" status
"$B/cpm" enable
"$B/cpm" record --out build/paper-circle-daemon.csv --until-idle &
rec=$!
"$B/cpm" circle --paper 2>/dev/null
wait $rec
"$B/cpm" disable
"$B/cpm" stats
kill -TERM $pid; wait $pid || true
trap - EXIT
rm -rf "$CPMD_THROWAWAY"
cat "$log"

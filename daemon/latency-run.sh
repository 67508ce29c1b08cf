#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# The loop's timing over a 60 s run at 1 kHz (issue 5): cpmd on the simulator
# backend, the machine enabled and running circles the whole time, then the
# wake-up latency and per-phase times as `cpm stats` prints them.
# Runs in a private network namespace when root (LCM stays inside), else on
# loopback with ttl=0.   usage: daemon/latency-run.sh [BUILD_DIR] [SECONDS] [STATS_JSON] [CPU]
# STATS_JSON: where to keep cpmd's --stats-json (bench/run.sh reads it).
# CPU: pin the loop to this CPU (cpmd --loop-cpu), instead of config/sim.yaml's loop.cpu.
set -euo pipefail
cd "$(dirname "$0")/.."
B=${1:-build}/bin
T=${2:-60}
J=${3:-}
cpu_opt=()
if [ -n "${4:-}" ]; then cpu_opt=(--loop-cpu "$4"); fi
if [ "$(id -u)" -eq 0 ] && [ -z "${CPMD_IN_NETNS:-}" ]; then
  exec unshare -n env CPMD_IN_NETNS=1 bash -c 'ip link set lo up; ip route add 224.0.0.0/4 dev lo; exec "$0" "$@"' "$0" "$@"
fi
out=$(mktemp -d)
. tools/throwaway-operator.sh "$B"   # a key for this run's commands (docs/security.md)
if [ -n "$J" ]; then trap 'rm -rf "$out" "$CPMD_THROWAWAY"' EXIT; else trap 'rm -rf "$CPMD_THROWAWAY"' EXIT; fi
"$B/cpmd" --config config/sim.yaml --operators "$CPMD_OPERATORS" "${cpu_opt[@]}" --duration "$T" \
  --stats-json "$out/stats.json" 2>"$out/cpmd.log" &
pid=$!
sleep 0.5
"$B/cpm" enable >/dev/null
end=$((SECONDS + T - 3))
while [ $SECONDS -lt $end ]; do
  "$B/cpm" circle --radius 0.1 --time 2 --ramp 0.5 --no-wait >/dev/null 2>&1 || true
  sleep 3
done
"$B/cpm" stats || true   # a run shorter than the stats period may end before one is published
wait $pid
cat "$out/cpmd.log"
if [ -n "$J" ]; then cp "$out/stats.json" "$J"; echo "JSON: $J"; else echo "JSON: $out/stats.json"; fi

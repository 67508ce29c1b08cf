#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# The performance figures of docs/performance.md, measured side by side with
# their references in one run, printed as a table and written as JSON.
#
#   bash bench/run.sh [--quick] [--json FILE] [--seconds S] [--segments K] [--raw DIR] [--build-dir DIR] [--no-build]
#                     [--no-linuxcnc]
#
#   --quick        seconds, not minutes: small samples, 2 s latency runs (2 turns), the
#                  5 s motion log (the smoke test; its figures are not the
#                  real ones)
#   --json FILE    where to write the JSON (default build/bench/perf.json)
#   --seconds S    length of each latency run (default 60; 2 with --quick)
#   --segments K   cut the latency runs into K turns of S/K seconds (default 6; 2
#                  with --quick)
#   --raw DIR      keep the raw outputs (every turn's histograms, logs) in DIR
#   --build-dir    the build to use (default build)
#   --no-build     do not run tools/build.sh first
#   --no-linuxcnc  leave LinuxCNC out of the latency runs
#
# What runs, in this order (one step at a time: each figure gets the machine
# to itself, but for the two programs of the latency comparison):
#   1. cpm_perf: control cycle, controller and plant steps per call,
#      real-time factors, CAN bus load, Kim's ball-bar solve (C++), and the
#      problem exported for SciPy;
#   2. bench/scipy_ballbar.py with Debian's /usr/bin/python3 and SciPy: the
#      same problem, the same residual, timed, solutions compared;
#   3. cpm_bench (Google Benchmark): diagnose on a motion log and on ball-bar files;
#   4. the zero-allocation test of the daemon's cycle;
#   5. the wake-up latency, in K turns of S/K seconds, each turn three runs
#      (ABBA order: the one that went second goes first next):
#      - together: cpmd on config/sim.yaml at its priority, running circles
#        (daemon/latency-run.sh), its loop pinned to one CPU, and cyclictest
#        at the same SCHED_FIFO priority and period, memory locked, pinned to
#        another CPU, at the same time (from 0.5 s before cpmd starts to
#        about 0.4 s after it ends); the two swap CPUs every turn. Both see the same
#        stalls of the machine: the ratio of the two is what cpmd's loop adds
#        to the kernel's own latency, the budget;
#      - idle: cyclictest alone, S/K seconds: the machine without cpmd, and
#        how cyclictest fares with cpmd running against without;
#      - control: two cyclictests at once, one on each CPU and swapped each
#        turn as cpmd and cyclictest are, S/K seconds: the spread this
#        machine puts on a p99 ratio of two identical programs.
#        A ratio above the budget but within that spread is UNDECIDED, not
#        FAIL: the run cannot tell it from noise.
#      (Order: together, idle, control; the next turn control, idle, together.)
#      With LinuxCNC (linuxcnc-uspace, from tools/setup.sh) the "together" run
#      has a third program: LinuxCNC's servo thread at 1 kHz, real-time at the
#      same priority, its motion controller with lineardeltakins running
#      circles, timedelta and the sampler recording every period and the
#      functions' .time (bench/linuxcnc/). It starts first and circles until
#      after cpmd and cyclictest end; two CPUs for three programs, so it
#      shares one: cyclictest's in half the turns, cpmd's in the other half,
#      on each CPU equally (--no-linuxcnc leaves it out).
#   6. bench/report.py: the table with the budgets, and the JSON.
# Exit status: 0 when every figure was measured (a budget that is not met is
# reported in the table and the JSON, not as a failure of the command).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
quick=0 json="" seconds="" segments="" raw="" build_dir=build do_build=1 use_linuxcnc=1
while [ $# -gt 0 ]; do
  case "$1" in
    --quick) quick=1 ;;
    --json) json=$2; shift ;;
    --seconds) seconds=$2; shift ;;
    --segments) segments=$2; shift ;;
    --raw) raw=$2; shift ;;
    --build-dir) build_dir=$2; shift ;;
    --no-build) do_build=0 ;;
    --no-linuxcnc) use_linuxcnc=0 ;;
    -h|--help) sed -n '2,57p' "$0"; exit 0 ;;
    *) echo "bench/run.sh: unknown option '$1'" >&2; exit 2 ;;
  esac
  shift
done
B=$(cd "$build_dir" 2>/dev/null && pwd || echo "$root/$build_dir")
[ -n "$json" ] || json=$B/bench/perf.json
case "$json" in /*) ;; *) json=$root/$json ;; esac
PY=/usr/bin/python3   # Debian's, with python3-scipy (a `python3` earlier on PATH may lack SciPy)
if [ $quick -eq 1 ]; then cycles=5000 repeat=5 motion_s=5 seconds=${seconds:-2} segments=${segments:-2}
else cycles=100000 repeat=200 motion_s=60 seconds=${seconds:-60} segments=${segments:-6}; fi
for v in "seconds:$seconds" "segments:$segments"; do
  case "${v#*:}" in ''|*[!0-9]*|0) echo "bench/run.sh: --${v%%:*} wants a whole number >= 1, not '${v#*:}'" >&2; exit 2 ;; esac
done
# Whole seconds per turn (cyclictest -D and the daemon's run take whole seconds).
segment_s=$(( seconds / segments > 0 ? seconds / segments : 1 ))
seconds=$(( segment_s * segments ))

say() { echo "bench: $*" >&2; }
if [ $do_build -eq 1 ]; then
  say "building (tools/build.sh)"
  bash tools/build.sh >/dev/null
fi
for exe in "$B/bin/cpm_perf" "$B/bin/cpm_bench" "$B/bin/cpmd" "$B/bin/cpm" "$B/tests/test_daemon"; do
  [ -x "$exe" ] || { echo "bench/run.sh: $exe is missing: build first (bash tools/build.sh)" >&2; exit 1; }
done
command -v cyclictest >/dev/null || { echo "bench/run.sh: cyclictest missing: bash tools/setup.sh (rt-tests)" >&2; exit 1; }
"$PY" -c 'import scipy' 2>/dev/null || { echo "bench/run.sh: $PY has no SciPy: bash tools/setup.sh (python3-scipy)" >&2; exit 1; }

out=$(mktemp -d)
if [ -n "$raw" ]; then
  mkdir -p "$raw" || { echo "bench/run.sh: cannot make --raw $raw" >&2; exit 2; }
  trap 'cp -r "$out"/. "$raw"/; rm -rf "$out"' EXIT
else
  trap 'rm -rf "$out"' EXIT
fi
mkdir -p "$(dirname "$json")"
# CPU accounting at each step's boundary: the machine's counters (/proc/stat)
# and this script's children (times), so that the report can say how much of
# the machine other processes took while each figure was measured.
mark() {
  times >"$out/times.txt"   # in this shell: a $(times) subshell would see no children
  echo "$1|$(head -1 /proc/stat)|$(tail -1 "$out/times.txt")" >>"$out/cpu_marks.txt"
}
mark start

say "1/5 control cycle, plant, real-time factors, bus, Kim's ball-bar in C++ ($cycles cycles)"
"$B/bin/cpm_perf" --source "$root" --cycles $cycles --repeat $repeat --kim-problem "$out/kim_problem.json" \
  --json "$out/perf.json"

say "2/5 the same ball-bar problem in SciPy ($repeat solves per method)"
"$PY" bench/scipy_ballbar.py "$out/kim_problem.json" --repeat $repeat --json "$out/scipy.json"

say "3/5 diagnose (Google Benchmark)"
"$B/bin/cpm_bench" --benchmark_filter="^BM_DiagnoseMotion1kHz/seconds:$motion_s/|^BM_DiagnoseBallbar" \
  --benchmark_format=json --benchmark_out="$out/gbench.json" --benchmark_out_format=json >/dev/null

say "4/5 zero heap allocations per cycle (the daemon's test)"
if "$B/tests/test_daemon" --gtest_filter='NoAllocation.*' >"$out/alloc.log" 2>&1; then alloc=passed; else alloc=failed; fi

# Scheduling: both latency runs ask for the same SCHED_FIFO priority (the
# loop's, from config/sim.yaml) and period; where SCHED_FIFO is refused both
# run with normal scheduling, and the table says so.
prio=$(sed -n 's/^ *priority: *\([0-9]*\).*/\1/p' config/sim.yaml | head -1)
rate=$(sed -n 's/^ *rate_hz: *\([0-9.]*\).*/\1/p' config/sim.yaml | head -1)
interval_us=$("$PY" -c "print(round(1e6 / $rate))")
if chrt -f "$prio" true 2>/dev/null; then rt=1; ct_sched=(-p "$prio"); else rt=0; ct_sched=(--policy=other -p 0); fi

mark compute
# LinuxCNC beside them, where it can run real-time here (bench/linuxcnc/run-linuxcnc.sh
# says what that takes); otherwise the table says why not.
lc=0
if [ $use_linuxcnc -eq 0 ]; then lc_why="left out (--no-linuxcnc)"
elif ! command -v linuxcnc >/dev/null || ! command -v halsampler >/dev/null; then lc_why="linuxcnc-uspace is not installed (bash tools/setup.sh)"
elif [ $rt -eq 0 ]; then lc_why="SCHED_FIFO refused: LinuxCNC's POSIX real-time needs it"
elif [ ! -f "$B/lib/libcpm_rtprio_shim.so" ]; then lc_why="$B/lib/libcpm_rtprio_shim.so missing: build first"
elif ! id -u nobody >/dev/null 2>&1; then lc_why="no user nobody for RTAPI_UID"
else lc=1; fi
[ $lc -eq 1 ] || echo "$lc_why" >"$out/linuxcnc_skipped.txt"
# Two CPUs for the latency runs: the last two (CPU 0 usually takes more of the
# machine's interrupts, and the turns swap them anyway). On one CPU both run on it.
ncpu=$(nproc)
if [ "$ncpu" -ge 2 ]; then cpu_a=$((ncpu - 2)) cpu_b=$((ncpu - 1)); else cpu_a="" cpu_b=""; fi
# cyclictest starts half a second before cpmd and runs a second longer than
# cpmd's loop (its -D takes whole seconds): cpmd's start, loop and exit lie
# inside cyclictest's run; the extra second, mostly without cpmd, can only
# flatter cyclictest.
say "5/5 wake-up latency: ${seconds} s in $segments turns of ${segment_s} s: cpmd with cyclictest at once (CPUs ${cpu_a:-any} and ${cpu_b:-any}, swapped each turn), and cyclictest alone (priority $prio, $interval_us us)"
# --default-system: cyclictest leaves power management as it is (it would
# otherwise hold /dev/cpu_dma_latency at 0, which cpmd does not): both
# programs see the same C-states. -m: memory locked, as cpmd's lock_memory.
# -h 2000: 1 us bins to 2 ms, the range of cpmd's histogram_1us.
cyclictest_run() {  # NAME SECONDS [CPU]
  local aff=()
  if [ -n "${3:-}" ]; then aff=(-a "$3"); fi
  cyclictest -q -m -t 1 "${ct_sched[@]}" "${aff[@]}" -i "$interval_us" -D "$2" -h 2000 --default-system \
    --json="$out/$1.json" >"$out/$1.log" 2>&1 ||
    { cat "$out/$1.log" >&2; echo "bench/run.sh: cyclictest ($1) failed" >&2; return 1; }
}
run_together() {  # K
  local cp_cpu=$cpu_b ct_cpu=$cpu_a lc_cpu=$cpu_a lc_pid=""
  if [ $(($1 % 2)) -eq 0 ]; then cp_cpu=$cpu_a ct_cpu=$cpu_b; fi
  # LinuxCNC on A in turns 1, 2 (mod 4), on B in 3, 4: with cyclictest, cpmd, cpmd, cyclictest.
  if [ $(($1 % 4)) -eq 0 ] || [ $(($1 % 4)) -eq 3 ]; then lc_cpu=$cpu_b; fi
  if [ $lc -eq 1 ]; then
    # It takes a few seconds to start and home: the others start once it circles.
    bash bench/linuxcnc/run-linuxcnc.sh $((segment_s + 2)) "$prio" "$lc_cpu" "$out/linuxcnc_$1.txt" \
      "$out/linuxcnc_ready_$1" "$B/lib/libcpm_rtprio_shim.so" >"$out/linuxcnc_run_$1.log" 2>&1 &
    lc_pid=$!
    local waited=0
    while [ ! -f "$out/linuxcnc_ready_$1" ]; do
      if ! kill -0 "$lc_pid" 2>/dev/null || [ $waited -ge 1200 ]; then
        cat "$out/linuxcnc_run_$1.log" >&2; echo "bench/run.sh: LinuxCNC did not start circling (turn $1)" >&2
        kill "$lc_pid" 2>/dev/null; exit 1
      fi
      sleep 0.1; waited=$((waited + 1))
    done
  fi
  cyclictest_run "cyclictest_$1" $((segment_s + 1)) "$ct_cpu" &
  local ct_pid=$!
  sleep 0.5
  bash daemon/latency-run.sh "$B" "$segment_s" "$out/cpmd_stats_$1.json" ${cp_cpu:+"$cp_cpu"} >"$out/cpmd_run_$1.log" 2>&1 ||
    { cat "$out/cpmd_run_$1.log" >&2; echo "bench/run.sh: the cpmd latency run ($1 of $segments) failed" >&2
      kill "$ct_pid" $lc_pid 2>/dev/null; exit 1; }
  wait "$ct_pid" || exit 1
  if [ -n "$lc_pid" ]; then
    wait "$lc_pid" || { cat "$out/linuxcnc_run_$1.log" >&2; echo "bench/run.sh: LinuxCNC failed (turn $1)" >&2; exit 1; }
  fi
  echo "cpmd_cpu=${cp_cpu:-any} cyclictest_cpu=${ct_cpu:-any}${lc_pid:+ linuxcnc_cpu=${lc_cpu:-any}}" >"$out/cpus_$1.txt"
}
run_control() {  # K: cyclictest against itself on run_together's CPUs, swapped as cpmd and cyclictest are
  local a_cpu=$cpu_b b_cpu=$cpu_a
  if [ $(($1 % 2)) -eq 0 ]; then a_cpu=$cpu_a b_cpu=$cpu_b; fi
  cyclictest_run "control_a_$1" "$segment_s" "$a_cpu" &
  local a_pid=$!
  cyclictest_run "control_b_$1" "$segment_s" "$b_cpu" || exit 1
  wait "$a_pid" || exit 1
}
for k in $(seq 1 "$segments"); do
  if [ $((k % 2)) -eq 1 ]; then
    run_together "$k"; cyclictest_run "cyclictest_idle_$k" "$segment_s" || exit 1; run_control "$k"
  else
    run_control "$k"; cyclictest_run "cyclictest_idle_$k" "$segment_s" || exit 1; run_together "$k"
  fi
done
mark latency_runs

"$PY" bench/report.py --dir "$out" --json "$json" --quick $quick --seconds "$seconds" --segments "$segments" --priority "$prio" \
  --interval-us "$interval_us" --realtime-allowed $rt --allocation-test $alloc
say "JSON: $json"

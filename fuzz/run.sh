#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# Build and run the libFuzzer targets of fuzz/targets (docs/fuzzing.md).
#   fuzz/run.sh build                     configure and build every fuzzer with clang
#   fuzz/run.sh run TARGET [SECONDS]      fuzz TARGET for SECONDS (default 20) from its corpus
#                                         (FUZZ_RUNS=N: the corpus, then N inputs, SECONDS at most)
#   fuzz/run.sh replay TARGET [FILE...]   run the committed corpus (or the files) once
#   fuzz/run.sh merge TARGET              add what the runs found to fuzz/corpus/TARGET, minimised
#   fuzz/run.sh list                      the targets
# Environment: FUZZ_BUILD_DIR (default <repo>/build-fuzz-clang), FUZZ_JOBS (2).
# A run that finds a crash, a sanitizer report, a leak, a hang (> 10 s per
# input) or a broken FUZZ_CHECK exits 1 and keeps the input in
# $FUZZ_BUILD_DIR/findings/TARGET/. Exit 77 when clang or libFuzzer is missing.
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
build="${FUZZ_BUILD_DIR:-$repo/build-fuzz-clang}"
jobs="${FUZZ_JOBS:-2}"
cmd="${1:-}"
target="${2:-}"

have_libfuzzer() {
  command -v clang++ >/dev/null 2>&1 || return 1
  local rt
  rt="$(clang++ -print-resource-dir 2>/dev/null)/lib/linux/libclang_rt.fuzzer-x86_64.a"
  [ -f "$rt" ] || [ -n "$(clang++ -print-file-name=libclang_rt.fuzzer-x86_64.a 2>/dev/null | grep /)" ]
}

targets() { (cd "$repo/fuzz/targets" && ls *.cpp | sed 's/\.cpp$//'); }

# Flags per target: the LCM messages are larger than libFuzzer's default 4 kB.
max_len() {
  case "$1" in
    lcm_trajectory) echo 8192 ;;
    lcm_session) echo 32768 ;;
    *) echo 8192 ;;
  esac
}

exe_of() {
  local exe="$build/fuzz/fuzz_$1"
  if [ ! -x "$exe" ]; then
    echo "fuzz: $exe is not built (fuzz/run.sh build)" >&2
    exit 77
  fi
  echo "$exe"
}

export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1:symbolize=1}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"

case "$cmd" in
  build)
    if ! have_libfuzzer; then
      echo "fuzz: clang++ with libFuzzer not found (Debian: clang libclang-rt-14-dev; tools/setup.sh installs them)" >&2
      exit 77
    fi
    san="-fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer -fsanitize=fuzzer-no-link"
    cmake -S "$repo" -B "$build" -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_BUILD_TYPE=Fuzz \
      -DCMAKE_CXX_FLAGS_FUZZ="-O1 -gline-tables-only" -DCMAKE_CXX_FLAGS="$san" \
      -DCPM_FUZZ=ON -DCPM_BUILD_TESTS=OFF -DCPM_BUILD_BENCH=OFF \
      "-DCPM_MODULES=kinematics;control;sim;io;path;msgs;hal;daemon;tools;fuzz" >/dev/null
    cmake --build "$build" --target fuzz_all -j"$jobs"
    ;;
  run)
    [ -n "$target" ] || { echo "usage: fuzz/run.sh run TARGET [SECONDS]" >&2; exit 2; }
    seconds="${3:-20}"
    exe="$(exe_of "$target")"
    work="$build/work/$target"          # what this run adds (the repo corpus stays as committed)
    findings="$build/findings/$target"
    mkdir -p "$work" "$findings"
    log="$build/logs/$target.log"
    mkdir -p "$(dirname "$log")"
    # CI's form: a fixed number of inputs past the corpus (libFuzzer counts the
    # corpus's own runs in -runs), the same ones every time with the fixed seed.
    runs_flag=()
    if [ "${FUZZ_RUNS:-0}" -gt 0 ]; then
      corpus_size=$(find "$repo/fuzz/corpus/$target" -type f | wc -l)
      runs_flag=(-runs=$((corpus_size + FUZZ_RUNS)))
    fi
    started=$SECONDS
    set +e
    # A fixed seed (FUZZ_SEED, default 1) keeps CI's runs alike from one to the next.
    "$exe" "${runs_flag[@]}" -seed="${FUZZ_SEED:-1}" -max_total_time="$seconds" -timeout=10 -error_exitcode=1 -timeout_exitcode=1 -rss_limit_mb=2048 -max_len="$(max_len "$target")" \
      -print_final_stats=1 -artifact_prefix="$findings/" "$work" "$repo/fuzz/corpus/$target" >"$log" 2>&1
    rc=$?
    set -e
    elapsed=$((SECONDS - started))
    runs=$(grep -oE '^stat::number_of_executed_units: *[0-9]+' "$log" | grep -oE '[0-9]+$' || echo "?")
    eps=$(grep -oE '^stat::average_exec_per_sec: *[0-9]+' "$log" | grep -oE '[0-9]+$' || echo "?")
    last=$(grep -E '^#[0-9]+' "$log" | tail -1)
    cov=$(echo "$last" | grep -oE 'cov: [0-9]+' | grep -oE '[0-9]+' || echo "?")
    ft=$(echo "$last" | grep -oE 'ft: [0-9]+' | grep -oE '[0-9]+' || echo "?")
    corp=$(echo "$last" | grep -oE 'corp: [0-9]+' | grep -oE '[0-9]+' || echo "?")
    if [ $rc -ne 0 ]; then
      echo "fuzz $target: FINDING after ${runs} runs (exit $rc). Log: $log"
      grep -E 'FUZZ FINDING|ERROR: |runtime error|SUMMARY|Test unit written|Base64' "$log" | head -20
      echo "Reproduce: $exe <file above>; keep the input as fuzz/corpus/$target/regress-<what> once fixed."
      exit 1
    fi
    line="fuzz $target: ${runs} runs in ${elapsed} s (${eps} exec/s), coverage ${cov} edges, ${ft} features, corpus ${corp}; no finding"
    echo "$line"
    echo "$line" >>"$build/summary.txt"
    ;;
  replay)
    [ -n "$target" ] || { echo "usage: fuzz/run.sh replay TARGET [FILE...]" >&2; exit 2; }
    exe="$(exe_of "$target")"
    shift 2
    mkdir -p "$build/findings/$target"
    flags=(-max_len="$(max_len "$target")" -error_exitcode=1 -artifact_prefix="$build/findings/$target/")
    if [ $# -gt 0 ]; then "$exe" "${flags[@]}" "$@"
    else "$exe" -runs=0 "${flags[@]}" "$repo/fuzz/corpus/$target"; fi
    ;;
  merge)
    [ -n "$target" ] || { echo "usage: fuzz/run.sh merge TARGET" >&2; exit 2; }
    exe="$(exe_of "$target")"
    "$exe" -merge=1 -max_len="$(max_len "$target")" "$repo/fuzz/corpus/$target" "$build/work/$target"
    ;;
  list) targets ;;
  *)
    sed -n '2,12p' "$0" | sed 's/^# \{0,1\}//'
    exit 2
    ;;
esac

#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# The SIL runner's contract, checked through the VM path: the command's exit
# code comes back; arguments, environment and working folder arrive intact;
# the working folder is writable and the rest of the host is not; a VM that
# dies without reporting, and one that overruns --timeout, are failures with
# their own codes (125, 124).
set -uo pipefail
RUNNER="$(cd "$(dirname "$0")" && pwd)/run-in-vm.sh"
fails=0
expect() {  # expect WHAT EXPECTED ACTUAL
  if [ "$2" = "$3" ]; then echo "ok: $1"; else echo "FAILED: $1: expected '$2', got '$3'"; fails=$((fails + 1)); fi
}

work=$(mktemp -d "${TMPDIR:-/tmp}/cpm-sil-test.XXXXXX")
export TMPDIR=$work   # the runner keeps failed runs' folders here: removed with it
trap 'rm -rf "$work"' EXIT
cd "$work"

# 1. Exit code, quoting, environment, working folder, writable and read-only,
#    output.
out=$(CPM_SIL_PROBE='x y$z' bash "$RUNNER" --vm --needs can -- bash -c '
  printf "%s|" "$@" > args.txt
  printf "%s" "$CPM_SIL_PROBE" > env.txt
  pwd > pwd.txt
  echo "$CPM_SIL" > mode.txt
  if touch /etc/cpm-sil-probe 2>/dev/null; then echo writable > ro.txt; else echo read-only > ro.txt; fi
  echo "hello from the guest"
  exit 7' sil 'a b' 'c"d' '$HOME' '' 2>/dev/null)
rc=$?
expect "exit code passes through" 7 "$rc"
expect "arguments arrive intact" 'a b|c"d|$HOME||' "$(cat args.txt 2>/dev/null)"
expect "environment arrives" 'x y$z' "$(cat env.txt 2>/dev/null)"
expect "working folder is the caller's" "$work" "$(cat pwd.txt 2>/dev/null)"
expect "the command ran in the VM" vm "$(cat mode.txt 2>/dev/null)"
expect "the rest of the host is read-only" read-only "$(cat ro.txt 2>/dev/null)"
[ ! -e /etc/cpm-sil-probe ] || { echo "FAILED: /etc/cpm-sil-probe was created on the host"; fails=$((fails + 1)); rm -f /etc/cpm-sil-probe; }

expect "output comes back on stdout" "hello from the guest" "$out"

# 3. A guest that powers off before reporting is a failure of the runner.
bash "$RUNNER" --vm --needs can -- bash -c 'echo o > /proc/sysrq-trigger; sleep 60' >/dev/null 2>&1
expect "a VM that dies without a result fails with 125" 125 "$?"

# 4. A run longer than --timeout is stopped and reported as 124.
bash "$RUNNER" --vm --needs can --timeout 6 -- sleep 600 >/dev/null 2>&1
expect "a run over --timeout fails with 124" 124 "$?"

# 6. The host path, exercised inside the VM (whose kernel has vcan and
#    gpio-sim, as a developer's PC would): --auto picks the host, both smoke
#    programs pass there, and the per-run gpio-sim chip is removed afterwards.
if [ $# -ge 2 ]; then
  out=$(bash "$RUNNER" --vm --needs can --rw "$work" --rw "$(dirname "$1")" --rw "$(dirname "$RUNNER")" -- bash -c '
    r=$1
    bash "$r" --auto -- sh -c "echo mode=\$CPM_SIL"
    bash "$r" --host --needs can -- "$2" >/dev/null && echo can=ok
    bash "$r" --host --needs gpio -- "$3" >/dev/null && echo gpio=ok
    echo chips=$(ls /sys/kernel/config/gpio-sim)' sil "$RUNNER" "$1" "$2" 2>&1)
  grep -q "^mode=host" <<<"$out" || printf "%s\n" "$out" | sed "s/^/  guest: /"
  expect "--auto uses a host that has vcan and gpio-sim" 1 "$(grep -c '^mode=host' <<<"$out")"
  expect "smoke_can passes on the host path" 1 "$(grep -c '^can=ok' <<<"$out")"
  expect "smoke_gpio passes on the host path" 1 "$(grep -c '^gpio=ok' <<<"$out")"
  expect "the host path removes its gpio-sim chip" "chips=cpm-sil" "$(grep '^chips=' <<<"$out")"
fi

# 7. Usage errors are the runner's (125), before any VM is booted.
bash "$RUNNER" --needs bogus -- true >/dev/null 2>&1
expect "an unknown --needs is refused" 125 "$?"

[ $fails -eq 0 ] && echo "test-runner: all checks passed" || echo "test-runner: $fails check(s) failed"
exit $((fails > 0))

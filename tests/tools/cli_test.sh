#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# The command lines as a user meets them (docs/cli.md):
#   cli_test.sh VERSION MAN_DIR CPM CPMD VIRTUAL_DRIVES NAME=PROGRAM...
# - every program prints "NAME VERSION" for --version, VERSION being the build's;
# - cpm COMMAND --help for every subcommand exits 0 and lists all its options;
# - a bad command line exits 2 and names the bad option (cpm, cpmd, virtual-drives);
# - an unknown effect name lists the valid ones (fit --add, diagnose --effect, sim --truth-effect);
# - the man pages were generated: cpm.1 naming every subcommand, cpm-COMMAND.1 for each, cpmd.8
#   with every option of cpmd --help, cpmd.yaml.5 and machine.yaml.5, all rendering without warnings;
# - JSON numbers are shortest round-trip (Table 3's 0.0027, not 0.0027000000000000001).
set -u
version=$1 man=$2 cpm=$(realpath "$3") cpmd=$(realpath "$4") vd=$(realpath "$5")
shift 5
failures=0
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }
ok() { echo "ok   $*"; }

# ---- --version
for pair in cpm="$cpm" cpmd="$cpmd" virtual-drives="$vd" "$@"; do
  name=${pair%%=*} exe=${pair#*=}
  out=$("$exe" --version 2>&1) rc=$?
  if [ $rc -eq 0 ] && [ "$out" = "$name $version" ]; then ok "$name --version: $out"
  else fail "$exe --version: exit $rc, '$out', wanted '$name $version'"; fi
done

# ---- cpm COMMAND --help lists every option
mapfile -t commands < <("$cpm" __complete "")
[ ${#commands[@]} -ge 20 ] || fail "cpm lists ${#commands[@]} subcommands"
for c in "${commands[@]}"; do
  help=$("$cpm" "$c" --help) rc=$?
  [ $rc -eq 0 ] || fail "cpm $c --help: exit $rc"
  [[ $help == *"Usage: cpm $c"* ]] || fail "cpm $c --help: no usage line"
  missing=()
  while read -r opt; do
    grep -qE -- "(^|[ ,])$opt( |,|$)" <<<"$help" || missing+=("$opt")
  done < <("$cpm" __complete "$c" --)
  [ ${#missing[@]} -eq 0 ] && ok "cpm $c --help lists its options" || fail "cpm $c --help lacks ${missing[*]}"
done
# Units and examples in the help.
"$cpm" sim --help | grep -q -- "--radius M .*in m (e.g. 0.150)" && ok "cpm sim --help: --radius in m with an example" ||
  fail "cpm sim --help: no unit or example for --radius"

# ---- bad command lines: exit 2, the option named
bad() {  # bad WORD-TO-FIND PROGRAM ARGS...
  local want=$1
  shift
  local err rc
  err=$("$@" 2>&1 >/dev/null) rc=$?
  if [ $rc -eq 2 ] && [[ $err == *"$want"* ]]; then ok "$(basename "$1") ${*:2}: exit 2, names $want"
  else fail "$* : exit $rc (wanted 2), '$err' does not name $want"; fi
}
bad --bogus "$cpm" sim --bogus
bad --radius "$cpm" sim --radius abc
bad --radius "$cpm" sim --radius nan
bad --plane "$cpm" sim --plane ab
bad --data "$cpm" diagnose
bad --max-steps "$cpm" loop --data x.csv --out y.yaml --max-steps 0
bad --out "$cpm" identify x.csv
bad --log "$cpm" identify x.csv --record-only
bad --from "$cpm" sim --trajectory p2p --from 0.3,0.3 --to 0.4,0.4,0.4
bad nosuch "$cpm" nosuch
bad --bogus "$cpmd" --config x.yaml --bogus
bad --config "$cpmd"
bad --duration "$cpmd" --config x.yaml --duration soon
bad --nodes "$vd" --interface vcan0 --nodes 1,2
bad --interface "$vd"

# ---- an unknown effect lists the valid ones
mapfile -t effects < <("$cpm" __complete fit --add "")
[ ${#effects[@]} -ge 10 ] || fail "only ${#effects[@]} effect names"
for args in "fit --data x.csv --out y.yaml --add nosuch:2" "diagnose --data x.csv --effect nosuch" \
            "sim --truth-effect nosuch:1:3"; do
  # shellcheck disable=SC2086
  err=$("$cpm" $args 2>&1) rc=$?
  missing=()
  for e in "${effects[@]}"; do [[ $err == *"$e"* ]] || missing+=("$e"); done
  if [ $rc -eq 2 ] && [[ $err == *"unknown effect 'nosuch'"* ]] && [ ${#missing[@]} -eq 0 ]; then
    ok "cpm $args: lists the ${#effects[@]} effects"
  else fail "cpm $args: exit $rc, missing ${missing[*]:-} in '$err'"; fi
done

# ---- man pages
page() { zcat "$man/$1.gz" 2>/dev/null; }
for p in man1/cpm.1 man8/cpmd.8 man5/cpmd.yaml.5 man5/machine.yaml.5; do
  [ -s "$man/$p.gz" ] && ok "$p generated" || fail "$man/$p.gz missing"
done
for c in "${commands[@]}"; do
  page man1/cpm.1 | grep -qxF -- "${c//-/\\-}" || fail "cpm.1 does not list $c"
  page "man1/cpm-$c.1" | grep -q "^\.TH CPM-${c^^} \"1\"" || fail "man1/cpm-$c.1.gz missing or without its title"
done
ok "cpm.1 and cpm-COMMAND.1 for the ${#commands[@]} subcommands"
while read -r opt; do
  page man8/cpmd.8 | grep -q -- "${opt//-/\\\\-}" || fail "cpmd.8 lacks $opt"
done < <("$cpmd" --help | grep -oE -- "--[a-z-]+" | sort -u)
page man5/machine.yaml.5 | grep -q "dynamic_effects" && page man5/cpmd.yaml.5 | grep -q "model_file" &&
  ok "machine.yaml.5 and cpmd.yaml.5 carry the docs' keys" || fail "the format pages lack their keys"
if command -v groff >/dev/null; then
  for f in "$man"/man?/*.gz; do
    warn=$(zcat "$f" | groff -man -Tutf8 -ww -z 2>&1)
    [ -z "$warn" ] || fail "$(basename "$f"): groff warns: $warn"
  done
  ok "every page renders without a groff warning"
else
  echo "note: no groff: the pages were not rendered"
fi

# ---- JSON numbers
(cd "$tmp" && "$cpm" table3 --json t3.json >/dev/null) || fail "cpm table3 failed"
grep -q '"paper_position_rmse": 0.0027,' "$tmp/t3.json" && ok "JSON: 0.0027 written as 0.0027" ||
  fail "JSON numbers are not shortest round-trip: $(grep paper_position_rmse "$tmp/t3.json" | head -1)"

[ $failures -eq 0 ] && echo "cli: all passed" && exit 0
echo "cli: $failures failed"
exit 1

#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# The bash completion of cpm (tools/completion/cpm), run as bash runs it:
# COMP_WORDS/COMP_CWORD set, _cpm called, COMPREPLY read. Once with the
# script alone, once with bash-completion loaded (what a Debian user has).
#   completion_test.sh CPM COMPLETION_SCRIPT
set -u
cpm=$1
script=$2
failures=0
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
touch "$tmp/machine.yaml" "$tmp/run.csv"
cd "$tmp" || exit 1

# complete WORD... : COMPREPLY for the command line "cpm WORD..." (the last word is completed)
complete_words() {
  COMP_WORDS=("$cpm" "$@")
  COMP_CWORD=$((${#COMP_WORDS[@]} - 1))
  COMP_LINE="${COMP_WORDS[*]}"
  COMP_POINT=${#COMP_LINE}
  COMPREPLY=()
  _cpm
}

# expect "WANTED" "UNWANTED" WORD... : WANTED among the candidates, UNWANTED not ("" for none)
expect() {
  local want=$1 unwanted=$2
  shift 2
  complete_words "$@"
  local got=" ${COMPREPLY[*]-} "
  if [[ $got != *" $want "* ]] || { [ -n "$unwanted" ] && [[ $got == *" $unwanted "* ]]; }; then
    echo "FAIL ($mode): cpm $* -> [${COMPREPLY[*]-}], wanted $want${unwanted:+, not $unwanted}"
    failures=$((failures + 1))
  else
    echo "ok   ($mode): cpm $* -> $want"
  fi
}

run_cases() {
  expect fit sim fi                                      # a subcommand
  expect --data --out fit --da                           # an option of the subcommand
  expect --truth-effect "" sim --truth-                  # an option of another subcommand
  expect coulomb_friction cogging fit --add cou          # an effect name after --add
  expect backlash "" diagnose --effect back              # ... after --effect
  expect stribeck_friction "" sim --truth-effect stri    # ... after --truth-effect
  expect yz "" sim --plane ""                            # a fixed list
  expect computed_torque "" controller comp              # a positional's fixed list
  expect show "" model ""                                # ... of the first positional
  expect machine.yaml run.csv model check mach           # a file
  expect run.csv "" fit --data r                         # a file after an option
}

mode="script alone"
# shellcheck source=/dev/null
source "$script"
run_cases

bc=/usr/share/bash-completion/bash_completion
if [ -r "$bc" ]; then
  mode="with bash-completion"
  # shellcheck source=/dev/null
  source "$bc"
  source "$script"
  run_cases
else
  echo "note: $bc not found: the case with bash-completion loaded was not run"
fi
[ "$failures" -eq 0 ] && echo "completion: all cases passed" && exit 0
echo "completion: $failures cases failed"
exit 1

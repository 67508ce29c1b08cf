#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# The man pages, at build time: help2man on the built cpm (cpm.1 and one
# cpm-COMMAND.1 per subcommand, as git has) and cpmd (cpmd.8), so that each
# page is the program's own --help; md2man.py on docs/daemon.md's
# configuration section (cpmd.yaml.5) and docs/model-file.md (machine.yaml.5).
# Compressed with gzip -9n (Debian policy).
#   make-man.sh OUT_DIR SOURCE_DIR CPM CPMD PYTHON3 HELP2MAN
set -euo pipefail
out=$1 src=$2 cpm=$3 cpmd=$4 py=$5 help2man=$6
man=$src/tools/man
version=$("$cpm" --version)
version=${version#cpm }
rm -rf "$out"
mkdir -p "$out/man1" "$out/man5" "$out/man8"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# The subcommands, from cpm itself: the completion's list.
mapfile -t commands < <("$cpm" __complete "")
[ ${#commands[@]} -gt 0 ] || { echo "make-man: $cpm lists no subcommand" >&2; exit 1; }

see_also=()
for c in "${commands[@]}"; do
  summary=$("$cpm" "$c" --help | head -n 1)
  "$help2man" --no-info --locale C.UTF-8 --section 1 --name "$summary" --help-option "$c --help" \
    --version-string "cpm-$c $version" --include "$man/cpm-command.h2m" \
    --output "$out/man1/cpm-$c.1" "$cpm"
  see_also+=(".BR cpm-$c (1),")
done
{
  cat "$man/cpm.h2m"
  printf '\n[SEE ALSO]\n'
  printf '%s\n' "${see_also[@]}"
  printf '.BR machine.yaml (5),\n.BR cpmd (8),\n.BR cpmd.yaml (5)\n'
} > "$tmp/cpm.h2m"
"$help2man" --no-info --locale C.UTF-8 --section 1 \
  --name "the command-line tool of cpmd: simulate, calibrate, identify, command" \
  --include "$tmp/cpm.h2m" --output "$out/man1/cpm.1" "$cpm"
"$help2man" --no-info --locale C.UTF-8 --section 8 --name "the motion controller daemon of a 3-PRRR parallel manipulator" \
  --include "$man/cpmd.h2m" --output "$out/man8/cpmd.8" "$cpmd"

"$py" "$man/md2man.py" "$src/docs/daemon.md" --heading Configuration --name cpmd.yaml --section 5 \
  --summary "the configuration file of cpmd" --version "$version" \
  --example "The simulator backend (/etc/cpmd/cpmd.yaml)=$src/config/cpmd.yaml" \
  --example "The CANopen backend=$src/config/canopen.yaml" \
  --see-also "cpmd(8), machine.yaml(5), cpm(1)" > "$out/man5/cpmd.yaml.5"
"$py" "$man/md2man.py" "$src/docs/model-file.md" --name machine.yaml --section 5 \
  --summary "the machine model file of cpmd and cpm" --version "$version" \
  --see-also "cpm(1), cpm-model(1), cpmd(8), cpmd.yaml(5)" > "$out/man5/machine.yaml.5"

gzip -9nf "$out"/man?/*

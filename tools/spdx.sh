#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# The licence line in every source file of the project (LICENSE, packaging/copyright).
#   tools/spdx.sh            add "SPDX-License-Identifier: Apache-2.0" to every source file
#                            that lacks it: "// " for C, C++ and LCM, "# " for shell,
#                            Python and CMake; after a #! line, else as the first line
#   tools/spdx.sh --check    list the source files that lack it; exit 1 if any does
#   tools/spdx.sh [--check] FILE...   the same for these files only
# Source files: the tracked files (git ls-files; every file when the tree is no
# git clone) named below. Data (fuzz corpora, CSV, YAML, G-code), docs and
# generated files are not source and carry no line.
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
cd "$repo"
id="SPDX-License-Identifier: Apache-2.0"

check=0
if [ "${1:-}" = "--check" ]; then check=1; shift; fi

# The comment that starts a line in FILE's language; empty: not a source file.
comment_of() {
  case "$1" in
    fuzz/corpus/* | tests/docs/fixture/*) ;;  # data; the link checker's fixture, whose line numbers its test asserts
    *.cpp | *.hpp | *.h | *.c | *.lcm | *.hpp.in) echo "//" ;;
    *.sh | *.py | *.cmake | *.cmake.in | */CMakeLists.txt | CMakeLists.txt) echo "#" ;;
    .ci/run | packaging/debian/postinst | packaging/debian/prerm | packaging/debian/postrm | tools/completion/cpm) echo "#" ;;
  esac
}

files() {
  if [ $# -gt 0 ]; then printf '%s\n' "$@"
  elif git rev-parse --is-inside-work-tree >/dev/null 2>&1; then git ls-files
  else find . -type f -not -path './build*' -not -path './.git/*' | sed 's|^\./||'
  fi
}

# The line is looked for in the first five lines: a #! line, an encoding line
# or a file's own first comment may come before it.
has_id() { head -n 5 "$1" | grep -q "SPDX-License-Identifier:"; }

missing=0
while IFS= read -r f; do
  c="$(comment_of "$f")"
  [ -n "$c" ] && [ -f "$f" ] || continue
  has_id "$f" && continue
  if [ $check -eq 1 ]; then
    echo "$f: no \"$c $id\" line (tools/spdx.sh adds it)"
    missing=$((missing + 1))
    continue
  fi
  tmp="$(mktemp "$f.spdx.XXXXXX")"
  if head -n 1 "$f" | grep -q '^#!'; then
    { head -n 1 "$f"; echo "$c $id"; tail -n +2 "$f"; } >"$tmp"
  else
    { echo "$c $id"; cat "$f"; } >"$tmp"
  fi
  chmod --reference="$f" "$tmp"
  mv "$tmp" "$f"
  echo "spdx: $f"
done < <(files "$@")

if [ $check -eq 1 ] && [ $missing -gt 0 ]; then
  echo "spdx: $missing source file(s) without the licence line" >&2
  exit 1
fi

#!/bin/bash
# SPDX-License-Identifier: Apache-2.0
# The ball-bar report of a simulated circle with a planted backlash (20 µm on
# x) and squareness (100 µrad) printed by headless Chromium: the PDF must be
# exactly one page, and the page must hold every section. Exit 77 (skipped)
# only when chromium is not installed.
# Usage: ballbar_report_page.sh CPM SOURCE_DIR
set -eu
cpm=$1 src=$2
chromium=$(command -v chromium || command -v chromium-browser || true)
if [ -z "$chromium" ]; then
  echo "SKIPPED: chromium is not installed (apt-get install chromium); the one-page print is not checked"
  exit 77
fi
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
"$cpm" circular-test --kinematic --truth "$src/tests/calibration/data/ballbar_planted.yaml" \
  --model "$src/config/machine.yaml" --magnification 5 --tolerances "$src/tests/calibration/data/ballbar_tolerances.yaml" \
  --report "$out/report.html" --report-json "$out/report.json"
for section in 'id="polar"' 'id="figures"' 'id="errors"' 'id="tolerances"' 'backlash x' 'squareness xy' 'FAIL'; do
  grep -q "$section" "$out/report.html" || { echo "the report lacks '$section'"; exit 1; }
done
# Chromium runs as root in CI containers: no sandbox there.
sandbox=()
[ "$(id -u)" = 0 ] && sandbox=(--no-sandbox)
timeout 60 "$chromium" --headless "${sandbox[@]}" --disable-gpu --no-pdf-header-footer \
  --print-to-pdf="$out/report.pdf" "file://$out/report.html" 2>"$out/chromium.log" || { cat "$out/chromium.log"; exit 1; }
pages=$(grep -a -o '/Type */Pages\?' "$out/report.pdf" | grep -c -v Pages || true)
echo "report printed to $pages page(s), $(stat -c %s "$out/report.pdf") bytes"
[ "$pages" = 1 ] || { echo "the report must print on one A4 page, it takes $pages"; exit 1; }
grep -a -q '/MediaBox \[0 0 59[45]' "$out/report.pdf" || { echo "the page is not A4 (595 x 842 pt)"; grep -a -o '/MediaBox[^]]*]' "$out/report.pdf" | head -1; exit 1; }

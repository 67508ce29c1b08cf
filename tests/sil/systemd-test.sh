#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# sil.systemd (docs/sil.md, "cpmd under systemd"): make the cpmd .deb of this
# build with cpack, then boot the systemd guest (tests/sil/systemd-vm.sh) and
# run tests/sil/systemd-checks.sh there. With --prepare: the image only.
#   usage: systemd-test.sh BUILD_DIR [--prepare] [PART]
# PART: ci (ctest sil.systemd), all (the long form, by hand), sim, canopen.
set -euo pipefail
BUILD=$(cd "$1" && pwd); shift
SIL_DIR=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
T=$(mktemp -d "${TMPDIR:-/tmp}/cpm-sil-deb.XXXXXX")
trap 'rm -rf "$T"' EXIT
t0=$SECONDS
# cpack installs from the build tree; the programs are built already (ctest runs after the build).
(cd "$T" && cpack -G DEB --config "$BUILD/CPackConfig.cmake" -B "$T/pkg" >"$T/cpack.log" 2>&1) \
  || { cat "$T/cpack.log"; echo "cpm-sil-systemd: cpack failed" >&2; exit 125; }
deb=$(ls "$T"/pkg/cpmd_*.deb)
echo "cpack: $(basename "$deb") in $((SECONDS - t0)) s"
if [ "${1:-}" = --prepare ]; then
  bash "$SIL_DIR/systemd-vm.sh" --prepare --deb "$deb"; exit
fi
# The canopen part: the virtual drives (built here, not packaged) with the
# libraries the image lacks, and the SIL configuration (config/sil.yaml).
vd=$BUILD/bin/virtual-drives
[ -x "$vd" ] || { echo "cpm-sil-systemd: $vd is not built" >&2; exit 125; }
mkdir -p "$T/lib"
ldd "$vd" | awk '/libgomp/ { print $3 }' | xargs -r cp -t "$T/lib"
CONF=$SIL_DIR/../../config
# The circle's in-process reference: the same build's cpm on the host, in a
# second instead of a minute of the guest's emulated CPU (the drop-in's 200 Hz).
ref=()
if "$BUILD/bin/cpm" sim --trajectory paper-circle --controller computed_torque --rate 200 \
    --json "$T/circle-ref.json" >"$T/circle-ref.log" 2>&1; then
  ref=(--file "$T/circle-ref.json")
else
  echo "cpm-sil-systemd: cpm sim on the host failed, the guest computes the reference:"; cat "$T/circle-ref.log"
fi
rc=0
bash "$SIL_DIR/systemd-vm.sh" --timeout "${CPM_SIL_TIMEOUT:-1100}" --deb "$deb" --file "$vd" --file "$T/lib" \
  --file "$CONF/sil.yaml" --file "$CONF/machine-sil.yaml" "${ref[@]}" -- "$SIL_DIR/systemd-checks.sh" "$@" || rc=$?
exit $rc

#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# LinuxCNC's own loader and motion module on a compensation file written by
# `cpm export-comp`: LinuxCNC (linuxcnc-uspace, not real-time) with the
# linear-delta config of bench/linuxcnc, COMP_FILE on joint 0, moved to a
# few poses; prints "COMP pos-cmd trim motor-pos-cmd" (mm) at each.
#
#   bench/linuxcnc/comp/comp-check.sh COMP_FILE COMP_FILE_TYPE
set -euo pipefail
[ $# -eq 2 ] || { echo "usage: comp-check.sh COMP_FILE COMP_FILE_TYPE" >&2; exit 2; }
here=$(cd "$(dirname "$0")" && pwd)
work=$(mktemp -d)
chmod 755 "$work"
trap 'rm -rf "$work"' EXIT
cp "$here"/../cpm-ldelta.hal "$here"/comp.py "$work"/
cp "$1" "$work"/joint0.comp
# The bench config with this display and the compensation on joint 0.
sed -e 's|^DISPLAY = ./circle.py|DISPLAY = ./comp.py|' \
    -e "s|^\[JOINT_0\]|[JOINT_0]\nCOMP_FILE = joint0.comp\nCOMP_FILE_TYPE = $2|" \
    "$here"/../cpm-ldelta.ini >"$work"/comp.ini
cp "$here"/../cpm-ldelta.var "$work"/cpm-ldelta.var
echo "T1 P1 D0 Z0 ;" >"$work"/cpm-ldelta.tbl
uid=$(id -u nobody)
mkdir -p "$work/fifo"
chown "$uid" "$work/fifo"
if [ "$(id -u)" -eq 0 ]; then export RTAPI_UID=$uid; fi
export RTAPI_FIFO_PATH=$work/fifo/rtapi_fifo RUNTESTS=1
cd "$work"
linuxcnc comp.ini

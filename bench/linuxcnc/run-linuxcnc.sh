#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# LinuxCNC's motion controller with lineardeltakins on a 1 kHz servo thread
# (cpm-ldelta.ini), real-time, circling for SECONDS, its servo thread at
# PRIORITY on CPU, every period's timedelta and function times in OUT.
#
#   bench/linuxcnc/run-linuxcnc.sh SECONDS PRIORITY CPU|"" OUT READY SHIM
#
# READY is written once the circles run and the sampler records. What it
# takes to run LinuxCNC's POSIX real-time here (docs/performance.md):
#  - rtapi_app is setuid root and, started by root, runs as RTAPI_UID (an
#    unprivileged user: nobody) with its socket at RTAPI_FIFO_PATH, a path
#    that user can write;
#  - LINUXCNC_FORCE_REALTIME=1: the kernel is not PREEMPT_RT, and without it
#    rtapi_app takes its non-real-time path (SCHED_OTHER);
#  - SHIM, LD_PRELOADed: rtapi_app raises RLIMIT_RTPRIO to unlimited before
#    it goes real-time and falls back to SCHED_OTHER when that fails, which
#    it does in a container without CAP_SYS_RESOURCE although root may use
#    SCHED_FIFO at any priority (CAP_SYS_NICE); the shim reports only that
#    one raise as done (bench/linuxcnc/rtprio_shim.c);
#  - RUNTESTS=1: the linuxcnc script keeps its output on stdout/stderr
#    instead of files it deletes when it has no terminal.
set -euo pipefail
[ $# -eq 6 ] || { echo "usage: run-linuxcnc.sh SECONDS PRIORITY CPU OUT READY SHIM" >&2; exit 2; }
seconds=$1 priority=$2 cpu=$3 out=$4 ready=$5 shim=$6
here=$(cd "$(dirname "$0")" && pwd)
work=$(mktemp -d)
chmod 755 "$work"   # rtapi_app, as RTAPI_UID, binds its socket below it
trap 'rm -rf "$work"' EXIT
cp "$here"/cpm-ldelta.ini "$here"/cpm-ldelta.hal "$here"/circle.py "$work"/
echo "T1 P1 D0 Z0 ;" >"$work"/cpm-ldelta.tbl
uid=$(id -u nobody)
mkdir -p "$work/fifo"
chown "$uid" "$work/fifo"
if [ "$(id -u)" -eq 0 ]; then export RTAPI_UID=$uid; fi
export RTAPI_FIFO_PATH=$work/fifo/rtapi_fifo LINUXCNC_FORCE_REALTIME=1 RUNTESTS=1 LD_PRELOAD=$shim
export CPM_LINUXCNC_SECONDS=$seconds CPM_LINUXCNC_PRIORITY=$priority CPM_LINUXCNC_CPU=$cpu \
  CPM_LINUXCNC_SAMPLES=$out CPM_LINUXCNC_READY=$ready
cd "$work"
linuxcnc cpm-ldelta.ini

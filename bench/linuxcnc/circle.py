#!/usr/bin/python3
# SPDX-License-Identifier: Apache-2.0
# The "display" of cpm-ldelta.ini (bench/run.sh): no GUI; it does what an
# operator would (e-stop reset, machine on, home, MDI circles) and what the
# comparison needs:
#  - the servo thread at the priority and on the CPU of the comparison
#    (CPM_LINUXCNC_PRIORITY, CPM_LINUXCNC_CPU): LinuxCNC gives its fastest
#    thread the highest SCHED_FIFO priority there is, cpmd and cyclictest run
#    at the loop's priority, so the thread is set to that one;
#  - the sampler on while the circles run, halsampler writing every period
#    to CPM_LINUXCNC_SAMPLES, and CPM_LINUXCNC_READY written once it samples;
#  - circles for CPM_LINUXCNC_SECONDS, then it leaves, which ends LinuxCNC.
import os
import subprocess
import sys
import time

import linuxcnc

seconds = float(os.environ.get("CPM_LINUXCNC_SECONDS", "10"))
cpu = os.environ.get("CPM_LINUXCNC_CPU", "")
priority = int(os.environ.get("CPM_LINUXCNC_PRIORITY", "0"))
samples = os.environ.get("CPM_LINUXCNC_SAMPLES", "")
ready = os.environ.get("CPM_LINUXCNC_READY", "")
c, s = linuxcnc.command(), linuxcnc.stat()


def wait(pred, timeout, what):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        s.poll()
        if pred():
            return
        time.sleep(0.01)
    sys.exit(f"circle.py: {what} did not happen within {timeout} s")


def servo_thread():
    """rtapi_app's SCHED_FIFO thread (the only real-time one: one thread in the ini)."""
    pid = subprocess.run(["pidof", "rtapi_app"], capture_output=True, text=True).stdout.split()
    found = []
    for p in pid:
        for tid in os.listdir(f"/proc/{p}/task"):
            try:
                if os.sched_getscheduler(int(tid)) == os.SCHED_FIFO:
                    found.append(int(tid))
            except OSError:
                pass
    if len(found) != 1:
        sys.exit(f"circle.py: expected one SCHED_FIFO thread in rtapi_app, found {found} (is it running real-time?)")
    return found[0]


tid = servo_thread()
before = os.sched_getparam(tid).sched_priority
if priority > 0:
    os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))
if cpu:
    os.sched_setaffinity(tid, {int(cpu)})
print(f"circle.py: servo thread {tid}: SCHED_FIFO {before} -> {os.sched_getparam(tid).sched_priority}, "
      f"CPUs {sorted(os.sched_getaffinity(tid))}", flush=True)

c.state(linuxcnc.STATE_ESTOP_RESET)
c.state(linuxcnc.STATE_ON)
wait(lambda: s.task_state == linuxcnc.STATE_ON, 20, "machine on")
c.home(-1)
wait(lambda: all(s.homed[:3]), 30, "homing")
c.mode(linuxcnc.MODE_MDI)
wait(lambda: s.task_mode == linuxcnc.MODE_MDI, 20, "MDI mode")
# A circle of 60 mm radius at pi/2 rad/s (the paper's angular speed; its
# 175 mm radius does not fit LinuxCNC's sample delta): 94 mm/s, from its
# start point, one MDI command per circle.
c.mdi("G21 G90 G17 G64 G1 X60 Y0 Z10 F6000")
c.wait_complete(30)
sampler = None
if samples:
    sampler = subprocess.Popen(["halsampler", "-t", samples])
    subprocess.run(["halcmd", "setp", "sampler.0.enable", "1"], check=True)
c.mdi("G2 X60 Y0 I-60 J0 F5655")
time.sleep(0.2)  # the circle is under way before the others start
if ready:
    with open(ready, "w") as f:
        f.write(f"{tid}\n")
t0 = time.monotonic()
circles = 0
while True:
    c.wait_complete(30)
    s.poll()
    if s.task_state != linuxcnc.STATE_ON:
        sys.exit("circle.py: the machine left the on state")
    circles += 1
    if time.monotonic() - t0 >= seconds:
        break
    c.mdi("G2 X60 Y0 I-60 J0 F5655")
if sampler:
    subprocess.run(["halcmd", "setp", "sampler.0.enable", "0"], check=True)
    time.sleep(0.5)  # halsampler empties the FIFO
    sampler.terminate()
    sampler.wait()
print(f"circle.py: {circles} circles in {time.monotonic() - t0:.1f} s", flush=True)

#!/usr/bin/python3
# SPDX-License-Identifier: Apache-2.0
# The "display" of comp-check.sh: machine on, home, then MDI moves; at each
# rest it prints joint 0's commanded position and the compensation LinuxCNC
# adds to it (joint.0.backlash-corr: the trim of its COMP_FILE, interpolated
# by the motion module), then quits, which ends LinuxCNC.
import subprocess
import sys
import time

import linuxcnc

c, s = linuxcnc.command(), linuxcnc.stat()


def wait(pred, timeout, what):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        s.poll()
        if pred():
            return
        time.sleep(0.01)
    sys.exit(f"comp.py: {what} did not happen within {timeout} s")


def pin(name):
    return float(subprocess.run(["halcmd", "getp", name], capture_output=True, text=True, check=True).stdout)


c.state(linuxcnc.STATE_ESTOP_RESET)
c.state(linuxcnc.STATE_ON)
wait(lambda: s.task_state == linuxcnc.STATE_ON, 20, "machine on")
c.home(-1)
wait(lambda: all(s.homed[:3]), 30, "homing")
c.mode(linuxcnc.MODE_MDI)
wait(lambda: s.task_mode == linuxcnc.MODE_MDI, 20, "MDI mode")
for x, y, z in [(0, 0, 0), (60, 0, 10), (-60, 20, 30), (30, -50, -20), (0, 70, 40)]:
    c.mdi(f"G21 G90 G1 X{x} Y{y} Z{z} F3000")
    c.wait_complete(30)
    time.sleep(0.3)
    print(f"COMP {pin('joint.0.pos-cmd'):.9f} {pin('joint.0.backlash-corr'):.12f} {pin('joint.0.motor-pos-cmd'):.9f}",
          flush=True)

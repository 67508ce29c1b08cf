# SPDX-License-Identifier: Apache-2.0
# Stage 2 of the SIL VM's /init, run by busybox ash with the run folder
# (virtio-9p tag "silrun") mounted at /sil. The initramfs has already
# mounted proc, sys, devtmpfs and loaded the modules. This script brings up
# vcan0 and the gpio-sim chip, makes the host's root file system (read-only)
# the root of the test, runs the command and leaves its exit code in /sil/rc
# and as a marker line on the console. Kept out of the initramfs so that a
# change here needs no rebuild of the cached image.

. /sil/sil-env.sh
. /sil/config            # RUN_PATH, RW_MOUNTS ("tag path" lines)

fail() { sil_err "$*"; echo "CPM-SIL-ERROR $*"; sync; poweroff -f; }

mount -t configfs configfs /sys/kernel/config || fail "cannot mount configfs"
sil_net_up || fail "network set-up failed"
sil_gpio_up cpm-sil || fail "gpio-sim set-up failed"
hostname cpm-sil

R=/newroot
mkdir -p $R
# msize: large 9p messages make loading binaries and libraries much faster.
mount -t 9p -o trans=virtio,version=9p2000.L,ro,msize=512000,cache=loose hostroot $R \
  || fail "cannot mount the host's root (9p tag hostroot)"
mount -t proc proc $R/proc || fail "proc"
mount -t sysfs sysfs $R/sys || fail "sysfs"
mount -t configfs configfs $R/sys/kernel/config 2>/dev/null
mount -t debugfs debugfs $R/sys/kernel/debug 2>/dev/null
mount -t devtmpfs devtmpfs $R/dev || fail "devtmpfs"
mkdir -p $R/dev/pts $R/dev/shm
mount -t devpts devpts $R/dev/pts
mount -t tmpfs -o mode=1777 tmpfs $R/dev/shm
mount -t tmpfs -o mode=1777 tmpfs $R/tmp || fail "tmpfs /tmp"
mount -t tmpfs -o mode=755 tmpfs $R/run || fail "tmpfs /run"
echo "$RW_MOUNTS" | while read -r tag path; do
  [ -n "$tag" ] || continue
  mkdir -p "$R$path" 2>/dev/null
  mount -t 9p -o trans=virtio,version=9p2000.L,msize=512000 "$tag" "$R$path" \
    || echo "CPM-SIL-ERROR cannot mount $path read-write"
done
mkdir -p "$R$RUN_PATH"
mount -o bind /sil "$R$RUN_PATH" || fail "cannot bind the run folder at $RUN_PATH"

# What the test sees (the host path exports the same names).
{
  echo "export CPM_SIL=vm"
  echo "export CPM_SIL_CAN=$CPM_SIL_CAN"
  echo "export CPM_SIL_GPIO_CHIP=$CPM_SIL_GPIO_CHIP"
  echo "export CPM_SIL_GPIO_SYSFS=$CPM_SIL_GPIO_SYSFS"
  echo "export CPM_SIL_GPIO_LABEL=$CPM_SIL_GPIO_LABEL"
  echo "export CPM_SIL_GPIO_LINES='$CPM_SIL_GPIO_LINES'"
} > /sil/guest-env

# The command's output goes to the second serial port (a file the host
# follows), raw so that no \r is added.
stty -F /dev/ttyS1 raw -echo 2>/dev/null
echo "CPM-SIL-START"
chroot $R /bin/bash "$RUN_PATH/cmd.sh" </dev/null >/dev/ttyS1 2>&1
rc=$?
echo "$rc" > /sil/rc.tmp && mv /sil/rc.tmp /sil/rc
sync
echo "CPM-SIL-EXIT $rc"
poweroff -f

#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# Boot Debian bookworm with systemd as PID 1 under QEMU (TCG) and run a check
# script there as root, with the cpmd packages of this build in the run
# folder, to be installed with dpkg inside the guest (docs/sil.md, "cpmd
# under systemd").
#
# The root file system is made from Debian's packages with mmdebstrap and
# cached as an ext4 image, keyed on the package list and the candidate
# versions (not on the .deb, which changes with every build); the guest
# boots it read-write with a QEMU snapshot, so every run starts from the same
# image. The kernel, its modules (CAN, vcan, virtio, 9p, ext4) and gpio-sim
# are the SIL runner's (tests/sil/run-in-vm.sh --export); a busybox
# initramfs loads them, mounts the image and hands over to systemd.
#
#   systemd-vm.sh --prepare --deb DEB              build (or find) the image only
#   systemd-vm.sh [--timeout S] [--keep] [--mem MiB] --deb DEB [--deb DEB2]
#                 [--file PATH]... -- SCRIPT [ARG...]
#
# SCRIPT runs in the guest as a unit of its own (cpm-sil-check.service) with
# the run folder mounted at /sil (the debs and each --file are there); its
# output is streamed to stdout. Exit status: SCRIPT's; 124 on time-out; 125
# when the runner failed (image, boot, no result).
set -euo pipefail

SIL_DIR=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
CACHE_ROOT=${CPM_SIL_CACHE:-${XDG_CACHE_HOME:-${HOME:-/var/tmp}/.cache}/cpmd-sil}
TIMEOUT=${CPM_SIL_TIMEOUT:-600}
MEM=${CPM_SIL_SYSTEMD_MEM:-384}
KEEP=${CPM_SIL_KEEP:-0}
PREPARE_ONLY=0
DEBS=() FILES=()

die() { echo "cpm-sil-systemd: error: $*" >&2; exit 125; }
note() { echo "cpm-sil-systemd: $*" >&2; }

while [ $# -gt 0 ]; do
  case $1 in
    --prepare) PREPARE_ONLY=1; shift ;;
    --deb) DEBS+=("$(readlink -f "${2:?--deb DEB}")"); shift 2 ;;
    --file) FILES+=("$(readlink -f "${2:?--file PATH}")"); shift 2 ;;
    --timeout) TIMEOUT=${2:?--timeout S}; shift 2 ;;
    --mem) MEM=${2:?--mem MiB}; shift 2 ;;
    --keep) KEEP=1; shift ;;
    --) shift; break ;;
    *) die "unknown argument $1 (see the head of $0)" ;;
  esac
done
[ ${#DEBS[@]} -gt 0 ] || die "--deb DEB (the cpmd package) is required: its Depends go into the image"
for d in "${DEBS[@]}"; do [ -f "$d" ] || die "no package $d"; done
[ $PREPARE_ONLY = 1 ] || [ $# -gt 0 ] || die "no SCRIPT to run"

# The image: what cpmd and the checks need, nothing more. No udev (devtmpfs
# is enough; the checks give the GPIO chip to cpmd as the udev rule of
# docs/install.md would), no dbus (systemctl talks to PID 1's private
# socket as root), no apt, no documentation.
BASE_PACKAGES=(systemd systemd-sysv iproute2)
deb_depends() {  # the first alternative of each Depends entry of the packages
  local d
  for d in "${DEBS[@]}"; do dpkg-deb -f "$d" Depends; done | tr ',' '\n' \
    | sed 's/|.*//; s/(.*//; s/[[:space:]]//g' | grep -v '^$' | grep -vx 'cpmd' | sort -u
}

customize_rootfs() {  # mmdebstrap customize hook; $1 is the root
  local r=$1
  echo cpm-sil > "$r/etc/hostname"
  : > "$r/etc/fstab"
  ln -sf /lib/systemd/system/multi-user.target "$r/etc/systemd/system/default.target"
  # Boot time under TCG: nothing that waits for a login, a clock, a timer;
  # nothing the image has done already (users, machine-id, a read-write root,
  # the initramfs's modules) or that cpmd does not use (a random seed, mqueue,
  # tracing, binfmt).
  local u
  for u in getty@tty1.service serial-getty@ttyS0.service console-getty.service systemd-logind.service \
           systemd-timesyncd.service systemd-networkd-wait-online.service e2scrub_reap.service \
           e2scrub_all.timer fstrim.timer dpkg-db-backup.timer apt-daily.timer apt-daily-upgrade.timer \
           man-db.timer systemd-tmpfiles-clean.timer systemd-update-utmp.service \
           systemd-update-utmp-runlevel.service getty-static.service dev-hugepages.mount \
           modprobe@configfs.service modprobe@dm_mod.service modprobe@drm.service modprobe@efi_pstore.service \
           modprobe@fuse.service modprobe@loop.service systemd-pstore.service \
           systemd-sysusers.service systemd-random-seed.service systemd-modules-load.service \
           systemd-remount-fs.service systemd-firstboot.service dev-mqueue.mount sys-kernel-tracing.mount \
           sys-kernel-debug.mount proc-sys-fs-binfmt_misc.automount; do
    ln -sf /dev/null "$r/etc/systemd/system/$u"
  done
  # LCM asks for a 4 MB receive buffer (lcm-proj.github.io/multicast_setup.html).
  echo 'net.core.rmem_max = 4194304' > "$r/etc/sysctl.d/60-cpm-lcm.conf"
  cat > "$r/usr/local/sbin/cpm-sil-check" <<'EOF'
#!/bin/sh
# Mount the run folder, run its check script, leave the exit code in /sil/rc
# and on the console (CPM-SIL-EXIT n), power off.
mkdir -p /sil
if ! mount -t 9p -o trans=virtio,version=9p2000.L,msize=512000 silrun /sil; then
  echo "CPM-SIL-ERROR cannot mount the run folder (9p tag silrun)" >/dev/console
  systemctl poweroff --force --force
fi
rc=0
/bin/bash /sil/cmd.sh </dev/null >>/sil/output.log 2>&1 || rc=$?
echo "$rc" > /sil/rc.tmp && mv /sil/rc.tmp /sil/rc
sync
echo "CPM-SIL-EXIT $rc" >/dev/console
systemctl poweroff --force --force
EOF
  chmod 755 "$r/usr/local/sbin/cpm-sil-check"
  cat > "$r/etc/systemd/system/cpm-sil-check.service" <<'EOF'
[Unit]
Description=cpm SIL checks (the run folder's script)
After=basic.target network.target
[Service]
Type=exec
ExecStart=/usr/local/sbin/cpm-sil-check
StandardOutput=journal+console
[Install]
WantedBy=multi-user.target
EOF
  mkdir -p "$r/etc/systemd/system/multi-user.target.wants"
  ln -sf /etc/systemd/system/cpm-sil-check.service "$r/etc/systemd/system/multi-user.target.wants/"
  rm -rf "$r/var/cache/apt/archives/"*.deb "$r/var/lib/apt/lists/"* 2>/dev/null || true
}

init_script() {
  cat <<'EOF'
#!/bin/busybox sh
# cpm-sil systemd guest: load the modules, mount the root image, hand over to systemd.
/bin/busybox --install -s /bin
export PATH=/bin
mount -t proc proc /proc
mount -t sysfs sysfs /sys
mount -t devtmpfs devtmpfs /dev
for m in $(cat /lib/modules/order); do
  insmod /lib/modules/$m || echo "CPM-SIL-ERROR insmod $m failed"
done
i=0
while [ ! -b /dev/vda ] && [ $i -lt 200 ]; do sleep 0.05; i=$((i + 1)); done
mkdir -p /newroot
if ! mount -t ext4 -o rw /dev/vda /newroot; then
  echo "CPM-SIL-ERROR cannot mount the root image /dev/vda"; poweroff -f
fi
umount /proc /sys
mount --move /dev /newroot/dev
exec switch_root /newroot /lib/systemd/systemd
EOF
}

prepare() {
  for t in mke2fs qemu-system-x86_64 dpkg-deb; do
    command -v $t >/dev/null || die "$t is missing (bash tools/setup.sh installs it)"
  done
  mkdir -p "$CACHE_ROOT"
  local parts=$CACHE_ROOT/systemd-parts
  local pkgs; pkgs=$(printf '%s\n' "${BASE_PACKAGES[@]}" $(deb_depends) | sort -u | tr '\n' ' ')
  # Where the root file system comes from: this host's own installed packages
  # when it runs bookworm and has them all (seconds), else Debian's mirror
  # through mmdebstrap (minutes). CPM_SIL_ROOTFS=host|mmdebstrap forces one.
  local source=${CPM_SIL_ROOTFS:-auto} versions
  if [ "$source" = auto ]; then
    source=mmdebstrap
    if grep -q '^12\.' /etc/debian_version 2>/dev/null && command -v python3 >/dev/null \
        && python3 "$SIL_DIR/host-rootfs.py" list $pkgs >/dev/null 2>&1; then
      source=host
    fi
  fi
  case $source in
    host)
      versions=$(python3 "$SIL_DIR/host-rootfs.py" list $pkgs) || die "host-rootfs.py list failed (above)"
      versions+=$'\n'"host-rootfs $(sha256sum < "$SIL_DIR/host-rootfs.py" | cut -c1-16)" ;;
    mmdebstrap)
      command -v mmdebstrap >/dev/null || die "mmdebstrap is missing (bash tools/setup.sh installs it)"
      versions=$(apt-cache policy $pkgs 2>/dev/null | awk '/^[^ ]/ { p = $1 } /Candidate:/ { print p, $2 }')
      if echo "$versions" | grep -q '(none)'; then
        die "packages without an installable version in the apt lists: $(echo "$versions" | awk '$2 == "(none)" { printf "%s ", $1 }')(apt-get update?)"
      fi ;;
    *) die "CPM_SIL_ROOTFS=$source: host or mmdebstrap" ;;
  esac
  local key; key=$( { echo "$versions"; declare -f customize_rootfs init_script; } | sha256sum | cut -c1-16)
  IMG_DIR=$CACHE_ROOT/systemd-$key
  exec 8>"$CACHE_ROOT/.systemd-lock"
  flock 8
  # The kernel's parts: the SIL runner's image, plus what mounts an ext4 root
  # (copied once; again only when the kernel or gpio-sim change).
  bash "$SIL_DIR/run-in-vm.sh" --export "$parts" crc32c_generic virtio_blk ext4 >&2 \
    || die "the SIL runner could not prepare the kernel and modules"
  if [ ! -f "$IMG_DIR/rootfs.img" ]; then
    local t0=$SECONDS x
    x=$(mktemp -d "$CACHE_ROOT/.sd.XXXXXX")
    note "building the systemd guest's root file system from $source (packages: $pkgs)"
    local sources=/etc/apt/sources.list.d/debian.sources
    [ -f $sources ] || sources=/etc/apt/sources.list
    { declare -f customize_rootfs; echo 'customize_rootfs "$1"'; } > "$x/customize.sh"
    if [ "$source" = host ]; then
      if ! python3 "$SIL_DIR/host-rootfs.py" copy "$x/root" $pkgs > "$x/host-rootfs.log" 2>&1; then
        tail -30 "$x/host-rootfs.log" >&2; rm -rf "$x"; die "host-rootfs.py copy failed (log above)"
      fi
      mkdir -p "$x/root"/usr/local/{bin,sbin,lib,share} "$x/root/etc/sysctl.d" "$x/root/etc/systemd/system"
      # What the packages' maintainer scripts did on the host: system users,
      # the library cache, a machine-id (no first-boot presets in the guest).
      systemd-sysusers --root "$x/root" >/dev/null && ldconfig -r "$x/root" \
        && systemd-machine-id-setup --root "$x/root" >/dev/null \
        || { rm -rf "$x"; die "systemd-sysusers, ldconfig or systemd-machine-id-setup on the new root failed"; }
      bash "$x/customize.sh" "$x/root"
    elif ! mmdebstrap --variant=essential --mode=root --include="${pkgs// /,}" \
        --aptopt='APT::Install-Recommends "false"' \
        --dpkgopt='path-exclude=/usr/share/man/*' --dpkgopt='path-exclude=/usr/share/doc/*' \
        --dpkgopt='path-exclude=/usr/share/locale/*' --dpkgopt='path-exclude=/usr/share/info/*' \
        --dpkgopt='path-include=/usr/share/doc/*/copyright' \
        --customize-hook="bash $x/customize.sh \"\$1\"" \
        bookworm "$x/root" "$sources" > "$x/mmdebstrap.log" 2>&1; then
      tail -30 "$x/mmdebstrap.log" >&2; rm -rf "$x"; die "mmdebstrap failed (log above)"
    fi
    local mb; mb=$(du -sm "$x/root" | cut -f1)
    # Room for the packages, the journal and the checks' files.
    mke2fs -q -F -t ext4 -L cpm-sil -d "$x/root" "$x/rootfs.img" "$((mb + 256))M" \
      || { rm -rf "$x"; die "mke2fs -d failed"; }
    mkdir -p "$IMG_DIR"
    mv "$x/rootfs.img" "$IMG_DIR/rootfs.img"
    rm -rf "$x"
    note "root file system: $mb MB of files, built in $((SECONDS - t0)) s ($IMG_DIR)"
  fi
  local ikey; ikey=$( { init_script; cat "$parts/modules/order"; sha256sum "$parts"/modules/*.ko "$parts/busybox"; } | sha256sum | cut -c1-16)
  INITRD=$IMG_DIR/initramfs-$ikey.cpio.gz
  if [ ! -f "$INITRD" ]; then
    local x; x=$(mktemp -d "$CACHE_ROOT/.sd.XXXXXX")
    mkdir -p "$x"/{bin,dev,proc,sys,newroot,lib/modules}
    cp "$parts/busybox" "$x/bin/busybox"
    cp "$parts"/modules/* "$x/lib/modules/"
    init_script > "$x/init"; chmod 755 "$x/init"
    (cd "$x" && find . | LC_ALL=C sort | "$parts/busybox" cpio -o -H newc 2>/dev/null) | gzip -1 > "$INITRD.tmp"
    mv "$INITRD.tmp" "$INITRD"
    find "$IMG_DIR" -maxdepth 1 -name 'initramfs-*.cpio.gz' ! -name "$(basename "$INITRD")" -delete
    rm -rf "$x"
  fi
  KERNEL=$parts/vmlinux
  flock -u 8
}

t0=$SECONDS
prepare
note "image ready in $((SECONDS - t0)) s: $IMG_DIR"
[ $PREPARE_ONLY = 0 ] || exit 0

run=$(mktemp -d "${TMPDIR:-/tmp}/cpm-sil-systemd.XXXXXX")
chmod 755 "$run"
cp "${DEBS[@]}" "$run/"
for f in "${FILES[@]}"; do cp -r "$f" "$run/"; done
cp "$SIL_DIR/sil-env.sh" "$run/"
cp "$1" "$run/check.sh"; shift
{
  echo '#!/bin/bash'
  echo 'cd /sil || exit 125'
  printf 'exec /bin/bash /sil/check.sh'; printf ' %q' "$@"; echo
} > "$run/cmd.sh"
: > "$run/output.log"

qemu=(qemu-system-x86_64 -accel tcg -cpu max -m "$MEM" -smp 1
  -nodefaults -no-user-config -display none -no-reboot
  -kernel "$KERNEL" -initrd "$INITRD"
  -append "console=ttyS0 panic=-1 rw ${CPM_SIL_KERNEL_ARGS:-quiet loglevel=3}"
  -drive "file=$IMG_DIR/rootfs.img,format=raw,if=virtio,snapshot=on"
  -chardev "file,id=con,path=$run/console.log" -serial chardev:con
  -virtfs "local,path=${run//,/,,},mount_tag=silrun,security_model=none")
t1=$SECONDS qrc=0
# QEMU's CPU seconds (user + system, from bash's `times`): what the guest
# costs the host, which a loaded host's wall time hides.
( qrc=0; timeout -k 5 "$TIMEOUT" "${qemu[@]}" </dev/null >"$run/qemu.log" 2>&1 || qrc=$?
  times > "$run/qemu-cpu"; exit $qrc ) &
qpid=$!
tail -n +1 -s 0.2 -f --pid=$qpid "$run/output.log" &
tpid=$!
wait $qpid || qrc=$?
wait $tpid 2>/dev/null || true
if [ -f "$run/rc" ]; then
  rc=$(cat "$run/rc")
else
  rc=$(tr -d '\r' < "$run/console.log" 2>/dev/null | sed -n 's/.*CPM-SIL-EXIT \([0-9]*\).*/\1/p' | tail -1)
fi
if [ -z "$rc" ]; then
  if [ $qrc = 124 ] || [ $qrc = 137 ]; then note "time-out: the guest ran more than $TIMEOUT s"; rc=124
  else note "the guest ended without reporting an exit code (qemu exit $qrc)"; rc=125; fi
  note "--- qemu: $(tail -5 "$run/qemu.log" | tr '\n' ' ')"
  note "--- last lines of the serial console ($run/console.log):"
  tr -d '\r' < "$run/console.log" | tail -30 | sed 's/^/  | /' >&2
  KEEP=1
elif [ "$rc" != 0 ]; then
  KEEP=1
fi
cpu=$(awk 'END { for (i = 1; i <= 2; i++) { split($i, t, /[ms]/); s += t[1] * 60 + t[2] } printf "%.1f", s }' "$run/qemu-cpu" 2>/dev/null)
note "guest run took $((SECONDS - t1)) s, QEMU ${cpu:-?} s of CPU; exit $rc"
if [ "$KEEP" = 1 ]; then note "run folder kept: $run"; else rm -rf "$run"; fi
exit "$rc"

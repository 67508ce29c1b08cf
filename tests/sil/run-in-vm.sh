#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# SIL runner: run COMMAND where a real kernel CAN stack (vcan0) and a
# simulated GPIO chip (gpio-sim) exist, and return COMMAND's exit status.
#
# On a host that can create a vcan interface (and, if GPIO is needed, has
# gpio-sim), COMMAND runs on the host inside a fresh network namespace.
# Otherwise (CI machines here: no CAN, no gpio in the running kernel) it
# boots Debian's own, pinned kernel under QEMU (TCG) with a busybox
# initramfs, the host's root file system shared read-only over virtio-9p so
# host-built binaries run in place, and runs COMMAND there.
# Downloads and built files are cached outside the work tree.
# See docs/sil.md.
set -euo pipefail

usage() {
  cat <<'EOF'
usage: run-in-vm.sh [options] [--] COMMAND [ARG...]
       run-in-vm.sh --prepare          download and build the VM image only
       run-in-vm.sh --export DIR [MODULE...]
                                       prepare, then copy into DIR the kernel (vmlinux),
                                       busybox, and modules/ (the guest's modules, MODULE...
                                       and their dependencies, gpio-sim.ko; load order in
                                       modules/order): another image's parts (systemd-vm.sh)

options:
  --auto            run on the host if it has what --needs asks, else in the VM (default)
  --vm              always boot the VM
  --host            always run on the host (fails if the host lacks vcan / gpio-sim)
  --needs LIST      what COMMAND needs: can, gpio or can,gpio (default can,gpio)
  --timeout S       limit for the whole run, boot included (default 300 s)
  --rw DIR          make host folder DIR writable inside the VM (repeatable). The
                    current folder always is; the rest of the host is read-only,
                    and the guest has its own /tmp and /run.
  --keep            keep the run folder (serial console log, output) even on success
  -h, --help        this text

environment:
  CPM_SIL_MODE=auto|vm|host, CPM_SIL_TIMEOUT, CPM_SIL_MEM (MiB, 512), CPM_SIL_SMP (1)
  CPM_SIL_CACHE       cache folder (default ${XDG_CACHE_HOME:-$HOME/.cache}/cpmd-sil)
  CPM_SIL_KERNEL_ABI  pinned kernel ABI, e.g. 6.1.0-50 (package linux-image-<ABI>-amd64)
  CPM_SIL_KERNEL_VERSION  its Debian version, e.g. 6.1.176-1 (also linux-source-6.1's)
  CPM_SIL_KEEP=1      same as --keep
  CPM_SIL_KERNEL_ARGS extra kernel command line (default "quiet loglevel=3"; set to
                      "loglevel=7" to see the whole boot in the serial console log)

COMMAND sees: CPM_SIL=vm|host, CPM_SIL_CAN=vcan0, CPM_SIL_GPIO_CHIP=/dev/gpiochipN,
CPM_SIL_GPIO_SYSFS=<dir with sim_gpioN/{pull,value}>, CPM_SIL_GPIO_LABEL, CPM_SIL_GPIO_LINES.
exit status: COMMAND's; 124 on time-out; 125 when the runner itself failed
(download, build, boot, no result from the VM).
EOF
}

# --- pinned versions --------------------------------------------------------
# The linux-image-amd64 metapackage moves with every Debian update, and
# gpio-sim must be built from the exact same source, so the release is
# pinned here. To move it: apt-cache madison linux-source-6.1, pick a version
# V whose linux-image-<ABI>-amd64, linux-headers-<ABI>-{amd64,common} and
# linux-kbuild-6.1 are also at V (docs/sil.md).
KABI=${CPM_SIL_KERNEL_ABI:-6.1.0-50}
KVER=${CPM_SIL_KERNEL_VERSION:-6.1.176-1}
FLAVOUR=amd64
KREL=$KABI-$FLAVOUR

SIL_DIR=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
CACHE_ROOT=${CPM_SIL_CACHE:-${XDG_CACHE_HOME:-${HOME:-/var/tmp}/.cache}/cpmd-sil}
KDIR=$CACHE_ROOT/$KREL-$KVER
MODE=${CPM_SIL_MODE:-auto}
TIMEOUT=${CPM_SIL_TIMEOUT:-300}
MEM=${CPM_SIL_MEM:-512}
SMP=${CPM_SIL_SMP:-1}  # one vCPU boots in about half the time of two under TCG
KEEP=${CPM_SIL_KEEP:-0}
NEEDS=can,gpio
RW_DIRS=()
PREPARE_ONLY=0
EXPORT_DIR=""

# Kernel modules the guest needs; their dependencies are resolved from the
# modules' own .modinfo, so the load order follows the pinned kernel.
GUEST_MODULES=(configfs can can-raw can-dev vcan virtio_pci 9pnet_virtio 9p)

die() { echo "cpm-sil: error: $*" >&2; exit 125; }
note() { echo "cpm-sil: $*" >&2; }

while [ $# -gt 0 ]; do
  case $1 in
    --auto|--vm|--host) MODE=${1#--}; shift ;;
    --needs) NEEDS=${2:?--needs LIST}; shift 2 ;;
    --timeout) TIMEOUT=${2:?--timeout SECONDS}; shift 2 ;;
    --rw) RW_DIRS+=("$(cd "${2:?--rw DIR}" && pwd)") || die "--rw: no folder $2"; shift 2 ;;
    --keep) KEEP=1; shift ;;
    --prepare) PREPARE_ONLY=1; shift ;;
    --export) PREPARE_ONLY=1; MODE=vm; EXPORT_DIR=${2:?--export DIR}; shift 2; break ;;
    -h|--help) usage; exit 0 ;;
    --) shift; break ;;
    -*) die "unknown option $1 (see --help)" ;;
    *) break ;;
  esac
done
case $MODE in auto|vm|host) ;; *) die "CPM_SIL_MODE/--mode must be auto, vm or host, not '$MODE'" ;; esac
[[ $TIMEOUT =~ ^[0-9]+$ ]] || die "--timeout/CPM_SIL_TIMEOUT must be whole seconds, not '$TIMEOUT'"
need_can=0; need_gpio=0
IFS=, read -ra _needs <<<"$NEEDS"
for n in "${_needs[@]}"; do
  case $n in can) need_can=1 ;; gpio) need_gpio=1 ;; "") ;; *) die "--needs: unknown '$n' (can, gpio)" ;; esac
done
if [ $PREPARE_ONLY = 0 ] && [ $# -eq 0 ]; then usage >&2; exit 125; fi
if [ -n "$EXPORT_DIR" ]; then GUEST_MODULES+=("$@"); set --; fi

# --- host path ---------------------------------------------------------------
host_can_ok() {
  command -v ip >/dev/null && command -v unshare >/dev/null || return 1
  local u=(unshare --net); [ "$(id -u)" -eq 0 ] || u=(unshare --user --map-root-user --net)
  "${u[@]}" sh -c 'ip link add dev vcan0 type vcan' >/dev/null 2>&1
}
host_gpio_ok() {
  [ "$(id -u)" -eq 0 ] || return 1
  [ -d /sys/kernel/config/gpio-sim ] || modprobe gpio-sim >/dev/null 2>&1 || return 1
  [ -d /sys/kernel/config/gpio-sim ]
}
host_ok() {
  { [ $need_can = 0 ] || host_can_ok; } && { [ $need_gpio = 0 ] || host_gpio_ok; }
}

HOST_GPIO_DEV=""
run_on_host() {
  local rc=0
  # shellcheck source=sil-env.sh
  . "$SIL_DIR/sil-env.sh"
  if [ $need_gpio = 1 ]; then
    HOST_GPIO_DEV=cpm-sil-$$
    trap 'sil_gpio_down "$HOST_GPIO_DEV"' EXIT
    sil_gpio_up "$HOST_GPIO_DEV" || die "gpio-sim set-up failed on the host"
  fi
  local u=(unshare --net); [ "$(id -u)" -eq 0 ] || u=(unshare --user --map-root-user --net)
  # A fresh network namespace per run: vcan0 and LCM's multicast are private
  # to this test, so tests running in parallel do not hear each other.
  CPM_SIL=host "${u[@]}" bash -c '. "$1"; shift; sil_net_up "$1" >&2 || exit 125; shift; exec "$@"' \
    sil "$SIL_DIR/sil-env.sh" "$([ $need_can = 1 ] && echo can || echo lo-only)" "$@" || rc=$?
  return $rc
}

# --- VM image: download, build, cache ---------------------------------------
apt_has() { apt-cache madison "$1" 2>/dev/null | awk -v v="$2" '$3 == v { f = 1 } END { exit !f }'; }

download() {  # download DEST PKG=VER...
  local dest=$1; shift
  local tmp; tmp=$(mktemp -d "$CACHE_ROOT/.dl.XXXXXX")
  local opts=(-q); [ "$(id -u)" -eq 0 ] && opts+=(-o APT::Sandbox::User=root)
  if ! (cd "$tmp" && apt-get download "${opts[@]}" "$@" >&2); then
    rm -rf "$tmp"; die "apt-get download $* failed (is a Debian mirror reachable?)"
  fi
  mkdir -p "$dest"; mv "$tmp"/*.deb "$dest"/; rmdir "$tmp"
}

check_pinned() {
  local pkgs=(linux-image-$KREL linux-headers-$KREL linux-headers-$KABI-common linux-kbuild-6.1 linux-source-6.1)
  local p missing=()
  for p in "${pkgs[@]}"; do apt_has "$p" "$KVER" || missing+=("$p"); done
  if [ ${#missing[@]} -gt 0 ] && [ "$(id -u)" -eq 0 ]; then
    note "pinned packages not in the apt lists; running apt-get update"
    apt-get update -qq >&2 || true
    missing=(); for p in "${pkgs[@]}"; do apt_has "$p" "$KVER" || missing+=("$p"); done
  fi
  if [ ${#missing[@]} -gt 0 ]; then
    {
      echo "cpm-sil: error: the pinned kernel $KREL $KVER is not available from the mirror:"
      echo "  missing: ${missing[*]/%/=$KVER}"
      echo "  linux-source-6.1 versions the mirror has: $(apt-cache madison linux-source-6.1 2>/dev/null | awk '{printf "%s ", $3}')"
      echo "  Pick a version V that also has linux-image-<ABI>-amd64 and linux-kbuild-6.1, then set"
      echo "  CPM_SIL_KERNEL_VERSION=V CPM_SIL_KERNEL_ABI=<ABI> (or move the pin in tests/sil/run-in-vm.sh)."
      echo "  e.g. apt-cache madison linux-kbuild-6.1; apt-cache madison linux-image-6.1.0-NN-amd64"
    } >&2
    exit 125
  fi
}

# mod_deps NAME: NAME's dependencies, from the .ko's .modinfo section.
declare -A MOD_PATH=() MOD_DONE=()
MOD_ORDER=()
mod_resolve() {
  local name=$1 key=${1//-/_}
  [ -n "${MOD_DONE[$key]:-}" ] && return 0
  local ko=${MOD_PATH[$key]:-}
  [ -n "$ko" ] || die "kernel module $name not found in $KREL (is it built in? see the kernel's config)"
  MOD_DONE[$key]=1
  local deps d
  local -a _deps
  deps=$(objcopy -O binary --only-section=.modinfo "$ko" /dev/stdout | tr '\0' '\n' | sed -n 's/^depends=//p')
  IFS=, read -ra _deps <<<"$deps"
  for d in "${_deps[@]}"; do [ -n "$d" ] && mod_resolve "$d"; done
  MOD_ORDER+=("$ko")
}

build_kernel() {  # vmlinux and the guest's modules, from linux-image
  local x; x=$(mktemp -d "$CACHE_ROOT/.x.XXXXXX")
  dpkg -x "$KDIR"/debs/linux-image-"$KREL"_*.deb "$x"
  local bz=$x/boot/vmlinuz-$KREL
  [ -f "$bz" ] || die "no /boot/vmlinuz-$KREL in linux-image-$KREL"
  # Boot the uncompressed ELF (CONFIG_PVH=y): about half the boot time of the
  # bzImage under TCG. It is the xz stream inside the bzImage.
  local off
  off=$(LC_ALL=C grep -obUaP '\xfd7zXZ\x00' "$bz" | head -1 | cut -d: -f1 || true)
  if [ -n "$off" ]; then
    tail -c +$((off + 1)) "$bz" | xz -dcq > "$x/vmlinux" 2>/dev/null || true
  fi
  if ! [ -s "$x/vmlinux" ] || [ "$(head -c4 "$x/vmlinux" | od -An -tx1 | tr -d ' ')" != 7f454c46 ]; then
    note "could not extract an ELF vmlinux; booting the bzImage (slower)"
    cp "$bz" "$x/vmlinux"
  fi
  local ko base
  while IFS= read -r ko; do
    base=$(basename "$ko" .ko); MOD_PATH[${base//-/_}]=$ko
  done < <(find "$x/lib/modules/$KREL" -name '*.ko')
  for m in "${GUEST_MODULES[@]}"; do mod_resolve "$m"; done
  mkdir -p "$x/modules"
  for ko in "${MOD_ORDER[@]}"; do
    cp "$ko" "$x/modules/"; basename "$ko" >> "$x/modules/order"
  done
  # Into the cache only when complete (an interrupted run leaves no half image).
  rm -rf "$KDIR/modules" "$KDIR/vmlinux"
  mv "$x/modules" "$KDIR/modules"
  mv "$x/vmlinux" "$KDIR/vmlinux"
  rm -rf "$x"
}

build_gpio_sim() {
  # gpio-sim is not built in Debian's kernel (nor gpio-mockup, nor IRQ_SIM):
  # build it out of tree from the matching source, with irq_sim.c linked in.
  local x; x=$(mktemp -d "$CACHE_ROOT/.x.XXXXXX")
  local d
  for d in "$KDIR"/debs/linux-headers-*.deb "$KDIR"/debs/linux-kbuild-*.deb; do dpkg -x "$d" "$x/root"; done
  local hdr=$x/root/usr/src/linux-headers-$KREL
  [ -f "$hdr/Makefile" ] || die "linux-headers-$KREL has no Makefile"
  # The headers' Makefile includes the -common tree by an absolute /usr/src path.
  sed -i "s|/usr/src/|$x/root/usr/src/|g" "$hdr/Makefile"
  mkdir -p "$x/src" "$x/mod"
  dpkg-deb --fsys-tarfile "$KDIR"/debs/linux-source-6.1_*.deb \
    | tar -xO ./usr/src/linux-source-6.1.tar.xz \
    | tar -xJ -C "$x/src" linux-source-6.1/drivers/gpio/gpio-sim.c \
        linux-source-6.1/drivers/gpio/gpiolib.h linux-source-6.1/kernel/irq/irq_sim.c \
    || die "cannot extract gpio-sim.c, gpiolib.h, irq_sim.c from linux-source-6.1 $KVER"
  cp "$x/src/linux-source-6.1/drivers/gpio/gpio-sim.c" "$x/mod/gpio-sim-core.c"
  cp "$x/src/linux-source-6.1/drivers/gpio/gpiolib.h" "$x/src/linux-source-6.1/kernel/irq/irq_sim.c" "$x/mod/"
  # irq_to_desc is not exported to modules: dispatch through the domain instead.
  perl -0pi -e 's/irqnum = irq_find_mapping\(work_ctx->domain, offset\);\n\s*handle_simple_irq\(irq_to_desc\(irqnum\)\);/generic_handle_domain_irq(work_ctx->domain, offset);/; s/\n\tint irqnum;//' "$x/mod/irq_sim.c"
  grep -q 'generic_handle_domain_irq(work_ctx->domain, offset)' "$x/mod/irq_sim.c" \
    || die "irq_sim.c of $KVER does not have the expected shape; cannot patch it (see docs/sil.md)"
  printf 'obj-m := gpio-sim.o\ngpio-sim-y := gpio-sim-core.o irq_sim.o\n' > "$x/mod/Kbuild"
  if ! make -s -C "$hdr" M="$x/mod" modules > "$x/build.log" 2>&1; then
    cat "$x/build.log" >&2; die "building gpio-sim.ko failed (log above; needs gcc-12 and make)"
  fi
  mv "$x/mod/gpio-sim.ko" "$KDIR/gpio-sim.ko"
  rm -rf "$x"
}

busybox_bin() {
  local bb=$CACHE_ROOT/busybox/busybox
  if [ ! -x "$bb" ]; then
    download "$CACHE_ROOT/busybox/debs" busybox-static
    local x; x=$(mktemp -d "$CACHE_ROOT/.x.XXXXXX")
    dpkg -x "$CACHE_ROOT"/busybox/debs/busybox-static_*.deb "$x"
    cp "$x/bin/busybox" "$bb.tmp" && mv "$bb.tmp" "$bb"
    rm -rf "$x"
  fi
  echo "$bb"
}

init_script() {
  cat <<'EOF'
#!/bin/busybox sh
# cpm-sil initramfs: mount the basics, load modules, hand over to the run's stage 2.
/bin/busybox --install -s /bin
export PATH=/bin
mount -t proc proc /proc
mount -t sysfs sysfs /sys
mount -t devtmpfs devtmpfs /dev
for m in $(cat /lib/modules/order); do
  insmod /lib/modules/$m || echo "CPM-SIL-ERROR insmod $m failed"
done
mkdir -p /sil
if mount -t 9p -o trans=virtio,version=9p2000.L,msize=512000 silrun /sil; then
  . /sil/sil-guest.sh
fi
echo "CPM-SIL-ERROR stage 2 did not run"
poweroff -f
EOF
}

build_initramfs() {  # echo the path of the (cached) initramfs
  local bb; bb=$(busybox_bin)
  local key; key=$( { init_script; cat "$KDIR/modules/order"; sha256sum "$bb" "$KDIR/gpio-sim.ko"; } | sha256sum | cut -c1-16)
  local img=$KDIR/initramfs-$key.cpio.gz
  if [ ! -f "$img" ]; then
    local x; x=$(mktemp -d "$CACHE_ROOT/.x.XXXXXX")
    mkdir -p "$x"/{bin,dev,proc,sys,tmp,lib/modules}
    cp "$bb" "$x/bin/busybox"
    cp "$KDIR"/modules/*.ko "$x/lib/modules/"
    cp "$KDIR/gpio-sim.ko" "$x/lib/modules/"
    { cat "$KDIR/modules/order"; echo gpio-sim.ko; } > "$x/lib/modules/order"
    init_script > "$x/init"; chmod 755 "$x/init"
    (cd "$x" && find . | LC_ALL=C sort | "$bb" cpio -o -H newc 2>/dev/null) | gzip -1 > "$img.tmp"
    mv "$img.tmp" "$img"
    rm -rf "$x"
    find "$KDIR" -maxdepth 1 -name 'initramfs-*.cpio.gz' ! -name "$(basename "$img")" -delete
  fi
  echo "$img"
}

prepare_vm() {
  for t in apt-get dpkg-deb objcopy xz gzip make perl; do
    command -v $t >/dev/null || die "$t is missing (bash tools/setup.sh installs the build tools)"
  done
  mkdir -p "$CACHE_ROOT"
  exec 9>"$CACHE_ROOT/.lock"
  flock 9   # parallel tests: one prepares, the others wait and reuse
  if [ ! -f "$KDIR/debs/.done" ]; then
    check_pinned
    local t0=$SECONDS
    note "downloading the pinned kernel $KREL $KVER and its sources into $KDIR (about 225 MB, once)"
    rm -rf "$KDIR/debs"
    download "$KDIR/debs" linux-image-"$KREL"="$KVER" linux-headers-"$KREL"="$KVER" \
      linux-headers-"$KABI"-common="$KVER" linux-kbuild-6.1="$KVER" linux-source-6.1="$KVER"
    touch "$KDIR/debs/.done"
    note "downloaded $(du -sm "$KDIR/debs" | cut -f1) MB in $((SECONDS - t0)) s"
  fi
  [ -f "$KDIR/vmlinux" ] && [ -f "$KDIR/modules/order" ] || { note "extracting the kernel and modules"; build_kernel; }
  [ -f "$KDIR/gpio-sim.ko" ] || { note "building gpio-sim.ko for $KREL"; build_gpio_sim; }
  INITRD=$(build_initramfs)
  flock -u 9
}

# export_parts DIR: the parts of the image, for a guest with its own root
# (tests/sil/systemd-vm.sh): vmlinux, busybox, the modules with their order.
export_parts() {
  local dir=$1 x ko base stamp
  # Done already for this kernel, these modules and this gpio-sim build?
  stamp="$KREL $KVER ${GUEST_MODULES[*]} $(stat -c %Y "$KDIR/vmlinux" "$KDIR/gpio-sim.ko" | tr '\n' ' ')"
  [ "$(cat "$dir/.stamp" 2>/dev/null)" != "$stamp" ] || return 0
  x=$(mktemp -d "$CACHE_ROOT/.x.XXXXXX")
  dpkg -x "$KDIR"/debs/linux-image-"$KREL"_*.deb "$x"
  MOD_PATH=(); MOD_DONE=(); MOD_ORDER=()
  while IFS= read -r ko; do
    base=$(basename "$ko" .ko); MOD_PATH[${base//-/_}]=$ko
  done < <(find "$x/lib/modules/$KREL" -name '*.ko')
  for m in "${GUEST_MODULES[@]}"; do mod_resolve "$m"; done
  rm -rf "$dir"; mkdir -p "$dir/modules"
  for ko in "${MOD_ORDER[@]}"; do
    cp "$ko" "$dir/modules/"; basename "$ko" >> "$dir/modules/order"
  done
  cp "$KDIR/gpio-sim.ko" "$dir/modules/"; echo gpio-sim.ko >> "$dir/modules/order"
  cp "$KDIR/vmlinux" "$dir/vmlinux"
  cp "$(busybox_bin)" "$dir/busybox"
  echo "$stamp" > "$dir/.stamp"
  rm -rf "$x"
}

# --- VM path -----------------------------------------------------------------
quote_cmd() { local a s=""; for a in "$@"; do s+=" $(printf '%q' "$a")"; done; echo "${s# }"; }

run_in_vm() {
  command -v qemu-system-x86_64 >/dev/null \
    || die "qemu-system-x86_64 is missing: bash tools/setup.sh installs it (Debian package qemu-system-x86)"
  prepare_vm
  local run; run=$(mktemp -d "${TMPDIR:-/tmp}/cpm-sil.XXXXXX")
  cp "$SIL_DIR/sil-env.sh" "$SIL_DIR/sil-guest.sh" "$run/"
  [ "$PWD" = / ] || RW_DIRS+=("$PWD")
  # The guest's /tmp and /run are its own tmpfs (sockets, locks, speed); a
  # command that lives under them on the host is shared in explicitly.
  local exe; exe=$(command -v -- "$1" 2>/dev/null || true)
  case $exe in
    /tmp/*|/run/*) RW_DIRS+=("$(dirname "$(readlink -f "$exe")")") ;;
  esac
  local rw_lines="" virtfs=() i=0 d
  # Parents before children, so that a share never hides another; once each.
  local sorted=()
  [ ${#RW_DIRS[@]} -eq 0 ] || mapfile -t sorted < <(printf '%s\n' "${RW_DIRS[@]}" | sort -u | awk '{ print length($0) "\t" $0 }' | sort -n -s -k1,1 | cut -f2-)
  for d in "${sorted[@]}"; do
    rw_lines+="rw$i $d"$'\n'
    virtfs+=(-virtfs "local,path=${d//,/,,},mount_tag=rw$i,security_model=none,multidevs=remap")
    i=$((i + 1))
  done
  { printf 'RUN_PATH=%q\n' "$run"; printf 'RW_MOUNTS=%q\n' "$rw_lines"; } > "$run/config"
  {
    echo '#!/bin/bash'
    # The host's environment, then what the guest set up, then the command.
    export -p | grep -Ev '^declare -[a-zA-Z]*r' || true
    echo ". $(printf '%q' "$run/guest-env")"
    echo "cd $(printf '%q' "$PWD") || exit 125"
    echo "exec $(quote_cmd "$@")"
  } > "$run/cmd.sh"
  : > "$run/output.log"

  local qemu=(qemu-system-x86_64 -accel tcg -cpu max -m "$MEM" -smp "$SMP"
    -nodefaults -no-user-config -display none -no-reboot
    -kernel "$KDIR/vmlinux" -initrd "$INITRD"
    -append "console=ttyS0 panic=-1 ${CPM_SIL_KERNEL_ARGS:-quiet loglevel=3}"
    -chardev "file,id=con,path=$run/console.log" -serial chardev:con
    -chardev "file,id=out,path=$run/output.log" -serial chardev:out
    -virtfs "local,path=/,mount_tag=hostroot,security_model=none,readonly=on,multidevs=remap"
    -virtfs "local,path=${run//,/,,},mount_tag=silrun,security_model=none"
    "${virtfs[@]}")
  local t0=$SECONDS qrc=0
  timeout -k 5 "$TIMEOUT" "${qemu[@]}" </dev/null >"$run/qemu.log" 2>&1 &
  local qpid=$!
  tail -n +1 -s 0.2 -f --pid=$qpid "$run/output.log" &
  local tpid=$!
  wait $qpid || qrc=$?
  wait $tpid 2>/dev/null || true
  local rc
  if [ -f "$run/rc" ]; then
    rc=$(cat "$run/rc")
  else
    rc=$(tr -d '\r' < "$run/console.log" 2>/dev/null | sed -n 's/.*CPM-SIL-EXIT \([0-9]*\).*/\1/p' | tail -1)
  fi
  if [ -z "$rc" ]; then
    if [ $qrc = 124 ] || [ $qrc = 137 ]; then
      note "time-out: the VM run exceeded ${TIMEOUT} s (--timeout / CPM_SIL_TIMEOUT)"; rc=124
    else
      note "the VM ended without reporting an exit code (qemu exit $qrc)"; rc=125
    fi
    note "--- qemu: $(tail -5 "$run/qemu.log" | tr '\n' ' ')"
    note "--- last lines of the serial console ($run/console.log):"
    tr -d '\r' < "$run/console.log" | tail -20 | sed 's/^/  | /' >&2
    KEEP=1
  elif [ "$rc" != 0 ]; then
    KEEP=1
  fi
  if [ "$KEEP" = 1 ]; then
    note "VM run took $((SECONDS - t0)) s; exit $rc; serial console log and output kept in $run"
  else
    rm -rf "$run"
  fi
  return "$rc"
}

# --- main --------------------------------------------------------------------
if [ $PREPARE_ONLY = 1 ]; then
  if [ "$MODE" = auto ] && host_ok; then note "the host provides --needs $NEEDS; no VM image needed"; exit 0; fi
  t0=$SECONDS; prepare_vm; note "VM image ready in $KDIR ($((SECONDS - t0)) s)"
  [ -z "$EXPORT_DIR" ] || export_parts "$EXPORT_DIR"
  exit 0
fi
case $MODE in
  host) host_ok || die "--host: this host cannot provide --needs $NEEDS (no vcan module, or no gpio-sim / not root)"
        rc=0; run_on_host "$@" || rc=$?; exit $rc ;;
  auto) if host_ok; then rc=0; run_on_host "$@" || rc=$?; exit $rc; fi ;;
esac
rc=0; run_in_vm "$@" || rc=$?
exit $rc

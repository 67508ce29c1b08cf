#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# The Debian package end to end (docs/install.md), on this system: build the
# packages from the build (cpack -G DEB), install them with dpkg, check dpkg -L
# and the conffiles, check the signing key postinst made (and keeps on a second
# configure), run `cpmd --version`, verify the installed unit; start cpmd as
# the cpmd user from the installed unit's own ExecStartPre and ExecStart (its
# limits, user, umask and no-new-privileges applied as systemd would: this
# host has no systemd as PID 1), with a throw-away operator key; read its
# state verified with the installed public key; send it the paper's circle
# with the installed cpm and read the tracking error; run cpm compare,
# diagnose, fit and calibrate from a folder outside the tree without --model
# (the installed default model); stop cpmd; dpkg --purge; nothing of the
# packages remains.
#
# Needs root and dpkg; skipped (exit 77, with the reason) otherwise, and where a
# cpmd is installed already (package or source install): it never replaces one.
# LCM runs in a private network namespace: no other cpmd is heard or disturbed.
#   usage: package.sh SOURCE_DIR BUILD_DIR CPM_VERSION DEBIAN_VERSION LIBDIR
set -euo pipefail
SRC=$(cd "$1" && pwd) BUILD=$(cd "$2" && pwd) VERSION=$3 DEBVERSION=$4 LIBDIR=$5
skip() { echo "SKIP: $*"; exit 77; }
fail() { echo "FAIL: $*" >&2; exit 1; }
. "$(dirname "$0")/default_model.sh"

if [ -z "${CPMD_IN_NETNS:-}" ]; then
  [ "$(id -u)" -eq 0 ] || skip "needs root (dpkg -i and --purge on this system); runs as root in CI"
  for p in dpkg dpkg-deb dpkg-query dpkg-shlibdeps cpack setpriv prlimit unshare ip; do
    command -v "$p" >/dev/null || skip "$p is missing (not a Debian system with dpkg-dev, util-linux and iproute2)"
  done
  if dpkg-query -W -f='${db:Status-Abbrev}' cpmd 2>/dev/null | grep -q '^.i'; then
    skip "the package cpmd is installed on this system: the test does not replace it"
  fi
  for f in /etc/cpmd /usr/bin/cpmd /usr/bin/cpm; do
    [ ! -e "$f" ] || skip "$f exists (a cpmd installed from source?): the test does not touch it"
  done
  [ ! -e /var/lib/cpmd ] || [ -z "$(ls -A /var/lib/cpmd)" ] || skip "/var/lib/cpmd holds files: the test does not touch it"
  unshare -n true 2>/dev/null || skip "cannot make a private network namespace for LCM"
  exec unshare -n env CPMD_IN_NETNS=1 bash -c 'ip link set lo up && ip route add 224.0.0.0/4 dev lo && exec bash "$@"' \
    _ "$0" "$@"
fi

started=$EPOCHREALTIME
elapsed() { awk -v a="$started" -v b="$EPOCHREALTIME" 'BEGIN { printf "%.1f", b - a }'; }
T=$(mktemp -d /tmp/cpmd-package.XXXXXX)
chmod 0755 "$T"
user_existed=$(getent passwd cpmd >/dev/null && echo yes || echo no)
# An empty /var/lib/cpmd found here is put back as found (purge removes it).
state_dir_was=$(stat -c '%a %U %G' /var/lib/cpmd 2>/dev/null || true)
pid=
cleanup() {
  [ -z "$pid" ] || kill -TERM "$pid" 2>/dev/null || true
  if dpkg-query -W -f='${db:Status-Abbrev}' cpmd-dev cpmd 2>/dev/null | grep -q '^.[ic]'; then
    dpkg --purge cpmd-dev cpmd >/dev/null 2>&1 || true
  fi
  if [ "$user_existed" = no ] && getent passwd cpmd >/dev/null; then
    userdel cpmd 2>/dev/null || true
    ! getent group cpmd >/dev/null || groupdel cpmd 2>/dev/null || true
  fi
  if [ -n "$state_dir_was" ] && [ ! -e /var/lib/cpmd ]; then
    read -r mode owner group <<<"$state_dir_was"
    install -d -m "$mode" -o "$owner" -g "$group" /var/lib/cpmd || true
  fi
  rm -rf "$T"
}
trap cleanup EXIT
step() { echo "== $* ($(elapsed) s)"; }

step "cpack -G DEB"
(cd "$T" && cpack -G DEB --config "$BUILD/CPackConfig.cmake" -B "$T/pkg" >"$T/cpack.log" 2>&1) \
  || { cat "$T/cpack.log"; fail "cpack failed"; }
ARCH=$(dpkg --print-architecture)
DEB=$T/pkg/cpmd_${DEBVERSION}_$ARCH.deb DEV=$T/pkg/cpmd-dev_${DEBVERSION}_$ARCH.deb
[ -f "$DEB" ] && [ -f "$DEV" ] || { ls -l "$T/pkg"; fail "expected $DEB and $DEV"; }
echo "cpmd: $(stat -c %s "$DEB") bytes, cpmd-dev: $(stat -c %s "$DEV") bytes"
dpkg-deb -f "$DEB" Package Version Depends | sed 's/^/  /'
[ "$(dpkg-deb -f "$DEB" Version)" = "$DEBVERSION" ] || fail "Version is not $DEBVERSION"
dpkg-deb -f "$DEB" Depends | grep -q 'libc6' || fail "no libc6 in Depends: dpkg-shlibdeps did not run"
dpkg-deb -f "$DEB" Depends | grep -q 'liblcm' || fail "no liblcm in Depends"
# The copyright files as Debian reads them (DEP-5, the licence named, Apache's
# NOTICE): lintian's copyright checks only, two seconds of CPU; the whole of
# lintian takes a minute and judges more than this test is about.
if command -v lintian >/dev/null; then
  step "lintian, copyright checks"
  findings=$(lintian -C debian/copyright,debian/copyright/dep5,debian/copyright/apache-notice "$DEB" "$DEV" 2>&1 \
             | grep -E '^[EW]: ' || true)
  [ -z "$findings" ] || { echo "$findings"; fail "lintian finds fault with the copyright files"; }
fi
dpkg-deb --ctrl-tarfile "$DEB" | tar -xO ./conffiles >"$T/conffiles"
for c in cpmd sim canopen machine machine-canopen; do
  grep -qx "/etc/cpmd/$c.yaml" "$T/conffiles" || fail "/etc/cpmd/$c.yaml is not a conffile"
done

step "dpkg -i"
dpkg -i "$DEB" "$DEV" >"$T/dpkg-i.log" 2>&1 || { cat "$T/dpkg-i.log"; fail "dpkg -i failed"; }
dpkg -L cpmd >"$T/files-cpmd"
dpkg -L cpmd-dev >"$T/files-dev"
echo "dpkg -L: cpmd $(wc -l <"$T/files-cpmd") paths, cpmd-dev $(wc -l <"$T/files-dev") paths"
for f in /usr/bin/cpmd /usr/bin/cpm /etc/cpmd/sim.yaml /etc/cpmd/machine.yaml /lib/systemd/system/cpmd.service \
         /usr/lib/sysusers.d/cpmd.conf /usr/lib/tmpfiles.d/cpmd.conf /usr/share/doc/cpmd/copyright \
         /usr/share/doc/cpmd/docs/install.md /usr/share/cpmd/lcm/state_t.lcm; do
  grep -qx "$f" "$T/files-cpmd" || fail "dpkg -L cpmd: no $f"
done
for f in /usr/include/cpm/daemon/client.hpp /usr/include/cpm_msgs/state_t.hpp "/usr/$LIBDIR/libcpm_client.a" \
         "/usr/$LIBDIR/cmake/cpmd/cpmdConfig.cmake" /usr/share/doc/cpmd-dev/copyright; do
  grep -qx "$f" "$T/files-dev" || fail "dpkg -L cpmd-dev: no $f"
done
getent passwd cpmd >/dev/null || fail "postinst made no user cpmd"
[ "$(stat -c '%U %a' /etc/cpmd/operators.d)" = "cpmd 700" ] || fail "/etc/cpmd/operators.d: $(stat -c '%U %a' /etc/cpmd/operators.d)"
[ "$(stat -c '%U' /var/lib/cpmd/models)" = cpmd ] || fail "/var/lib/cpmd/models is not cpmd's"
# cpmd's signing key, made by postinst: cpmd's own, 0600; its public half for everyone.
[ "$(stat -c '%U %a' /etc/cpmd/cpmd.key 2>&1)" = "cpmd 600" ] || fail "/etc/cpmd/cpmd.key: $(stat -c '%U %a' /etc/cpmd/cpmd.key 2>&1)"
[ "$(stat -c '%U %a' /etc/cpmd/cpmd.pub 2>&1)" = "root 644" ] || fail "/etc/cpmd/cpmd.pub: $(stat -c '%U %a' /etc/cpmd/cpmd.pub 2>&1)"
grep -q "signing key /etc/cpmd/cpmd.key" "$T/dpkg-i.log" || fail "postinst did not say where the key and its public half are"
key_sum=$(sha256sum </etc/cpmd/cpmd.key) pub_sum=$(sha256sum </etc/cpmd/cpmd.pub)
# configure again (an upgrade, dpkg-reconfigure): the key stays as it is.
/var/lib/dpkg/info/cpmd.postinst configure "$DEBVERSION" >"$T/postinst-again.log" 2>&1 \
  || { cat "$T/postinst-again.log"; fail "postinst configure, again"; }
[ "$(sha256sum </etc/cpmd/cpmd.key)" = "$key_sum" ] && [ "$(sha256sum </etc/cpmd/cpmd.pub)" = "$pub_sum" ] \
  || fail "postinst replaced cpmd's key"
echo "cpmd.key (cpmd 600) and cpmd.pub (root 644) made at install, kept on configure again"

step "cpmd --version"
cpmd --version >"$T/version.txt" 2>&1 || fail "cpmd --version: $(cat "$T/version.txt")"
cat "$T/version.txt"
grep -qF "$VERSION" "$T/version.txt" || fail "cpmd --version does not say $VERSION"

UNIT=/lib/systemd/system/cpmd.service
if command -v systemd-analyze >/dev/null; then
  step "systemd-analyze verify and security on $UNIT"
  # The unit's Documentation= names man:cpmd(8), which the package installs: verify checks it resolves.
  systemd-analyze verify "$UNIT" >"$T/verify.txt" 2>&1 || { cat "$T/verify.txt"; fail "systemd-analyze verify $UNIT"; }
  systemd-analyze security --offline=yes "$UNIT" | tail -n 1
else
  echo "SKIPPED: systemd-analyze (not installed)"
fi

step "a throw-away operator"
mkdir -m 0700 "$T/operator" "$T/home" "$T/work"
cpm keygen "$T/operator/e2e.key" >/dev/null
install -o cpmd -g cpmd -m 0600 "$T/operator/e2e.key" /etc/cpmd/operators.d/e2e.key
printf '# throw-away operator of tests/install/package.sh\ne2e: engineer\n' >/etc/cpmd/operators.d/roles.yaml
export CPM_KEY_FILE=$T/operator/e2e.key CPM_OPERATOR=e2e HOME=$T/home
# The user's copy of cpmd's public half, where cpm looks (docs/security.md).
install -D -m 0644 /etc/cpmd/cpmd.pub "$HOME/.config/cpm/cpmd.pub"

# The unit's own command lines and configuration (on the simulator; it names the signing key).
exec_start=$(sed -n 's/^ExecStart=//p' "$UNIT")
exec_pre=$(sed -n 's/^ExecStartPre=//p' "$UNIT")
[ "$exec_start" = "/usr/bin/cpmd --config /etc/cpmd/cpmd.yaml" ] || fail "ExecStart=$exec_start"
rtprio=$(sed -n 's/^LimitRTPRIO=//p' "$UNIT")
memlock=$(sed -n 's/^LimitMEMLOCK=//p' "$UNIT")
[ "$memlock" = infinity ] && memlock=unlimited
nice=$(sed -n 's/^Nice=//p' "$UNIT")
umask_=$(sed -n 's/^UMask=//p' "$UNIT")
user=$(sed -n 's/^User=//p' "$UNIT") group=$(sed -n 's/^Group=//p' "$UNIT")
limits=(--rtprio="$rtprio" --memlock="$memlock")
if ! prlimit "${limits[@]}" true 2>/dev/null; then
  # A container without CAP_SYS_RESOURCE: cpmd then runs with normal
  # scheduling and unlocked memory, as wherever they are refused (it says so).
  echo "this system may not raise RLIMIT_RTPRIO to $rtprio and RLIMIT_MEMLOCK to $memlock: cpmd runs without them"
  limits=()
fi
# As systemd would start it: limits, nice and umask set as root, then the
# user and group without capabilities. Execs: call it in a subshell.
as_unit() {
  cd / && umask "$umask_" && exec nice -n "$nice" prlimit "${limits[@]}" -- \
    setpriv --reuid="$user" --regid="$group" --init-groups --no-new-privs --inh-caps=-all --bounding-set=-all -- \
    env -i PATH=/usr/bin:/bin HOME=/var/lib/cpmd "$@"
}

step "ExecStartPre as $user: $exec_pre"
# shellcheck disable=SC2086  # the unit's command line, split as systemd splits it (no quotes in it)
(as_unit $exec_pre) | tee "$T/check.txt"
grep -q '1 operators may command' "$T/check.txt" || fail "the throw-away operator is not loaded"
grep -q '^/etc/cpmd/cpmd.key: cpmd seals' "$T/check.txt" || fail "the unit's configuration does not read cpmd's key"

step "ExecStart as $user: $exec_start"
# shellcheck disable=SC2086
(as_unit $exec_start) 2>"$T/cpmd.log" &
pid=$!  # the subshell execs down to cpmd: this is cpmd's pid
cd "$T/work"
for _ in $(seq 100); do cpm status >/dev/null 2>&1 && break; kill -0 $pid 2>/dev/null || break; sleep 0.1; done
cpm status >status.txt || { cat status.txt "$T/cpmd.log"; fail "cpmd does not answer"; }
cat status.txt
grep -q '^state signed by cpmd and verified' status.txt || fail "cpm did not verify cpmd's state with the installed key"
grep -o 'sim backend.*' "$T/cpmd.log" || true
[ "$(ps -o user=,comm= -p $pid | tr -s ' ')" = "$user cpmd" ] || fail "pid $pid is not cpmd run by $user: $(ps -o user=,comm= -p $pid)"

step "the paper's circle"
cpm enable
cpm record --out circle.csv --until-idle >record.txt 2>&1 &
rec=$!
cpm circle --paper >circle.txt 2>circle.err || { cat circle.txt circle.err; fail "cpm circle --paper"; }
cat circle.txt  # (its progress bar went to circle.err)
wait $rec || { cat record.txt; fail "cpm record"; }
cpm disable
rms=$(sed -n 's/^tracking error over the segment: RMS \([0-9.]*\) um.*/\1/p' circle.txt)
[ -n "$rms" ] || fail "no tracking error in cpm circle's output"
# In process, the same circle on the same model: cpm sim (the daemon's loop
# reproduces it exactly when no slot is skipped; docs/daemon.md).
ref=$(cpm sim --trajectory paper-circle --controller computed_torque --json sim.json >/dev/null &&
      sed -n 's/.*"position_rmse": *\([0-9.e+-]*\).*/\1/p' sim.json | head -n 1)
awk -v r="$rms" -v f="$ref" 'BEGIN { printf "tracking error RMS %s um through the installed cpmd; in process %.2f um\n", r, f * 1e6 }'
echo "$rms $ref" | awk '{ if ($1 < 0.75 * $2 * 1e6 || $1 > 1.25 * $2 * 1e6) exit 1 }' \
  || fail "tracking error $rms um is not within 25 % of the in-process $ref m"

step "cpm compare, diagnose, fit, calibrate from $T/work, no --model"
M=/etc/cpmd/machine.yaml
check_default_model cpm circle.csv force_gain:1 "$M"

step "stop cpmd"
kill -TERM $pid
wait $pid || { cat "$T/cpmd.log"; fail "cpmd did not stop cleanly"; }
pid=
tail -n 1 "$T/cpmd.log"
cd /

step "dpkg --purge"
dpkg --purge cpmd-dev cpmd >"$T/purge.log" 2>&1 || { cat "$T/purge.log"; fail "dpkg --purge failed"; }
if dpkg-query -W -f='${db:Status-Abbrev}' cpmd cpmd-dev 2>/dev/null | grep -q '^.[^n]'; then fail "still known to dpkg"; fi
left=0
while read -r f; do
  [ -e "$f" ] || [ -L "$f" ] || continue
  # A folder other packages hold (/usr/bin, /lib -> usr/lib, ...) stays.
  if [ -d "$f" ] && dpkg-query -S "$f" >/dev/null 2>&1; then continue; fi
  echo "left behind: $f"; left=$((left + 1))
done < <(cat "$T/files-cpmd" "$T/files-dev")
for d in /etc/cpmd /var/lib/cpmd; do [ ! -e "$d" ] || { echo "left behind: $d"; left=$((left + 1)); }; done
[ "$left" -eq 0 ] || fail "$left paths of the packages remain after purge"
getent passwd cpmd >/dev/null && echo "user cpmd kept, as Debian keeps system users (docs/install.md)"
echo "PASS in $(elapsed) s: tracking error RMS $rms um"

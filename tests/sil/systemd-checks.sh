#!/bin/bash
# SPDX-License-Identifier: Apache-2.0
# The checks of cpmd.service under a real systemd (issue 31, docs/sil.md
# "cpmd under systemd"). Runs as root inside the guest of
# tests/sil/systemd-vm.sh, from the run folder /sil that holds the cpmd .deb
# of this build and sil-env.sh. Asserts with systemd's own tools
# (systemctl, journalctl, systemd-analyze) and prints the figures.
#   usage: systemd-checks.sh [sim|canopen|all|ci]    (default all)
# ci: CI's form (ctest sil.systemd): every check of all but the watchdog on
# the simulator, which the canopen part checks with more (brake, enable line,
# the drives' own view); systemd's own timings (watchdog 2 s, RestartSec) are
# kept. With /sil/circle-ref.json (cpm sim of the same build, run on the
# host) the circle's in-process reference is not computed again in the guest.
set -uo pipefail
PART=${1:-all}
case $PART in sim|canopen|all|ci) ;; *) echo "systemd-checks: unknown part '$PART' (sim, canopen, all, ci)"; exit 2 ;; esac
UNIT=cpmd.service
fails=0
up() { cut -d' ' -f1 /proc/uptime; }
step() { echo; echo "== $* (guest uptime $(up) s)"; }
ok() { echo "ok: $*"; }
fail() { echo "FAIL: $*"; fails=$((fails + 1)); }
fatal() {
  echo "FAIL: $*"
  systemctl status --no-pager -l $UNIT 2>&1 | tail -20
  journalctl --no-pager -b -o short-monotonic | tail -60
  exit 1
}
prop() { systemctl show -P "$1" $UNIT; }
# journal lines of the unit and of systemd about it, with monotonic stamps
# ("SECONDS host unit[pid]: message"; journalctl is slow under TCG: call it once, then grep)
jrnl() { journalctl --no-pager -b -o short-monotonic _SYSTEMD_UNIT=$UNIT + UNIT=$UNIT "$@" | sed 's/^\[ *\([0-9.]*\)\]/\1/'; }
# the stamp (s) of the first line of the journal copy $1 at or after $2 s matching $3
stamp_after() { awk -v t0="$2" -v re="$3" '$1 + 0 >= t0 && $0 ~ re { print $1; exit }' "$1"; }
since() { awk -v t0="$2" '$1 + 0 >= t0' "$1"; }
wait_for() {  # wait_for SECONDS CMD...: poll (hang guard, not a deadline)
  # Every 0.5 s: each poll starts processes on the one emulated CPU that cpmd
  # needs; the figures come from the journal's stamps, not from the polls.
  local n=$(( $1 * 2 )); shift
  for _ in $(seq "$n"); do "$@" >/dev/null 2>&1 && return 0; sleep 0.5; done
  return 1
}
# cpm, again while it says "no answer from cpmd": its acks wait 2 s, and under
# TCG cpmd's LCM thread (normal scheduling) can wait longer behind the
# SCHED_FIFO loop on the one emulated CPU. A refusal is final.
cpm_try() {
  local out rc=0
  for _ in 1 2 3 4 5 6; do
    rc=0; out=$(cpm "$@" 2>&1) || rc=$?
    [ $rc -ne 0 ] && echo "$out" | grep -q 'no answer from cpmd' || break
    echo "(cpm $1: no answer from cpmd within 2 s; again)" >&2
  done
  echo "$out" | grep -v 'no public key of cpmd'
  return $rc
}
# restarted R0 PID0: systemd restarted the unit (NRestarts > R0, active, a new
# main PID); one systemctl per poll
restarted() {
  systemctl show -p NRestarts -p ActiveState -p MainPID $UNIT \
    | awk -F= -v r0="$1" -v p0="$2" '{ v[$1] = $2 } END { exit !(v["NRestarts"] > r0 && v["ActiveState"] == "active" && v["MainPID"] != p0) }'
}
json_field() { sed -n "s/.*\"$1\": *\"\\{0,1\\}\\([^\",]*\\).*/\\1/p" | head -n 1; }

step "the guest: $(systemctl is-system-running) with $(cat /proc/1/comm) as PID 1"
systemd-analyze time | head -n 1
systemd-analyze blame --no-pager | head -n 8 | sed "s/^/  blame: /"
systemctl --failed --no-legend | sed 's/^/failed unit: /'
. /sil/sil-env.sh
ip link set lo up && ip route replace 224.0.0.0/4 dev lo || fatal "multicast route on lo"

step "dpkg -i $(ls /sil/cpmd_*.deb | xargs -n1 basename)"
dpkg -i /sil/cpmd_*.deb >/tmp/dpkg.log 2>&1 || { cat /tmp/dpkg.log; fatal "dpkg -i failed"; }
getent passwd cpmd >/dev/null || fatal "dpkg -i made no user cpmd"
systemd-analyze verify /lib/systemd/system/$UNIT 2>&1 | grep -v 'man:cpmd(8)' | sed 's/^/verify: /'
exposure=$(systemd-analyze security $UNIT --no-pager | sed -n 's/.*Overall exposure level for .*: \([0-9.]*\).*/\1/p')
echo "systemd-analyze security: exposure $exposure"
awk -v e="$exposure" 'BEGIN { exit !(e != "" && e <= 2.0) }' && ok "exposure $exposure <= 2.0" || fail "exposure '$exposure' > 2.0"

step "a throw-away operator"
mkdir -m 0700 -p /root/op
cpm keygen /root/op/sil.key >/dev/null || fatal "cpm keygen"
install -o cpmd -g cpmd -m 0600 /root/op/sil.key /etc/cpmd/operators.d/sil.key
printf 'sil: engineer\nsil2: engineer\n' >/etc/cpmd/operators.d/roles.yaml
chown cpmd:cpmd /etc/cpmd/operators.d/roles.yaml
export CPM_KEY_FILE=/root/op/sil.key CPM_OPERATOR=sil HOME=/root
cd /root || exit 1

if [ "$PART" != canopen ]; then
# For this test only: the shipped cpmd.yaml at 200 Hz instead of 1 kHz, and
# overruns not a fault. Under TCG on one emulated CPU the 1 kHz loop ran late
# 5 times in a row within 0.5 s (fault "overrun" at cycle 498) and starved the
# rest of the guest; time in the guest is not real time (docs/sil.md).
sed -e 's/^\(  rate_hz:\) 1000/\1 200/' -e 's/^\(  max_consecutive_overruns:\) 5 /\1 100000 /' \
  /etc/cpmd/cpmd.yaml > /etc/cpmd/tcg.yaml
grep -q 'rate_hz: 200' /etc/cpmd/tcg.yaml && grep -q 'overruns: 100000' /etc/cpmd/tcg.yaml || fatal "cannot make tcg.yaml"
chmod 0644 /etc/cpmd/tcg.yaml
mkdir -p /etc/systemd/system/$UNIT.d
cat > /etc/systemd/system/$UNIT.d/sil-tcg.conf <<'EOF'
[Service]
ExecStartPre=
ExecStartPre=/usr/bin/cpmd --config /etc/cpmd/tcg.yaml --check
ExecStart=
ExecStart=/usr/bin/cpmd --config /etc/cpmd/tcg.yaml
EOF
systemctl daemon-reload
step "systemctl start $UNIT (the shipped cpmd.yaml, simulator backend, at 200 Hz: drop-in sil-tcg.conf)"
t_start=$(up)
systemctl start $UNIT || fatal "systemctl start $UNIT failed"
t_active=$(up)
echo "$(prop ActiveState) ($(prop SubState)), status '$(prop StatusText)', start took $(awk -v a="$t_start" -v b="$t_active" 'BEGIN { printf "%.1f", b - a }') s"
[ "$(prop ActiveState)/$(prop SubState)" = active/running ] || fatal "not active (running)"
# Type=notify: systemd logs "Started" only once READY=1 came; cpmd logs its
# loop's set-up just before it sends READY=1.
jrnl > j.txt
t_loop=$(stamp_after j.txt "$t_start" 'backend, .* Hz')
t_started=$(stamp_after j.txt "$t_start" 'Started cpmd')
echo "journal: loop up at $t_loop s, systemd's 'Started' at $t_started s"
[ -n "$t_loop" ] && [ -n "$t_started" ] && awk -v a="$t_loop" -v b="$t_started" 'BEGIN { exit !(a <= b) }' \
  && ok "active (running) only after the loop ran and READY=1 came" || fail "'Started' before the loop was up"
[ "$(prop StatusText)" != "" ] && ok "STATUS= from cpmd: $(prop StatusText)" || fail "no STATUS= from cpmd"

step "the loop: SCHED_FIFO, memory locked, user cpmd, no capabilities"
pid=$(prop MainPID)
grep -E '^(Uid|Gid|CapInh|CapPrm|CapEff|CapBnd|CapAmb|NoNewPrivs|Seccomp|VmLck|VmRSS):' /proc/$pid/status | tr -s '\t ' ' '
[ "$(awk '/^Uid:/ { print $2 "," $3 "," $4 "," $5 }' /proc/$pid/status)" = "$(id -u cpmd),$(id -u cpmd),$(id -u cpmd),$(id -u cpmd)" ] \
  && ok "runs as cpmd" || fail "not user cpmd"
for c in CapInh CapPrm CapEff CapBnd CapAmb; do
  [ "$(awk -v c="$c:" '$1 == c { print $2 }' /proc/$pid/status)" = 0000000000000000 ] || fail "$c is not empty"
done && ok "no capabilities (effective, permitted, bounding, ambient all empty)"
[ "$(awk '/^Seccomp:/ { print $2 }' /proc/$pid/status)" = 2 ] && ok "seccomp filter on" || fail "no seccomp filter"
vmlck=$(awk '/^VmLck:/ { print $2 }' /proc/$pid/status) vmrss=$(awk '/^VmRSS:/ { print $2 }' /proc/$pid/status)
[ "${vmlck:-0}" -gt 0 ] && [ "$vmlck" -ge "$vmrss" ] && ok "memory locked: VmLck $vmlck kB >= VmRSS $vmrss kB" \
  || fail "memory not locked: VmLck ${vmlck:-?} kB, VmRSS $vmrss kB"
fifo=""
for t in /proc/$pid/task/*; do
  pol=$(chrt -p "${t##*/}" 2>/dev/null | sed -n "s/.*scheduling policy: //p")
  pri=$(chrt -p "${t##*/}" 2>/dev/null | sed -n "s/.*scheduling priority: //p")
  echo "thread ${t##*/} ($(cat "$t/comm")): $pol $pri"
  [ "$pol" = SCHED_FIFO ] && fifo="${t##*/} at $pri"
done
[ -n "$fifo" ] && ok "a thread runs SCHED_FIFO: $fifo" || fail "no thread runs SCHED_FIFO"
journalctl --no-pager -b _SYSTEMD_UNIT=$UNIT -p warning -o cat | sed 's/^/warning at start: /'

step "cpm status from the guest"
wait_for 60 cpm status || fatal "cpm status: cpmd does not answer"
cpm status --json > status0.json
mode=$(json_field mode < status0.json)
[ "$mode" = disabled ] && ok "mode: $mode" || fail "mode after start is '$mode', not disabled"

# -- watchdog ------------------------------------------------------------------
if [ "$PART" != ci ]; then
step "SIGSTOP: the watchdog kills cpmd, Restart=on-failure brings it back, disabled"
pos0=$(sed -n 's/.*"position": *\[\([^]]*\)\].*/\1/p' status0.json)
restarts0=$(prop NRestarts)
t_sig=$(up)
kill -STOP "$pid"
wait_for 120 restarted "$restarts0" "$pid" \
  || fatal "cpmd was not restarted within 120 s of the SIGSTOP"
pid2=$(prop MainPID)
jrnl > j.txt
t_wd=$(stamp_after j.txt "$t_sig" 'Watchdog timeout')
t_killed=$(stamp_after j.txt "$t_sig" 'Main process exited')
t_sched=$(stamp_after j.txt "$t_sig" 'Scheduled restart job')
t_ready=$(stamp_after j.txt "$t_sig" 'Started cpmd')
since j.txt "$t_sig" | grep -E 'systemd\[1\]' | sed 's/^/  /'
awk -v s="$t_sig" -v w="$t_wd" -v k="$t_killed" -v r="$t_sched" -v e="$t_ready" 'BEGIN {
  printf "WATCHDOG-FIGURES SIGSTOP at %.3f s; watchdog timeout +%.3f s; main process dead +%.3f s; restart scheduled +%.3f s; restarted daemon ready +%.3f s\n", s, w - s, k - s, r - s, e - s }'
[ -n "$t_wd" ] && ok "systemd: watchdog timeout" || fail "no 'Watchdog timeout' from systemd"
grep -q 'Failed with result .watchdog.' j.txt && ok "result: watchdog" || fail "no 'Failed with result watchdog'"
[ "$(prop NRestarts)" -eq $((restarts0 + 1)) ] && ok "NRestarts $(prop NRestarts)" || fail "NRestarts $(prop NRestarts)"
wait_for 60 cpm status || fatal "the restarted cpmd does not answer"
cpm status --json > status1.json
mode=$(json_field mode < status1.json)
pos1=$(sed -n 's/.*"position": *\[\([^]]*\)\].*/\1/p' status1.json)
echo "position before: [$pos0] m, after the restart: [$pos1] m"
[ "$mode" = disabled ] && ok "the restarted cpmd is disabled (pid $pid -> $pid2)" || fail "the restarted cpmd is '$mode'"
awk -v a="$pos0" -v b="$pos1" 'BEGIN { split(a, p, ","); split(b, q, ","); for (i = 1; i <= 3; i++) if ((p[i] - q[i])^2 > 1e-12) exit 1 }' \
  && ok "nothing moved (positions equal to 1 um)" || fail "the platform moved: [$pos0] -> [$pos1]"
pid=$pid2
fi

# -- reload --------------------------------------------------------------------
step "systemctl reload re-reads operators.d"
cpm keygen /root/op/sil2.key >/dev/null
CPM_KEY_FILE=/root/op/sil2.key CPM_OPERATOR=sil2 cpm_try enable > enable.err
grep -q 'not authorized' enable.err || fail "an unknown key was not refused: $(cat enable.err)"
install -o cpmd -g cpmd -m 0600 /root/op/sil2.key /etc/cpmd/operators.d/sil2.key
t_r=$(up)
systemctl reload $UNIT || fail "systemctl reload failed"
jrnl > j.txt
since j.txt "$t_r" | grep 'SIGHUP' | tail -n 1 | sed 's/^/  /'
since j.txt "$t_r" | grep -q 'SIGHUP' || fail "no 'operators: ... (SIGHUP)' line after the reload"
if CPM_KEY_FILE=/root/op/sil2.key CPM_OPERATOR=sil2 cpm_try enable; then
  ok "the new key works after the reload"
  CPM_KEY_FILE=/root/op/sil2.key CPM_OPERATOR=sil2 cpm_try disable >/dev/null || fail "disable with the new key"
else fail "the new key is refused after the reload"; fi
rm /etc/cpmd/operators.d/sil2.key
t_r=$(up)
systemctl reload $UNIT || fail "systemctl reload failed"
jrnl > j.txt
since j.txt "$t_r" | grep -q 'SIGHUP' || fail "no SIGHUP line after the second reload"
CPM_KEY_FILE=/root/op/sil2.key CPM_OPERATOR=sil2 cpm_try enable > enable.err
if grep -q 'not authorized' enable.err; then ok "the removed key is refused: $(grep 'not authorized' enable.err | head -n 1)"
else fail "the removed key is not refused: $(cat enable.err)"; cpm_try disable; fi
if [ "$(prop MainPID)" = "$pid" ]; then ok "same process (pid $pid): reloaded, not restarted"
else
  fail "cpmd was restarted during the reload steps (pid $pid -> $(prop MainPID)); systemd said:"
  jrnl | grep -E 'Watchdog|Main process exited|Failed with result|Scheduled restart' | sed 's/^/  /'
fi

# -- the paper's circle ----------------------------------------------------------
step "the paper's circle from the guest's cpm, against the same circle in process"
cpm_try enable >/dev/null || fail "cpm enable for the circle"
if cpm_try circle --paper >circle.txt; then
  cat circle.txt
  rms=$(sed -n 's/^tracking error over the segment: RMS \([0-9.]*\) um.*/\1/p' circle.txt)
  # In process: the same trajectory, controller and rate (the drop-in's 200 Hz),
  # from the host when the run folder has it (the same build's cpm).
  if [ -s /sil/circle-ref.json ]; then cp /sil/circle-ref.json sim.json; echo "in-process reference: the host's cpm sim"
  else cpm sim --trajectory paper-circle --controller computed_torque --rate 200 --json sim.json >/dev/null 2>&1; fi
  ref=$(sed -n 's/.*"position_rmse": *\([0-9.e+-]*\).*/\1/p' sim.json | head -n 1)
  awk -v r="$rms" -v f="$ref" 'BEGIN { printf "CIRCLE-FIGURES tracking error RMS %s um through cpmd under systemd; in process %.2f um\n", r, f * 1e6 }'
  [ -n "$rms" ] && [ -n "$ref" ] && echo "$rms $ref" | awk '{ exit !($1 >= 0.75 * $2 * 1e6 && $1 <= 1.25 * $2 * 1e6) }' \
    && ok "the circle tracks as in process (within 25 %)" || fail "tracking error $rms um against $ref m in process"
else
  tail -n 5 circle.txt; fail "cpm circle --paper"
fi
cpm_try disable >/dev/null || fail "cpm disable after the circle"

# -- journal severities --------------------------------------------------------
step "the journal has cpmd's severities"
# A file in operators.d that is no key: cpmd warns about it on the reload.
echo "not a key" > /etc/cpmd/operators.d/junk.key; chown cpmd:cpmd /etc/cpmd/operators.d/junk.key; chmod 600 /etc/cpmd/operators.d/junk.key
systemctl reload $UNIT; sleep 1
for p in 3 4 5 6; do
  echo "priority $p: $(journalctl -b _SYSTEMD_UNIT=$UNIT PRIORITY=$p -o cat --no-pager | wc -l) lines$(journalctl -b _SYSTEMD_UNIT=$UNIT PRIORITY=$p -o cat --no-pager | tail -n 1 | sed 's/^/; last: /')"
done
[ "$(journalctl -b _SYSTEMD_UNIT=$UNIT PRIORITY=6 -o cat --no-pager | wc -l)" -gt 0 ] && ok "info lines at priority 6" || fail "no info (6) lines"
journalctl -b _SYSTEMD_UNIT=$UNIT -p warning -o cat --no-pager | grep -q . && ok "journalctl -p warning shows cpmd's warnings" \
  || fail "journalctl -p warning shows nothing of cpmd"
journalctl -b _SYSTEMD_UNIT=$UNIT -p warning -o cat --no-pager | grep -q 'Hz, ' && fail "an info line came out at warning" || ok "no info line at warning or above"
rm -f /etc/cpmd/operators.d/junk.key

# -- stop ----------------------------------------------------------------------
step "systemctl stop disables and stops within TimeoutStopSec"
t_s=$(up)
systemctl stop $UNIT
t_e=$(up)
echo "stop took $(awk -v a="$t_s" -v b="$t_e" 'BEGIN { printf "%.2f", b - a }') s (TimeoutStopSec $(prop TimeoutStopUSec)); result $(prop Result), exit status $(prop ExecMainStatus)"
[ "$(prop Result)" = success ] && [ "$(prop ExecMainStatus)" = 0 ] && ok "clean stop" || fail "stop: result $(prop Result), status $(prop ExecMainStatus)"
jrnl > j.txt
since j.txt "$t_s" | grep -E 'disabling the drives|stopped after|Deactivated|Stopped' | sed 's/^/  /'
since j.txt "$t_s" | grep -q 'disabling the drives and stopping' \
  && ok "cpmd disabled the drives on SIGTERM" || fail "no 'disabling the drives' line on stop"
fi

if [ "$PART" != sim ]; then
# -- CANopen on vcan0, GPIO on gpio-sim -----------------------------------------
step "canopen: vcan0, the gpio-sim chip, the virtual drives"
systemctl is-active --quiet $UNIT && systemctl stop $UNIT
mountpoint -q /sys/kernel/config || mount -t configfs configfs /sys/kernel/config
ip link add dev "$CPM_SIL_CAN" type vcan && ip link set "$CPM_SIL_CAN" up || fatal "cannot bring up $CPM_SIL_CAN"
sil_gpio_up cpm-sil || fatal "gpio-sim chip"
pull() { echo "pull-$2" > "$CPM_SIL_GPIO_SYSFS/sim_gpio$1/pull"; }
value() { cat "$CPM_SIL_GPIO_SYSFS/sim_gpio$1/value"; }
pull 0 up   # e-stop chain closed (the line is active low)
# What the udev rule of docs/install.md does on the machine's PC.
chgrp cpmd "$CPM_SIL_GPIO_CHIP" && chmod 0660 "$CPM_SIL_GPIO_CHIP"
ls -l "$CPM_SIL_GPIO_CHIP"
# The SIL configuration (config/sil.yaml: the canopen backend on vcan0, the
# chip labelled cpm-sil), in place of cpmd.yaml through the drop-in.
install -m 0644 /sil/sil.yaml /sil/machine-sil.yaml /etc/cpmd/
cat > /etc/systemd/system/$UNIT.d/sil-tcg.conf <<'EOF'
[Service]
ExecStartPre=
ExecStartPre=/usr/bin/cpmd --config /etc/cpmd/sil.yaml --check
ExecStart=
ExecStart=/usr/bin/cpmd --config /etc/cpmd/sil.yaml
EOF
systemctl daemon-reload
rm -f /run/vd.in; mkfifo /run/vd.in; exec 7<>/run/vd.in
LD_LIBRARY_PATH=/sil/lib /sil/virtual-drives --interface "$CPM_SIL_CAN" --model /etc/cpmd/machine-sil.yaml --rate 200 \
  --stdin <&7 2>/tmp/vd.log &
vdpid=$!
vd_status() {  # the drives' own view: "syncs N ... position X Y Z states S1 S2 S3"
  local n; n=$(grep -c ' status -> ' /tmp/vd.log)
  echo status >&7
  wait_for 30 sh -c "[ \$(grep -c ' status -> ' /tmp/vd.log) -gt $n ]" || { echo "no answer"; return 1; }
  grep ' status -> ' /tmp/vd.log | tail -n 1 | sed 's/.* status -> ok //'
}
wait_for 30 grep -q 'virtual-drives: nodes' /tmp/vd.log || { cat /tmp/vd.log; fatal "virtual-drives did not start"; }
head -n 1 /tmp/vd.log
t_start=$(up)
systemctl start $UNIT || fatal "systemctl start $UNIT on sil.yaml failed"
echo "$(prop ActiveState) ($(prop SubState)) on the canopen backend, status '$(prop StatusText)', start took $(awk -v a="$t_start" -v b="$(up)" 'BEGIN { printf "%.1f", b - a }') s"
[ "$(prop ActiveState)/$(prop SubState)" = active/running ] && ok "active (running) on canopen + gpio-sim" || fatal "not active (running)"
journalctl --no-pager -b _SYSTEMD_UNIT=$UNIT -o cat | grep -E 'CAN |backend' | tail -n 3 | sed 's/^/  /'
wait_for 60 cpm status || fatal "cpmd does not answer"
cpm drives 2>/dev/null | head -n 8
echo "drives: $(vd_status)"
[ "$(value 8)" = 0 ] && ok "z brake on (brake_z 0) while disabled" || fail "brake_z $(value 8) while disabled"
cpm_try enable || { fail "cpm enable on canopen"; cpm status 2>/dev/null | head -n 5; jrnl | grep -iE 'fault|watchdog' | tail -n 5; }
wait_for 60 sh -c 'cpm status --json 2>/dev/null | grep -q "\"mode\": *\"holding\""' || fail "not holding after enable"
s=$(vd_status); echo "drives: $s"
echo "$s" | grep -q 'states operation enabled operation enabled operation enabled' && ok "the drives are operation enabled" \
  || fail "drives not operation enabled: $s"
[ "$(value 1)" = 1 ] && [ "$(value 8)" = 1 ] && ok "enable line 1, z brake released" || fail "enable $(value 1), brake_z $(value 8) while holding"

step "canopen: SIGSTOP while holding: watchdog, restart, disabled, brake on, nothing moved"
pid=$(prop MainPID) restarts0=$(prop NRestarts)
p0=$(vd_status | sed -n 's/.*position \([^ ]* [^ ]* [^ ]*\).*/\1/p')
t_sig=$(up)
kill -STOP "$pid"
wait_for 180 restarted "$restarts0" "$pid" \
  || fatal "cpmd on canopen was not restarted"
jrnl > j.txt
awk -v s="$t_sig" -v w="$(stamp_after j.txt "$t_sig" 'Watchdog timeout')" -v k="$(stamp_after j.txt "$t_sig" 'Main process exited')" \
    -v e="$(stamp_after j.txt "$t_sig" 'Started cpmd')" 'BEGIN {
  printf "WATCHDOG-FIGURES canopen: watchdog timeout +%.3f s; main process dead +%.3f s; restarted daemon ready +%.3f s\n", w - s, k - s, e - s }'
wait_for 60 cpm status || fatal "the restarted cpmd does not answer"
mode=$(cpm status --json 2>/dev/null | json_field mode)
s=$(vd_status); echo "drives: $s"
p1=$(echo "$s" | sed -n 's/.*position \([^ ]* [^ ]* [^ ]*\).*/\1/p')
echo "plant position before the SIGSTOP: $p0; after the restart: $p1 (m)"
[ "$mode" = disabled ] && ok "the restarted cpmd is disabled" || fail "the restarted cpmd is '$mode'"
[ "$(value 8)" = 0 ] && [ "$(value 1)" = 0 ] && ok "brake on, enable line off" || fail "brake_z $(value 8), enable $(value 1) after the restart"
echo "$s" | grep -q "operation enabled" && fail "a drive is still operation enabled: $s" || ok "no drive operation enabled"
awk -v a="$p0" -v b="$p1" 'BEGIN { split(a, p, " "); split(b, q, " "); d = 0; for (i = 1; i <= 3; i++) d += (p[i] - q[i])^2;
  printf "moved %.1f um\n", sqrt(d) * 1e6; exit !(sqrt(d) < 1e-4) }' && ok "nothing moved (< 100 um)" || fail "the platform moved"

step "canopen: systemctl stop while holding disables the drives"
cpm_try reset >/dev/null 2>&1 || true
cpm_try enable || fail "cpm enable after the restart"
wait_for 60 sh -c 'cpm status --json 2>/dev/null | grep -q "\"mode\": *\"holding\""' || fail "not holding"
t_s=$(up)
systemctl stop $UNIT
echo "stop took $(awk -v a="$t_s" -v b="$(up)" 'BEGIN { printf "%.2f", b - a }') s (TimeoutStopSec $(prop TimeoutStopUSec)); result $(prop Result)"
[ "$(prop Result)" = success ] && ok "stopped cleanly within TimeoutStopSec" || fail "stop: result $(prop Result)"
s=$(vd_status); echo "drives: $s"
echo "$s" | grep -q "operation enabled" && fail "a drive is still operation enabled after stop: $s" || ok "the drives saw the disable"
[ "$(value 8)" = 0 ] && [ "$(value 1)" = 0 ] && ok "brake on, enable line off after stop" || fail "brake_z $(value 8), enable $(value 1) after stop"
kill "$vdpid" 2>/dev/null
fi

step "seccomp: system calls refused (audit type=1326) and SIGSYS kills"
journalctl -b -k --no-pager -o cat | grep -E 'type=1326|audit.*seccomp' | sed 's/^/  /'
journalctl -b -k --no-pager -o cat | grep -qE 'type=1326|audit.*seccomp' && fail "seccomp refused a system call" || ok "none"

echo
if [ $fails -eq 0 ]; then echo "PASS (guest uptime $(up) s)"; else echo "FAILED: $fails checks"; fi
[ $fails -eq 0 ]

#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# Our virtual drives commissioned by CANopenNode: canopend (CANopenNode's
# CANopen device with SDO client, NMT master and the CiA 309-3 ASCII gateway)
# driven by cocomm, on vcan0, does to build/bin/virtual-drives what a
# commissioning tool does to a real drive: reads and writes objects by SDO
# (expedited and segmented), maps a TPDO and checks its frames against the
# objects, starts, stops and resets the nodes by NMT, consumes their
# heartbeat and their EMCY. A misreading of CiA 301 in hal::VirtualDrive
# fails here, against an implementation we did not write.
#
#   commissioning.sh VIRTUAL_DRIVES CANOPEND COCOMM      (run by tests/sil/run-in-vm.sh: needs vcan0)
set -uo pipefail
vd=$1 canopend=$2 cocomm=$3
can=${CPM_SIL_CAN:-vcan0}
run=$(mktemp -d /run/cpm-commissioning.XXXXXX 2>/dev/null || mktemp -d)
failures=0
pids=()
trap 'kill "${pids[@]}" 2>/dev/null; wait 2>/dev/null; rm -rf "$run"' EXIT

fail() { echo "commissioning: FAILED: $*"; failures=$((failures + 1)); }
# cocomm's answer without its colour codes and "[1] " sequence tag.
cc() { "$cocomm" -s "$run/gw.sock" "$1" 2>&1 | sed -e 's/\x1b\[[0-9;]*m//g' -e 's/^\[[0-9]*\] *//' | tr -d '\r'; }
expect() {  # WHAT COMMAND WANT: the gateway's answer must be WANT
  local got
  got=$(cc "$2")
  if [ "$got" = "$3" ]; then echo "commissioning: $1: '$2' -> $got"; else fail "$1: '$2' answered '$got', expected '$3'"; fi
}
# Fault injection through the virtual drives' stdin (a FIFO): no process to start per
# command, which costs seconds in an emulated VM.
vd_command() { echo "$1" >&5; }
log_has() {  # TEXT SECONDS: the gateway's message log shows TEXT within SECONDS (emulated time is slow)
  local i
  local log=""
  for i in $(seq 1 $((2 * $2))); do
    log+=$(cc log)   # the gateway hands each message out once
    grep -q -- "$1" <<<"$log" && return 0
    sleep 0.5
  done
  return 1
}
# Frames with COB-ID ID (hex) seen on the bus for SECONDS: "count len first-data-hex".
frames() { python3 - "$can" "$1" "$2" <<'PY'
import socket, struct, sys, time
s = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
s.bind((sys.argv[1],)); s.settimeout(0.05)
want, n, first = int(sys.argv[2], 16), 0, None
t0 = time.monotonic()
while time.monotonic() - t0 < float(sys.argv[3]):
    try:
        cid, dlc, data = struct.unpack("=IB3x8s", s.recv(16))
    except socket.timeout:
        continue
    if cid == want:
        n += 1
        first = first or (dlc, data[:dlc].hex())
print(n, *(first or (0, "-")))
PY
}

mkfifo "$run/vd.in"
"$vd" --interface "$can" --rate 1000 --stdin --ready-file "$run/vd.ready" <"$run/vd.in" 2>"$run/vd.log" &
pids+=($!)
exec 5>"$run/vd.in"
# Node 126; storage in the run folder (its example dictionary keeps 0x1010/0x1011 there).
"$canopend" "$can" -i 126 -c "local-$run/gw.sock" -s "$run/od_" >"$run/canopend.log" 2>&1 &
pids+=($!)
for i in $(seq 1 600); do [ -S "$run/gw.sock" ] && [ -f "$run/vd.ready" ] && break; sleep 0.1; done
[ -S "$run/gw.sock" ] && [ -f "$run/vd.ready" ] ||
  { cat "$run/canopend.log" "$run/vd.log"; echo "commissioning: canopend or the virtual drives did not start"; exit 1; }

# SDO, expedited: identity and profile; a write read back; an abort for what is not there.
expect "device type (CiA 402)" "1 r 0x1000 0 x32" "0x00020192"
expect "vendor-specific identity" "2 r 0x1018 0 u8" "4"
expect "producer heartbeat written" "1 w 0x1017 0 u16 100" "OK"
expect "and read back" "1 r 0x1017 0 u16" "100"
expect "statusword: switch on disabled" "1 r 0x6041 0 u16" "576"
expect "max torque written" "3 w 0x6072 0 u16 3000" "OK"
expect "and read back" "3 r 0x6072 0 u16" "3000"
expect "a read-only object refuses a write" "1 w 0x6041 0 u16 0" "ERROR:0x06010002 #Attempt to write a read only object."
expect "an object that is not there" "1 r 0x607A 0 u32" "ERROR:0x06020000 #Object does not exist."
# SDO, segmented: the device name (26 bytes) and a 52-byte parameter block, written and read back.
expect "device name, segmented read" "1 r 0x1008 0 vs" '"cpm virtual CiA 402 drive"'
block="commissioning-parameter-block-0123456789-abcdefghij"
expect "parameter block, segmented write" "2 w 0x2000 0 vs $block" "OK"
expect "and segmented read" "2 r 0x2000 0 vs" "\"$block\""
domain=AAECAwQFBgcICQoLDA0ODxAREhMUFRYXGBkaGxwdHh8=   # bytes 0..31, base64 (CiA 309-3 domain)
expect "binary block, segmented write" "2 w 0x2000 0 d $domain" "OK"
expect "and read back byte for byte" "2 r 0x2000 0 d" "$domain"
# SDO block transfer: the virtual drive does not offer it and refuses the
# initiate with the abort CiA 301 gives for that (a tool must fall back to
# segmented, as canopend does by default); it must not hang or answer wrongly.
expect "block transfer on in the tool" "set sdo_block 1" "OK"
expect "block upload refused" "1 r 0x1008 0 vs" "ERROR:0x05040001 #Command specifier not valid or unknown."
expect "block download refused" "2 w 0x2000 0 vs $block" "ERROR:0x05040001 #Command specifier not valid or unknown."
expect "block transfer off again" "set sdo_block 0" "OK"

# PDO mapping as CiA 301 asks: invalidate, clear, map, count, type, validate.
expect "TPDO1 invalidated" "1 w 0x1800 1 u32 0x80000181" "OK"
expect "mapping cleared" "1 w 0x1A00 0 u8 0" "OK"
expect "statusword mapped" "1 w 0x1A00 1 u32 0x60410010" "OK"
expect "position mapped" "1 w 0x1A00 2 u32 0x60640020" "OK"
expect "two objects" "1 w 0x1A00 0 u8 2" "OK"
expect "every SYNC" "1 w 0x1800 2 u8 1" "OK"
expect "TPDO1 valid" "1 w 0x1800 1 u32 0x00000181" "OK"
expect "mapping read back" "1 r 0x1A00 2 x32" "0x60640020"

# Heartbeat consumer in canopend (node 126's own 0x1016, through the gateway's local SDO): node 1, 500 ms.
expect "canopend consumes node 1's heartbeat" "126 w 0x1016 1 u32 0x000101F4" "OK"
# NMT start, canopend as SYNC producer (10 ms): node 1's TPDO1 on the bus, 6 bytes, the objects' values.
expect "NMT start" "1 start" "OK"
log_has 'node ID = 0x01 (index = 0): NMT state changed to: "operational"' 20 || fail "canopend did not see node 1 operational by its heartbeat"
expect "SYNC period" "126 w 0x1006 0 u32 10000" "OK"
expect "canopend produces SYNC" "126 w 0x1005 0 u32 0x40000080" "OK"
# The platform is held still (no drive enabled): the objects read now are what every TPDO carries.
position=$(cc "1 r 0x6064 0 i32")
sw=$(cc "1 r 0x6041 0 u16")
want=$(printf '%02x%02x' $((sw & 255)) $((sw >> 8)))$(printf '%02x%02x%02x%02x' $((position & 255)) $(((position >> 8) & 255)) $(((position >> 16) & 255)) $(((position >> 24) & 255)))
read -r n len data <<<"$(frames 181 1.0)"
if [ "$n" -gt 0 ] && [ "$len" = 6 ] && [ "$data" = "$want" ]; then
  echo "commissioning: TPDO1 0x181 every SYNC: $n frames in 1 s, 6 bytes $data = statusword $sw, position $position"
else
  fail "TPDO1: $n frames, length $len, data $data; the objects give $want (statusword $sw, position $position)"
fi
# NMT pre-operational: the TPDO stops, SDO still answers.
expect "NMT pre-operational" "1 preop" "OK"
read -r n _ _ <<<"$(frames 181 0.5)"
[ "$n" -eq 0 ] || fail "TPDO1 still sent in pre-operational ($n frames)"
expect "SDO in pre-operational" "1 r 0x1017 0 u16" "100"
# EMCY consumed by canopend.
vd_command "emcy 1 0x2310 0x02"
log_has "Emergency message from node 0x01: errorCode=0x2310" 20 || fail "canopend did not log node 1's EMCY 0x2310"
# The heartbeat stops: canopend's consumer times out.
vd_command "heartbeat 1 off"
log_has 'node ID = 0x01 (index = 0): NMT state changed to: "unknown"' 60 || fail "canopend's heartbeat consumer did not time out"
vd_command "heartbeat 1 on"
# NMT stopped: no SDO answer (CiA 301); reset communication: boot-up, pre-operational, the
# communication area back to its power-on values, profile objects kept.
expect "NMT stop" "1 stop" "OK"
expect "SDO in stopped" "1 r 0x1017 0 u16" "ERROR:0x05040000 #SDO protocol timed out."
cc log >/dev/null   # what the log held so far: the boot-up below must be new
expect "NMT reset communication" "1 reset communication" "OK"
log_has 'node ID = 0x01 (index = 0): NMT state changed to: "initializing"' 20 || fail "no boot-up after reset communication"
expect "0x1017 back to its power-on value" "1 r 0x1017 0 u16" "0"
expect "TPDO1 mapping back to its power-on value" "1 r 0x1A00 0 u8" "1"
expect "profile object kept" "3 r 0x6072 0 u16" "3000"
expect "NMT reset node" "3 reset node" "OK"
sleep 0.5
expect "profile object back to its power-on value" "3 r 0x6072 0 u16" "1000"

if [ $failures -ne 0 ]; then
  echo "---- canopend log"; cc log; cat "$run/canopend.log"; echo "---- virtual-drives log"; cat "$run/vd.log"
  echo "commissioning: $failures check(s) failed"
  exit 1
fi
echo "commissioning: all checks passed"

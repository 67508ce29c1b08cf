# SPDX-License-Identifier: Apache-2.0
# Shared set-up of the SIL environment: loopback and multicast route, vcan0,
# and a gpio-sim chip with the machine's named lines. POSIX sh: it is sourced
# by busybox ash inside the VM and by bash on a host that has vcan/gpio-sim,
# so both paths give a test the same devices and the same CPM_SIL_* variables.

# Names of the simulated GPIO lines, by offset (bank0 of the chip labelled
# "cpm-sil"). Inputs are driven from the test through
# $CPM_SIL_GPIO_SYSFS/sim_gpio<offset>/pull; outputs read back from .../value.
CPM_SIL_GPIO_LABEL=cpm-sil
CPM_SIL_GPIO_LINES="estop enable limit_x_min limit_x_max limit_y_min limit_y_max limit_z_min limit_z_max brake_z spare9 spare10 spare11 spare12 spare13 spare14 spare15"
CPM_SIL_CAN=vcan0

sil_err() { echo "cpm-sil: $*" >&2; }

# Inside a fresh network namespace (host path) or the VM: bring up lo with a
# multicast route (LCM at ttl=0 stays on the machine) and vcan0 (unless
# called with "lo-only").
sil_net_up() {
  ip link set lo up || { sil_err "cannot bring lo up"; return 1; }
  ip route add 224.0.0.0/4 dev lo || { sil_err "cannot add the multicast route on lo"; return 1; }
  [ "${1:-}" = lo-only ] && return 0
  ip link add dev "$CPM_SIL_CAN" type vcan || { sil_err "cannot create $CPM_SIL_CAN (ip link add ... type vcan)"; return 1; }
  ip link set "$CPM_SIL_CAN" up || { sil_err "cannot bring $CPM_SIL_CAN up"; return 1; }
  export CPM_SIL_CAN
}

# sil_gpio_up NAME: create and enable gpio-sim device NAME through configfs;
# exports CPM_SIL_GPIO_CHIP (/dev/gpiochipN), CPM_SIL_GPIO_SYSFS (the
# directory holding sim_gpioN/{pull,value}) and CPM_SIL_GPIO_LINES.
sil_gpio_up() {
  _d=/sys/kernel/config/gpio-sim/$1
  [ -d /sys/kernel/config/gpio-sim ] || { sil_err "no /sys/kernel/config/gpio-sim (configfs or gpio-sim missing)"; return 1; }
  mkdir "$_d" "$_d/bank0" || { sil_err "cannot create $_d"; return 1; }
  echo "$CPM_SIL_GPIO_LABEL" > "$_d/bank0/label" || return 1
  _n=0
  for _name in $CPM_SIL_GPIO_LINES; do
    mkdir "$_d/bank0/line$_n" && echo "$_name" > "$_d/bank0/line$_n/name" || { sil_err "cannot name line $_n"; return 1; }
    _n=$((_n + 1))
  done
  echo "$_n" > "$_d/bank0/num_lines" || return 1
  echo 1 > "$_d/live" || { sil_err "cannot make $_d live"; return 1; }
  _dev=$(cat "$_d/dev_name") && _chip=$(cat "$_d/bank0/chip_name") || return 1
  CPM_SIL_GPIO_CHIP=/dev/$_chip
  CPM_SIL_GPIO_SYSFS=/sys/devices/platform/$_dev/$_chip
  [ -c "$CPM_SIL_GPIO_CHIP" ] || { sil_err "$CPM_SIL_GPIO_CHIP did not appear"; return 1; }
  [ -d "$CPM_SIL_GPIO_SYSFS/sim_gpio0" ] || { sil_err "$CPM_SIL_GPIO_SYSFS/sim_gpio0 missing"; return 1; }
  export CPM_SIL_GPIO_CHIP CPM_SIL_GPIO_SYSFS CPM_SIL_GPIO_LINES CPM_SIL_GPIO_LABEL
}

# sil_gpio_down NAME: undo sil_gpio_up (host path; the VM just powers off).
sil_gpio_down() {
  _d=/sys/kernel/config/gpio-sim/$1
  [ -d "$_d" ] || return 0
  echo 0 > "$_d/live" 2>/dev/null
  for _l in "$_d"/bank0/line*; do [ -d "$_l" ] && rmdir "$_l"; done
  rmdir "$_d/bank0" "$_d" 2>/dev/null
  return 0
}

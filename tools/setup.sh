#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# Install what cpmd needs to build and test, from Debian bookworm's packages.
# Idempotent and quiet when everything is already there.
set -euo pipefail
packages=(
  build-essential cmake pkg-config
  ninja-build              # tools/build.sh: the build's generator
  lintian                  # tests/install: the .deb checked as Debian checks packages
  libeigen3-dev            # linear algebra (fixed-size types in the control cycle)
  libgtest-dev libgmock-dev googletest
  libbenchmark-dev
  libyaml-cpp-dev          # configuration and model files
  libmuparser-dev          # formulas of user expression effects (docs/libraries.md)
  libcli11-dev             # every command line (cpm, cpmd, the drives, the tools)
  nlohmann-json3-dev       # every JSON read and written
  help2man                 # man pages generated from --help
  bash-completion          # completion for cpm (pkg-config gives its install folder)
  libncurses-dev           # cpm watch and cpm jog: the full-screen terminal
  libcpp-httplib-dev       # cpm scope: the page's HTTP server
  tmux                     # tests/tools: cpm watch in an 80 x 24 pane, captured
  chromium                 # tests/calibration: prints the ball-bar report to PDF, checks one A4 page
  libsodium-dev            # Ed25519: cpmd signs its state and acks (docs/security.md)
  libssl-dev               # SHA-256 of data files (libcrypto), model file provenance
  liblcm-dev liblcm-bin    # LCM transport and lcm-gen
  libgpiod-dev             # GPIO (v1 API, libgpiod 1.6)
  clang libclang-rt-14-dev # fuzz/: libFuzzer with ASan/UBSan (clang 14 of bookworm)
  qemu-system-x86 xz-utils # SIL tests: boots Debian's kernel (vcan, gpio-sim) when the host has none
  mmdebstrap e2fsprogs     # SIL test sil.systemd: a bookworm root file system for cpmd under systemd as PID 1
  rt-tests                 # bench/run.sh: cyclictest, the kernel's own wake-up latency beside cpmd's
  python3-scipy            # bench/run.sh: SciPy's least_squares on Kim's ball-bar problem beside cpmd's solver
  linuxcnc-uspace          # bench/run.sh: LinuxCNC's servo thread and motion controller (lineardeltakins) beside cpmd's loop
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
echo "setup: installing ${missing[*]}"
SUDO=""
[ "$(id -u)" -ne 0 ] && SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null

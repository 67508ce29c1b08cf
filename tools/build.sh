#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# Configure and build everything into build/ (binaries in build/bin).
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
# Ninja: one graph for the whole tree, so both cores stay busy across targets
# (make starts a target's units only once the targets it links are built).
# A build/ made with another generator keeps it.
generator=()
if [ ! -f build/CMakeCache.txt ] && command -v ninja >/dev/null; then
  generator=(-G Ninja)
fi
# Precompiled third-party headers: this build has no ccache (CMakeLists.txt, CPM_PCH).
cmake -S . -B build "${generator[@]}" -DCMAKE_BUILD_TYPE=Release -DCPM_PCH=ON >/dev/null
cmake --build build -j"$(nproc)"

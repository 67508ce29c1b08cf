#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# The main job: set up, build, start cpmd on its simulator backend, run the
# paper's circle through `cpm`, print the tracking error, stop.
set -euo pipefail
cd "$(dirname "$0")/.."
exec bash tools/run-main-daemon.sh

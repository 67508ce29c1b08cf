#!/usr/bin/env bash
# The main job: set up, build, and run the machine on its simulator.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/build.sh >/dev/null
exec build/bin/cpm sim --controller computed_torque --trajectory paper-circle --log build/paper-circle.csv

# SPDX-License-Identifier: Apache-2.0
# Sourced by the demo scripts (tools/run-main-daemon.sh, daemon/latency-run.sh):
# a throw-away operator for one run against the simulator (docs/security.md).
# Makes a fresh key under a private temporary directory, known to cpmd through
# `--operators "$CPMD_OPERATORS"` (role engineer) and to cpm through
# CPM_KEY_FILE. The caller removes "$CPMD_THROWAWAY" when the run ends.
#   usage: . tools/throwaway-operator.sh BIN_DIR
CPMD_THROWAWAY=$(mktemp -d "${TMPDIR:-/tmp}/cpmd-operator.XXXXXX")   # mode 0700: this user's only
CPMD_OPERATORS="$CPMD_THROWAWAY/operators.d"
mkdir -m 0700 "$CPMD_OPERATORS"
"$1/cpm" keygen "$CPMD_OPERATORS/demo.key" >/dev/null
printf '# throw-away operator of one demo run\ndemo: engineer\n' >"$CPMD_OPERATORS/roles.yaml"
chmod 0644 "$CPMD_OPERATORS/roles.yaml"
export CPM_KEY_FILE="$CPMD_OPERATORS/demo.key" CPM_OPERATOR=demo

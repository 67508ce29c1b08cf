// SPDX-License-Identifier: Apache-2.0
// What cpmd checks at start, beyond each file's own rules (config.cpp,
// the model file): that the configuration, the model and the backend fit
// together, so that a machine that cannot be run safely is refused before
// anything is powered, with what and why.
//   - the configured law and gains hold the machine at the loop's rate
//     (ctl::check_gains through check_daemon_gains);
//   - the actuator space's PD gains (homing.actuator_gains) do too: each
//     actuator is held by them, with the weight, until homed;
//   - every homing position (home_position, final_position) lies within the
//     model's strokes;
//   - the backend can run a drive's own homing where the config asks for it.
// `cpmd --check` runs it too.
#pragma once

#include "cpm/control/machine.hpp"
#include "cpm/daemon/backend.hpp"
#include "cpm/daemon/config.hpp"

namespace cpm::daemon {

// Throws Error naming the key and the figure of the first misfit.
void preflight(const DaemonConfig& cfg, const ctl::Machine& model, const Backend& backend);

}  // namespace cpm::daemon

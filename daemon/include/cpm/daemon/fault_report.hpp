// SPDX-License-Identifier: Apache-2.0
// The first fault of a state message in words an operator reads: the one
// place that writes them, for `cpm status` (text and --json "fault_report"),
// the journal (cpmd logs it when a fault latches) and any other client.
//
// The state message carries the fault as figures (state_t.first_fault,
// fault_axis, fault_value, fault_limit in SI units, and fault_text: the
// backend's words, or the kinematic cause such as "near_singularity"); this
// turns them into one line:
//   following_error: the platform was 5.046 mm from its reference against a
//   limit of 5.000 mm: the actuators could not follow the command (a
//   collision, a drive without power, gains too soft); check the axes, then
//   reset and enable
// Axes are numbered 1-3 as on the machine (x, y, z); a fault of no one axis
// names none. Not for the real-time path (it allocates).
#pragma once

#include <string>

#include <cpm_msgs/state_t.hpp>

namespace cpm::daemon {

// "" when no fault has latched (state.first_fault == 0).
std::string fault_report(const cpm_msgs::state_t& state);

}  // namespace cpm::daemon

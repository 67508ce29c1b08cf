// SPDX-License-Identifier: Apache-2.0
// Homing one actuator: a small state machine stepped once per control cycle,
// with the phases of LinuxCNC's homing (src/emc/motion/homing.c) for a home
// switch and an index, and a hand-over to a drive that homes itself (CiA 402
// homing mode). docs/operating.md has the sequences and the faults.
//
//   switch, from the switch released:
//     search     toward the switch at search_velocity until it is actuated
//                (give up after max_travel)
//     back_off   stop, then leave it at latch_velocity until it releases:
//                that edge, met slowly from one side, is the homing event
//     index      (use_index) on at latch_velocity to the next index mark
//     final      to final_position (if set)
//   switch, from the switch actuated: first away from it at the search
//   speed until it releases (back_off), then as above.
//   drive: the drive homes itself (drive); when it reports homing attained
//   its counts are redefined; then final.
//
// Positions are the actuator's raw reading (before the offset homing finds)
// in m; what the sequence asks for is a target velocity or a target
// position of the actuator's reference, or the drive's homing mode. The
// offset it reports at the homing event is what to add to the raw reading
// so that the actuator reads home_position there. Allocation-free, noexcept.
#pragma once

#include <cstdint>

#include "cpm/daemon/backend.hpp"
#include "cpm/daemon/config.hpp"

namespace cpm::daemon {

// = state_t.HOMING_*
enum class HomingPhase : std::int8_t { idle = 0, search = 1, back_off = 2, latch = 3, index = 4, drive = 5, final_ = 6 };
const char* homing_phase_name(HomingPhase p) noexcept;

class AxisHoming {
 public:
  // What one step saw of the actuator.
  struct Inputs {
    double t = 0.0;             // s, the cycle's nominal time
    double raw = 0.0;           // the actuator's reading without the homing offset (m)
    double reference = 0.0;     // the actuator's reference, in the same raw terms (m)
    bool reference_at_rest = true;
    bool home_switch = false;
    bool index = false;
    DriveHoming drive = DriveHoming::idle;
  };
  // What the sequence asks for this cycle.
  struct Request {
    enum class Kind : std::uint8_t { velocity, position, drive } kind = Kind::velocity;
    double velocity = 0.0;      // m/s (Kind::velocity)
    double position = 0.0;      // m, raw terms (Kind::position)
    double speed = 0.0;         // m/s, the fastest a position move may go
  };
  enum class Outcome : std::uint8_t { running, homed, failed };
  struct Failure {
    const char* cause = "";     // "switch_not_found", "switch_stuck", "index_not_found", "timeout", "drive_error"
    double value = 0.0;         // the figure (m travelled, s elapsed)
    double limit = 0.0;         // the limit it broke
  };

  // Begin homing with `cfg` at time t0; `switch_now`: the home switch's state.
  void start(const AxisHomingConfig& cfg, double t0, bool switch_now) noexcept;
  void abort() noexcept { phase_ = HomingPhase::idle; }
  Outcome step(const Inputs& in, Request& req) noexcept;

  [[nodiscard]] HomingPhase phase() const noexcept { return phase_; }
  [[nodiscard]] bool active() const noexcept { return phase_ != HomingPhase::idle; }
  // After Outcome::homed: the offset to add to raw readings (m). For a drive
  // that homed itself, 0 (its own counts moved).
  [[nodiscard]] double offset() const noexcept { return offset_; }
  // Set when the homing event has happened (the offset is known), before
  // the final move; the caller applies the offset at once.
  [[nodiscard]] bool event_seen() const noexcept { return event_seen_; }
  [[nodiscard]] const Failure& failure() const noexcept { return failure_; }

 private:
  Outcome fail(const char* cause, double value, double limit) noexcept;
  Outcome begin_final(const Inputs& in, Request& req) noexcept;
  AxisHomingConfig cfg_{};
  HomingPhase phase_ = HomingPhase::idle;
  double t0_ = 0.0;
  double mark_ = 0.0;           // raw position where the phase began
  double offset_ = 0.0;
  bool event_seen_ = false;
  bool stopping_ = false;       // search: the switch was met, the reference is stopping
  bool drive_started_ = false;  // drive: the drive has reported running
  Failure failure_{};
};

}  // namespace cpm::daemon

// SPDX-License-Identifier: Apache-2.0
// The true machine as drives on a synchronous CAN bus move it: one
// sim::Plant stepped by exactly one control period per SYNC frame, with the
// brake rule and the two timings of the header of virtual_machine.hpp.
//
// Whatever implements the drives (hal::VirtualDrive in VirtualMachine, or
// an independent CANopen stack in tests/canopennode/) tells it at each SYNC
// which drives hold their axis and which torques they took, and reads back
// the encoder values the drives' TPDOs carry. Keeping this in one place is
// what makes a run through another stack comparable with ours.
#pragma once

#include <array>
#include <cstdint>
#include <memory>

#include "cpm/control/machine.hpp"
#include "cpm/hal/pdo.hpp"
#include "cpm/sim/plant.hpp"

namespace cpm::sim {

enum class DriveTiming : std::uint8_t;
struct VirtualMachineConfig;

class SyncedPlant {
 public:
  // Validates the period and each axis's scaling (throws Error) and puts
  // the platform at cfg.initial_position. A velocity unit of 0 means counts
  // per second. Keeps a reference to `truth`.
  SyncedPlant(const ctl::Machine& truth, const VirtualMachineConfig& cfg);
  ~SyncedPlant();

  // One SYNC. holding[i]: drive i handled this SYNC (operational, not
  // silent) and is in operation enabled; activated[i]: the force (N) drive i
  // took from its RPDO at this SYNC.
  void on_sync(const std::array<bool, 3>& holding, const Vec3& activated);

  // The encoders of axis i in its drive's units (0x6064 counts, 0x606C).
  [[nodiscard]] std::int32_t position_units(int i) const noexcept;
  [[nodiscard]] std::int32_t velocity_units(int i) const noexcept;
  [[nodiscard]] const hal::pdo::Scaling& scaling(int i) const noexcept { return scaling_[static_cast<std::size_t>(i)]; }

  [[nodiscard]] const Plant& plant() const noexcept { return *plant_; }
  [[nodiscard]] std::uint64_t steps() const noexcept { return steps_; }  // SYNCs that moved the plant
  [[nodiscard]] const Vec3& last_force() const noexcept { return force_; }
  [[nodiscard]] bool failed() const noexcept { return failed_; }

 private:
  std::array<hal::pdo::Scaling, 3> scaling_{};
  DriveTiming timing_;
  double period_;
  std::unique_ptr<Plant> plant_;
  EncoderReading reading_{};
  Vec3 force_ = Vec3::Zero();
  std::uint64_t steps_ = 0;
  bool failed_ = false;
  bool enabled_before_ = false;  // every drive was in operation enabled at the previous SYNC
  bool released_ = false;        // synchronous timing: the brakes were open over the period now ending
};

}  // namespace cpm::sim

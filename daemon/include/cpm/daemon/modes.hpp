// SPDX-License-Identifier: Apache-2.0
// The loop's modes and fault bits (= state_t.MODE_* and state_t.FAULT_*) and
// their names: shared by the loop and its clients (cpm_client).
#pragma once

#include <cstdint>

namespace cpm::daemon {

enum class Mode : std::uint8_t { init = 0, disabled, enabling, holding, moving, stopping, fault, homing, jogging };
const char* mode_name(Mode m) noexcept;

// Latched fault bits (= state_t.FAULT_*).
enum FaultBit : std::uint32_t {
  kFaultFollowingError = 1,
  kFaultSoftLimit = 2,
  kFaultOverspeed = 4,
  kFaultController = 8,
  kFaultEstimate = 16,
  kFaultDrive = 32,
  kFaultBackendIo = 64,
  kFaultEstop = 128,
  kFaultOverrun = 256,
  kFaultEnableTimeout = 512,
  kFaultLimitSwitch = 1024,
  // An actuator held at the force limit longer than limits.saturation_time.
  kFaultSaturation = 2048,
  // A setpoint stream ran dry while moving (its next chunk was late): the
  // loop stops along the path at limits.stop_deceleration, then latches this.
  kFaultStreamUnderrun = 4096,
  // Homing failed: the switch was not found within its travel, it timed out,
  // or the drive reported a homing error (fault_text says which).
  kFaultHoming = 8192,
};
// "following_error,estop" for a mask (static storage per bit; the joined text
// is built in `buf`, not for the real-time path).
const char* fault_bit_name(std::uint32_t bit) noexcept;

}  // namespace cpm::daemon

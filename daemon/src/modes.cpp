// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/modes.hpp"

namespace cpm::daemon {

const char* mode_name(Mode m) noexcept {
  switch (m) {
    case Mode::init: return "init";
    case Mode::disabled: return "disabled";
    case Mode::enabling: return "enabling";
    case Mode::holding: return "holding";
    case Mode::moving: return "moving";
    case Mode::stopping: return "stopping";
    case Mode::fault: return "fault";
    case Mode::homing: return "homing";
    case Mode::jogging: return "jogging";
  }
  return "?";
}

const char* fault_bit_name(std::uint32_t bit) noexcept {
  switch (bit) {
    case kFaultFollowingError: return "following_error";
    case kFaultSoftLimit: return "soft_limit";
    case kFaultOverspeed: return "overspeed";
    case kFaultController: return "controller";
    case kFaultEstimate: return "estimate";
    case kFaultDrive: return "drive";
    case kFaultBackendIo: return "backend_io";
    case kFaultEstop: return "estop";
    case kFaultOverrun: return "overrun";
    case kFaultEnableTimeout: return "enable_timeout";
    case kFaultLimitSwitch: return "limit_switch";
    case kFaultSaturation: return "force_saturation";
    case kFaultStreamUnderrun: return "stream_underrun";
    case kFaultHoming: return "homing";
    default: return "unknown";
  }
}

}  // namespace cpm::daemon

// SPDX-License-Identifier: Apache-2.0
// The machine as three CiA 402 drives see it: three hal::VirtualDrive on one
// CAN bus, coupled by one sim::Plant (the true machine, a rigid platform on
// three actuators).
//
// The plant steps by exactly one control period per SYNC frame, never by
// the wall clock, so the closed loop through the bus is deterministic
// whatever the host's speed (a software-emulated VM included). Two timings:
//
//  * synchronous (the default, what a CiA 402 drive in cyclic synchronous
//    torque does): the SYNC ends the period that ran since the last one, so
//    the plant first steps through it under the torque that became active at
//    the last SYNC; then each drive samples its actual position 0x6064 and
//    velocity 0x606C and answers with them; then it activates the target
//    torque 0x6071 of the RPDO it got before this SYNC, for the period that
//    starts now. The master computes that torque from the positions of the
//    SYNC before, so a command acts one period after the sample it was made
//    from: the dead time of a synchronous bus, an actuation_delay of T.
//  * lockstep: every drive applies the RPDOs it got before the SYNC, then the
//    plant steps under them, then the drives answer: the command acts from
//    the sample it was made from, as in sim::run_closed_loop, which no real
//    bus does. Kept to compare with the in-process loop.
//
// Either way the plant holds the force over a period (zero-order hold).
//
// Brakes: while any drive is not in "operation enabled" (and during the
// first SYNC after all are, when the brake is still opening) the platform is
// held still where it is, as the daemon's simulator backend does.
//
// Frames are fed one at a time (pump() or on_frame()), so three drives that
// share one socket see the same frame order as on a real bus.
//
// Homing: each drive reads the sensors wired to it (hal::DriveInputs), set
// from the true actuator displacement d_i at every SYNC: a home switch
// actuated while d_i < home_switch[i] (near the low stroke end), limit
// switches within limit_margin of both stroke ends of the true machine, and
// an encoder index at every whole multiple of index_pitch (captured where it
// is). With `incremental`, the encoders count from 0 wherever each carriage
// stands when the drives power on (and again at each reappearance), as
// incremental encoders do: the master reads an unknown offset until it homes.
// The drives' own loops (homing mode) are tuned to the effective mass of
// each actuator at the initial position.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string_view>
#include <string>
#include <vector>

#include "cpm/control/machine.hpp"
#include "cpm/hal/can.hpp"
#include "cpm/hal/pdo.hpp"
#include "cpm/hal/virtual_drive.hpp"
#include "cpm/sim/plant.hpp"
#include "cpm/sim/synced_plant.hpp"

namespace cpm::sim {

struct VirtualAxis {
  int node_id = 1;
  hal::pdo::Scaling scaling;   // the same numbers as the master's drive config
};

// When an RPDO's torque acts (see the header comment).
enum class DriveTiming : std::uint8_t { synchronous, lockstep };
const char* timing_name(DriveTiming t) noexcept;                     // "synchronous", "lockstep"
std::optional<DriveTiming> timing_from_name(std::string_view name) noexcept;

struct VirtualMachineConfig {
  std::array<VirtualAxis, 3> axes{};
  DriveTiming timing = DriveTiming::synchronous;
  double period = 1e-3;                                  // s the plant advances per SYNC
  Vec3 initial_position = Vec3(0.600, 0.425, 0.300);     // platform centre at power-on (m)
  PlantOptions plant;
  int quick_stop_option = 2;                             // each drive's 0x605A default
  // Homing sensors and encoders (see the header comment).
  bool incremental = false;                              // counts start at 0 at power-on
  Vec3 home_switch = Vec3::Constant(0.010);              // d_i below which actuator i's home switch is actuated (m)
  double limit_margin = 0.003;                           // limit switches this far inside each stroke end (m); 0: none
  double index_pitch = 0.0;                              // an index every this much d (m); 0: none
  // The default: node ids 1, 2, 3; 1e7 counts/m (0.1 um), velocity in
  // counts/s, rated force 40 N, clamp 3000 per mille (120 N, docs/model.md).
  static VirtualMachineConfig defaults();
};

class VirtualMachine {
 public:
  // Keeps references to `bus` and `truth`. Throws Error on a bad config or an
  // initial position outside the true machine's workspace.
  VirtualMachine(hal::CanBus& bus, const ctl::Machine& truth, const VirtualMachineConfig& cfg);
  ~VirtualMachine();
  VirtualMachine(const VirtualMachine&) = delete;
  VirtualMachine& operator=(const VirtualMachine&) = delete;

  // Power the drives on (boot-up messages).
  void power_on(std::int64_t now_ns);
  // Every frame the bus has, one at a time, then poll (heartbeats, late answers).
  void pump(std::int64_t now_ns);
  // One received frame to every drive; a SYNC steps the plant.
  void on_frame(const hal::CanFrame& f, std::int64_t now_ns);
  // Let time pass without frames.
  void poll(std::int64_t now_ns);

  // Fault injection: the whole set of drives vanishes (power cut, cable
  // pulled) or comes back (boots again, pre-operational).
  void disappear(bool gone, std::int64_t now_ns);
  [[nodiscard]] bool gone() const noexcept { return gone_; }
  // Fault injection: actuator i's home switch never actuates (broken, or
  // its wire cut), or works again.
  void break_home_switch(int i, bool broken);
  // The counts of actuator i's encoder where its drive counts from 0 (the
  // plant's units at the last power-on with `incremental`, else 0).
  [[nodiscard]] std::int64_t encoder_zero(int i) const noexcept { return zero_.at(static_cast<std::size_t>(i)); }

  [[nodiscard]] hal::VirtualDrive& drive(int i) { return *drives_.at(static_cast<std::size_t>(i)); }
  [[nodiscard]] const Plant& plant() const noexcept { return plant_->plant(); }
  [[nodiscard]] std::uint64_t steps() const noexcept { return plant_->steps(); }  // SYNCs that moved the plant
  [[nodiscard]] std::uint64_t syncs() const noexcept { return syncs_; }     // SYNCs seen
  // N, per actuator: the force acting now (synchronous: over the period that starts at the last SYNC).
  [[nodiscard]] const Vec3& last_force() const noexcept { return plant_->last_force(); }
  [[nodiscard]] bool plant_failed() const noexcept { return plant_->failed(); }
  [[nodiscard]] const VirtualMachineConfig& config() const noexcept { return cfg_; }

 private:
  class Port;
  void on_sync(std::int64_t now_ns);
  hal::CanBus& bus_;
  VirtualMachineConfig cfg_;
  std::unique_ptr<SyncedPlant> plant_;
  std::vector<std::unique_ptr<Port>> ports_;
  std::vector<std::unique_ptr<hal::VirtualDrive>> drives_;
  std::array<std::uint64_t, 3> sync_seen_{};  // each drive's SYNC count before the frame
  std::uint64_t syncs_ = 0;
  bool gone_ = false;
  // Homing sensors.
  [[nodiscard]] std::int32_t encoder_counts(int i) const noexcept;  // what drive i counts now
  void set_sensors();
  kin::Strokes strokes_;
  std::array<std::int64_t, 3> zero_{};
  std::array<bool, 3> home_broken_{};
  Vec3 d_before_ = Vec3::Zero();  // d at the last SYNC (index crossings)
};

}  // namespace cpm::sim

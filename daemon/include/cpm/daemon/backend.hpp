// SPDX-License-Identifier: Apache-2.0
// The seam between the control loop and the machine's I/O.
//
// The loop sees two calls per cycle, read() at its start and write() before
// it ends, each with plain data in actuator space. Everything that can fail
// slowly or allocate (opening devices, CANopen boot-up, configuring PDOs)
// happens in start(), outside the loop. Implementations: the embedded
// simulator (sim_backend.hpp), CANopen drives over SocketCAN with GPIO
// (next issue, an adapter over hal/), and scripted fakes in tests.
//
// Units: actuator displacements along each actuator axis as the encoders
// read them (m), their velocities (m/s), forces along the actuator axes (N).
// Index i = 0, 1, 2 is actuator (limb) 1, 2, 3.
#pragma once

#include <array>
#include <cstdint>

namespace cpm::daemon {

// The homing status a drive reports while it runs its own homing procedure
// (CiA 402 homing mode, statusword bits 10, 12, 13).
enum class DriveHoming : std::uint8_t {
  idle = 0,      // not in homing mode, or homing not started
  running,       // homing in progress
  attained,      // homing attained: the drive's position now counts from its home
  error,         // homing error (switch not found, limit reached, ...)
};

// How the loop wants actuator i driven this cycle.
enum class AxisDrive : std::uint8_t {
  torque = 0,    // cyclic synchronous torque: BackendOutput::force
  homing,        // the drive's own homing mode; force ignored
};

struct BackendInput {
  std::array<double, 3> position{};       // encoder displacement d_i (m)
  std::array<double, 3> velocity{};       // d_i rate as the drive reports it (m/s)
  std::array<std::uint16_t, 3> statusword{};  // CiA 402 statusword, 0 when not applicable
  std::array<bool, 3> drive_enabled{};    // drive in "operation enabled", brake released
  std::array<bool, 3> drive_fault{};      // drive reports a fault
  bool estop = false;                     // emergency-stop chain open (GPIO input)
  std::array<bool, 3> limit_switch{};     // a limit switch of actuator i (either end) tripped this cycle
  std::uint32_t digital_inputs = 0;       // raw GPIO inputs, bit i = line i
  // Homing inputs: the home switch of actuator i (true = actuated), the
  // encoder's index pulse seen since the last read, and the status of a
  // drive running its own homing (AxisDrive::homing).
  std::array<bool, 3> home_switch{};
  std::array<bool, 3> index_pulse{};
  std::array<DriveHoming, 3> drive_homing{};
  // The drive lost its position since the last read (it rebooted, or its
  // feedback was interrupted): a homed actuator must be homed again.
  std::array<bool, 3> position_lost{};
};

struct BackendOutput {
  std::array<double, 3> force{};  // target force per actuator (N), already limited
  bool enable = false;            // drives to "operation enabled" (false: disable, brake)
  std::uint32_t digital_outputs = 0;
  // Per actuator: torque (the default), or the drive's own homing mode;
  // with homing, start_homing starts it (a rising edge is the backend's
  // business: held true while the loop wants homing to run).
  std::array<AxisDrive, 3> axis_drive{};
  std::array<bool, 3> start_homing{};
};

// What the commissioning view shows of each drive (drives_t); a backend
// fills what it knows and leaves the rest at the defaults.
struct DriveDiagnostics {
  int node_id = 0;                      // CANopen node id; 0: none
  std::int8_t nmt = -1;                 // drives_t.NMT_* (-1 unknown)
  std::int8_t cia402 = 8;               // drives_t.CIA402_* (8 unknown)
  std::uint16_t statusword = 0, controlword = 0;
  std::int8_t mode_display = 0;         // 0x6061
  std::int64_t heartbeat_age_ns = -1;   // -1: never heard, or no heartbeat
  std::uint32_t master_faults = 0;      // hal::DriveFault bits
  std::uint32_t emcy_count = 0;
  std::uint16_t last_emcy_code = 0;     // the last EMCY with a non-zero code
  std::uint8_t last_emcy_register = 0;
};
struct BackendDiagnostics {
  std::int8_t backend = 0;              // drives_t.BACKEND_*
  std::array<DriveDiagnostics, 3> drive{};
  std::int8_t bus_state = -1;           // drives_t.BUS_* (-1: no bus)
  std::uint64_t error_frames = 0, rx_dropped = 0, tx_failures = 0;
  int tx_error_counter = -1, rx_error_counter = -1;
  double bus_load = 0;
  bool estop = false;
  std::array<bool, 3> limit_low{}, limit_high{}, home_switch{};
};

enum class BackendResult : std::uint8_t { ok = 0, io_error, timeout };

class Backend {
 public:
  virtual ~Backend() = default;
  [[nodiscard]] virtual const char* name() const noexcept = 0;
  // Non-real-time: open and configure the devices for a loop of `period` (s).
  // Throws cpm::Error saying what failed.
  virtual void start(double period) = 0;
  // Non-real-time: leave the machine safe (drives disabled, brakes on).
  virtual void stop() noexcept = 0;
  // Real-time: feedback for cycle `cycle` (nominal time cycle * period).
  // Allocation-free, no lock, noexcept; only the device I/O as system calls.
  virtual BackendResult read(std::int64_t cycle, BackendInput& in) noexcept = 0;
  // Real-time: commands computed in cycle `cycle`, held until the next write.
  virtual BackendResult write(std::int64_t cycle, const BackendOutput& out) noexcept = 0;
  // Real-time: what the backend found wrong in the last read()/write(), as
  // one readable line ("drive 2 (y, node 2): heartbeat lost"); "" when
  // nothing. The loop copies it into the state when it latches a drive,
  // I/O, e-stop or limit-switch fault. Allocation-free.
  [[nodiscard]] virtual const char* fault_text() const noexcept { return ""; }
  // Real-time: the drives and bus for the commissioning view, as of the last
  // read(). Allocation-free; called a few times a second.
  virtual void diagnostics(BackendDiagnostics& out) const noexcept { out = BackendDiagnostics{}; }
  // Non-real-time: which actuators the backend can home with the drive's own
  // homing mode (AxisDrive::homing). Checked against the configuration at start.
  [[nodiscard]] virtual bool drive_homing_supported(int /*axis*/) const noexcept { return false; }
};

}  // namespace cpm::daemon

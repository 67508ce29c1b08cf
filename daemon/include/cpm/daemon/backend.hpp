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

struct BackendInput {
  std::array<double, 3> position{};       // encoder displacement d_i (m)
  std::array<double, 3> velocity{};       // d_i rate as the drive reports it (m/s)
  std::array<std::uint16_t, 3> statusword{};  // CiA 402 statusword, 0 when not applicable
  std::array<bool, 3> drive_enabled{};    // drive in "operation enabled", brake released
  std::array<bool, 3> drive_fault{};      // drive reports a fault
  bool estop = false;                     // emergency-stop chain open (GPIO input)
  std::array<bool, 3> limit_switch{};     // a limit switch of actuator i (either end) tripped this cycle
  std::uint32_t digital_inputs = 0;       // raw GPIO inputs, bit i = line i
};

struct BackendOutput {
  std::array<double, 3> force{};  // target force per actuator (N), already limited
  bool enable = false;            // drives to "operation enabled" (false: disable, brake)
  std::uint32_t digital_outputs = 0;
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
};

}  // namespace cpm::daemon

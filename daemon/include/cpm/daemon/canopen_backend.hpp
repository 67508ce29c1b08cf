// SPDX-License-Identifier: Apache-2.0
// The CANopen backend: the daemon's Backend over hal/ — three CiA 402 drives
// in cyclic synchronous torque through hal::Master on a CAN bus, and the
// machine's GPIO through hal::DigitalIo. docs/canopen-backend.md.
//
// start() (non-real-time, throws cpm::Error saying what and where): opens the
// SocketCAN interface and the GPIO lines (outputs at their safe level),
// checks the bus load, then NMT reset, SDO configuration and PDO mapping
// written and read back, NMT start, and one SYNC whose TPDOs must come back
// (so the first cycle already has the drives' positions).
//
// read()/write() (per cycle, allocation-free, never throw):
//   read   waits at most canopen.feedback_wait for this cycle's TPDOs, takes
//          the master's feedback and the GPIO inputs, and reports per drive
//          a fault while a condition holds (heartbeat lost, TPDOs missing,
//          CiA 402 fault, NMT not operational, unknown statusword) or in the
//          cycle an event arrives (EMCY, malformed TPDO); bus-off and error
//          passive as io_error; the e-stop input; a limit switch in the cycle
//          it trips (either end of an axis).
//   write  sends the controlwords and target torques (enable only when the
//          loop asks, the e-stop chain is closed and the GPIO works), then
//          SYNC; drives the enable output and the z brake (released only
//          while drive 3 reports operation enabled). On e-stop every drive
//          gets "disable voltage" and the brake engages in that same cycle,
//          whatever the loop asked. While not enabled, a drive in fault gets
//          a fault reset: a drive whose cause is gone returns to "switch on
//          disabled" (nothing moves); the daemon's own fault stays latched
//          until the operator's reset.
//   fault_text  the first problem of the cycle, e.g.
//          "drive 2 (y, node 2): heartbeat lost (no heartbeat for 160 ms)".
//
// Homing with the drive's own homing mode (drive_homing_supported(i): the
// drive's DriveHomingConfig::enabled): BackendOutput::axis_drive homing runs
// the drive in mode 6 (the force is ignored), start_homing held true makes
// the start (the master makes the rising edge of controlword bit 4).
// BackendInput::drive_homing: running while in progress, interrupted or
// attained but still moving; attained only once completed at rest at home;
// error on a homing error (with a line in fault_text, "drive 3 (z, node 3):
// homing error (statusword 0x2637)"); idle outside mode 6. position_lost:
// the drive booted again (its counts restarted). home_switch and
// index_pulse: the GPIO lines home_x..z, index_x..z. diagnostics(): the
// master's feedback, the bus and the GPIO inputs as of the last read().
#pragma once

#include <array>
#include <memory>

#include "cpm/daemon/backend.hpp"
#include "cpm/daemon/config.hpp"
#include "cpm/hal/digital_io.hpp"
#include "cpm/hal/master.hpp"

namespace cpm::daemon {

class CanopenBackend final : public Backend {
 public:
  // The daemon: opens SocketCAN `cfg.interface` and the GPIO lines at start().
  explicit CanopenBackend(const CanopenConfig& cfg);
  // Tests: devices owned by the caller (fake bus, fake clock, fake GPIO).
  CanopenBackend(const CanopenConfig& cfg, hal::CanBus& bus, hal::Clock& clock, hal::DigitalIo& io);
  ~CanopenBackend() override;
  CanopenBackend(const CanopenBackend&) = delete;
  CanopenBackend& operator=(const CanopenBackend&) = delete;

  [[nodiscard]] const char* name() const noexcept override { return "canopen"; }
  void start(double period) override;
  void stop() noexcept override;
  BackendResult read(std::int64_t cycle, BackendInput& in) noexcept override;
  BackendResult write(std::int64_t cycle, const BackendOutput& out) noexcept override;
  [[nodiscard]] const char* fault_text() const noexcept override { return text_; }
  void diagnostics(BackendDiagnostics& out) const noexcept override;
  [[nodiscard]] bool drive_homing_supported(int axis) const noexcept override;

  // For tests and diagnostics (loop thread only).
  [[nodiscard]] const hal::Feedback& feedback() const noexcept { return fb_; }
  [[nodiscard]] const hal::Commands& commands() const noexcept { return cmd_; }
  [[nodiscard]] const hal::DigitalInputs& inputs() const noexcept { return din_; }
  [[nodiscard]] const hal::DigitalOutputs& outputs() const noexcept { return dout_; }
  [[nodiscard]] const hal::BusLoad& bus_load() const noexcept { return cfg_.load; }

 private:
  void note(const char* fmt, ...) noexcept __attribute__((format(printf, 2, 3)));
  // read()'s steps: the bounded wait for this cycle's TPDOs; one drive's
  // feedback and faults into `in`; the bus's state after the master's read
  // `ms`; the GPIO inputs into `in` (false: GPIO read failed).
  void wait_for_feedback() noexcept;
  void read_drive(std::size_t i, BackendInput& in) noexcept;
  [[nodiscard]] bool bus_ok(const hal::Status& ms) noexcept;
  [[nodiscard]] bool read_gpio(BackendInput& in) noexcept;
  void open_devices();

  CanopenConfig cfg_;
  // Owned devices (daemon) or the caller's (tests).
  std::unique_ptr<hal::CanBus> own_bus_;
  std::unique_ptr<hal::Clock> own_clock_;
  std::unique_ptr<hal::DigitalIo> own_io_;
  hal::CanBus* bus_ = nullptr;
  hal::Clock* clock_ = nullptr;
  hal::DigitalIo* io_ = nullptr;
  std::unique_ptr<hal::Master> master_;
  bool started_ = false;

  hal::Feedback fb_{};
  hal::Commands cmd_{};
  hal::DigitalInputs din_{};
  hal::DigitalOutputs dout_{};
  bool io_ok_ = false;
  std::array<std::uint32_t, 3> emcy_seen_{};
  std::array<std::uint32_t, 3> faults_seen_{};
  std::array<bool, 3> limit_before_{};
  std::array<bool, 3> was_enabled_{};   // operation enabled while we asked for it, last read
  bool enabled_asked_ = false;          // the last write asked for operation enabled
  std::uint64_t error_frames_seen_ = 0;
  std::int64_t feedback_wait_ns_ = 0;
  char text_[160] = {};
  std::size_t text_len_ = 0;
};

}  // namespace cpm::daemon

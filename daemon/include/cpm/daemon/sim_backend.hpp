// SPDX-License-Identifier: Apache-2.0
// The embedded simulator backend: the plant of sim/ (the true machine, with
// its own parameters and effects) stepped in-process by the loop.
//
// Time is the loop's nominal time, not the wall clock: read(k) first
// advances the plant to t = k * period under the force of the last write()
// held constant (zero-order hold, exactly as sim::run_closed_loop does), so a
// skipped slot is simulated as the real machine would live it (the old force
// held for two periods) and a run with no overruns is bit-for-bit the
// in-process closed loop.
//
// Drives: enable = true releases the brakes and, after `enable_delay` (s),
// reports the drives as enabled; enable = false applies the brakes, which
// hold the platform still where it is (the simulated plant is not stepped).
// Faults can be injected (drive fault, e-stop, I/O error) for tests.
//
// Homing inputs (SimConfig): incremental encoders read d - encoder_zero;
// home switches and index marks are placed in the true d, where the plant
// is, whatever the encoders read.
#pragma once

#include <atomic>
#include <limits>
#include <memory>

#include "cpm/daemon/backend.hpp"
#include "cpm/sim/plant.hpp"

namespace cpm::daemon {

struct SimBackendOptions {
  sim::PlantOptions plant;
  Vec3 initial_position = Vec3(0.600, 0.425, 0.300);  // platform centre at start (m)
  double enable_delay = 0.005;                          // s from enable to "operation enabled"
  // BackendInput::position = d - encoder_zero (m): an incremental encoder's
  // count starts wherever the actuator was; 0 = an absolute encoder.
  Vec3 encoder_zero = Vec3::Zero();
  // BackendInput::home_switch[i] is true while the true d_i < home_switch[i] (m); NaN: no switch.
  Vec3 home_switch = Vec3::Constant(std::numeric_limits<double>::quiet_NaN());
  // Index marks at d = k index_pitch (m, k integer; 0 = none). index_pulse[i]
  // is true when a read finds d_i within kIndexHalfWidth of a mark, or finds
  // that d_i crossed a mark since the last read: a mark is never missed,
  // whatever the speed, and it is seen within one period's travel (or the
  // half width) of where it is.
  double index_pitch = 0.0;
  static constexpr double kIndexHalfWidth = 5e-6;  // m: a mark 10 um wide, as an encoder's index of a few counts
};

struct SimConfig;
// The options of cpmd's `sim:` section.
SimBackendOptions sim_backend_options(const SimConfig& sim);

class SimBackend final : public Backend {
 public:
  // Takes ownership of the true machine.
  SimBackend(std::unique_ptr<ctl::Machine> truth, const SimBackendOptions& options);
  [[nodiscard]] const char* name() const noexcept override { return "sim"; }
  void start(double period) override;
  void stop() noexcept override;
  BackendResult read(std::int64_t cycle, BackendInput& in) noexcept override;
  BackendResult write(std::int64_t cycle, const BackendOutput& out) noexcept override;
  // BACKEND_SIM: node ids 0, the CiA 402 state of the statusword the last
  // read() reported (mode 10: the simulator acts as in cyclic synchronous
  // torque), no bus, the e-stop and home switches as read; no limit switches.
  void diagnostics(BackendDiagnostics& out) const noexcept override;

  // Fault injection (any thread): a drive fault on actuator `axis` (-1 clears),
  // the e-stop chain, an I/O error on the next reads.
  void inject_drive_fault(int axis) noexcept { drive_fault_axis_.store(axis); }
  void set_estop(bool open) noexcept { estop_.store(open); }
  void inject_io_error(bool on) noexcept { io_error_.store(on); }

  // The true platform state (for tests; not thread-safe against the loop).
  [[nodiscard]] const sim::Plant& plant() const noexcept { return *plant_; }

 private:
  [[nodiscard]] bool drives_on() const noexcept;
  std::unique_ptr<ctl::Machine> truth_;
  SimBackendOptions opt_;
  std::unique_ptr<sim::Plant> plant_;
  double period_ = 1e-3;
  std::int64_t plant_cycle_ = 0;  // cycle the plant's state belongs to
  Vec3 force_ = Vec3::Zero();
  bool enable_ = false;
  std::int64_t enabled_for_ = 0;  // cycles with enable = true
  bool plant_failed_ = false;
  // What the last read() reported, for diagnostics(); the true d it found
  // (for the index marks crossed since).
  BackendInput last_in_{};
  Vec3 last_d_ = Vec3::Zero();
  std::atomic<int> drive_fault_axis_{-1};
  std::atomic<bool> estop_{false};
  std::atomic<bool> io_error_{false};
};

}  // namespace cpm::daemon

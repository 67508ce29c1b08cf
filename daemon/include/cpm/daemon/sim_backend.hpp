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
#pragma once

#include <atomic>
#include <memory>

#include "cpm/daemon/backend.hpp"
#include "cpm/sim/plant.hpp"

namespace cpm::daemon {

struct SimBackendOptions {
  sim::PlantOptions plant;
  Vec3 initial_position = Vec3(0.600, 0.425, 0.300);  // platform centre at start (m)
  double enable_delay = 0.005;                          // s from enable to "operation enabled"
};

class SimBackend final : public Backend {
 public:
  // Takes ownership of the true machine.
  SimBackend(std::unique_ptr<ctl::Machine> truth, const SimBackendOptions& options);
  [[nodiscard]] const char* name() const noexcept override { return "sim"; }
  void start(double period) override;
  void stop() noexcept override;
  BackendResult read(std::int64_t cycle, BackendInput& in) noexcept override;
  BackendResult write(std::int64_t cycle, const BackendOutput& out) noexcept override;

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
  std::atomic<int> drive_fault_axis_{-1};
  std::atomic<bool> estop_{false};
  std::atomic<bool> io_error_{false};
};

}  // namespace cpm::daemon

#include "cpm/daemon/sim_backend.hpp"

#include <cmath>

namespace cpm::daemon {

SimBackend::SimBackend(std::unique_ptr<ctl::Machine> truth, const SimBackendOptions& options)
    : truth_(std::move(truth)), opt_(options) {
  opt_.plant.validate();
  if (!(opt_.enable_delay >= 0.0)) throw Error("sim backend: enable_delay must be >= 0 s");
  plant_ = std::make_unique<sim::Plant>(*truth_, opt_.plant);
  if (Status s = plant_->reset(opt_.initial_position); !s)
    throw Error("sim backend: initial position is outside the true machine's workspace: " + describe(s));
}

void SimBackend::start(double period) {
  if (!(period > 0.0)) throw Error("sim backend: period must be > 0");
  ctl::check_delay_fits(truth_->actuation_delay(), 1.0 / period);  // the plant's command history
  period_ = period;
  plant_cycle_ = 0;
}

void SimBackend::stop() noexcept { enable_ = false; }

bool SimBackend::drives_on() const noexcept {
  return enable_ && static_cast<double>(enabled_for_) * period_ >= opt_.enable_delay - 1e-12;
}

BackendResult SimBackend::read(std::int64_t cycle, BackendInput& in) noexcept {
  // Advance the plant to this cycle's nominal time under the held force
  // (one step per slot, so a skipped slot holds the old force twice). While
  // the drives are off, the brakes hold the platform still.
  while (plant_cycle_ < cycle) {
    if (drives_on() && !plant_failed_) {
      if (Status s = plant_->step(force_, period_); !s) plant_failed_ = true;
    } else {
      if (plant_->velocity().squaredNorm() > 0.0) (void)plant_->reset(plant_->position());
      // The drives take the commands while the brakes hold: under an
      // actuation delay the last one acts when they come on, until the
      // first delayed one does.
      plant_->forget_commands(force_);
    }
    ++plant_cycle_;
  }
  if (io_error_.load(std::memory_order_relaxed)) return BackendResult::io_error;
  const sim::EncoderReading r = plant_->read();
  for (int i = 0; i < 3; ++i) {
    in.position[i] = r.d[i];
    in.velocity[i] = r.d_dot[i];
  }
  const bool on = drives_on();
  const int fault_axis = drive_fault_axis_.load(std::memory_order_relaxed);
  for (int i = 0; i < 3; ++i) {
    // The platform leaving the true machine's workspace is what a drive
    // reports as a limit-switch fault.
    in.drive_fault[i] = fault_axis == i || plant_failed_;
    in.drive_enabled[i] = on && !in.drive_fault[i];
    // CiA 402 statusword: 0x0237 operation enabled, 0x0250 switch-on disabled, 0x0218 fault.
    in.statusword[i] = in.drive_fault[i] ? 0x0218 : (in.drive_enabled[i] ? 0x0237 : 0x0250);
  }
  in.estop = estop_.load(std::memory_order_relaxed);
  in.digital_inputs = in.estop ? 0u : 1u;  // line 0: e-stop chain closed
  return BackendResult::ok;
}

BackendResult SimBackend::write(std::int64_t, const BackendOutput& out) noexcept {
  if (io_error_.load(std::memory_order_relaxed)) return BackendResult::io_error;
  // The e-stop chain cuts the drives' power whatever the loop asks.
  enable_ = out.enable && !estop_.load(std::memory_order_relaxed);
  enabled_for_ = enable_ ? enabled_for_ + 1 : 0;
  for (int i = 0; i < 3; ++i) force_[i] = std::isfinite(out.force[i]) ? out.force[i] : 0.0;
  return BackendResult::ok;
}

}  // namespace cpm::daemon

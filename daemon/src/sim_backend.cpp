// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/sim_backend.hpp"

#include "cpm/daemon/config.hpp"

#include <cmath>

#include <cpm_msgs/drives_t.hpp>

#include "cpm/hal/cia402.hpp"

namespace cpm::daemon {
namespace {

// drives_t.CIA402_* of a statusword.
std::int8_t cia402_code(std::uint16_t statusword) noexcept {
  using hal::cia402::State;
  using D = cpm_msgs::drives_t;
  switch (hal::cia402::decode_statusword(statusword)) {
    case State::not_ready_to_switch_on: return D::CIA402_NOT_READY;
    case State::switch_on_disabled: return D::CIA402_SWITCH_ON_DISABLED;
    case State::ready_to_switch_on: return D::CIA402_READY;
    case State::switched_on: return D::CIA402_SWITCHED_ON;
    case State::operation_enabled: return D::CIA402_OPERATION_ENABLED;
    case State::quick_stop_active: return D::CIA402_QUICK_STOP;
    case State::fault_reaction_active: return D::CIA402_FAULT_REACTION;
    case State::fault: return D::CIA402_FAULT;
    case State::unknown: break;
  }
  return D::CIA402_UNKNOWN;
}

// The index mark nearest to d (m), for marks every `pitch`.
double nearest_mark(double d, double pitch) noexcept { return std::round(d / pitch) * pitch; }

}  // namespace

SimBackendOptions sim_backend_options(const SimConfig& sim) {
  SimBackendOptions so;
  so.plant = sim.plant;
  so.initial_position = sim.initial_position;
  so.enable_delay = sim.enable_delay;
  so.encoder_zero = sim.encoder_zero;
  so.home_switch = sim.home_switch;
  so.index_pitch = sim.index_pitch;
  return so;
}

SimBackend::SimBackend(std::unique_ptr<ctl::Machine> truth, const SimBackendOptions& options)
    : truth_(std::move(truth)), opt_(options) {
  opt_.plant.validate();
  if (!(opt_.enable_delay >= 0.0)) throw Error("sim backend: enable_delay must be >= 0 s");
  if (!opt_.encoder_zero.allFinite()) throw Error("sim backend: encoder_zero must be finite (m)");
  if (!(opt_.index_pitch >= 0.0 && std::isfinite(opt_.index_pitch)) ||
      (opt_.index_pitch > 0.0 && opt_.index_pitch <= 2.0 * SimBackendOptions::kIndexHalfWidth))
    throw Error("sim backend: index_pitch must be 0 (none) or wider than an index mark (10 um)");
  plant_ = std::make_unique<sim::Plant>(*truth_, opt_.plant);
  if (Status s = plant_->reset(opt_.initial_position); !s)
    throw Error("sim backend: initial position is outside the true machine's workspace: " + describe(s));
  Vec3 v;
  if (Status s = plant_->actuator_state(last_d_, v); !s) throw Error("sim backend: " + describe(s));
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
    in.position[i] = r.d[i] - opt_.encoder_zero[i];
    in.velocity[i] = r.d_dot[i];
  }
  // Switches and marks are where the plant truly is (no encoder model). A
  // failed plant keeps its last good state, so last_d_ stays meaningful.
  Vec3 d = last_d_, d_dot;
  if (Status s = plant_->actuator_state(d, d_dot); !s) d = last_d_;
  for (int i = 0; i < 3; ++i) {
    in.home_switch[i] = d[i] < opt_.home_switch[i];  // false for NaN: no switch
    const double pitch = opt_.index_pitch;
    in.index_pulse[i] = pitch > 0.0 && (std::abs(d[i] - nearest_mark(d[i], pitch)) < SimBackendOptions::kIndexHalfWidth ||
                                        std::floor(d[i] / pitch) != std::floor(last_d_[i] / pitch));
    in.drive_homing[i] = DriveHoming::idle;
    in.position_lost[i] = false;
  }
  last_d_ = d;
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
  last_in_ = in;
  return BackendResult::ok;
}

void SimBackend::diagnostics(BackendDiagnostics& out) const noexcept {
  out = BackendDiagnostics{};
  out.backend = cpm_msgs::drives_t::BACKEND_SIM;
  for (std::size_t i = 0; i < 3; ++i) {
    auto& d = out.drive[i];
    d.statusword = last_in_.statusword[i];
    d.cia402 = cia402_code(d.statusword);
    d.mode_display = hal::cia402::kModeCyclicSyncTorque;
    out.home_switch[i] = last_in_.home_switch[i];
  }
  out.bus_state = cpm_msgs::drives_t::BUS_NONE;
  out.estop = last_in_.estop;
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

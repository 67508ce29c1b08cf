// SPDX-License-Identifier: Apache-2.0
#include "cpm/sim/synced_plant.hpp"

#include <cmath>
#include <string>

#include "cpm/sim/virtual_machine.hpp"

namespace cpm::sim {

namespace {
std::int32_t to_units(double v, double per_unit, int direction) {
  const double raw = std::round(direction * v * per_unit);
  return static_cast<std::int32_t>(std::fmax(-2147483648.0, std::fmin(2147483647.0, raw)));
}
}  // namespace

SyncedPlant::SyncedPlant(const ctl::Machine& truth, const VirtualMachineConfig& cfg)
    : timing_(cfg.timing), period_(cfg.period) {
  if (!(period_ > 0) || !std::isfinite(period_)) throw Error("virtual machine: period must be > 0 s");
  for (std::size_t i = 0; i < 3; ++i) {
    hal::pdo::Scaling s = cfg.axes[i].scaling;
    if (!(s.counts_per_m > 0) || !(s.rated_force_n > 0) || (s.direction != 1 && s.direction != -1))
      throw Error("virtual machine: axes[" + std::to_string(i) + "]: counts_per_m and rated_force_n must be > 0, direction +-1");
    if (s.velocity_units_per_mps == 0) s.velocity_units_per_mps = s.counts_per_m;  // counts per second
    scaling_[i] = s;
  }
  cfg.plant.validate();
  ctl::check_delay_fits(truth.actuation_delay(), 1.0 / period_);  // the plant's command history
  plant_ = std::make_unique<Plant>(truth, cfg.plant);
  if (Status s = plant_->reset(cfg.initial_position); !s)
    throw Error("virtual machine: the initial position is outside the true machine's workspace: " + describe(s));
  reading_ = plant_->read();  // the encoders before the first SYNC (the first TPDOs carry them)
}

SyncedPlant::~SyncedPlant() = default;

void SyncedPlant::on_sync(const std::array<bool, 3>& holding, const Vec3& activated) {
  const bool all_enabled = holding[0] && holding[1] && holding[2];
  // The brakes open one period after every drive holds its axis (the master
  // releases the z brake once drive 3 reports operation enabled), so the
  // first SYNC in operation enabled, whose torque the master sent before it
  // knew, still finds the platform braked.
  const bool released = all_enabled && enabled_before_;
  enabled_before_ = all_enabled;
  // Synchronous: the period ending now ran under what the last SYNC
  // activated, if the brakes were open then and the drives still hold their
  // axes now (one that quick-stopped meanwhile, the master silent, applied
  // nothing); lockstep: the new torque acts over the period starting now,
  // run at once.
  const bool run = timing_ == DriveTiming::synchronous ? released_ && all_enabled : released;
  if (timing_ == DriveTiming::lockstep) force_ = activated;
  if (run && !failed_) {
    if (Status s = plant_->step(force_, period_); !s) failed_ = true;  // left the strokes: stays put
    ++steps_;
  } else if (plant_->velocity().squaredNorm() > 0.0) {
    (void)plant_->reset(plant_->position());  // brakes hold it still
  }
  released_ = released;
  force_ = activated;
  reading_ = plant_->read();
}

std::int32_t SyncedPlant::position_units(int i) const noexcept {
  const auto& s = scaling_[static_cast<std::size_t>(i)];
  return to_units(reading_.d[i] - s.position_offset_m, s.counts_per_m, s.direction);
}

std::int32_t SyncedPlant::velocity_units(int i) const noexcept {
  const auto& s = scaling_[static_cast<std::size_t>(i)];
  return to_units(reading_.d_dot[i], s.velocity_units_per_mps, s.direction);
}

}  // namespace cpm::sim

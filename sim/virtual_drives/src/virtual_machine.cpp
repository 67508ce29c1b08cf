// SPDX-License-Identifier: Apache-2.0
#include "cpm/sim/virtual_machine.hpp"

#include <algorithm>
#include <climits>
#include <cmath>

#include "cpm/hal/canopen.hpp"

namespace cpm::sim {


// One drive's view of the bus: frames handed in by the machine, one at a
// time; sends go to the real bus unless the drives have disappeared.
class VirtualMachine::Port final : public hal::CanBus {
 public:
  Port(hal::CanBus& bus, const bool& gone) : bus_(bus), gone_(gone) {}
  hal::Status send(const hal::CanFrame& f) noexcept override {
    if (gone_) return {};
    return bus_.send(f);
  }
  hal::Status receive(hal::CanFrame& f) noexcept override {
    if (count_ == 0) return {hal::Code::would_block, -1, 0};
    f = ring_[head_];
    head_ = (head_ + 1) % ring_.size();
    --count_;
    return {};
  }
  void set_filters(std::span<const hal::CanFilter>, bool) override {}
  bool wait_receivable(std::int64_t) override { return count_ > 0; }
  [[nodiscard]] const hal::CanStats& stats() const noexcept override { return bus_.stats(); }
  void push(const hal::CanFrame& f) noexcept {
    if (count_ == ring_.size()) return;  // the drive polls after every frame: never full
    ring_[(head_ + count_) % ring_.size()] = f;
    ++count_;
  }

 private:
  hal::CanBus& bus_;
  const bool& gone_;
  std::array<hal::CanFrame, 16> ring_{};
  std::size_t head_ = 0, count_ = 0;
};

const char* timing_name(DriveTiming t) noexcept {
  return t == DriveTiming::lockstep ? "lockstep" : "synchronous";
}

std::optional<DriveTiming> timing_from_name(std::string_view name) noexcept {
  for (DriveTiming t : {DriveTiming::synchronous, DriveTiming::lockstep})
    if (name == timing_name(t)) return t;
  return std::nullopt;
}

VirtualMachineConfig VirtualMachineConfig::defaults() {
  VirtualMachineConfig c;
  for (int i = 0; i < 3; ++i) {
    auto& a = c.axes[static_cast<std::size_t>(i)];
    a.node_id = i + 1;
    a.scaling.counts_per_m = 1e7;
    a.scaling.velocity_units_per_mps = 0;
    a.scaling.rated_force_n = 40;
    a.scaling.max_torque_permille = 3000;
  }
  return c;
}

VirtualMachine::VirtualMachine(hal::CanBus& bus, const ctl::Machine& truth, const VirtualMachineConfig& cfg)
    : bus_(bus), cfg_(cfg), strokes_(truth.model().strokes) {
  for (std::size_t i = 0; i < 3; ++i)
    if (!hal::canopen::valid_node_id(cfg_.axes[i].node_id))
      throw Error("virtual machine: axes[" + std::to_string(i) + "].node_id must be 1..127");
  for (int i = 0; i < 3; ++i)
    if (!std::isfinite(cfg_.home_switch[i]))
      throw Error("virtual machine: home_switch[" + std::to_string(i) + "] must be finite (m of d)");
  if (!(cfg_.limit_margin >= 0) || !std::isfinite(cfg_.limit_margin))
    throw Error("virtual machine: limit_margin must be >= 0 m");
  if (!(cfg_.index_pitch >= 0) || !std::isfinite(cfg_.index_pitch))
    throw Error("virtual machine: index_pitch must be >= 0 m");
  plant_ = std::make_unique<SyncedPlant>(truth, cfg_);
  // The effective mass each actuator moves at the initial position (J^T M J
  // on the diagonal, J = dp/dd): what the drives' own loops are tuned to.
  Vec3 d, d_dot;
  ctl::RigidBodyTerms rb;
  Mat3 J;
  const Plant& plant = plant_->plant();
  if (!plant.actuator_state(d, d_dot) || !truth.rigid_body(plant.position(), Vec3::Zero(), rb) ||
      !truth.jacobian(d, plant.position(), plant.kinematic_inputs(), J))
    throw Error("virtual machine: no inertia at the initial position");
  const Mat3 mass = J.transpose() * rb.M * J;
  for (std::size_t i = 0; i < 3; ++i) {
    cfg_.axes[i].scaling = plant_->scaling(static_cast<int>(i));
    const hal::pdo::Scaling& s = cfg_.axes[i].scaling;
    ports_.push_back(std::make_unique<Port>(bus_, gone_));
    hal::VirtualDriveConfig vc;
    vc.node_id = static_cast<std::uint8_t>(cfg_.axes[i].node_id);
    vc.rated_torque = static_cast<std::uint32_t>(std::lround(s.rated_force_n * 1000));  // mN
    vc.quick_stop_option = static_cast<std::int16_t>(cfg_.quick_stop_option);
    vc.tune_loops(mass(static_cast<int>(i), static_cast<int>(i)), s.rated_force_n, s.velocity_units_per_mps, cfg_.period);
    vc.velocity_per_count = s.velocity_units_per_mps / s.counts_per_m;
    drives_.push_back(std::make_unique<hal::VirtualDrive>(*ports_.back(), vc));
    drives_.back()->hold_tpdos = true;
  }
  d_before_ = d;
  // The encoders before the first SYNC (a drive's TPDOs carry them).
  for (int i = 0; i < 3; ++i) drives_[static_cast<std::size_t>(i)]->set_actual(encoder_counts(i), 0);
}

std::int32_t VirtualMachine::encoder_counts(int i) const noexcept {
  const std::int64_t c = std::int64_t{plant_->position_units(i)} - zero_[static_cast<std::size_t>(i)];
  return static_cast<std::int32_t>(std::clamp<std::int64_t>(c, INT32_MIN, INT32_MAX));
}

void VirtualMachine::break_home_switch(int i, bool broken) { home_broken_.at(static_cast<std::size_t>(i)) = broken; }

void VirtualMachine::set_sensors() {
  Vec3 d, d_dot;
  if (!plant_->plant().actuator_state(d, d_dot)) return;  // the plant failed: the sensors keep their last reading
  for (std::size_t i = 0; i < 3; ++i) {
    const int k = static_cast<int>(i);
    const hal::pdo::Scaling& s = cfg_.axes[i].scaling;
    hal::DriveInputs in;
    const bool low = cfg_.limit_margin > 0 && d[k] < strokes_.min[k] + cfg_.limit_margin;
    const bool high = cfg_.limit_margin > 0 && d[k] > strokes_.max[k] - cfg_.limit_margin;
    // The drive's negative side is low d when it counts with d.
    in.negative_limit = s.direction > 0 ? low : high;
    in.positive_limit = s.direction > 0 ? high : low;
    in.home_switch = !home_broken_[i] && d[k] < cfg_.home_switch[k];
    if (cfg_.index_pitch > 0) {
      const double m0 = std::floor(d_before_[k] / cfg_.index_pitch), m1 = std::floor(d[k] / cfg_.index_pitch);
      if (m0 != m1) {  // a mark crossed since the last SYNC: the drive captures it where it is
        const double x = std::max(m0, m1) * cfg_.index_pitch;
        const double counts = std::round(s.direction * (x - s.position_offset_m) * s.counts_per_m);
        in.index_pulse = true;
        in.index_position = static_cast<std::int32_t>(static_cast<std::int64_t>(counts) - zero_[i]);
      }
    }
    drives_[i]->set_inputs(in);
  }
  d_before_ = d;
}

VirtualMachine::~VirtualMachine() = default;

void VirtualMachine::power_on(std::int64_t now_ns) {
  // Incremental encoders count from where the carriages stand now.
  for (int i = 0; i < 3; ++i) zero_[static_cast<std::size_t>(i)] = cfg_.incremental ? plant_->position_units(i) : 0;
  for (std::size_t i = 0; i < 3; ++i) {
    drives_[i]->power_on(now_ns);
    drives_[i]->set_actual(encoder_counts(static_cast<int>(i)), 0);
  }
  set_sensors();
}

void VirtualMachine::disappear(bool gone, std::int64_t now_ns) {
  if (gone == gone_) return;
  gone_ = gone;
  for (auto& d : drives_) d->go_silent(gone);
  if (!gone) power_on(now_ns);  // power comes back: the drives boot again
}

void VirtualMachine::on_frame(const hal::CanFrame& f, std::int64_t now_ns) {
  if (gone_) return;
  for (std::size_t i = 0; i < 3; ++i) {
    sync_seen_[i] = drives_[i]->sync_count();
    ports_[i]->push(f);
    drives_[i]->poll(now_ns);
  }
  if (!f.is_error() && !f.is_extended() && !f.is_rtr() && f.cob_id() == hal::canopen::kSync) on_sync(now_ns);
}

void VirtualMachine::on_sync(std::int64_t) {
  ++syncs_;
  std::array<bool, 3> took{}, holding{};
  Vec3 activated;  // the torques the drives took from their RPDOs at this SYNC
  for (std::size_t i = 0; i < 3; ++i) {
    took[i] = drives_[i]->sync_count() > sync_seen_[i];  // it handled this SYNC (operational, not silent)
    holding[i] = took[i] && drives_[i]->state() == hal::cia402::State::operation_enabled;
    activated[static_cast<int>(i)] = hal::pdo::force_n(drives_[i]->applied_torque(), cfg_.axes[i].scaling);
  }
  plant_->on_sync(holding, activated);
  set_sensors();
  for (std::size_t i = 0; i < 3; ++i) {
    const int k = static_cast<int>(i);
    drives_[i]->set_actual(encoder_counts(k), plant_->velocity_units(k), drives_[i]->applied_torque());
    if (took[i]) drives_[i]->transmit_sync_pdos();
  }
}

void VirtualMachine::poll(std::int64_t now_ns) {
  for (auto& d : drives_) d->poll(now_ns);
}

void VirtualMachine::pump(std::int64_t now_ns) {
  hal::CanFrame f;
  for (int n = 0; n < 4096 && bus_.receive(f).ok(); ++n) on_frame(f, now_ns);
  poll(now_ns);
}

}  // namespace cpm::sim

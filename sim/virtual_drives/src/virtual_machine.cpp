#include "cpm/sim/virtual_machine.hpp"

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
    : bus_(bus), cfg_(cfg) {
  for (std::size_t i = 0; i < 3; ++i)
    if (!hal::canopen::valid_node_id(cfg_.axes[i].node_id))
      throw Error("virtual machine: axes[" + std::to_string(i) + "].node_id must be 1..127");
  plant_ = std::make_unique<SyncedPlant>(truth, cfg_);
  for (std::size_t i = 0; i < 3; ++i) {
    cfg_.axes[i].scaling = plant_->scaling(static_cast<int>(i));
    ports_.push_back(std::make_unique<Port>(bus_, gone_));
    hal::VirtualDriveConfig vc;
    vc.node_id = static_cast<std::uint8_t>(cfg_.axes[i].node_id);
    vc.rated_torque = static_cast<std::uint32_t>(std::lround(cfg_.axes[i].scaling.rated_force_n * 1000));  // mN
    vc.quick_stop_option = static_cast<std::int16_t>(cfg_.quick_stop_option);
    drives_.push_back(std::make_unique<hal::VirtualDrive>(*ports_.back(), vc));
    drives_.back()->hold_tpdos = true;
    // The encoders before the first SYNC (a drive's TPDOs carry them).
    drives_.back()->set_actual(plant_->position_units(static_cast<int>(i)), 0);
  }
}

VirtualMachine::~VirtualMachine() = default;

void VirtualMachine::power_on(std::int64_t now_ns) {
  for (auto& d : drives_) d->power_on(now_ns);
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
  for (std::size_t i = 0; i < 3; ++i) {
    const int k = static_cast<int>(i);
    drives_[i]->set_actual(plant_->position_units(k), plant_->velocity_units(k), drives_[i]->applied_torque());
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

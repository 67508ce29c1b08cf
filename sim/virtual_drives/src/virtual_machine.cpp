#include "cpm/sim/virtual_machine.hpp"

#include <cmath>

#include "cpm/hal/canopen.hpp"

namespace cpm::sim {

namespace {
hal::pdo::Scaling effective(hal::pdo::Scaling s) {
  if (s.velocity_units_per_mps == 0) s.velocity_units_per_mps = s.counts_per_m;  // counts per second
  return s;
}
std::int32_t to_units(double v, double per_unit, int direction) {
  const double raw = std::round(direction * v * per_unit);
  return static_cast<std::int32_t>(std::fmax(-2147483648.0, std::fmin(2147483647.0, raw)));
}
}  // namespace

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
  if (!(cfg_.period > 0) || !std::isfinite(cfg_.period)) throw Error("virtual machine: period must be > 0 s");
  for (std::size_t i = 0; i < 3; ++i) {
    auto& a = cfg_.axes[i];
    if (!hal::canopen::valid_node_id(a.node_id))
      throw Error("virtual machine: axes[" + std::to_string(i) + "].node_id must be 1..127");
    if (!(a.scaling.counts_per_m > 0) || !(a.scaling.rated_force_n > 0) || (a.scaling.direction != 1 && a.scaling.direction != -1))
      throw Error("virtual machine: axes[" + std::to_string(i) + "]: counts_per_m and rated_force_n must be > 0, direction +-1");
    a.scaling = effective(a.scaling);
  }
  cfg_.plant.validate();
  ctl::check_delay_fits(truth.actuation_delay(), 1.0 / cfg_.period);  // the plant's command history
  plant_ = std::make_unique<Plant>(truth, cfg_.plant);
  if (Status s = plant_->reset(cfg_.initial_position); !s)
    throw Error("virtual machine: the initial position is outside the true machine's workspace: " + describe(s));
  for (std::size_t i = 0; i < 3; ++i) {
    ports_.push_back(std::make_unique<Port>(bus_, gone_));
    hal::VirtualDriveConfig vc;
    vc.node_id = static_cast<std::uint8_t>(cfg_.axes[i].node_id);
    vc.rated_torque = static_cast<std::uint32_t>(std::lround(cfg_.axes[i].scaling.rated_force_n * 1000));  // mN
    vc.quick_stop_option = static_cast<std::int16_t>(cfg_.quick_stop_option);
    drives_.push_back(std::make_unique<hal::VirtualDrive>(*ports_.back(), vc));
    drives_.back()->hold_tpdos = true;
  }
  // The encoders before the first SYNC (a drive's TPDOs carry them).
  const EncoderReading r = plant_->read();
  for (std::size_t i = 0; i < 3; ++i) {
    const auto& s = cfg_.axes[i].scaling;
    drives_[i]->set_actual(to_units(r.d[static_cast<int>(i)] - s.position_offset_m, s.counts_per_m, s.direction), 0);
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
  bool took[3];
  bool all_enabled = true;
  for (std::size_t i = 0; i < 3; ++i) {
    took[i] = drives_[i]->sync_count() > sync_seen_[i];  // it handled this SYNC (operational, not silent)
    all_enabled = all_enabled && took[i] && drives_[i]->state() == hal::cia402::State::operation_enabled;
  }
  // The torques the drives took from their RPDOs at this SYNC.
  Vec3 activated;
  for (int i = 0; i < 3; ++i)
    activated[i] = hal::pdo::force_n(drives_[static_cast<std::size_t>(i)]->applied_torque(), cfg_.axes[static_cast<std::size_t>(i)].scaling);
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
  const bool run = cfg_.timing == DriveTiming::synchronous ? released_ && all_enabled : released;
  if (cfg_.timing == DriveTiming::lockstep) force_ = activated;
  if (run && !plant_failed_) {
    if (Status s = plant_->step(force_, cfg_.period); !s) plant_failed_ = true;  // left the strokes: stays put
    ++steps_;
  } else if (plant_->velocity().squaredNorm() > 0.0) {
    (void)plant_->reset(plant_->position());  // brakes hold it still
  }
  released_ = released;
  force_ = activated;
  const EncoderReading r = plant_->read();
  for (std::size_t i = 0; i < 3; ++i) {
    const auto& s = cfg_.axes[i].scaling;
    const int k = static_cast<int>(i);
    drives_[i]->set_actual(to_units(r.d[k] - s.position_offset_m, s.counts_per_m, s.direction),
                           to_units(r.d_dot[k], s.velocity_units_per_mps, s.direction), drives_[i]->applied_torque());
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

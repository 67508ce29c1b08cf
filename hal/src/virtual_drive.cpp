// SPDX-License-Identifier: Apache-2.0
#include "cpm/hal/virtual_drive.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <iterator>

#include "cpm/hal/common.hpp"

namespace cpm::hal {

using namespace canopen;
using cia402::Command;
using cia402::State;

namespace {
constexpr std::uint32_t kRpdoBase[4] = {kRpdo1Base, kRpdo2Base, kRpdo3Base, kRpdo4Base};
constexpr std::uint32_t kTpdoBase[4] = {kTpdo1Base, kTpdo2Base, kTpdo3Base, kTpdo4Base};
constexpr std::size_t kMaxDomain = 64;
bool is_rpdo_comm(std::uint16_t i) { return i >= 0x1400 && i <= 0x1403; }
bool is_tpdo_comm(std::uint16_t i) { return i >= 0x1800 && i <= 0x1803; }
bool is_rpdo_map(std::uint16_t i) { return i >= 0x1600 && i <= 0x1603; }
bool is_tpdo_map(std::uint16_t i) { return i >= 0x1A00 && i <= 0x1A03; }
// The modes the drive takes: 0 (none), CSP and CSV (accepted, no motion
// here), homing and cyclic synchronous torque.
bool mode_supported(std::int8_t m) {
  return m == 0 || m == 8 || m == 9 || m == cia402::kModeHoming || m == cia402::kModeCyclicSyncTorque;
}
}  // namespace

VirtualDrive::VirtualDrive(CanBus& bus, VirtualDriveConfig cfg) : bus_(bus), cfg_(std::move(cfg)) {
  if (!valid_node_id(cfg_.node_id))
    throw Error("virtual drive: node id " + std::to_string(cfg_.node_id) + " outside 1..127");
  build_dictionary();
  late_.reserve(64);
}

void VirtualDrive::add(std::uint16_t index, std::uint8_t sub, std::uint8_t size, bool writable,
                       std::uint32_t value, bool mappable, bool readable) {
  od_.push_back(Entry{index, sub, size, writable, readable, mappable, value, value, {}, {}});
}

void VirtualDrive::build_dictionary() {
  const std::uint32_t n = cfg_.node_id;
  add(kDeviceType, 0, 4, false, 0x00020192);  // CiA 402 servo drive
  add(0x1001, 0, 1, false, 0);
  add(0x1008, 0, 0, false, 0);
  od_.back().bytes.assign(cfg_.device_name.begin(), cfg_.device_name.end());
  od_.back().initial_bytes = od_.back().bytes;
  add(kConsumerHeartbeatTime, 0, 1, false, 1);
  add(kConsumerHeartbeatTime, 1, 4, true, 0);
  add(kProducerHeartbeatTime, 0, 2, true, 0);
  add(0x1018, 0, 1, false, 4);
  add(0x1018, 1, 4, false, cfg_.vendor_id);
  add(0x1018, 2, 4, false, cfg_.product_code);
  add(0x1018, 3, 4, false, 0x00010000);
  add(0x1018, 4, 4, false, 0x5E000000 + n);
  for (std::uint16_t i = 0; i < std::clamp(cfg_.pdos, 1, 4); ++i) {
    add(0x1400 + i, 0, 1, false, 2);
    add(0x1400 + i, 1, 4, true, kRpdoBase[i] + n + (i == 0 ? 0 : kCobIdInvalid));
    add(0x1400 + i, 2, 1, true, 255);
    add(0x1600 + i, 0, 1, true, i == 0 ? 1 : 0);
    for (std::uint8_t s = 1; s <= 8; ++s) add(0x1600 + i, s, 4, true, (i == 0 && s == 1) ? 0x60400010 : 0);
    add(0x1800 + i, 0, 1, false, 5);
    add(0x1800 + i, 1, 4, true, kTpdoBase[i] + n + (i < 2 ? 0 : kCobIdInvalid));
    add(0x1800 + i, 2, 1, true, 255);
    add(0x1800 + i, 3, 2, true, 0);
    add(0x1800 + i, 5, 2, true, 0);
    add(0x1A00 + i, 0, 1, true, i == 0 ? 1 : 0);
    for (std::uint8_t s = 1; s <= 8; ++s) add(0x1A00 + i, s, 4, true, (i == 0 && s == 1) ? 0x60410010 : 0);
  }
  add(0x2000, 0, 0, true, 0);  // a manufacturer parameter block (domain): segmented transfers
  add(cia402::kAbortConnectionOption, 0, 2, true, 1);
  add(cia402::kErrorCode, 0, 2, false, 0);
  add(cia402::kControlword, 0, 2, true, 0, true);
  add(cia402::kStatusword, 0, 2, false, 0, true);
  add(cia402::kQuickStopOption, 0, 2, true, static_cast<std::uint16_t>(cfg_.quick_stop_option));
  add(cia402::kModesOfOperation, 0, 1, true, 0, true);
  add(cia402::kModesDisplay, 0, 1, false, 0, true);
  add(cia402::kPositionActual, 0, 4, false, 0, true);
  add(cia402::kVelocityActual, 0, 4, false, 0, true);
  add(cia402::kTargetTorque, 0, 2, true, 0, true);
  add(cia402::kMaxTorque, 0, 2, true, 1000, true);
  add(cia402::kRatedTorque, 0, 4, true, cfg_.rated_torque);
  add(cia402::kTorqueActual, 0, 2, false, 0, true);
  add(cia402::kInterpolationPeriod, 0, 1, false, 2);
  add(cia402::kInterpolationPeriod, 1, 1, true, 1);
  add(cia402::kInterpolationPeriod, 2, 1, true, 0xFD);  // 10^-3 s
  // Homing mode. CiA 402-2 lets 0x607C, 0x6098, 0x6099 and 0x609A be mapped
  // (optional); 0x6098 starts at 0, "no method", which a start turns into a
  // homing error.
  add(cia402::kHomeOffset, 0, 4, true, 0, true);
  add(cia402::kHomingMethod, 0, 1, true, 0, true);
  add(cia402::kHomingSpeeds, 0, 1, false, 2);
  add(cia402::kHomingSpeeds, 1, 4, true, 0, true);
  add(cia402::kHomingSpeeds, 2, 4, true, 0, true);
  add(cia402::kHomingAcceleration, 0, 4, true, 0, true);
  // 0x60E3 supported homing methods (ro).
  static constexpr std::int8_t kMethods[] = {1, 2, 3, 4, 5, 6, 17, 18, 19, 20, 21, 22, 33, 34, 35, 37};
  add(0x60E3, 0, 1, false, std::size(kMethods));
  for (std::uint8_t i = 0; i < std::size(kMethods); ++i)
    add(0x60E3, static_cast<std::uint8_t>(i + 1), 1, false, static_cast<std::uint8_t>(kMethods[i]));
  std::sort(od_.begin(), od_.end(), [](const Entry& a, const Entry& b) {
    return a.index != b.index ? a.index < b.index : a.sub < b.sub;
  });
}

VirtualDrive::Entry* VirtualDrive::find(std::uint16_t index, std::uint8_t sub) {
  auto it = std::lower_bound(od_.begin(), od_.end(), std::pair{index, sub}, [](const Entry& e, auto k) {
    return e.index != k.first ? e.index < k.first : e.sub < k.second;
  });
  return (it != od_.end() && it->index == index && it->sub == sub) ? &*it : nullptr;
}
const VirtualDrive::Entry* VirtualDrive::find(std::uint16_t index, std::uint8_t sub) const {
  return const_cast<VirtualDrive*>(this)->find(index, sub);
}
bool VirtualDrive::index_exists(std::uint16_t index) const {
  return std::any_of(od_.begin(), od_.end(), [&](const Entry& e) { return e.index == index; });
}

std::uint32_t VirtualDrive::od_value(std::uint16_t index, std::uint8_t sub) const {
  if (index == cia402::kStatusword && sub == 0) return statusword();
  const Entry* e = find(index, sub);
  if (!e) throw Error("virtual drive: no object " + std::to_string(index) + ":" + std::to_string(sub));
  return e->value;
}
void VirtualDrive::od_set(std::uint16_t index, std::uint8_t sub, std::uint32_t value) {
  Entry* e = find(index, sub);
  if (!e) throw Error("virtual drive: no object " + std::to_string(index) + ":" + std::to_string(sub));
  e->value = value;
}
std::vector<std::uint8_t> VirtualDrive::od_bytes(std::uint16_t index, std::uint8_t sub) const {
  const Entry* e = find(index, sub);
  if (!e) throw Error("virtual drive: no object " + std::to_string(index) + ":" + std::to_string(sub));
  return e->bytes;
}

std::uint16_t VirtualDrive::statusword() const {
  std::uint16_t sw = cia402::statusword_state_bits(state_) | cia402::kSwRemote;
  if (state_ == State::ready_to_switch_on || state_ == State::switched_on ||
      state_ == State::operation_enabled || state_ == State::quick_stop_active)
    sw |= cia402::kSwVoltageEnabled;
  if (state_ == State::operation_enabled && mode_display() == cia402::kModeHoming) {
    // CiA 402-2 homing: bits 13, 12, 10.
    switch (phase_) {
      case Phase::idle:
      case Phase::interrupted: sw |= cia402::kSwTargetReached; break;
      case Phase::search:
      case Phase::approach:
      case Phase::index: break;
      case Phase::to_home: sw |= cia402::kSwHomingAttained; break;
      case Phase::done: sw |= cia402::kSwHomingAttained | cia402::kSwTargetReached; break;
      case Phase::error: sw |= cia402::kSwHomingError | (at_rest_ ? cia402::kSwTargetReached : 0); break;
    }
    if (saturated_) sw |= cia402::kSwInternalLimit;
  } else if (state_ == State::operation_enabled) {
    sw |= cia402::kSwFollowsCommand;
    const auto target = static_cast<std::int16_t>(find(cia402::kTargetTorque, 0)->value);
    const auto max = static_cast<int>(find(cia402::kMaxTorque, 0)->value);
    if (target > max || target < -max) sw |= cia402::kSwInternalLimit;
  }
  return sw;
}

std::int8_t VirtualDrive::mode_display() const {
  return static_cast<std::int8_t>(find(cia402::kModesDisplay, 0)->value);
}

std::int16_t VirtualDrive::applied_torque() const {
  if (state_ != State::operation_enabled) return 0;
  const std::int8_t mode = mode_display();
  if (mode == cia402::kModeHoming) return loop_active_ ? homing_torque_ : 0;
  if (mode != cia402::kModeCyclicSyncTorque) return 0;
  const int target = static_cast<std::int16_t>(find(cia402::kTargetTorque, 0)->value);
  const int max = static_cast<int>(find(cia402::kMaxTorque, 0)->value);
  return static_cast<std::int16_t>(std::clamp(target, -max, max));
}

void VirtualDrive::set_actual(std::int32_t position, std::int32_t velocity, std::int16_t torque) {
  raw_position_ = position;
  raw_velocity_ = velocity;
  set_position_actual();
  find(cia402::kVelocityActual, 0)->value = static_cast<std::uint32_t>(velocity);
  find(cia402::kTorqueActual, 0)->value = static_cast<std::uint16_t>(torque);
}

void VirtualDrive::set_position_actual() {
  // 32-bit position values wrap, as a drive's counter does.
  const auto p = static_cast<std::uint64_t>(std::int64_t{raw_position_} + shift_);
  find(cia402::kPositionActual, 0)->value = static_cast<std::uint32_t>(p);
}

void VirtualDrive::send(const CanFrame& f) {
  if (!silent_) (void)bus_.send(f);
}

void VirtualDrive::send_sdo(const CanFrame& f, std::int64_t now_ns) {
  if (sdo_delay_ns_ > 0) late_.push_back(Late{f, now_ns + sdo_delay_ns_});
  else send(f);
}

void VirtualDrive::send_emcy(std::uint16_t code, std::uint8_t error_register) {
  Emcy e;
  e.code = code;
  e.error_register = error_register;
  find(0x1001, 0)->value = error_register;
  send(make_emcy(cfg_.node_id, e));
}

void VirtualDrive::refuse(Command c, bool refuse_it) noexcept {
  const unsigned bit = 1u << static_cast<unsigned>(c);
  refused_ = refuse_it ? (refused_ | bit) : (refused_ & ~bit);
}

void VirtualDrive::reset(bool application) {
  for (auto& e : od_) {
    if (application || (e.index >= 0x1000 && e.index <= 0x1FFF)) {
      e.value = e.initial;
      e.bytes = e.initial_bytes;
    }
  }
  if (application) {
    state_ = State::not_ready_to_switch_on;
    last_controlword_ = 0;
    fault_persistent_ = false;
    // The application restarts: a homing's redefinition of the counts is gone.
    shift_ = 0;
    phase_ = Phase::idle;
    loop_active_ = start_pending_ = interrupt_pending_ = false;
    homing_torque_ = 0;
  }
  sdo_ = SdoTransfer{};
  rpdo_pending_.fill(false);
  master_last_hb_ns_ = -1;
  master_timed_out_ = false;
}

void VirtualDrive::power_on(std::int64_t now_ns) {
  powered_ = true;
  reset(true);
  state_ = State::switch_on_disabled;  // transitions 0 and 1 happen by themselves
  last_transition_ = 1;
  nmt_ = NmtState::preoperational;
  send(make_heartbeat(cfg_.node_id, NmtState::boot_up));
  next_heartbeat_ns_ = now_ns;
}

// Long (about 80 lines) on purpose: one pass of the drive in the order of
// its events (frames received, answers held back, heartbeat produced and
// consumed, the fault reaction), so that their order reads in one place.
void VirtualDrive::poll(std::int64_t now_ns) {
  if (!powered_) return;
  CanFrame f;
  while (bus_.receive(f).ok()) {
    if (silent_ || f.is_error() || f.is_rtr() || f.is_extended()) continue;
    const std::uint32_t cob = f.cob_id();
    if (cob == kNmt) {
      on_nmt(f, now_ns);
      continue;
    }
    if (nmt_ == NmtState::stopped) continue;
    const std::uint32_t consumer = find(kConsumerHeartbeatTime, 1)->value;
    if (consumer != 0 && cob == kHeartbeatBase + ((consumer >> 16) & 0x7F)) {
      master_last_hb_ns_ = now_ns;
      master_timed_out_ = false;
      continue;
    }
    if (cob == kSdoRxBase + cfg_.node_id) {
      on_sdo(f, now_ns);
      continue;
    }
    if (nmt_ != NmtState::operational) continue;
    if (cob == kSync) {
      handle_sync(now_ns);
      continue;
    }
    for (int i = 0; i < 4; ++i) {
      const Entry* e = find(static_cast<std::uint16_t>(0x1400 + i), 1);
      if (e && !(e->value & kCobIdInvalid) && (e->value & 0x7FF) == cob) on_rpdo(i, f);
    }
  }
  // Answers held back by answer_late().
  for (std::size_t i = 0; i < late_.size();) {
    if (late_[i].due <= now_ns) {
      send(late_[i].f);
      late_.erase(late_.begin() + static_cast<std::ptrdiff_t>(i));
    } else {
      ++i;
    }
  }
  // Heartbeat producer.
  const std::uint32_t period_ms = find(kProducerHeartbeatTime, 0)->value;
  if (period_ms > 0 && now_ns >= next_heartbeat_ns_) {
    if (!heartbeat_stopped_) send(make_heartbeat(cfg_.node_id, nmt_));
    const std::int64_t p = std::int64_t{period_ms} * 1'000'000;
    next_heartbeat_ns_ += p;
    if (next_heartbeat_ns_ <= now_ns) next_heartbeat_ns_ = now_ns + p;
  }
  // Heartbeat consumer: the master's heartbeat, once first heard.
  const std::uint32_t consumer = find(kConsumerHeartbeatTime, 1)->value;
  const std::int64_t timeout = std::int64_t{consumer & 0xFFFF} * 1'000'000;
  if (timeout > 0 && master_last_hb_ns_ >= 0 && !master_timed_out_ && now_ns - master_last_hb_ns_ > timeout) {
    master_timed_out_ = true;
    ++master_heartbeat_timeouts;
    // The abort connection option code (0x6007) says what the drive does.
    const auto option = static_cast<std::int16_t>(find(cia402::kAbortConnectionOption, 0)->value);
    if (option == 1) {
      enter_fault(0x8130, 0x11);
    } else {
      send_emcy(0x8130, 0x11);
      if (option == 2) {
        const auto s = cia402::apply(state_, Command::disable_voltage);
        state_ = s.next;
        last_transition_ = s.transition;
      } else if (option == 3) {
        if (state_ == State::operation_enabled) {
          state_ = State::quick_stop_active;
          quick_stop_left_ = cfg_.quick_stop_syncs;
          last_transition_ = 11;
        } else {
          const auto s = cia402::apply(state_, Command::disable_voltage);
          state_ = s.next;
          last_transition_ = s.transition;
        }
      }
    }
  }
  if (state_ == State::fault_reaction_active && nmt_ != NmtState::operational) {
    state_ = State::fault;
    last_transition_ = 14;
  }
}

void VirtualDrive::on_nmt(const CanFrame& f, std::int64_t now_ns) {
  if (f.len != 2 || (f.data[1] != 0 && f.data[1] != cfg_.node_id)) return;
  switch (static_cast<NmtCommand>(f.data[0])) {
    case NmtCommand::start: nmt_ = NmtState::operational; break;
    case NmtCommand::stop: nmt_ = NmtState::stopped; break;
    case NmtCommand::enter_preoperational: nmt_ = NmtState::preoperational; break;
    case NmtCommand::reset_node:
    case NmtCommand::reset_communication: {
      const bool app = static_cast<NmtCommand>(f.data[0]) == NmtCommand::reset_node;
      const State keep = state_;
      reset(app);
      state_ = app ? State::switch_on_disabled : keep;
      nmt_ = NmtState::preoperational;
      send(make_heartbeat(cfg_.node_id, NmtState::boot_up));
      next_heartbeat_ns_ = now_ns;
      break;
    }
    default: break;
  }
}

void VirtualDrive::apply_command(Command c) {
  if (refused_ & (1u << static_cast<unsigned>(c))) {
    last_transition_ = -2;
    return;
  }
  if (c == Command::fault_reset && state_ == State::fault && fault_persistent_) {
    last_transition_ = -1;
    return;
  }
  const bool stays = cfg_.quick_stop_option >= 5 && cfg_.quick_stop_option <= 8;
  const auto s = cia402::apply(state_, c, stays);
  if (s.transition == 11) quick_stop_left_ = cfg_.quick_stop_syncs;
  if (s.transition == 15) {
    find(cia402::kErrorCode, 0)->value = 0;
    send_emcy(0x0000, 0);  // error reset
  }
  if (s.transition != 0) last_transition_ = s.transition;
  state_ = s.next;
}

void VirtualDrive::enter_fault(std::uint16_t code, std::uint8_t reg) {
  state_ = State::fault_reaction_active;
  last_transition_ = 13;
  find(cia402::kErrorCode, 0)->value = code;
  send_emcy(code, reg);
}

void VirtualDrive::inject_fault(std::uint16_t code, std::uint8_t reg, bool persistent) {
  fault_persistent_ = persistent;
  enter_fault(code, reg);
}

void VirtualDrive::on_rpdo(int n, const CanFrame& f) {
  const std::uint16_t map = static_cast<std::uint16_t>(0x1600 + n);
  const std::uint32_t count = find(map, 0)->value;
  int bytes = 0;
  for (std::uint8_t s = 1; s <= count; ++s) bytes += static_cast<int>(find(map, s)->value & 0xFF) / 8;
  if (f.len != bytes) {
    ++bad_pdos;
    send_emcy(f.len < bytes ? 0x8210 : 0x8220, 0x11);
    return;
  }
  const auto type = find(static_cast<std::uint16_t>(0x1400 + n), 2)->value;
  rpdo_buf_[static_cast<std::size_t>(n)] = f;
  rpdo_pending_[static_cast<std::size_t>(n)] = true;
  if (type > 240) {  // event-driven: takes effect at once
    rpdo_pending_[static_cast<std::size_t>(n)] = false;
    apply_rpdo(static_cast<std::size_t>(n), f);
  }
}

void VirtualDrive::apply_rpdo(std::size_t n, const CanFrame& f) {
  const std::int16_t torque_before = applied_torque();
  const std::uint16_t map = static_cast<std::uint16_t>(0x1600 + n);
  const std::uint32_t count = find(map, 0)->value;
  std::size_t off = 0;
  bool controlword = false, mode = false;
  std::uint32_t mode_value = 0;
  for (std::uint8_t s = 1; s <= count; ++s) {
    const std::uint32_t m = find(map, s)->value;
    const std::size_t nb = (m & 0xFF) / 8;
    std::uint32_t v = 0;
    for (std::size_t b = 0; b < nb; ++b) v |= std::uint32_t{f.data[off + b]} << (8 * b);
    off += nb;
    const auto index = static_cast<std::uint16_t>(m >> 16);
    if (index == cia402::kModesOfOperation) {
      mode = true;
      mode_value = v;
      continue;
    }
    find(index, static_cast<std::uint8_t>(m >> 8))->value = v;
    controlword = controlword || index == cia402::kControlword;
  }
  if (mode) set_mode(static_cast<std::int8_t>(mode_value), torque_before);
  if (controlword) on_controlword(static_cast<std::uint16_t>(find(cia402::kControlword, 0)->value));
}

void VirtualDrive::handle_sync(std::int64_t) {
  ++syncs_;
  if (state_ == State::fault_reaction_active) {
    state_ = State::fault;
    last_transition_ = 14;
  }
  // Synchronous RPDOs take effect at this SYNC.
  for (std::size_t n = 0; n < 4; ++n) {
    if (!rpdo_pending_[n]) continue;
    rpdo_pending_[n] = false;
    apply_rpdo(n, rpdo_buf_[n]);
  }
  if (state_ == State::quick_stop_active && quick_stop_left_ > 0 && --quick_stop_left_ == 0 &&
      cfg_.quick_stop_option >= 1 && cfg_.quick_stop_option <= 4) {
    state_ = State::switch_on_disabled;  // the quick stop is complete
    last_transition_ = 12;
  }
  if (on_sync) on_sync(*this);
  if (!hold_tpdos) transmit_sync_pdos();
}

void VirtualDrive::transmit_sync_pdos() {
  homing_step();
  find(cia402::kStatusword, 0)->value = statusword();
  for (std::uint16_t n = 0; n < 4 && find(static_cast<std::uint16_t>(0x1800 + n), 1); ++n) {
    const std::uint32_t cob = find(static_cast<std::uint16_t>(0x1800 + n), 1)->value;
    const std::uint32_t type = find(static_cast<std::uint16_t>(0x1800 + n), 2)->value;
    if ((cob & kCobIdInvalid) || type < 1 || type > 240 || syncs_ % type != 0) continue;
    const std::uint16_t map = static_cast<std::uint16_t>(0x1A00 + n);
    const std::uint32_t count = find(map, 0)->value;
    CanFrame f;
    f.id = cob & 0x7FF;
    std::size_t off = 0;
    for (std::uint8_t s = 1; s <= count; ++s) {
      const std::uint32_t m = find(map, s)->value;
      const std::size_t nb = (m & 0xFF) / 8;
      const std::uint32_t v = find(static_cast<std::uint16_t>(m >> 16), static_cast<std::uint8_t>(m >> 8))->value;
      for (std::size_t b = 0; b < nb && off + b < 8; ++b) f.data[off + b] = static_cast<std::uint8_t>(v >> (8 * b));
      off += nb;
    }
    f.len = static_cast<std::uint8_t>(off);
    send(f);
  }
}

std::uint32_t VirtualDrive::check_pdo_write(std::uint16_t index, std::uint8_t sub, std::uint32_t v) const {
  if (is_rpdo_comm(index) || is_tpdo_comm(index)) {
    if (sub == 1) {
      const std::uint32_t cur = find(index, 1)->value;
      if (v & 0x20000000) return kAbortInvalidValue;  // 29-bit ids not supported
      if (!(v & kCobIdInvalid) && (v & 0x7FF) == 0) return kAbortInvalidValue;
      if (!(cur & kCobIdInvalid) && !(v & kCobIdInvalid) && (cur & 0x7FF) != (v & 0x7FF))
        return kAbortInvalidValue;  // change the id of a valid PDO: invalidate it first
    }
    if (sub == 2 && v > 240 && v < 254) return kAbortInvalidValue;
    if (sub == 2 && is_tpdo_comm(index) && v == 0) return kAbortInvalidValue;  // acyclic sync not supported
    return 0;
  }
  const bool rx = is_rpdo_map(index);
  const std::uint16_t comm = static_cast<std::uint16_t>(rx ? index - 0x200 : index - 0x200);
  if (!(find(comm, 1)->value & kCobIdInvalid)) return kAbortDeviceState;  // PDO valid: mapping locked
  if (sub == 0) {
    if (v > 8) return kAbortValueTooHigh;
    int bits = 0;
    for (std::uint8_t s = 1; s <= v; ++s) {
      const std::uint32_t m = find(index, s)->value;
      if (m == 0) return kAbortParamIncompatible;
      bits += static_cast<int>(m & 0xFF);
    }
    return bits > 64 ? std::uint32_t{kAbortPdoLength} : 0u;
  }
  if (find(index, 0)->value != 0) return kAbortDeviceState;  // mapping not disabled
  if (v == 0) return 0;
  const Entry* o = find(static_cast<std::uint16_t>(v >> 16), static_cast<std::uint8_t>(v >> 8));
  if (!o) return kAbortNoObject;
  if (!o->mappable || (rx && !o->writable) || (!rx && !o->readable)) return kAbortNotMappable;
  if ((v & 0xFF) != o->size * 8u) return kAbortParamIncompatible;
  return 0;
}

std::uint32_t VirtualDrive::write_entry(std::uint16_t index, std::uint8_t sub, const std::uint8_t* data, std::size_t n) {
  Entry* e = find(index, sub);
  if (!e) return index_exists(index) ? kAbortNoSubindex : kAbortNoObject;
  if (!e->writable) return kAbortReadOnly;
  if (e->size == 0) {
    if (n > kMaxDomain) return kAbortTypeTooHigh;
    e->bytes.assign(data, data + n);
    return 0;
  }
  if (n != e->size) return n > e->size ? kAbortTypeTooHigh : kAbortTypeTooLow;
  std::uint32_t v = 0;
  for (std::size_t b = 0; b < n; ++b) v |= std::uint32_t{data[b]} << (8 * b);
  if (is_rpdo_comm(index) || is_tpdo_comm(index) || is_rpdo_map(index) || is_tpdo_map(index)) {
    if (const std::uint32_t a = check_pdo_write(index, sub, v)) return a;
  }
  if (index == cia402::kModesOfOperation && !mode_supported(static_cast<std::int8_t>(v))) return kAbortInvalidValue;
  if (index == cia402::kHomingMethod) {
    Plan p;
    if (!plan_for(static_cast<std::int8_t>(v), p)) return kAbortInvalidValue;
  }
  if (index == cia402::kMaxTorque && v > 32767) return kAbortValueTooHigh;
  if (index == cia402::kAbortConnectionOption && static_cast<std::int16_t>(v) > 3) return kAbortValueTooHigh;
  if (index == cia402::kModesOfOperation) {
    set_mode(static_cast<std::int8_t>(v), applied_torque());
    return 0;
  }
  e->value = v;
  if (index == kConsumerHeartbeatTime) {
    master_last_hb_ns_ = -1;  // monitoring starts at the next heartbeat heard
    master_timed_out_ = false;
  }
  if (index == cia402::kControlword) on_controlword(static_cast<std::uint16_t>(v));
  return 0;
}

// Long (about 90 lines) on purpose: the SDO server's one switch over the
// client's command specifiers (CiA 301 §7.2.4.3), expedited and segmented.
void VirtualDrive::on_sdo(const CanFrame& f, std::int64_t now_ns) {
  const std::uint32_t tx = kSdoTxBase + cfg_.node_id;
  if (f.len != 8) return;  // CiA 301: SDO frames are always 8 bytes
  const std::uint8_t cmd = f.data[0];
  const std::uint8_t ccs = cmd >> 5;
  const std::uint16_t index = get_u16(&f.data[1]);
  const std::uint8_t sub = f.data[3];
  auto abort = [&](std::uint16_t i, std::uint8_t s, std::uint32_t code) {
    sdo_.active = false;
    send_sdo(make_sdo_abort(tx, i, s, code), now_ns);
  };
  CanFrame r;
  r.id = tx;
  r.len = 8;
  switch (ccs) {
    case kCsAbort:
      sdo_.active = false;
      return;
    case kCcsInitiateDownload: {
      sdo_.active = false;
      const bool e = cmd & 0x02, s = cmd & 0x01;
      if (e) {
        const std::size_t n = s ? 4 - ((cmd >> 2) & 0x03) : 4;
        if (const std::uint32_t a = write_entry(index, sub, &f.data[4], n)) return abort(index, sub, a);
      } else {
        const Entry* en = find(index, sub);
        if (!en) return abort(index, sub, index_exists(index) ? kAbortNoSubindex : kAbortNoObject);
        if (!en->writable) return abort(index, sub, kAbortReadOnly);
        sdo_ = SdoTransfer{true, true, index, sub, false, 0, s ? get_u32(&f.data[4]) : 0, {}};
        if (sdo_.expected > kMaxDomain && en->size == 0) return abort(index, sub, kAbortTypeTooHigh);
      }
      r.data[0] = kScsInitiateDownload << 5;
      put_u16(&r.data[1], index);
      r.data[3] = sub;
      return send_sdo(r, now_ns);
    }
    case kCcsDownloadSegment: {
      if (!sdo_.active || !sdo_.download) return abort(sdo_.index, sdo_.sub, kAbortCommand);
      if (((cmd & 0x10) != 0) != sdo_.toggle) return abort(sdo_.index, sdo_.sub, kAbortToggle);
      const std::size_t n = 7 - ((cmd >> 1) & 0x07);
      sdo_.data.insert(sdo_.data.end(), &f.data[1], &f.data[1 + n]);
      if (sdo_.data.size() > kMaxDomain) return abort(sdo_.index, sdo_.sub, kAbortTypeTooHigh);
      r.data[0] = static_cast<std::uint8_t>((kScsDownloadSegment << 5) | (sdo_.toggle ? 0x10 : 0));
      sdo_.toggle = !sdo_.toggle;
      if (cmd & 0x01) {
        if (sdo_.expected && sdo_.data.size() != sdo_.expected) return abort(sdo_.index, sdo_.sub, kAbortTypeLength);
        if (const std::uint32_t a = write_entry(sdo_.index, sdo_.sub, sdo_.data.data(), sdo_.data.size()))
          return abort(sdo_.index, sdo_.sub, a);
        sdo_.active = false;
      }
      return send_sdo(r, now_ns);
    }
    case kCcsInitiateUpload: {
      sdo_.active = false;
      const Entry* en = find(index, sub);
      if (!en) return abort(index, sub, index_exists(index) ? kAbortNoSubindex : kAbortNoObject);
      if (!en->readable) return abort(index, sub, kAbortWriteOnly);
      put_u16(&r.data[1], index);
      r.data[3] = sub;
      if (en->size > 0) {
        const std::uint32_t v = (index == cia402::kStatusword) ? statusword() : en->value;
        r.data[0] = static_cast<std::uint8_t>((kScsInitiateUpload << 5) | ((4 - en->size) << 2) | 0x03);
        put_u32(&r.data[4], v);
      } else {
        r.data[0] = static_cast<std::uint8_t>((kScsInitiateUpload << 5) | 0x01);
        put_u32(&r.data[4], static_cast<std::uint32_t>(en->bytes.size()));
        sdo_ = SdoTransfer{true, false, index, sub, false, 0, en->bytes.size(), en->bytes};
      }
      return send_sdo(r, now_ns);
    }
    case kCcsUploadSegment: {
      if (!sdo_.active || sdo_.download) return abort(sdo_.index, sdo_.sub, kAbortCommand);
      if (((cmd & 0x10) != 0) != sdo_.toggle) return abort(sdo_.index, sdo_.sub, kAbortToggle);
      const std::size_t left = sdo_.data.size() - sdo_.offset;
      const std::size_t n = left < 7 ? left : 7;
      const bool last = n == left;
      r.data[0] = static_cast<std::uint8_t>((sdo_.toggle ? 0x10 : 0) | ((7 - n) << 1) | (last ? 1 : 0));
      std::memcpy(&r.data[1], sdo_.data.data() + sdo_.offset, n);
      sdo_.offset += n;
      sdo_.toggle = !sdo_.toggle;
      if (last) sdo_.active = false;
      return send_sdo(r, now_ns);
    }
    default:
      return abort(index, sub, kAbortCommand);
  }
}

// ---------------------------------------------------------------- homing mode

void VirtualDriveConfig::tune_loops(double mass_kg, double rated_force_n, double velocity_units_per_mps,
                                    double period_s) {
  if (!(mass_kg > 0) || !(rated_force_n > 0) || !(velocity_units_per_mps > 0) || !(period_s > 0))
    throw Error("virtual drive: tune_loops needs a mass, a rated force, a velocity unit and a period > 0");
  const double bandwidth_hz = std::min(20.0, 0.05 / period_s);
  const double w = 2 * 3.141592653589793 * bandwidth_hz;
  const double per_mille_per_newton = 1000.0 / rated_force_n;
  velocity_kp = mass_kg * w * per_mille_per_newton / velocity_units_per_mps;  // N/(m/s) -> per mille per unit
  velocity_ki = velocity_kp * w / 5;
  position_kp = w / 5;
}

double VirtualDrive::period_s() const {
  const double value = find(cia402::kInterpolationPeriod, 1)->value;
  const auto exponent = static_cast<std::int8_t>(find(cia402::kInterpolationPeriod, 2)->value);
  const double t = value * std::pow(10.0, exponent);
  return t > 0 ? t : 1e-3;
}

void VirtualDrive::set_mode(std::int8_t mode, std::int16_t torque_before) {
  if (!mode_supported(mode)) return;  // from a PDO, which cannot be refused: the mode stays
  const bool entering = mode == cia402::kModeHoming && mode_display() != cia402::kModeHoming;
  find(cia402::kModesOfOperation, 0)->value = static_cast<std::uint8_t>(mode);
  find(cia402::kModesDisplay, 0)->value = static_cast<std::uint8_t>(mode);
  // From cyclic synchronous torque straight into homing mode: the drive's
  // loops take over the torque it was applying, so a held load stays held.
  if (entering && state_ == State::operation_enabled) activate_loops(torque_before);
}

void VirtualDrive::activate_loops(std::int16_t torque) {
  loop_active_ = true;
  integral_ = torque;
  homing_torque_ = torque;
  v_profile_ = raw_velocity_;
  hold_raw_ = raw_position_;
  holding_ = true;
  phase_ = Phase::idle;
}

void VirtualDrive::on_controlword(std::uint16_t cw) {
  const std::uint16_t before = last_controlword_;
  last_controlword_ = cw;
  // Fault reset acts on the rising edge of bit 7 only.
  const bool reset_edge = (cw & 0x80) && !(before & 0x80);
  if (!(cw & 0x80) || reset_edge) apply_command(cia402::decode_controlword(cw));
  // Homing operation start, bit 4 in mode 6: the rising edge starts, the
  // falling edge interrupts. Outside operation enabled it means nothing.
  if (state_ == State::operation_enabled && mode_display() == cia402::kModeHoming) {
    const bool now = (cw & cia402::kCwHomingStart) != 0, was = (before & cia402::kCwHomingStart) != 0;
    if (now && !was) {
      start_pending_ = true;
      interrupt_pending_ = false;
    } else if (!now && was) {
      interrupt_pending_ = true;
      start_pending_ = false;
    }
  }
}

bool VirtualDrive::plan_for(int method, Plan& p) noexcept {
  // CiA 402-2 homing methods. The switch of 3-6 and 19-22 is a home switch
  // actuated on one side of its edge: "positive" (3, 4, 19, 20) on the side
  // of higher counts, "negative" (5, 6, 21, 22) on the lower. The index
  // methods are the switch methods (16 more) followed by the first index
  // pulse in the final direction.
  p = Plan{};
  const int base = method >= 17 && method <= 22 ? method - 16 : method;
  switch (base) {
    case 1: p = {2, +1, true, false, false}; break;   // negative limit: home where it releases, moving up
    case 2: p = {3, -1, true, false, false}; break;   // positive limit: where it releases, moving down
    case 3: p = {1, -1, true, false, false}; break;   // positive home switch: where it releases, moving down
    case 4: p = {1, +1, false, false, false}; break;  // positive home switch: where it actuates, moving up
    case 5: p = {1, +1, true, false, false}; break;   // negative home switch: where it releases, moving up
    case 6: p = {1, -1, false, false, false}; break;  // negative home switch: where it actuates, moving down
    case 33: p = {0, -1, false, true, false}; return true;
    case 34: p = {0, +1, false, true, false}; return true;
    case 35:
    case 37: p.here = true; return true;
    default: return false;  // 0: no method; 7-14, 23-30 (home switch between limit switches): not here
  }
  p.index = method <= 6;
  return true;
}

bool VirtualDrive::homing_signal() const {
  switch (plan_.signal) {
    case 1: return inputs_.home_switch;
    case 2: return inputs_.negative_limit;
    case 3: return inputs_.positive_limit;
    default: return false;
  }
}

bool VirtualDrive::moving_into_foreign_limit(double direction) const {
  return (direction < 0 && inputs_.negative_limit && plan_.signal != 2) ||
         (direction > 0 && inputs_.positive_limit && plan_.signal != 3);
}

void VirtualDrive::start_homing() {
  reversed_ = false;
  holding_ = false;
  if (!plan_for(static_cast<std::int8_t>(find(cia402::kHomingMethod, 0)->value), plan_)) {
    phase_ = Phase::error;  // no method (0x6098 = 0)
    return;
  }
  if (plan_.here) home_event(raw_position_);
  else if (plan_.signal == 0) phase_ = Phase::index;
  else phase_ = homing_signal() == plan_.before ? Phase::approach : Phase::search;
}

void VirtualDrive::home_event(std::int32_t raw_home) {
  // CiA 402-2: after homing the position actual value at the home position
  // is the home offset.
  home_raw_ = raw_home;
  shift_ = std::int64_t{static_cast<std::int32_t>(find(cia402::kHomeOffset, 0)->value)} - raw_home;
  set_position_actual();
  phase_ = Phase::to_home;
}

// Long (about 85 lines) on purpose: one switch over the drive's homing
// phases (CiA 402-2 homing mode), as the standard's method description reads.
void VirtualDrive::homing_step() {
  const bool active = state_ == State::operation_enabled && mode_display() == cia402::kModeHoming;
  if (!active) {
    // Leaving operation enabled or the mode aborts a running procedure.
    loop_active_ = start_pending_ = interrupt_pending_ = saturated_ = false;
    homing_torque_ = 0;
    phase_ = Phase::idle;
    return;
  }
  if (!loop_active_) activate_loops(0);  // enabled in mode 6: nothing was applied before
  speed_search_ = find(cia402::kHomingSpeeds, 1)->value;
  speed_zero_ = find(cia402::kHomingSpeeds, 2)->value;
  acceleration_ = find(cia402::kHomingAcceleration, 0)->value;
  const double period = period_s();
  const double v_rest = std::max(1.0, 0.05 * speed_zero_);
  const double window = std::max(1.0, speed_zero_ * period / cfg_.velocity_per_count);  // counts

  if (interrupt_pending_) {
    interrupt_pending_ = false;
    if (phase_ == Phase::search || phase_ == Phase::approach || phase_ == Phase::index || phase_ == Phase::to_home) {
      phase_ = Phase::interrupted;
      holding_ = false;
    }
  }
  if (start_pending_) {
    start_pending_ = false;
    start_homing();
  }
  // What this sample says.
  const double dir = plan_.direction;
  switch (phase_) {
    case Phase::search:
      if (homing_signal() == plan_.before) {
        phase_ = Phase::approach;
        reversed_ = true;
      }
      break;
    case Phase::approach:
      if (v_profile_ * dir > 0 && homing_signal() != plan_.before) {
        if (plan_.index) phase_ = Phase::index;
        else home_event(raw_position_);
      }
      break;
    case Phase::index:
      if (v_profile_ * dir > 0 && inputs_.index_pulse) home_event(inputs_.index_position);
      break;
    case Phase::to_home:
      if (std::abs(static_cast<double>(home_raw_ - raw_position_)) <= window && std::abs(raw_velocity_) <= v_rest) {
        phase_ = Phase::done;
        hold_raw_ = home_raw_;
        holding_ = true;
      }
      break;
    default:
      break;
  }
  // A limit switch ahead that is not the method's: the switch sought was
  // not found.
  const double heading = phase_ == Phase::search ? -dir : dir;
  if ((phase_ == Phase::search || phase_ == Phase::approach || phase_ == Phase::index) &&
      moving_into_foreign_limit(heading)) {
    phase_ = Phase::error;
    holding_ = false;
  }
  // The motion for the next period.
  switch (phase_) {
    case Phase::search: run_loops(-dir * speed_search_, false, 0); break;
    case Phase::approach: run_loops(dir * (reversed_ ? speed_zero_ : speed_search_), false, 0); break;
    case Phase::index: run_loops(dir * speed_zero_, false, 0); break;
    case Phase::to_home: run_loops(0, true, home_raw_); break;
    case Phase::idle:
    case Phase::done:
    case Phase::error:
    case Phase::interrupted:
      if (!holding_ && v_profile_ == 0) {  // stopped: hold here
        hold_raw_ = raw_position_;
        holding_ = true;
      }
      if (holding_) run_loops(0, true, hold_raw_);
      else run_loops(0, false, 0);
      break;
  }
  at_rest_ = std::abs(raw_velocity_) <= v_rest && std::abs(v_profile_) <= v_rest;
}

void VirtualDrive::run_loops(double v_target, bool position_target, std::int64_t target_raw) {
  const double period = period_s();
  const double a = acceleration_;
  double v_des = v_target;
  if (position_target) {
    // The slower of the position loop and the braking curve, within the
    // speed for zero.
    const double e = static_cast<double>(target_raw - raw_position_) * cfg_.velocity_per_count;  // units x s
    double mag = cfg_.position_kp * std::abs(e);
    if (a > 0) mag = std::min(mag, std::sqrt(2 * a * std::abs(e)));
    if (speed_zero_ > 0) mag = std::min(mag, speed_zero_);
    v_des = e >= 0 ? mag : -mag;
  }
  // Acceleration-limited speed profile (0x609A).
  if (a > 0) v_profile_ += std::clamp(v_des - v_profile_, -a * period, a * period);
  else v_profile_ = v_des;
  // PI velocity loop, integrating only while the torque is within 0x6072
  // (no wind-up at the limit).
  const double max = find(cia402::kMaxTorque, 0)->value;
  const double err = v_profile_ - raw_velocity_;
  const double integral = integral_ + cfg_.velocity_ki * err * period;
  const double torque = cfg_.velocity_kp * err + integral;
  saturated_ = std::abs(torque) > max;
  if (!saturated_) integral_ = integral;
  homing_torque_ = static_cast<std::int16_t>(std::lround(std::clamp(cfg_.velocity_kp * err + integral_, -max, max)));
}

}  // namespace cpm::hal

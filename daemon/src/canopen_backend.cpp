// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/canopen_backend.hpp"

#include <cmath>
#include <cstdarg>
#include <cstdio>

#include <cpm_msgs/drives_t.hpp>

#include "cpm/hal/gpiod_io.hpp"
#include "cpm/hal/socketcan.hpp"

namespace cpm::daemon {

using hal::cia402::State;

CanopenBackend::CanopenBackend(const CanopenConfig& cfg) : cfg_(cfg) {
  feedback_wait_ns_ = static_cast<std::int64_t>(std::llround(cfg_.feedback_wait * 1e9));
  // The plan of this mapping (homing drives carry two more bytes per cycle).
  if (!cfg_.master.drives.empty()) cfg_.load = hal::bus_load(cfg_.master);
}

namespace {

// What the loop needs of the drive's homing: "attained" only once the drive
// is at rest at its home (completed); before that it is still running.
DriveHoming loop_homing(hal::cia402::HomingStatus h) noexcept {
  using H = hal::cia402::HomingStatus;
  switch (h) {
    case H::idle: return DriveHoming::idle;
    case H::in_progress:
    case H::interrupted:
    case H::attained: return DriveHoming::running;
    case H::completed: return DriveHoming::attained;
    case H::error: return DriveHoming::error;
  }
  return DriveHoming::idle;
}

// drives_t's codes are CiA 301's NMT states and cia402::State's order.
static_assert(cpm_msgs::drives_t::NMT_BOOT_UP == static_cast<int>(hal::canopen::NmtState::boot_up) &&
              cpm_msgs::drives_t::NMT_STOPPED == static_cast<int>(hal::canopen::NmtState::stopped) &&
              cpm_msgs::drives_t::NMT_OPERATIONAL == static_cast<int>(hal::canopen::NmtState::operational) &&
              cpm_msgs::drives_t::NMT_PRE_OPERATIONAL == static_cast<int>(hal::canopen::NmtState::preoperational));
static_assert(cpm_msgs::drives_t::CIA402_NOT_READY == static_cast<int>(State::not_ready_to_switch_on) &&
              cpm_msgs::drives_t::CIA402_SWITCH_ON_DISABLED == static_cast<int>(State::switch_on_disabled) &&
              cpm_msgs::drives_t::CIA402_READY == static_cast<int>(State::ready_to_switch_on) &&
              cpm_msgs::drives_t::CIA402_SWITCHED_ON == static_cast<int>(State::switched_on) &&
              cpm_msgs::drives_t::CIA402_OPERATION_ENABLED == static_cast<int>(State::operation_enabled) &&
              cpm_msgs::drives_t::CIA402_QUICK_STOP == static_cast<int>(State::quick_stop_active) &&
              cpm_msgs::drives_t::CIA402_FAULT_REACTION == static_cast<int>(State::fault_reaction_active) &&
              cpm_msgs::drives_t::CIA402_FAULT == static_cast<int>(State::fault) &&
              cpm_msgs::drives_t::CIA402_UNKNOWN == static_cast<int>(State::unknown));
static_assert(cpm_msgs::drives_t::BUS_ERROR_ACTIVE == static_cast<int>(hal::BusState::error_active) &&
              cpm_msgs::drives_t::BUS_ERROR_WARNING == static_cast<int>(hal::BusState::error_warning) &&
              cpm_msgs::drives_t::BUS_ERROR_PASSIVE == static_cast<int>(hal::BusState::error_passive) &&
              cpm_msgs::drives_t::BUS_OFF == static_cast<int>(hal::BusState::bus_off));

}  // namespace

CanopenBackend::CanopenBackend(const CanopenConfig& cfg, hal::CanBus& bus, hal::Clock& clock, hal::DigitalIo& io)
    : CanopenBackend(cfg) {
  bus_ = &bus;
  clock_ = &clock;
  io_ = &io;
}

CanopenBackend::~CanopenBackend() { stop(); }

void CanopenBackend::open_devices() {
  if (bus_ == nullptr) {
    own_clock_ = std::make_unique<hal::SteadyClock>();
    clock_ = own_clock_.get();
    // GPIO first: its outputs come up at their safe level (drives off, brake on).
    own_io_ = std::make_unique<hal::GpiodIo>(cfg_.gpio);
    io_ = own_io_.get();
    own_bus_ = std::make_unique<hal::SocketCanBus>(cfg_.interface);
    bus_ = own_bus_.get();
  }
}

void CanopenBackend::start(double period) {
  if (!(period > 0)) throw Error("canopen backend: the loop period must be > 0");
  if (std::abs(1.0 / period - cfg_.master.rate_hz) > 1e-6 * cfg_.master.rate_hz)
    throw Error("canopen backend: configured for " + std::to_string(cfg_.master.rate_hz) + " Hz, started at " +
                std::to_string(1.0 / period) + " Hz");
  try {
    open_devices();
    (void)io_->safe_state();
    master_ = std::make_unique<hal::Master>(*bus_, *clock_, cfg_.master);
    master_->start();
    // One SYNC with every drive disabled: its TPDOs carry the positions the
    // first cycle needs, and prove the PDO mapping works end to end.
    for (std::size_t i = 0; i < cfg_.master.drives.size(); ++i) cmd_.drive[i] = hal::DriveCommand{};
    if (hal::Status s = master_->write(cmd_); !s)
      throw Error(std::string("the first SYNC could not be sent: ") + hal::code_name(s.code));
    const std::int64_t deadline = clock_->now_ns() + std::int64_t{cfg_.master.sdo_timeout_ms} * 1'000'000;
    for (;;) {
      master_->service();
      if (master_->feedback_complete() || clock_->now_ns() >= deadline) break;
      if (!bus_->wait_receivable(200'000)) clock_->wait(200'000);
    }
    if (!master_->feedback_complete())
      throw Error("no TPDOs from every drive within " + std::to_string(cfg_.master.sdo_timeout_ms) +
                  " ms after the first SYNC (are the drives' PDOs mapped and synchronous?)");
    io_ok_ = io_->read(din_).ok();
  } catch (const hal::Error& e) {
    master_.reset();
    if (io_ != nullptr) (void)io_->safe_state();
    throw Error(std::string("canopen backend on ") + cfg_.interface + ": " + e.what());
  } catch (const Error& e) {
    master_.reset();
    if (io_ != nullptr) (void)io_->safe_state();
    throw Error(std::string("canopen backend on ") + cfg_.interface + ": " + e.what());
  }
  for (std::size_t i = 0; i < 3; ++i) {
    emcy_seen_[i] = 0;
    faults_seen_[i] = 0;
    limit_before_[i] = false;
    was_enabled_[i] = false;
  }
  enabled_asked_ = false;
  error_frames_seen_ = 0;
  started_ = true;
}

void CanopenBackend::stop() noexcept {
  if (io_ != nullptr) (void)io_->safe_state();
  if (master_ && started_) master_->stop();
  started_ = false;
}

void CanopenBackend::note(const char* fmt, ...) noexcept {
  if (text_len_ + 3 >= sizeof text_) return;
  if (text_len_ > 0) {
    text_[text_len_++] = ';';
    text_[text_len_++] = ' ';
  }
  va_list ap;
  va_start(ap, fmt);
  const int n = std::vsnprintf(text_ + text_len_, sizeof text_ - text_len_, fmt, ap);
  va_end(ap);
  if (n > 0) text_len_ = std::min(sizeof text_ - 1, text_len_ + static_cast<std::size_t>(n));
  text_[text_len_] = '\0';
}

BackendResult CanopenBackend::read(std::int64_t, BackendInput& in) noexcept {
  text_len_ = 0;
  text_[0] = '\0';
  if (!started_) {
    in.estop = true;
    note("canopen backend not started");
    return BackendResult::io_error;
  }
  wait_for_feedback();
  const hal::Status ms = master_->read(fb_);
  io_ok_ = io_->read(din_).ok();
  for (std::size_t i = 0; i < 3; ++i) read_drive(i, in);
  const bool bus = bus_ok(ms);
  const bool gpio = read_gpio(in);
  return bus && gpio ? BackendResult::ok : BackendResult::io_error;
}

void CanopenBackend::wait_for_feedback() noexcept {
  // Bounded wait for this cycle's TPDOs (slow hosts, SIL): never longer than
  // configured, never more than a few rounds on a fake clock.
  if (feedback_wait_ns_ > 0) {
    const std::int64_t deadline = clock_->now_ns() + feedback_wait_ns_;
    master_->service();
    for (int round = 0; round < 64 && !master_->feedback_complete(); ++round) {
      const std::int64_t left = deadline - clock_->now_ns();
      if (left <= 0) break;
      bus_->wait_receivable(left);
      master_->service();
    }
  }
}

void CanopenBackend::read_drive(std::size_t i, BackendInput& in) noexcept {
  const auto timeout_ns = std::int64_t{cfg_.master.heartbeat_timeout_ms} * 1'000'000;
  const hal::DriveFeedback& d = fb_.drive[i];
  const hal::DriveConfig& dc = cfg_.master.drives[i];
  in.position[i] = d.position_m;
  in.velocity[i] = d.velocity_mps;
  in.statusword[i] = d.statusword;
  bool fault = false;
  if (d.heartbeat_age_ns < 0 || d.heartbeat_age_ns > timeout_ns) {
    fault = true;
    note("drive %zu (%s, node %d): heartbeat lost (none for %lld ms)", i + 1, dc.name.c_str(), dc.node_id,
         static_cast<long long>(d.heartbeat_age_ns < 0 ? -1 : d.heartbeat_age_ns / 1'000'000));
  } else if (d.nmt != hal::canopen::NmtState::operational) {
    fault = true;
    note("drive %zu (%s, node %d): NMT %s, not operational (rebooted? restart cpmd to configure it again)", i + 1,
         dc.name.c_str(), dc.node_id, hal::canopen::nmt_state_name(d.nmt));
  }
  if (d.missed_cycles >= static_cast<std::uint32_t>(cfg_.master.pdo_timeout_cycles)) {
    fault = true;
    note("drive %zu (%s, node %d): no TPDO for %u cycles", i + 1, dc.name.c_str(), dc.node_id, d.missed_cycles);
  }
  // Every error EMCY since the last cycle, even when the drive's "error
  // reset" EMCY came after it in the same cycle.
  if (d.error_emcy_count != emcy_seen_[i]) {
    emcy_seen_[i] = d.error_emcy_count;
    fault = true;
    char e[112];
    hal::canopen::describe_emcy(static_cast<std::uint8_t>(dc.node_id), d.last_error_emcy, e, sizeof e);
    note("drive %zu (%s): %s", i + 1, dc.name.c_str(), e);
  }
  const std::uint32_t fresh_bits = d.faults & ~faults_seen_[i];
  faults_seen_[i] = d.faults;
  if (fresh_bits & hal::kFaultBadPdo) {
    fault = true;
    note("drive %zu (%s, node %d): malformed TPDO", i + 1, dc.name.c_str(), dc.node_id);
  }
  if (d.state == State::fault || d.state == State::fault_reaction_active) {
    fault = true;
    note("drive %zu (%s, node %d): CiA 402 %s (statusword 0x%04X)", i + 1, dc.name.c_str(), dc.node_id,
         hal::cia402::state_name(d.state), d.statusword);
  } else if (was_enabled_[i] && enabled_asked_ && d.state != State::operation_enabled) {
    fault = true;  // e.g. its own quick stop: the loop still expects it to hold the axis
    note("drive %zu (%s, node %d): left operation enabled on its own, now %s", i + 1, dc.name.c_str(), dc.node_id,
         hal::cia402::state_name(d.state));
  } else if (d.state == State::unknown) {
    fault = true;
    note("drive %zu (%s, node %d): statusword 0x%04X decodes to no CiA 402 state", i + 1, dc.name.c_str(), dc.node_id,
         d.statusword);
  }
  in.drive_fault[i] = fault;
  was_enabled_[i] = enabled_asked_ && d.state == State::operation_enabled;
  in.drive_enabled[i] = !fault && d.state == State::operation_enabled && dout_.drive_enable &&
                        (i != 2 || dout_.brake_release_z);
  // Homing: the drive's own (mode 6), and what it needs from the machine.
  in.drive_homing[i] = loop_homing(d.homing);
  if (d.homing == hal::cia402::HomingStatus::error)
    note("drive %zu (%s, node %d): homing error (statusword 0x%04X)", i + 1, dc.name.c_str(), dc.node_id,
         d.statusword);
  in.position_lost[i] = d.position_lost;
  in.home_switch[i] = din_.home[i];
  in.index_pulse[i] = din_.index[i];
  // Limit switches: the cycle one trips (an operator may reset, enable and move off it).
  const bool lim = din_.limit_low[i] || din_.limit_high[i];
  in.limit_switch[i] = lim && !limit_before_[i];
  if (in.limit_switch[i])
    note("limit switch %s of actuator %zu tripped", din_.limit_low[i] ? hal::line_name(static_cast<hal::Line>(1 + i))
                                                                      : hal::line_name(static_cast<hal::Line>(4 + i)), i + 1);
  limit_before_[i] = lim;
}

bool CanopenBackend::bus_ok(const hal::Status& ms) noexcept {
  bool ok = true;
  if (fb_.error_frames != error_frames_seen_) {
    error_frames_seen_ = fb_.error_frames;
    if (fb_.last_error.bus_off || fb_.last_error.passive) {
      char e[96];
      hal::describe_error_frame(fb_.last_error, e, sizeof e);
      note("CAN %s: %s", cfg_.interface.c_str(), e);
    }
  }
  if (fb_.bus_state == hal::BusState::bus_off || fb_.bus_state == hal::BusState::error_passive) {
    ok = false;
    note("CAN %s is %s", cfg_.interface.c_str(), hal::bus_state_name(fb_.bus_state));
  } else if (!ms.ok() && ms.code != hal::Code::would_block) {
    ok = false;
    note("CAN %s: receive failed: %s (%d)", cfg_.interface.c_str(), hal::code_name(ms.code), ms.detail);
  }
  return ok;
}

bool CanopenBackend::read_gpio(BackendInput& in) noexcept {
  bool ok = true;
  in.estop = din_.estop;  // the GPIO reads an error as "e-stop asserted"
  if (!io_ok_) {
    ok = false;
    note("GPIO read failed (e-stop taken as open)");
  } else if (din_.estop) {
    note("e-stop chain open");
  }
  std::uint32_t bits = 0;
  if (din_.estop) bits |= 1u << static_cast<unsigned>(hal::Line::estop);
  for (std::size_t i = 0; i < 3; ++i) {
    if (din_.limit_low[i]) bits |= 1u << (static_cast<unsigned>(hal::Line::limit_low_x) + i);
    if (din_.limit_high[i]) bits |= 1u << (static_cast<unsigned>(hal::Line::limit_high_x) + i);
    if (din_.home[i]) bits |= 1u << (static_cast<unsigned>(hal::Line::home_x) + i);
    if (din_.index[i]) bits |= 1u << (static_cast<unsigned>(hal::Line::index_x) + i);
  }
  in.digital_inputs = bits;
  return ok;
}

BackendResult CanopenBackend::write(std::int64_t, const BackendOutput& out) noexcept {
  if (!started_) return BackendResult::io_error;
  // The e-stop chain and a GPIO failure override the loop: every drive off,
  // brake on, in this very cycle.
  const bool enable = out.enable && !din_.estop && io_ok_;
  for (std::size_t i = 0; i < 3; ++i) {
    hal::DriveCommand& c = cmd_.drive[i];
    c.target = enable ? hal::cia402::Target::enabled : hal::cia402::Target::disabled;
    c.force_n = enable ? out.force[i] : 0.0;
    c.reset_fault = !enable;
    // The drive's own homing (the master ignores it for a drive without).
    c.homing = enable && out.axis_drive[i] == AxisDrive::homing;
    c.start_homing = c.homing && out.start_homing[i];
  }
  BackendResult result = BackendResult::ok;
  const hal::Status ws = master_->write(cmd_);
  if (!ws.ok() && ws.code != hal::Code::saturated && ws.code != hal::Code::not_finite) {
    result = BackendResult::io_error;
    note("CAN %s: send failed: %s (%d)", cfg_.interface.c_str(), hal::code_name(ws.code), ws.detail);
  }
  enabled_asked_ = enable;
  dout_.drive_enable = enable;
  // The z brake opens only once drive 3 holds the axis (operation enabled).
  dout_.brake_release_z = enable && fb_.drive[2].state == State::operation_enabled;
  if (!io_->write(dout_).ok()) {
    result = BackendResult::io_error;
    note("GPIO write failed");
  }
  return result;
}

bool CanopenBackend::drive_homing_supported(int axis) const noexcept {
  return axis >= 0 && static_cast<std::size_t>(axis) < cfg_.master.drives.size() &&
         cfg_.master.drives[static_cast<std::size_t>(axis)].homing.enabled;
}

void CanopenBackend::diagnostics(BackendDiagnostics& out) const noexcept {
  out = BackendDiagnostics{};
  out.backend = cpm_msgs::drives_t::BACKEND_CANOPEN;
  for (std::size_t i = 0; i < 3 && i < cfg_.master.drives.size(); ++i) {
    const hal::DriveFeedback& d = fb_.drive[i];
    DriveDiagnostics& x = out.drive[i];
    x.node_id = cfg_.master.drives[i].node_id;
    x.nmt = d.nmt == hal::canopen::NmtState::unknown ? std::int8_t{-1} : static_cast<std::int8_t>(d.nmt);
    x.cia402 = static_cast<std::int8_t>(d.state);
    x.statusword = d.statusword;
    x.controlword = d.controlword;
    x.mode_display = d.mode_display;
    x.heartbeat_age_ns = d.heartbeat_age_ns;
    x.master_faults = d.faults;
    x.emcy_count = d.emcy_count;
    x.last_emcy_code = d.last_error_emcy.code;
    x.last_emcy_register = d.last_error_emcy.error_register;
  }
  if (started_) out.bus_state = static_cast<std::int8_t>(fb_.bus_state);
  out.error_frames = fb_.error_frames;
  out.rx_dropped = fb_.rx_dropped;
  out.tx_failures = fb_.tx_failures;
  // The counters come with error frames only: none seen, none known.
  if (fb_.error_frames > 0) {
    out.tx_error_counter = fb_.last_error.tx_error_count;
    out.rx_error_counter = fb_.last_error.rx_error_count;
  }
  out.bus_load = cfg_.load.load;
  out.estop = din_.estop;
  out.limit_low = din_.limit_low;
  out.limit_high = din_.limit_high;
  out.home_switch = din_.home;
}

}  // namespace cpm::daemon

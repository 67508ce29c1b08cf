#include "cpm/daemon/canopen_backend.hpp"

#include <cmath>
#include <cstdarg>
#include <cstdio>

#include "cpm/hal/gpiod_io.hpp"
#include "cpm/hal/socketcan.hpp"

namespace cpm::daemon {

using hal::cia402::State;

CanopenBackend::CanopenBackend(const CanopenConfig& cfg) : cfg_(cfg) {
  feedback_wait_ns_ = static_cast<std::int64_t>(std::llround(cfg_.feedback_wait * 1e9));
}

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
  const hal::Status ms = master_->read(fb_);
  io_ok_ = io_->read(din_).ok();

  BackendResult result = BackendResult::ok;
  const auto timeout_ns = std::int64_t{cfg_.master.heartbeat_timeout_ms} * 1'000'000;
  for (std::size_t i = 0; i < 3; ++i) {
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
    // Limit switches: the cycle one trips (an operator may reset, enable and move off it).
    const bool lim = din_.limit_low[i] || din_.limit_high[i];
    in.limit_switch[i] = lim && !limit_before_[i];
    if (in.limit_switch[i])
      note("limit switch %s of actuator %zu tripped", din_.limit_low[i] ? hal::line_name(static_cast<hal::Line>(1 + i))
                                                                        : hal::line_name(static_cast<hal::Line>(4 + i)), i + 1);
    limit_before_[i] = lim;
  }
  if (fb_.error_frames != error_frames_seen_) {
    error_frames_seen_ = fb_.error_frames;
    if (fb_.last_error.bus_off || fb_.last_error.passive) {
      char e[96];
      hal::describe_error_frame(fb_.last_error, e, sizeof e);
      note("CAN %s: %s", cfg_.interface.c_str(), e);
    }
  }
  if (fb_.bus_state == hal::BusState::bus_off || fb_.bus_state == hal::BusState::error_passive) {
    result = BackendResult::io_error;
    note("CAN %s is %s", cfg_.interface.c_str(), hal::bus_state_name(fb_.bus_state));
  } else if (!ms.ok() && ms.code != hal::Code::would_block) {
    result = BackendResult::io_error;
    note("CAN %s: receive failed: %s (%d)", cfg_.interface.c_str(), hal::code_name(ms.code), ms.detail);
  }
  in.estop = din_.estop;  // the GPIO reads an error as "e-stop asserted"
  if (!io_ok_) {
    result = BackendResult::io_error;
    note("GPIO read failed (e-stop taken as open)");
  } else if (din_.estop) {
    note("e-stop chain open");
  }
  std::uint32_t bits = 0;
  if (din_.estop) bits |= 1u << static_cast<unsigned>(hal::Line::estop);
  for (std::size_t i = 0; i < 3; ++i) {
    if (din_.limit_low[i]) bits |= 1u << (static_cast<unsigned>(hal::Line::limit_low_x) + i);
    if (din_.limit_high[i]) bits |= 1u << (static_cast<unsigned>(hal::Line::limit_high_x) + i);
  }
  in.digital_inputs = bits;
  return result;
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

}  // namespace cpm::daemon

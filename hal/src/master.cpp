// SPDX-License-Identifier: Apache-2.0
#include "cpm/hal/master.hpp"

#include <cmath>
#include <cstdio>

namespace cpm::hal {

using namespace canopen;
using cia402::State;

namespace {

constexpr std::int64_t kMs = 1'000'000;
constexpr std::int64_t kPollNs = 200'000;  // start-up loops: how long to let time pass when idle
constexpr double kBitrates[] = {10e3, 20e3, 50e3, 125e3, 250e3, 500e3, 800e3, 1e6};  // CiA 301

std::string hex(std::uint32_t v, int digits) {
  char b[16];
  std::snprintf(b, sizeof b, "0x%0*X", digits, v);
  return b;
}
std::string object(std::uint16_t index, std::uint8_t sub) { return hex(index, 4) + ":" + hex(sub, 2).substr(2); }

[[noreturn]] void bad(const std::string& key, const std::string& why) {
  throw Error("CAN master configuration: " + key + ": " + why);
}

// 0x60C2: the period as value * 10^exponent s, value 1..255.
bool interpolation_period(double rate_hz, std::uint8_t& value, std::int8_t& exponent) {
  const double period_us = 1e6 / rate_hz;
  const double rounded = std::round(period_us);
  if (std::abs(period_us - rounded) > 1e-6 * period_us) return false;
  const auto us = static_cast<long long>(rounded);
  // The largest exponent that states the period exactly (1 ms = 1 x 10^-3 s).
  long long scale = 1'000'000;
  for (int e = 0; e >= -6; --e, scale /= 10) {
    if (us % scale == 0 && us / scale <= 255 && us / scale >= 1) {
      value = static_cast<std::uint8_t>(us / scale);
      exponent = static_cast<std::int8_t>(e);
      return true;
    }
  }
  return false;
}

// The drive's homing objects in its units (DriveHomingConfig is in SI).
struct HomingObjects {
  std::int8_t method = 0;
  std::int32_t offset = 0;          // 0x607C, counts
  std::uint32_t speed_search = 0;   // 0x6099:1, velocity units
  std::uint32_t speed_zero = 0;     // 0x6099:2
  std::uint32_t acceleration = 0;   // 0x609A, velocity units per s
};

double velocity_units_per_mps(const DriveConfig& d) {
  return d.velocity_units_per_mps > 0 ? d.velocity_units_per_mps : d.counts_per_m;
}

// The home offset is the position the drive reports at home: the counts
// that the master's scaling turns into offset_m.
double home_offset_counts(const DriveConfig& d) {
  return d.direction * (d.homing.offset_m - d.position_offset_m) * d.counts_per_m;
}

HomingObjects homing_objects(const DriveConfig& d) {
  const double v = velocity_units_per_mps(d);
  HomingObjects o;
  o.method = static_cast<std::int8_t>(d.homing.method);
  o.offset = static_cast<std::int32_t>(std::llround(home_offset_counts(d)));
  o.speed_search = static_cast<std::uint32_t>(std::llround(d.homing.speed_search_mps * v));
  o.speed_zero = static_cast<std::uint32_t>(std::llround(d.homing.speed_zero_mps * v));
  o.acceleration = static_cast<std::uint32_t>(std::llround(d.homing.acceleration_mps2 * v));
  return o;
}

void validate_homing(const DriveConfig& d, const std::string& k) {
  const DriveHomingConfig& h = d.homing;
  // CiA 402-2: 1..14, 17..30, 33, 34, 35 and 37 are the standard's methods,
  // -128..-1 the manufacturer's; which of them a drive has is its business
  // (it refuses the others, and start() names the object).
  if (h.method < -128 || h.method > 127 || h.method == 0)
    bad(k + "method", "must be a CiA 402 homing method (0x6098: -128..-1 or 1..127, not 0), got " + std::to_string(h.method));
  const double v = velocity_units_per_mps(d);
  auto speed = [&](const char* key, double mps, const char* what) {
    if (!std::isfinite(mps) || mps <= 0) bad(k + key, std::string("must be finite and > 0 (") + what + "), got " + std::to_string(mps));
    const double units = mps * v;
    if (units < 1 || units > 4294967295.0)
      bad(k + key, std::string(what) + " " + std::to_string(mps) + " is " + std::to_string(units) +
                       " drive units: outside 1..4294967295 of the 32-bit object");
  };
  speed("speed_search_mps", h.speed_search_mps, "m/s, 0x6099:1");
  speed("speed_zero_mps", h.speed_zero_mps, "m/s, 0x6099:2");
  speed("acceleration_mps2", h.acceleration_mps2, "m/s^2, 0x609A");
  if (!std::isfinite(h.offset_m)) bad(k + "offset_m", "must be finite");
  const double counts = home_offset_counts(d);
  if (std::abs(counts) > 2147483647.0)
    bad(k + "offset_m", std::to_string(h.offset_m) + " m is " + std::to_string(counts) +
                            " counts: outside the 32-bit 0x607C");
}

}  // namespace

void validate(const MasterConfig& c) {
  auto finite_pos = [](double v) { return std::isfinite(v) && v > 0; };
  if (!valid_node_id(c.master_node_id)) bad("master_node_id", "must be 1..127, got " + std::to_string(c.master_node_id));
  if (!finite_pos(c.rate_hz) || c.rate_hz > 10000) bad("rate_hz", "must be in (0, 10000] Hz, got " + std::to_string(c.rate_hz));
  {
    std::uint8_t v;
    std::int8_t e;
    if (!interpolation_period(c.rate_hz, v, e))
      bad("rate_hz", "the period 1/" + std::to_string(c.rate_hz) +
                         " s must be a whole number of microseconds that fits 0x60C2 (value 1..255 x 10^e s)");
  }
  bool known = false;
  for (double b : kBitrates) known = known || c.bitrate == b;
  if (!known) bad("bitrate", "must be a CiA 301 bitrate (10k, 20k, 50k, 125k, 250k, 500k, 800k, 1M bit/s), got " + std::to_string(c.bitrate));
  if (!(c.max_bus_load > 0 && c.max_bus_load <= 1)) bad("max_bus_load", "must be in (0, 1], got " + std::to_string(c.max_bus_load));
  auto ms = [&](const char* key, int v, int lo, int hi) {
    if (v < lo || v > hi) bad(key, "must be " + std::to_string(lo) + ".." + std::to_string(hi) + " ms, got " + std::to_string(v));
  };
  ms("master_heartbeat_ms", c.master_heartbeat_ms, 1, 65535);
  ms("drive_heartbeat_ms", c.drive_heartbeat_ms, 1, 65535);
  ms("heartbeat_timeout_ms", c.heartbeat_timeout_ms, 1, 65535);
  ms("drive_consumer_timeout_ms", c.drive_consumer_timeout_ms, 1, 65535);
  ms("sdo_timeout_ms", c.sdo_timeout_ms, 1, 60000);
  ms("boot_timeout_ms", c.boot_timeout_ms, 1, 600000);
  if (c.heartbeat_timeout_ms <= c.drive_heartbeat_ms)
    bad("heartbeat_timeout_ms", "must exceed drive_heartbeat_ms (" + std::to_string(c.drive_heartbeat_ms) + "), got " + std::to_string(c.heartbeat_timeout_ms));
  if (c.drive_consumer_timeout_ms <= c.master_heartbeat_ms)
    bad("drive_consumer_timeout_ms", "must exceed master_heartbeat_ms (" + std::to_string(c.master_heartbeat_ms) + "), got " + std::to_string(c.drive_consumer_timeout_ms));
  if (c.abort_connection_option < 0 || c.abort_connection_option > 3)
    bad("abort_connection_option", "must be 0 (none), 1 (fault), 2 (disable voltage) or 3 (quick stop), got " + std::to_string(c.abort_connection_option));
  if (c.pdo_timeout_cycles < 1 || c.pdo_timeout_cycles > 1000) bad("pdo_timeout_cycles", "must be 1..1000, got " + std::to_string(c.pdo_timeout_cycles));
  if (c.drives.empty() || c.drives.size() > kMaxDrives)
    bad("drives", "must list 1.." + std::to_string(kMaxDrives) + " drives, got " + std::to_string(c.drives.size()));
  for (std::size_t i = 0; i < c.drives.size(); ++i) {
    const DriveConfig& d = c.drives[i];
    const std::string k = "drives[" + std::to_string(i) + "].";
    if (!valid_node_id(d.node_id)) bad(k + "node_id", "must be 1..127, got " + std::to_string(d.node_id));
    if (d.node_id == c.master_node_id) bad(k + "node_id", "equals master_node_id " + std::to_string(d.node_id));
    for (std::size_t j = 0; j < i; ++j)
      if (c.drives[j].node_id == d.node_id) bad(k + "node_id", std::to_string(d.node_id) + " is also drives[" + std::to_string(j) + "].node_id");
    if (!finite_pos(d.counts_per_m)) bad(k + "counts_per_m", "must be finite and > 0, got " + std::to_string(d.counts_per_m));
    if (!std::isfinite(d.velocity_units_per_mps) || d.velocity_units_per_mps < 0)
      bad(k + "velocity_units_per_mps", "must be finite and >= 0 (0: counts per second), got " + std::to_string(d.velocity_units_per_mps));
    if (!finite_pos(d.rated_force_n)) bad(k + "rated_force_n", "must be finite and > 0 N, got " + std::to_string(d.rated_force_n));
    if (d.max_torque_permille < 1 || d.max_torque_permille > 32767)
      bad(k + "max_torque_permille", "must be 1..32767, got " + std::to_string(d.max_torque_permille));
    if (d.direction != 1 && d.direction != -1) bad(k + "direction", "must be 1 or -1, got " + std::to_string(d.direction));
    if (!std::isfinite(d.position_offset_m)) bad(k + "position_offset_m", "must be finite");
    if (d.homing.enabled) validate_homing(d, k + "homing.");
  }
}

BusLoad bus_load(const MasterConfig& c) {
  BusLoadInput in;
  in.rate_hz = c.rate_hz;
  in.bitrate = c.bitrate;
  in.max_load = c.max_bus_load;
  in.cyclic_frames.push_back(0);  // SYNC
  for (std::size_t i = 0; i < c.drives.size(); ++i) {
    const bool homing = c.drives[i].homing.enabled;
    in.cyclic_frames.push_back((homing ? pdo::kRpdo1Homing : pdo::kRpdo1).bytes());
    in.cyclic_frames.push_back((homing ? pdo::kTpdo1Homing : pdo::kTpdo1).bytes());
    if (c.velocity_from_drive) in.cyclic_frames.push_back(pdo::kTpdo2.bytes());
    in.periodic.push_back({1, c.drive_heartbeat_ms * 1e-3});
  }
  in.periodic.push_back({1, c.master_heartbeat_ms * 1e-3});
  return compute_bus_load(in);
}

std::size_t describe_drive_faults(std::uint32_t faults, char* out, std::size_t size) noexcept {
  static const char* const names[] = {"heartbeat lost", "EMCY", "drive fault", "PDO timeout",
                                      "bad PDO", "left NMT operational", "unknown CiA 402 state"};
  if (size == 0) return 0;
  out[0] = '\0';
  std::size_t n = 0;
  for (int b = 0; b < 7; ++b) {
    if (!(faults & (1u << b))) continue;
    const int w = std::snprintf(out + n, size - n, "%s%s", n ? ", " : "", names[b]);
    if (w < 0) break;
    n = n + static_cast<std::size_t>(w) < size ? n + static_cast<std::size_t>(w) : size - 1;
  }
  return n;
}

Master::Drive::Drive(const DriveConfig& c, std::int64_t sdo_timeout_ns)
    : cfg(c), node(static_cast<std::uint8_t>(c.node_id)), sdo(static_cast<std::uint8_t>(c.node_id), sdo_timeout_ns) {
  scaling.counts_per_m = c.counts_per_m;
  scaling.velocity_units_per_mps = c.velocity_units_per_mps > 0 ? c.velocity_units_per_mps : c.counts_per_m;
  scaling.rated_force_n = c.rated_force_n;
  scaling.max_torque_permille = c.max_torque_permille;
  scaling.direction = c.direction;
  scaling.position_offset_m = c.position_offset_m;
  if (cfg.name.empty()) cfg.name = "node " + std::to_string(c.node_id);
}

Master::Master(CanBus& bus, Clock& clock, MasterConfig cfg) : bus_(bus), clock_(clock), cfg_(std::move(cfg)) {
  validate(cfg_);
  load_ = bus_load(cfg_);
  if (!load_.fits) {
    char b[160];
    std::snprintf(b, sizeof b, "; lower rate_hz to at most %.0f Hz%s, or raise the bitrate",
                  std::floor(load_.max_rate_hz), cfg_.velocity_from_drive ? ", set velocity_from_drive: false" : "");
    throw Error("CAN master configuration: bus load does not fit " + std::to_string(cfg_.drives.size()) +
                " drives at " + std::to_string(static_cast<int>(cfg_.rate_hz)) + " Hz on " +
                std::to_string(static_cast<int>(cfg_.bitrate / 1000)) + " kbit/s (max_bus_load " +
                std::to_string(static_cast<int>(100 * cfg_.max_bus_load)) + " %): " + load_.describe() + b);
  }
  period_ns_ = static_cast<std::int64_t>(std::llround(1e9 / cfg_.rate_hz));
  drives_.reserve(cfg_.drives.size());
  for (const auto& d : cfg_.drives) drives_.emplace_back(d, std::int64_t{cfg_.sdo_timeout_ms} * kMs);
}

std::string Master::who(std::uint8_t node) const {
  for (const auto& d : drives_)
    if (d.node == node) return "node " + std::to_string(node) + " (" + d.cfg.name + ")";
  return "node " + std::to_string(node);
}

Master::Drive& Master::drive_by_node(std::uint8_t node) {
  for (auto& d : drives_)
    if (d.node == node) return d;
  throw Error("CAN master: node " + std::to_string(node) + " is not one of the configured drives");
}

void Master::send_nmt(NmtCommand c, std::uint8_t node) {
  const Status s = bus_.send(make_nmt(c, node));
  if (!s.ok()) throw Error(std::string("CAN master: NMT command to node ") + std::to_string(node) + " not sent: " + code_name(s.code));
}

void Master::service() noexcept {
  const std::int64_t now = clock_.now_ns();
  CanFrame f;
  while (bus_.receive(f).ok()) dispatch(f, now);
}

bool Master::feedback_complete() const noexcept {
  for (const auto& d : drives_)
    if (!d.got_tpdo1 || (cfg_.velocity_from_drive && !d.got_tpdo2)) return false;
  return true;
}

void Master::dispatch(const CanFrame& f, std::int64_t now) noexcept {
  if (f.is_error()) {
    ++error_frames_;
    last_error_ = decode_error_frame(f);
    if (last_error_.has_state) bus_state_ = last_error_.state;
    if (last_error_.bus_off) bus_off_seen_ = true;
    return;
  }
  if (f.is_extended() || f.is_rtr()) return;
  const std::uint32_t cob = f.cob_id();
  const std::uint32_t fn = cob & 0x780;
  const auto node = static_cast<std::uint8_t>(cob & 0x7F);
  Drive* d = nullptr;
  for (auto& x : drives_)
    if (x.node == node) d = &x;
  if (d == nullptr || node == 0) return;
  DriveFeedback& fb = d->fb;
  switch (fn) {
    case kEmcyBase: {
      Emcy e;
      if (!decode_emcy(f, e)) return;
      fb.last_emcy = e;
      ++fb.emcy_count;
      fb.emcy_active = e.code != 0;
      if (e.code != 0) {
        fb.faults |= kFaultEmcy;
        fb.last_error_emcy = e;
        ++fb.error_emcy_count;
      }
      return;
    }
    case kTpdo1Base: {
      if (!started_) return;
      std::uint16_t sw;
      std::int32_t pos;
      std::int8_t mode = 0;
      if (d->cfg.homing.enabled ? !pdo::unpack_tpdo1_homing(f, sw, pos, mode) : !pdo::unpack_tpdo1(f, sw, pos)) {
        fb.faults |= kFaultBadPdo;
        return;
      }
      fb.mode_display = mode;
      fb.statusword = sw;
      fb.position_counts = pos;
      fb.state = cia402::decode_statusword(sw);
      if (fb.state == State::fault || fb.state == State::fault_reaction_active) fb.faults |= kFaultDrive;
      if (fb.state == State::unknown) fb.faults |= kFaultUnknownState;
      d->got_tpdo1 = true;
      return;
    }
    case kTpdo2Base: {
      if (!started_ || !cfg_.velocity_from_drive) return;
      std::int32_t v;
      if (!pdo::unpack_tpdo2(f, v)) {
        fb.faults |= kFaultBadPdo;
        return;
      }
      fb.velocity_units = v;
      d->got_tpdo2 = true;
      return;
    }
    case kSdoTxBase:
      d->sdo.on_frame(bus_, f, now);
      return;
    case kHeartbeatBase: {
      if (f.len != 1) return;
      const auto s = static_cast<NmtState>(f.data[0] & 0x7F);
      fb.nmt = s;
      d->last_heartbeat_ns = now;
      if (started_ && s != NmtState::operational) fb.faults |= kFaultNmtState;
      // A boot-up while running: the drive restarted and its counts with it
      // (an incremental encoder's zero, a homing's redefinition are gone).
      if (started_ && s == NmtState::boot_up) fb.position_lost = true;
      return;
    }
    default:
      return;
  }
}

// ---------------------------------------------------------------- SDO, blocking

namespace {
const char* verb(bool write) { return write ? "write" : "read"; }
}  // namespace

void Master::sdo_write(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::span<const std::uint8_t> data,
                       bool force_segmented) {
  Drive& d = drive_by_node(node);
  if (!d.sdo.start_download(bus_, index, sub, data, clock_.now_ns(), force_segmented))
    throw Error(who(node) + ": SDO write " + object(index, sub) + " could not start (" +
                std::to_string(data.size()) + " bytes; at most " + std::to_string(SdoClient::kMaxBytes) + ")");
  while (d.sdo.state() == SdoClient::State::busy) {
    service();
    d.sdo.poll(bus_, clock_.now_ns());
    if (d.sdo.state() == SdoClient::State::busy && !bus_.wait_receivable(0)) clock_.wait(kPollNs);
  }
  if (d.sdo.state() == SdoClient::State::done) return;
  const bool to = d.sdo.state() == SdoClient::State::timed_out;
  throw Error(who(node) + ": SDO " + verb(true) + " " + object(index, sub) +
              (to ? " got no answer within " + std::to_string(cfg_.sdo_timeout_ms) + " ms (SDO timeout)"
                  : std::string(" aborted by the ") + (d.sdo.aborted_by_server() ? "drive" : "master") + ": " +
                        hex(d.sdo.abort_code(), 8) + " " + sdo_abort_text(d.sdo.abort_code())));
}

std::vector<std::uint8_t> Master::sdo_read(std::uint8_t node, std::uint16_t index, std::uint8_t sub) {
  Drive& d = drive_by_node(node);
  if (!d.sdo.start_upload(bus_, index, sub, clock_.now_ns()))
    throw Error(who(node) + ": SDO read " + object(index, sub) + " could not start (a transfer is busy)");
  while (d.sdo.state() == SdoClient::State::busy) {
    service();
    d.sdo.poll(bus_, clock_.now_ns());
    if (d.sdo.state() == SdoClient::State::busy && !bus_.wait_receivable(0)) clock_.wait(kPollNs);
  }
  if (d.sdo.state() == SdoClient::State::done) return {d.sdo.data().begin(), d.sdo.data().end()};
  const bool to = d.sdo.state() == SdoClient::State::timed_out;
  throw Error(who(node) + ": SDO " + verb(false) + " " + object(index, sub) +
              (to ? " got no answer within " + std::to_string(cfg_.sdo_timeout_ms) + " ms (SDO timeout)"
                  : std::string(" aborted by the ") + (d.sdo.aborted_by_server() ? "drive" : "master") + ": " +
                        hex(d.sdo.abort_code(), 8) + " " + sdo_abort_text(d.sdo.abort_code())));
}

void Master::sdo_write_u8(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint8_t v) {
  sdo_write(node, index, sub, std::span<const std::uint8_t>(&v, 1));
}
void Master::sdo_write_u16(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint16_t v) {
  std::uint8_t b[2];
  put_u16(b, v);
  sdo_write(node, index, sub, b);
}
void Master::sdo_write_u32(std::uint8_t node, std::uint16_t index, std::uint8_t sub, std::uint32_t v) {
  std::uint8_t b[4];
  put_u32(b, v);
  sdo_write(node, index, sub, b);
}
std::uint32_t Master::sdo_read_u32(std::uint8_t node, std::uint16_t index, std::uint8_t sub) {
  const auto b = sdo_read(node, index, sub);
  if (b.empty() || b.size() > 4)
    throw Error(who(node) + ": SDO read " + object(index, sub) + " returned " + std::to_string(b.size()) +
                " bytes, expected 1 to 4");
  std::uint32_t v = 0;
  for (std::size_t i = 0; i < b.size(); ++i) v |= std::uint32_t{b[i]} << (8 * i);
  return v;
}

// ---------------------------------------------------------------- start-up

void Master::check_u32(Drive& d, std::uint16_t index, std::uint8_t sub, std::uint32_t want, const char* what) {
  const std::uint32_t got = sdo_read_u32(d.node, index, sub);
  if (got != want)
    throw Error(who(d.node) + ": " + what + " " + object(index, sub) + " reads back " + hex(got, 8) +
                " after writing " + hex(want, 8));
}

void Master::write_pdo(Drive& d, const pdo::Layout& l, bool enabled) {
  const std::uint32_t cob = l.cob_base + d.node;
  // CiA 301 §7.5.2.36: invalidate, clear the mapping, map, set the count, validate.
  sdo_write_u32(d.node, l.comm_index, 1, cob | kCobIdInvalid);
  sdo_write_u8(d.node, l.map_index, 0, 0);
  for (std::uint8_t i = 0; i < l.count; ++i)
    sdo_write_u32(d.node, l.map_index, static_cast<std::uint8_t>(i + 1), pdo::mapping_entry(l.objects[i]));
  sdo_write_u8(d.node, l.map_index, 0, l.count);
  sdo_write_u8(d.node, l.comm_index, 2, l.transmission_type);
  if (enabled) sdo_write_u32(d.node, l.comm_index, 1, cob);
  // Read everything back: a drive that silently ignored a write is caught here.
  check_u32(d, l.map_index, 0, l.count, "PDO mapping count");
  for (std::uint8_t i = 0; i < l.count; ++i)
    check_u32(d, l.map_index, static_cast<std::uint8_t>(i + 1), pdo::mapping_entry(l.objects[i]), "PDO mapping entry");
  check_u32(d, l.comm_index, 2, l.transmission_type, "PDO transmission type");
  check_u32(d, l.comm_index, 1, enabled ? cob : (cob | kCobIdInvalid), "PDO COB-ID");
}

void Master::disable_unused_pdos(Drive& d) {
  const std::uint16_t unused[] = {0x1401, 0x1402, 0x1403, 0x1802, 0x1803};
  for (std::uint16_t comm : unused) {
    std::uint32_t cur = 0;
    try {
      cur = sdo_read_u32(d.node, comm, 1);
    } catch (const Error&) {
      // CiA 301 makes every PDO optional: a drive without this one answers
      // "object does not exist", and there is nothing to disable.
      if (d.sdo.state() == SdoClient::State::aborted && d.sdo.aborted_by_server() &&
          d.sdo.abort_code() == kAbortNoObject)
        continue;
      throw;
    }
    if (!(cur & kCobIdInvalid)) sdo_write_u32(d.node, comm, 1, cur | kCobIdInvalid);
  }
}

void Master::configure_drive(Drive& d) {
  const std::uint32_t type = sdo_read_u32(d.node, kDeviceType, 0);
  if ((type & 0xFFFF) != kProfileDrive)
    throw Error(who(d.node) + ": device type 0x1000 = " + hex(type, 8) + " is not a CiA 402 drive (profile 402 expected)");
  sdo_write_u16(d.node, kProducerHeartbeatTime, 0, static_cast<std::uint16_t>(cfg_.drive_heartbeat_ms));
  check_u32(d, kProducerHeartbeatTime, 0, static_cast<std::uint32_t>(cfg_.drive_heartbeat_ms), "producer heartbeat time");
  const std::uint32_t consumer = (static_cast<std::uint32_t>(cfg_.master_node_id) << 16) |
                                 static_cast<std::uint32_t>(cfg_.drive_consumer_timeout_ms);
  sdo_write_u32(d.node, kConsumerHeartbeatTime, 1, consumer);
  check_u32(d, kConsumerHeartbeatTime, 1, consumer, "consumer heartbeat time");
  sdo_write_u16(d.node, cia402::kAbortConnectionOption, 0, static_cast<std::uint16_t>(cfg_.abort_connection_option));
  check_u32(d, cia402::kAbortConnectionOption, 0, static_cast<std::uint32_t>(cfg_.abort_connection_option),
            "abort connection option code");
  sdo_write_u16(d.node, cia402::kMaxTorque, 0, static_cast<std::uint16_t>(d.cfg.max_torque_permille));
  std::uint8_t value = 1;
  std::int8_t exponent = -3;
  interpolation_period(cfg_.rate_hz, value, exponent);
  sdo_write_u8(d.node, cia402::kInterpolationPeriod, 1, value);
  sdo_write_u8(d.node, cia402::kInterpolationPeriod, 2, static_cast<std::uint8_t>(exponent));
  // Zero torque before the mode is in force, then cyclic synchronous torque.
  sdo_write_u16(d.node, cia402::kTargetTorque, 0, 0);
  sdo_write_u8(d.node, cia402::kModesOfOperation, 0, static_cast<std::uint8_t>(cia402::kModeCyclicSyncTorque));
  check_u32(d, cia402::kModesDisplay, 0, static_cast<std::uint8_t>(cia402::kModeCyclicSyncTorque),
            "modes of operation display (cyclic synchronous torque = 10)");
  if (d.cfg.homing.enabled) {
    // The drive's own homing (mode 6): its parameters in its units.
    const HomingObjects h = homing_objects(d.cfg);
    sdo_write_u8(d.node, cia402::kHomingMethod, 0, static_cast<std::uint8_t>(h.method));
    check_u32(d, cia402::kHomingMethod, 0, static_cast<std::uint8_t>(h.method), "homing method");
    sdo_write_u32(d.node, cia402::kHomeOffset, 0, static_cast<std::uint32_t>(h.offset));
    check_u32(d, cia402::kHomeOffset, 0, static_cast<std::uint32_t>(h.offset), "home offset");
    sdo_write_u32(d.node, cia402::kHomingSpeeds, 1, h.speed_search);
    check_u32(d, cia402::kHomingSpeeds, 1, h.speed_search, "homing speed during search for switch");
    sdo_write_u32(d.node, cia402::kHomingSpeeds, 2, h.speed_zero);
    check_u32(d, cia402::kHomingSpeeds, 2, h.speed_zero, "homing speed during search for zero");
    sdo_write_u32(d.node, cia402::kHomingAcceleration, 0, h.acceleration);
    check_u32(d, cia402::kHomingAcceleration, 0, h.acceleration, "homing acceleration");
  }
  disable_unused_pdos(d);
  write_pdo(d, d.cfg.homing.enabled ? pdo::kRpdo1Homing : pdo::kRpdo1, true);
  write_pdo(d, d.cfg.homing.enabled ? pdo::kTpdo1Homing : pdo::kTpdo1, true);
  write_pdo(d, pdo::kTpdo2, cfg_.velocity_from_drive);
}

void Master::wait_nmt_state(NmtState want, bool boot_up, const char* what) {
  const std::int64_t deadline = clock_.now_ns() + std::int64_t{cfg_.boot_timeout_ms} * kMs;
  for (;;) {
    service();
    bool all = true;
    for (auto& d : drives_) all = all && (boot_up ? d.fb.nmt == NmtState::boot_up || d.fb.nmt == NmtState::preoperational
                                                   : d.fb.nmt == want);
    if (all) return;
    if (clock_.now_ns() > deadline) {
      std::string missing;
      for (auto& d : drives_)
        if (d.fb.nmt != want && !(boot_up && d.fb.nmt == NmtState::preoperational))
          missing += (missing.empty() ? "" : ", ") + who(d.node) + " (last heard: " + nmt_state_name(d.fb.nmt) + ")";
      throw Error(std::string("CAN master: ") + what + ": no answer within " + std::to_string(cfg_.boot_timeout_ms) +
                  " ms from " + missing);
    }
    if (!bus_.wait_receivable(0)) clock_.wait(kPollNs);
  }
}

void Master::start() {
  started_ = false;
  bus_.set_filters({}, true);
  service();
  for (auto& d : drives_) {
    d.fb = DriveFeedback{};
    d.last_heartbeat_ns = -1;
  }
  if (cfg_.reset_on_start) {
    for (auto& d : drives_) send_nmt(NmtCommand::reset_communication, d.node);
    wait_nmt_state(NmtState::boot_up, true, "boot-up after NMT reset communication");
  }
  for (auto& d : drives_) configure_drive(d);
  for (auto& d : drives_) send_nmt(NmtCommand::start, d.node);
  wait_nmt_state(NmtState::operational, false, "NMT start");
  for (auto& d : drives_) {
    d.fb.faults = kFaultNone;
    d.fb.missed_cycles = 0;
    d.fb.position_lost = false;
    d.got_tpdo1 = d.got_tpdo2 = false;
    d.have_prev = false;
    d.homing_armed = d.sent_mode6_low = false;
  }
  bus_off_seen_ = false;
  bus_state_ = BusState::error_active;
  cycle_ = 0;
  next_heartbeat_ns_ = clock_.now_ns();
  started_ = true;
}

void Master::stop() noexcept {
  if (!started_) return;
  try {
    for (auto& d : drives_)
      (void)bus_.send(rpdo1(d, cia402::controlword(cia402::Command::disable_voltage), 0, cia402::kModeCyclicSyncTorque));
    (void)bus_.send(make_sync());
    clock_.wait(2 * period_ns_);
    service();
    for (auto& d : drives_) (void)bus_.send(make_nmt(NmtCommand::enter_preoperational, d.node));
  } catch (...) {
  }
  started_ = false;
}

// ---------------------------------------------------------------- per cycle

Status Master::read(Feedback& out) noexcept {
  const std::int64_t now = clock_.now_ns();
  Status st;
  CanFrame f;
  // Bounded: a flooded bus cannot hold the cycle here.
  for (int i = 0; i < 1024; ++i) {
    const Status r = bus_.receive(f);
    if (r.code == Code::would_block) break;
    if (!r.ok()) {
      st = r;
      break;
    }
    dispatch(f, now);
  }
  out.count = drives_.size();
  for (std::size_t i = 0; i < drives_.size(); ++i) {
    Drive& d = drives_[i];
    DriveFeedback& fb = d.fb;
    fb.heartbeat_age_ns = d.last_heartbeat_ns < 0 ? -1 : now - d.last_heartbeat_ns;
    if (started_ && (d.last_heartbeat_ns < 0 || fb.heartbeat_age_ns > std::int64_t{cfg_.heartbeat_timeout_ms} * kMs))
      fb.faults |= kFaultHeartbeatLost;
    if (started_ && cycle_ > 0) {
      fb.fresh = d.got_tpdo1 && (d.got_tpdo2 || !cfg_.velocity_from_drive);
      if (fb.fresh) {
        fb.missed_cycles = 0;
      } else if (++fb.missed_cycles >= static_cast<std::uint32_t>(cfg_.pdo_timeout_cycles)) {
        fb.faults |= kFaultPdoTimeout;
      }
    }
    if (d.got_tpdo1) {
      const double p = pdo::position_m(fb.position_counts, d.scaling);
      if (!cfg_.velocity_from_drive) {
        // Positions are sampled at SYNC, so the difference spans whole periods
        // (more than one when TPDOs were missed).
        const double periods = static_cast<double>(cycle_ - d.prev_cycle);
        fb.velocity_mps = (d.have_prev && periods > 0) ? (p - fb.position_m) * cfg_.rate_hz / periods : 0.0;
        d.prev_cycle = cycle_;
        d.have_prev = true;
      }
      fb.position_m = p;
    }
    if (cfg_.velocity_from_drive && d.got_tpdo2) fb.velocity_mps = pdo::velocity_mps(fb.velocity_units, d.scaling);
    // The homing bits mean something only while the drive runs mode 6.
    fb.homing = (fb.mode_display == cia402::kModeHoming && fb.state == State::operation_enabled)
                    ? cia402::decode_homing(fb.statusword)
                    : cia402::HomingStatus::idle;
    out.drive[i] = fb;
    fb.position_lost = false;  // reported once
  }
  out.cycle = cycle_;
  out.bus_state = bus_state_;
  out.bus_off_seen = bus_off_seen_;
  out.last_error = last_error_;
  out.error_frames = error_frames_;
  out.rx_dropped = bus_.stats().rx_dropped;
  out.tx_failures = tx_failures_;
  if (st.ok() && bus_state_ == BusState::bus_off) st = {Code::bus_off, -1, 0};
  return st;
}

Status Master::write(const Commands& in) noexcept {
  if (!started_) return {Code::not_started, -1, 0};
  const std::int64_t now = clock_.now_ns();
  Status result;
  auto note = [&](Status s, std::size_t i) {
    if (s.ok()) return;
    ++tx_failures_;
    if (result.ok() || s.code == Code::bus_off) result = Status{s.code, static_cast<std::int8_t>(i), s.detail};
  };
  Status torque_status;
  for (std::size_t i = 0; i < drives_.size(); ++i) {
    Drive& d = drives_[i];
    const DriveCommand& c = in.drive[i];
    cia402::Command cmd = cia402::next_command(d.fb.state, c.target, c.reset_fault);
    // Fault reset acts on the rising edge of bit 7: drop it for a cycle first.
    if (cmd == cia402::Command::fault_reset && (d.fb.controlword & cia402::kCwFaultReset)) cmd = cia402::Command::disable_voltage;
    std::uint16_t cw = cia402::controlword(cmd);
    const bool driving = d.fb.state == State::operation_enabled && c.target == cia402::Target::enabled &&
                         cmd == cia402::Command::enable_operation;
    const bool homing = d.cfg.homing.enabled && c.homing;
    std::int16_t torque = 0;
    Code code = Code::ok;
    if (homing) {
      // Bit 4 starts homing on its rising edge, in mode 6: hold it low until
      // the drive displays mode 6 after an RPDO that had it low, so the
      // drive has seen it low in that mode (the TPDO of a SYNC shows the
      // RPDO applied at it).
      if (d.got_tpdo1) d.homing_armed = d.fb.mode_display == cia402::kModeHoming && (d.homing_armed || d.sent_mode6_low);
      if (driving && c.start_homing && d.homing_armed) cw |= cia402::kCwHomingStart;
      d.sent_mode6_low = !(cw & cia402::kCwHomingStart);
    } else {
      d.homing_armed = d.sent_mode6_low = false;
      if (driving) {
        torque = pdo::torque_permille(c.force_n, d.scaling, code);
        if (code != Code::ok && torque_status.ok()) torque_status = Status{code, static_cast<std::int8_t>(i), torque};
      }
    }
    d.fb.controlword = cw;
    d.fb.torque_permille = torque;
    d.fb.torque_code = code;
    note(bus_.send(rpdo1(d, cw, torque, homing ? cia402::kModeHoming : cia402::kModeCyclicSyncTorque)), i);
  }
  // SYNC after the RPDOs: the drives apply them at this SYNC and answer with
  // TPDOs sampled at it, read by the next cycle's read().
  note(bus_.send(make_sync()), static_cast<std::size_t>(-1));
  for (auto& d : drives_) d.got_tpdo1 = d.got_tpdo2 = false;
  ++cycle_;
  if (now >= next_heartbeat_ns_) {
    note(bus_.send(make_heartbeat(static_cast<std::uint8_t>(cfg_.master_node_id), NmtState::operational)),
         static_cast<std::size_t>(-1));
    next_heartbeat_ns_ += std::int64_t{cfg_.master_heartbeat_ms} * kMs;
    if (next_heartbeat_ns_ <= now) next_heartbeat_ns_ = now + std::int64_t{cfg_.master_heartbeat_ms} * kMs;
  }
  if (result.code == Code::bus_off) bus_off_seen_ = true;
  return result.ok() ? torque_status : result;
}

CanFrame Master::rpdo1(const Drive& d, std::uint16_t cw, std::int16_t torque, std::int8_t mode) noexcept {
  return d.cfg.homing.enabled ? pdo::pack_rpdo1_homing(d.node, cw, torque, mode) : pdo::pack_rpdo1(d.node, cw, torque);
}

void Master::reset_faults() noexcept {
  for (auto& d : drives_) {
    d.fb.faults = kFaultNone;
    d.fb.missed_cycles = 0;
  }
  if (bus_state_ != BusState::bus_off) bus_off_seen_ = false;
}

}  // namespace cpm::hal

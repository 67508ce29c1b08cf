// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/config.hpp"

#include <fcntl.h>
#include <linux/openat2.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <unistd.h>
#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/yaml.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "cpm/daemon/params.hpp"

#ifdef CPM_HAVE_IO
#include "cpm/io/model_file.hpp"
#endif

namespace cpm::daemon {
namespace {

// Walks the YAML tree, refusing what it does not know, with file:line:col and key path.
class Reader {
 public:
  explicit Reader(std::string name) : name_(std::move(name)) {}

  [[noreturn]] void fail(const YAML::Node& n, const std::string& path, const std::string& why) const {
    std::ostringstream os;
    os << name_;
    if (n.IsDefined() && n.Mark().line >= 0) os << ':' << n.Mark().line + 1 << ':' << n.Mark().column + 1;
    os << ": " << path << ": " << why;
    throw Error(os.str());
  }

  // The map at `path`, with exactly the keys of `required` and any of `optional`.
  YAML::Node map(const YAML::Node& n, const std::string& path, const std::set<std::string>& required,
                 const std::set<std::string>& optional = {}) const {
    if (!n.IsMap()) fail(n, path.empty() ? "(top level)" : path, "expected a mapping of keys");
    for (const auto& kv : n) {
      // A complex key (`? [a, b]`, a mapping, a null) is no key of ours.
      if (!kv.first.IsScalar()) fail(kv.first, path.empty() ? "(top level)" : path, "a key must be a plain name");
      const std::string key = kv.first.Scalar();
      if (!required.count(key) && !optional.count(key)) {
        std::string known;
        for (const auto& k : required) known += (known.empty() ? "" : ", ") + k;
        for (const auto& k : optional) known += (known.empty() ? "" : ", ") + k;
        fail(kv.first, join(path, key), "unknown key (known here: " + known + ")");
      }
    }
    for (const auto& k : required)
      if (!n[k]) fail(n, join(path, k), "missing (required)");
    return n;
  }

  static std::string join(const std::string& a, const std::string& b) { return a.empty() ? b : a + "." + b; }

  // Any number, NaN and infinities included (.nan, .inf): the caller checks the range.
  double real(const YAML::Node& n, const std::string& path) const {
    if (!n.IsScalar()) fail(n, path, "expected a number");
    try {
      return n.as<double>();
    } catch (const YAML::Exception&) {
      fail(n, path, "expected a number, got '" + n.Scalar() + "'");
    }
  }
  double number(const YAML::Node& n, const std::string& path, double lo, double hi, const char* unit) const {
    const double v = real(n, path);
    if (!std::isfinite(v) || v < lo || v > hi) {
      std::ostringstream os;
      os << "must be within " << lo << " .. " << hi << ' ' << unit << ", got " << n.Scalar();
      fail(n, path, os.str());
    }
    return v;
  }
  // Strictly positive variant: (0, hi].
  double positive(const YAML::Node& n, const std::string& path, double hi, const char* unit) const {
    const double v = number(n, path, 0.0, hi, unit);
    if (!(v > 0.0)) fail(n, path, std::string("must be > 0 ") + unit + ", got " + n.Scalar());
    return v;
  }
  long integer(const YAML::Node& n, const std::string& path, long lo, long hi) const {
    if (!n.IsScalar()) fail(n, path, "expected an integer");
    long v = 0;
    try {
      v = n.as<long>();
    } catch (const YAML::Exception&) {
      fail(n, path, "expected an integer, got '" + n.Scalar() + "'");
    }
    if (v < lo || v > hi)
      fail(n, path, "must be within " + std::to_string(lo) + " .. " + std::to_string(hi) + ", got " + n.Scalar());
    return v;
  }
  bool boolean(const YAML::Node& n, const std::string& path) const {
    if (!n.IsScalar()) fail(n, path, "expected true or false");
    try {
      return n.as<bool>();
    } catch (const YAML::Exception&) {
      fail(n, path, "expected true or false, got '" + n.Scalar() + "'");
    }
  }
  std::string text(const YAML::Node& n, const std::string& path) const {
    if (!n.IsScalar() || n.Scalar().empty()) fail(n, path, "expected a non-empty string");
    return n.Scalar();
  }
  void three(const YAML::Node& n, const std::string& path, const std::string& unit) const {
    if (!n.IsSequence() || n.size() != 3) fail(n, path, "expected a list of three numbers [x, y, z] in " + unit);
  }
  Vec3 vec3(const YAML::Node& n, const std::string& path, double lo, double hi, const char* unit) const {
    three(n, path, unit);
    Vec3 v;
    for (int i = 0; i < 3; ++i) v[i] = number(n[i], path + "[" + std::to_string(i) + "]", lo, hi, unit);
    return v;
  }
  // A run-time parameter (params.hpp): the range is the table's, the one `cpm set` checks.
  double param(const YAML::Node& n, const std::string& path, const char* name,
               ctl::ControlLaw law = ctl::ControlLaw::computed_torque) const {
    const double v = real(n, path);
    if (const std::string why = param_range_error(find_param(name), v, law); !why.empty()) fail(n, path, why);
    return v;
  }
  // Three parameters NAME.x, NAME.y, NAME.z written as a list at `path`.
  Vec3 param3(const YAML::Node& n, const std::string& path, const std::string& name,
              ctl::ControlLaw law = ctl::ControlLaw::computed_torque) const {
    three(n, path, param_unit(find_param(name + ".x"), law));
    Vec3 v;
    for (int i = 0; i < 3; ++i)
      v[i] = param(n[i], path + "[" + std::to_string(i) + "]", (name + "." + "xyz"[i]).c_str(), law);
    return v;
  }

 private:
  std::string name_;
};

std::string resolve(const std::string& base, const std::string& p) {
  if (p.rfind("builtin:", 0) == 0) return p;
  std::filesystem::path fp(p);
  if (fp.is_absolute()) return p;
  return (std::filesystem::path(base) / fp).lexically_normal().string();
}

void parse_line(const Reader& r, const YAML::Node& n, const std::string& path, hal::LineConfig& l) {
  r.map(n, path, {}, {"chip", "name", "offset", "active_low"});
  l.present = true;
  if (n["chip"]) l.chip = r.text(n["chip"], path + ".chip");
  if (n["name"]) l.name = r.text(n["name"], path + ".name");
  if (n["offset"]) l.offset = static_cast<int>(r.integer(n["offset"], path + ".offset", 0, 4095));
  if (n["active_low"]) l.active_low = r.boolean(n["active_low"], path + ".active_low");
  if (l.name.empty() && l.offset < 0) r.fail(n, path, "give the line's name, or chip and offset");
  if (l.offset >= 0 && l.chip.empty()) r.fail(n, path + ".chip", "missing (required with offset)");
}

int milliseconds(const Reader& r, const YAML::Node& n, const std::string& path, long lo, long hi) {
  return static_cast<int>(r.integer(n, path, lo, hi));
}

// canopen.heartbeat: the periods and timeouts both ways.
void parse_heartbeat(const Reader& r, const YAML::Node& node, hal::MasterConfig& m) {
  const auto h = r.map(node, "canopen.heartbeat", {}, {"master_ms", "drive_ms", "timeout_ms", "drive_consumer_timeout_ms"});
  if (h["master_ms"]) m.master_heartbeat_ms = milliseconds(r, h["master_ms"], "canopen.heartbeat.master_ms", 1, 65535);
  if (h["drive_ms"]) m.drive_heartbeat_ms = milliseconds(r, h["drive_ms"], "canopen.heartbeat.drive_ms", 1, 65535);
  if (h["timeout_ms"]) m.heartbeat_timeout_ms = milliseconds(r, h["timeout_ms"], "canopen.heartbeat.timeout_ms", 1, 65535);
  if (h["drive_consumer_timeout_ms"])
    m.drive_consumer_timeout_ms = milliseconds(r, h["drive_consumer_timeout_ms"], "canopen.heartbeat.drive_consumer_timeout_ms", 1, 65535);
  if (m.heartbeat_timeout_ms <= m.drive_heartbeat_ms)
    r.fail(h, "canopen.heartbeat.timeout_ms", "must exceed canopen.heartbeat.drive_ms (a drive's heartbeat period)");
  if (m.drive_consumer_timeout_ms <= m.master_heartbeat_ms)
    r.fail(h, "canopen.heartbeat.drive_consumer_timeout_ms", "must exceed canopen.heartbeat.master_ms (the master's heartbeat period)");
}

// canopen.gpio: the machine's safety and auxiliary lines.
void parse_gpio(const Reader& r, const YAML::Node& node, hal::DigitalIoConfig& gpio) {
  const auto g = r.map(node, "canopen.gpio", {"estop", "drive_enable"},
                       {"consumer", "limit_low_x", "limit_low_y", "limit_low_z", "limit_high_x", "limit_high_y",
                        "limit_high_z", "brake_release_z", "home_x", "home_y", "home_z", "index_x", "index_y",
                        "index_z"});
  if (g["consumer"]) gpio.consumer = r.text(g["consumer"], "canopen.gpio.consumer");
  for (std::size_t k = 0; k < hal::kLineCount; ++k) {
    const auto line = static_cast<hal::Line>(k);
    const char* name = hal::line_name(line);
    if (g[name]) parse_line(r, g[name], std::string("canopen.gpio.") + name, gpio[line]);
  }
  try {
    hal::validate(gpio);
  } catch (const std::exception& e) {
    r.fail(g, "canopen.gpio", e.what());
  }
}

void parse_canopen(const Reader& r, const YAML::Node& n, double rate_hz, bool skip_late_slots,
                   const HomingConfig& homing, CanopenConfig& c) {
  r.map(n, "canopen", {"interface", "bitrate", "drives", "gpio"},
        {"master_node_id", "velocity_from_drive", "max_bus_load", "heartbeat", "abort_connection_option",
         "pdo_timeout_cycles", "sdo_timeout_ms", "boot_timeout_ms", "reset_on_start", "feedback_wait_ms"});
  auto& m = c.master;
  m.rate_hz = rate_hz;
  c.interface = r.text(n["interface"], "canopen.interface");
  m.bitrate = r.number(n["bitrate"], "canopen.bitrate", 10e3, 1e6, "bit/s");
  bool known = false;
  for (double b : {10e3, 20e3, 50e3, 125e3, 250e3, 500e3, 800e3, 1e6}) known = known || m.bitrate == b;
  if (!known) r.fail(n["bitrate"], "canopen.bitrate", "must be a CiA 301 bitrate: 10000, 20000, 50000, 125000, 250000, 500000, 800000 or 1000000, got " + n["bitrate"].Scalar());
  if (n["master_node_id"]) m.master_node_id = static_cast<int>(r.integer(n["master_node_id"], "canopen.master_node_id", 1, 127));
  if (n["velocity_from_drive"]) m.velocity_from_drive = r.boolean(n["velocity_from_drive"], "canopen.velocity_from_drive");
  if (n["max_bus_load"]) m.max_bus_load = r.positive(n["max_bus_load"], "canopen.max_bus_load", 1.0, "(fraction)");
  if (n["abort_connection_option"])
    m.abort_connection_option = static_cast<int>(r.integer(n["abort_connection_option"], "canopen.abort_connection_option", 0, 3));
  if (n["pdo_timeout_cycles"]) m.pdo_timeout_cycles = static_cast<int>(r.integer(n["pdo_timeout_cycles"], "canopen.pdo_timeout_cycles", 1, 1000));
  if (n["sdo_timeout_ms"]) m.sdo_timeout_ms = milliseconds(r, n["sdo_timeout_ms"], "canopen.sdo_timeout_ms", 1, 60000);
  if (n["boot_timeout_ms"]) m.boot_timeout_ms = milliseconds(r, n["boot_timeout_ms"], "canopen.boot_timeout_ms", 1, 600000);
  if (n["reset_on_start"]) m.reset_on_start = r.boolean(n["reset_on_start"], "canopen.reset_on_start");
  if (n["feedback_wait_ms"]) c.feedback_wait = r.number(n["feedback_wait_ms"], "canopen.feedback_wait_ms", 0, 1000, "ms") * 1e-3;
  if (c.feedback_wait >= 1.0 / rate_hz && skip_late_slots)
    r.fail(n["feedback_wait_ms"], "canopen.feedback_wait_ms",
           "must be shorter than the control period (1 / loop.rate_hz), unless loop.skip_late_slots is false");
  if (n["heartbeat"]) parse_heartbeat(r, n["heartbeat"], m);
  const YAML::Node ds = n["drives"];
  if (!ds.IsSequence() || ds.size() != 3)
    r.fail(ds, "canopen.drives", "expected a list of three drives (actuators 1, 2, 3)");
  m.drives.clear();
  for (std::size_t i = 0; i < 3; ++i) {
    const std::string p = "canopen.drives[" + std::to_string(i) + "]";
    const auto d = r.map(ds[i], p, {"node_id", "counts_per_m", "rated_force"},
                         {"name", "velocity_units_per_mps", "max_torque_permille", "direction", "position_offset"});
    hal::DriveConfig dc;
    dc.name = d["name"] ? r.text(d["name"], p + ".name") : std::string(1, static_cast<char>('1' + i));
    dc.node_id = static_cast<int>(r.integer(d["node_id"], p + ".node_id", 1, 127));
    if (dc.node_id == m.master_node_id) r.fail(d["node_id"], p + ".node_id", "is the master's own node id (canopen.master_node_id)");
    for (const auto& o : m.drives)
      if (o.node_id == dc.node_id) r.fail(d["node_id"], p + ".node_id", "node id " + std::to_string(dc.node_id) + " is used twice");
    dc.counts_per_m = r.positive(d["counts_per_m"], p + ".counts_per_m", 1e12, "counts/m");
    if (d["velocity_units_per_mps"])
      dc.velocity_units_per_mps = r.number(d["velocity_units_per_mps"], p + ".velocity_units_per_mps", 0, 1e12, "units per m/s (0: counts/s)");
    dc.rated_force_n = r.positive(d["rated_force"], p + ".rated_force", 1e6, "N");
    if (d["max_torque_permille"])
      dc.max_torque_permille = static_cast<int>(r.integer(d["max_torque_permille"], p + ".max_torque_permille", 1, 32767));
    if (d["direction"]) {
      dc.direction = static_cast<int>(r.integer(d["direction"], p + ".direction", -1, 1));
      if (dc.direction == 0) r.fail(d["direction"], p + ".direction", "must be 1 or -1");
    }
    if (d["position_offset"]) dc.position_offset_m = r.number(d["position_offset"], p + ".position_offset", -10, 10, "m");
    // The drive's own homing (homing.axes.*.method: drive): its objects are
    // written at start, and its PDOs carry the mode (the bus load below).
    if (const auto& a = homing.axes[i]; a.method == HomingMethod::drive)
      dc.homing = hal::DriveHomingConfig{.enabled = true,
                                         .method = a.drive_method,
                                         .speed_search_mps = std::abs(a.search_velocity),
                                         .speed_zero_mps = a.latch_velocity,
                                         .acceleration_mps2 = a.acceleration,
                                         .offset_m = a.home_position};
    m.drives.push_back(dc);
  }
  parse_gpio(r, n["gpio"], c.gpio);
  try {
    hal::validate(m);
  } catch (const std::exception& e) {
    r.fail(n, "canopen", e.what());
  }
  c.load = hal::bus_load(m);
  if (!c.load.fits) {
    std::ostringstream os;
    os << "the cyclic traffic does not fit the bus at loop.rate_hz " << rate_hz << " Hz: " << c.load.describe()
       << "; lower loop.rate_hz to at most " << std::floor(c.load.max_rate_hz) << " Hz"
       << (m.velocity_from_drive ? ", set canopen.velocity_from_drive: false" : "") << ", or raise canopen.bitrate";
    r.fail(n, "canopen", os.str());
  }
}

constexpr const char* kAxisNames[3] = {"x", "y", "z"};

// Which keys each homing method uses (a key of another method is refused by name).
struct MethodKeys {
  std::set<std::string> required, optional;
};
MethodKeys method_keys(HomingMethod m) {
  switch (m) {
    case HomingMethod::absolute: return {{"method"}, {}};
    case HomingMethod::switch_:
      return {{"method", "search_velocity", "home_position"},
              {"latch_velocity", "acceleration", "use_index", "max_travel", "final_position", "timeout"}};
    case HomingMethod::drive:
      return {{"method", "drive_method", "search_velocity", "home_position"},
              {"latch_velocity", "acceleration", "final_position", "timeout"}};
  }
  return {};
}

// CiA 402 homing methods (0x6098): 1-14 with the index, 17-30 without, 33-34
// the index alone, 35 and 37 the current position; 15, 16, 31, 32, 36 are
// reserved and the negative ones the manufacturer's.
bool standard_drive_method(long m) { return (m >= 1 && m <= 14) || (m >= 17 && m <= 30) || (m >= 33 && m <= 35) || m == 37; }

// An optional position that may be "none": absent, null or .nan.
double position_or_none(const Reader& r, const YAML::Node& n, const std::string& path, double lo, double hi) {
  if (!n || n.IsNull()) return std::numeric_limits<double>::quiet_NaN();
  const double v = r.real(n, path);
  if (std::isnan(v)) return v;
  return r.number(n, path, lo, hi, "m (or null: none)");
}

AxisHomingConfig parse_axis_homing(const Reader& r, const YAML::Node& n, const std::string& p) {
  if (!n.IsMap()) r.fail(n, p, "expected a mapping with method: absolute, switch or drive");
  if (!n["method"]) r.fail(n, p + ".method", "missing (required: absolute, switch or drive)");
  AxisHomingConfig a;
  const std::string method = r.text(n["method"], p + ".method");
  if (method == "absolute")
    a.method = HomingMethod::absolute;
  else if (method == "switch")
    a.method = HomingMethod::switch_;
  else if (method == "drive")
    a.method = HomingMethod::drive;
  else
    r.fail(n["method"], p + ".method", "must be absolute, switch or drive, got '" + method + "'");
  const MethodKeys keys = method_keys(a.method);
  std::set<std::string> every;
  for (HomingMethod m : {HomingMethod::absolute, HomingMethod::switch_, HomingMethod::drive}) {
    const MethodKeys k = method_keys(m);
    every.insert(k.required.begin(), k.required.end());
    every.insert(k.optional.begin(), k.optional.end());
  }
  // A key of another method: a typo of the method, or a leftover that would
  // silently do nothing.
  for (const auto& kv : n)
    if (kv.first.IsScalar() && every.count(kv.first.Scalar()) && !keys.required.count(kv.first.Scalar()) &&
        !keys.optional.count(kv.first.Scalar()))
      r.fail(kv.first, p + "." + kv.first.Scalar(), "not used by method " + method);
  r.map(n, p, keys.required, keys.optional);
  if (a.method == HomingMethod::absolute) return a;

  const std::string sv = p + ".search_velocity", lv = p + ".latch_velocity";
  a.search_velocity = r.number(n["search_velocity"], sv, -1.0, 1.0, "m/s");
  if (a.method == HomingMethod::switch_ && a.search_velocity == 0.0)
    r.fail(n["search_velocity"], sv, "must not be 0: its sign is the direction the switch is searched in (m/s)");
  if (a.method == HomingMethod::drive && !(a.search_velocity > 0.0))
    r.fail(n["search_velocity"], sv,
           "must be > 0 m/s: the drive's method (drive_method) sets the direction, this is the speed, got " +
               n["search_velocity"].Scalar());
  if (n["latch_velocity"]) a.latch_velocity = r.positive(n["latch_velocity"], lv, 1.0, "m/s");
  const YAML::Node& latch_node = n["latch_velocity"] ? n["latch_velocity"] : n;
  auto mm_s = [](double v) {
    std::ostringstream os;
    os << v * 1e3 << " mm/s";
    return os.str();
  };
  if (a.method == HomingMethod::switch_ && !(a.latch_velocity < std::abs(a.search_velocity)))
    r.fail(latch_node, lv,
           "must be slower than |search_velocity| (" + mm_s(std::abs(a.search_velocity)) + "), got " +
               mm_s(a.latch_velocity));
  if (a.method == HomingMethod::drive && a.latch_velocity > a.search_velocity)
    r.fail(latch_node, lv,
           "must not be faster than search_velocity (" + mm_s(a.search_velocity) + "), got " + mm_s(a.latch_velocity));
  if (n["acceleration"]) a.acceleration = r.positive(n["acceleration"], p + ".acceleration", 100.0, "m/s^2");
  a.home_position = r.number(n["home_position"], p + ".home_position", -10.0, 10.0, "m");
  a.final_position = position_or_none(r, n["final_position"], p + ".final_position", -10.0, 10.0);
  if (n["timeout"]) a.timeout = r.positive(n["timeout"], p + ".timeout", 3600.0, "s");
  if (a.method == HomingMethod::drive) {
    const long m = r.integer(n["drive_method"], p + ".drive_method", -128, 127);
    if (!standard_drive_method(m))
      r.fail(n["drive_method"], p + ".drive_method",
             "must be a CiA 402 homing method: 1-14, 17-30, 33-35 or 37 (15, 16, 31, 32, 36 are reserved, the "
             "negative ones the manufacturer's), got " + n["drive_method"].Scalar());
    a.drive_method = static_cast<int>(m);
    return a;
  }
  if (n["use_index"]) a.use_index = r.boolean(n["use_index"], p + ".use_index");
  if (n["max_travel"]) a.max_travel = r.positive(n["max_travel"], p + ".max_travel", 10.0, "m");
  // A timeout shorter than the search over max_travel would end every long search before its travel does.
  const double search_time = a.max_travel / std::abs(a.search_velocity);
  if (a.timeout < search_time) {
    std::ostringstream os;
    os << "must be at least the search over max_travel: " << a.max_travel * 1e3 << " mm at "
       << std::abs(a.search_velocity) * 1e3 << " mm/s take " << search_time << " s, got " << a.timeout << " s";
    r.fail(n["timeout"] ? n["timeout"] : n, p + ".timeout", os.str());
  }
  return a;
}

// Where the homing section's nodes are, for the checks made once the
// backend's section is read.
struct HomingNodes {
  YAML::Node section;
  std::array<YAML::Node, 3> axis;  // homing.axes.x|y|z (undefined: not given, absolute)
};

int actuator_of(const Reader& r, const YAML::Node& n, const std::string& path) {
  if (n.IsScalar()) {
    const std::string& a = n.Scalar();
    for (int i = 0; i < 3; ++i)
      if (a == kAxisNames[i] || a == std::to_string(i + 1)) return i;
  }
  r.fail(n, path, "expected an actuator: x, y, z or 1, 2, 3");
}

void parse_homing(const Reader& r, const YAML::Node& n, const DaemonConfig& c, HomingConfig& h, HomingNodes& where) {
  where.section = n;
  r.map(n, "homing", {"axes"}, {"order", "actuator_gains"});
  const auto axes = r.map(n["axes"], "homing.axes", {}, {"x", "y", "z"});
  for (int i = 0; i < 3; ++i) {
    if (!axes[kAxisNames[i]]) continue;
    where.axis[static_cast<std::size_t>(i)] = axes[kAxisNames[i]];
    const std::string p = std::string("homing.axes.") + kAxisNames[i];
    auto& a = h.axes[static_cast<std::size_t>(i)];
    a = parse_axis_homing(r, axes[kAxisNames[i]], p);
    if (a.method == HomingMethod::drive && c.backend != "canopen")
      r.fail(axes[kAxisNames[i]]["method"], p + ".method",
             "drive needs backend: canopen (the drive's own homing mode); the simulator homes with switch");
    if (const ConstraintError e = homing_motion_error(a, c.jog, c.limits, i); !e.empty()) {
      const std::string key = e.key.substr(e.key.rfind('.') + 1);
      r.fail(axes[kAxisNames[i]][key] ? axes[kAxisNames[i]][key] : axes[kAxisNames[i]], e.key, e.why);
    }
  }
  if (n["order"]) {
    const YAML::Node o = n["order"];
    if (!o.IsSequence() || o.size() < 1 || o.size() > 3)
      r.fail(o, "homing.order", "expected a list of one to three actuators, e.g. [z, x, y]");
    h.order_count = 0;
    std::array<bool, 3> listed{};
    for (std::size_t k = 0; k < o.size(); ++k) {
      const std::string p = "homing.order[" + std::to_string(k) + "]";
      const int i = actuator_of(r, o[k], p);
      if (listed[static_cast<std::size_t>(i)]) r.fail(o[k], p, std::string("actuator ") + kAxisNames[i] + " is listed twice");
      if (h.axes[static_cast<std::size_t>(i)].method == HomingMethod::absolute)
        r.fail(o[k], p,
               std::string("actuator ") + kAxisNames[i] + " is absolute (homing.axes." + kAxisNames[i] +
                   "): nothing to home; leave it out");
      listed[static_cast<std::size_t>(i)] = true;
      h.order[static_cast<std::size_t>(h.order_count++)] = i;
    }
    for (int i = 0; i < 3; ++i)
      if (!listed[static_cast<std::size_t>(i)] && h.axes[static_cast<std::size_t>(i)].method != HomingMethod::absolute)
        r.fail(o, "homing.order",
               std::string("actuator ") + kAxisNames[i] + " is homed (method " +
                   homing_method_name(h.axes[static_cast<std::size_t>(i)].method) + ") but not listed");
  } else {
    // z first: away from the work.
    h.order_count = 0;
    for (int i : {2, 0, 1})
      if (h.axes[static_cast<std::size_t>(i)].method != HomingMethod::absolute)
        h.order[static_cast<std::size_t>(h.order_count++)] = i;
  }
  if (n["actuator_gains"]) {
    const auto g = r.map(n["actuator_gains"], "homing.actuator_gains", {"kp", "kd"});
    h.actuator_gains.kp = r.vec3(g["kp"], "homing.actuator_gains.kp", 0.0, 1e9, "N/m");
    h.actuator_gains.kd = r.vec3(g["kd"], "homing.actuator_gains.kd", 0.0, 1e7, "N s/m");
    for (int i = 0; i < 3; ++i)
      if (!(h.actuator_gains.kp[i] > 0.0))
        r.fail(g["kp"][i], "homing.actuator_gains.kp[" + std::to_string(i) + "]",
               "must be > 0 N/m: it holds the actuator until every actuator is homed");
  }
}

// What homing needs from the backend: switches and index marks where the
// method uses them, known only once the backend's section is read.
void check_homing_inputs(const Reader& r, const YAML::Node& root, const DaemonConfig& c, const HomingNodes& where) {
  const bool sim = c.backend == "sim";
  for (int i = 0; i < 3; ++i) {
    const auto& a = c.homing.axes[static_cast<std::size_t>(i)];
    const std::string p = std::string("homing.axes.") + kAxisNames[i];
    const YAML::Node& n = where.axis[static_cast<std::size_t>(i)];
    if (sim && a.method == HomingMethod::absolute && c.sim.encoder_zero[i] != 0.0) {
      std::ostringstream os;
      os << "is " << c.sim.encoder_zero[i] * 1e3 << " mm but actuator " << kAxisNames[i]
         << " is absolute (no homing.axes." << kAxisNames[i] << "): the daemon would take its position "
         << "wrong by that much; home it (method: switch) or set 0";
      r.fail(root["sim"]["encoder_zero"][i], "sim.encoder_zero[" + std::to_string(i) + "]", os.str());
    }
    if (a.method != HomingMethod::switch_) continue;
    const auto home = static_cast<hal::Line>(static_cast<int>(hal::Line::home_x) + i);
    const auto index = static_cast<hal::Line>(static_cast<int>(hal::Line::index_x) + i);
    if (sim && std::isnan(c.sim.home_switch[i]))
      r.fail(n["method"], p + ".method",
             "switch needs a home switch: sim.home_switch[" + std::to_string(i) + "] is none");
    if (!sim && !c.canopen.gpio[home].present)
      r.fail(n["method"], p + ".method",
             std::string("switch needs a home switch line: canopen.gpio.") + hal::line_name(home) + " is not given");
    if (a.use_index && sim && !(c.sim.index_pitch > 0.0))
      r.fail(n["use_index"], p + ".use_index", "needs index marks: sim.index_pitch is 0 (none)");
    if (a.use_index && !sim && !c.canopen.gpio[index].present)
      r.fail(n["use_index"], p + ".use_index",
             std::string("needs the index line: canopen.gpio.") + hal::line_name(index) + " is not given");
  }
}

}  // namespace

const char* homing_method_name(HomingMethod m) noexcept {
  switch (m) {
    case HomingMethod::absolute: return "absolute";
    case HomingMethod::switch_: return "switch";
    case HomingMethod::drive: return "drive";
  }
  return "invalid";
}

bool HomingConfig::all_absolute() const noexcept {
  for (const auto& a : axes)
    if (a.method != HomingMethod::absolute) return false;
  return true;
}

namespace {
DaemonConfig parse_config_checked(const std::string& text, const std::string& name,
                                  const std::string& base_dir);
}  // namespace

DaemonConfig parse_config(const std::string& text, const std::string& name, const std::string& base_dir) {
  // Every refusal is an Error naming file, line and key; a yaml-cpp exception
  // that a check did not anticipate is turned into one too, never let out.
  try {
    return parse_config_checked(text, name, base_dir);
  } catch (const YAML::Exception& e) {
    throw Error(name + ":" + std::to_string(e.mark.line + 1) + ":" + std::to_string(e.mark.column + 1) +
                ": " + e.msg);
  }
}

namespace {
// The file's sections, one function each (parse_config_checked reads them in order).
void parse_sim(const Reader& r, const YAML::Node& node, const std::string& base_dir, SimConfig& sim) {
  const auto s = r.map(node, "sim", {"truth_model_file", "initial_position"},
                       {"substeps", "enable_delay", "encoder", "encoder_zero", "home_switch", "index_pitch"});
  sim.truth_model_file = resolve(base_dir, r.text(s["truth_model_file"], "sim.truth_model_file"));
  sim.initial_position = r.vec3(s["initial_position"], "sim.initial_position", 0.0, 2.0, "m");
  if (s["substeps"]) sim.plant.substeps = static_cast<int>(r.integer(s["substeps"], "sim.substeps", 1, 1000));
  if (s["enable_delay"]) sim.enable_delay = r.number(s["enable_delay"], "sim.enable_delay", 0.0, 10.0, "s");
  if (s["encoder"]) {
    const auto e = r.map(s["encoder"], "sim.encoder", {},
                         {"resolution", "position_noise", "velocity_noise", "seed"});
    auto& enc = sim.plant.encoder;
    if (e["resolution"]) enc.resolution = r.number(e["resolution"], "sim.encoder.resolution", 0.0, 1e-3, "m");
    if (e["position_noise"])
      enc.position_noise = r.number(e["position_noise"], "sim.encoder.position_noise", 0.0, 1e-3, "m");
    if (e["velocity_noise"])
      enc.velocity_noise = r.number(e["velocity_noise"], "sim.encoder.velocity_noise", 0.0, 1.0, "m/s");
    if (e["seed"]) enc.seed = static_cast<std::uint64_t>(r.integer(e["seed"], "sim.encoder.seed", 0, 1L << 62));
  }
  if (s["encoder_zero"]) sim.encoder_zero = r.vec3(s["encoder_zero"], "sim.encoder_zero", -10.0, 10.0, "m");
  if (s["home_switch"]) {
    const YAML::Node h = s["home_switch"];
    r.three(h, "sim.home_switch", "m (null: no switch)");
    for (int i = 0; i < 3; ++i)
      sim.home_switch[i] = position_or_none(r, h[i], "sim.home_switch[" + std::to_string(i) + "]", -10.0, 10.0);
  }
  if (s["index_pitch"]) {
    sim.index_pitch = r.number(s["index_pitch"], "sim.index_pitch", 0.0, 1.0, "m");
    // Marks closer than this would run into one another (the simulator's mark is 10 um wide).
    if (sim.index_pitch > 0.0 && sim.index_pitch < 1e-4)
      r.fail(s["index_pitch"], "sim.index_pitch", "must be 0 (no index) or at least 0.1 mm, got " + s["index_pitch"].Scalar());
  }
}

void parse_loop(const Reader& r, const YAML::Node& node, LoopConfig& loop) {
  const auto l = r.map(node, "loop", {"rate_hz"},
                       {"priority", "cpu", "lock_memory", "max_consecutive_overruns", "skip_late_slots"});
  loop.rate_hz = r.number(l["rate_hz"], "loop.rate_hz", 10.0, 10000.0, "Hz");
  if (l["priority"]) loop.priority = static_cast<int>(r.integer(l["priority"], "loop.priority", 0, 99));
  if (l["cpu"]) loop.cpu = static_cast<int>(r.integer(l["cpu"], "loop.cpu", -1, 1023));
  if (l["lock_memory"]) loop.lock_memory = r.boolean(l["lock_memory"], "loop.lock_memory");
  if (l["skip_late_slots"]) loop.skip_late_slots = r.boolean(l["skip_late_slots"], "loop.skip_late_slots");
  if (l["max_consecutive_overruns"])
    loop.max_consecutive_overruns =
        static_cast<int>(r.integer(l["max_consecutive_overruns"], "loop.max_consecutive_overruns", 1, 100000));
}

void parse_controller(const Reader& r, const YAML::Node& node, ControllerConfig& controller) {
  const auto k = r.map(node, "controller", {"law"}, {"kp", "kd", "transfer_time"});
  const std::string law = r.text(k["law"], "controller.law");
  const auto lw = ctl::law_from_name(law);
  if (!lw) r.fail(k["law"], "controller.law", "must be pd, pd_gravity, pd_feedforward or computed_torque, got '" + law + "'");
  controller.law = *lw;
  controller.gains = ctl::table3_gains(*lw);
  if (k["kp"].IsDefined() != k["kd"].IsDefined())
    r.fail(k, "controller", "give both kp and kd, or neither (Table 3 gains)");
  if (k["kp"]) {
    controller.gains.kp = r.param3(k["kp"], "controller.kp", "controller.kp", *lw);
    controller.gains.kd = r.param3(k["kd"], "controller.kd", "controller.kd", *lw);
  }
  if (k["transfer_time"])
    controller.transfer_time = r.param(k["transfer_time"], "controller.transfer_time", "controller.transfer_time");
  try {
    controller.gains.validate();
  } catch (const Error& e) {
    r.fail(k, "controller", e.what());
  }
}

void parse_lcm(const Reader& r, const YAML::Node& node, LcmConfig& lcm) {
  const auto n = r.map(node, "lcm", {"url"}, {"channels", "state_decimation", "session_timeout"});
  lcm.url = r.text(n["url"], "lcm.url");
  if (lcm.url.find("://") == std::string::npos)
    r.fail(n["url"], "lcm.url", "expected an LCM URL such as udpm://239.255.76.67:7667?ttl=0");
  if (n["state_decimation"])
    lcm.state_decimation = static_cast<int>(r.integer(n["state_decimation"], "lcm.state_decimation", 1, 1000));
  if (n["session_timeout"]) {
    lcm.session_timeout = r.positive(n["session_timeout"], "lcm.session_timeout", 3600.0, "s");
    if (lcm.session_timeout < 0.5)
      r.fail(n["session_timeout"], "lcm.session_timeout", "must be at least 0.5 s (clients ping every 0.25 s)");
  }
  if (n["channels"]) {
    const auto ch = r.map(n["channels"], "lcm.channels", {},
                          {"state", "stats", "trajectory", "control", "ack", "security", "drives", "params", "path", "seal"});
    if (ch["state"]) lcm.state_channel = r.text(ch["state"], "lcm.channels.state");
    if (ch["stats"]) lcm.stats_channel = r.text(ch["stats"], "lcm.channels.stats");
    if (ch["trajectory"]) lcm.trajectory_channel = r.text(ch["trajectory"], "lcm.channels.trajectory");
    if (ch["control"]) lcm.control_channel = r.text(ch["control"], "lcm.channels.control");
    if (ch["ack"]) lcm.ack_channel = r.text(ch["ack"], "lcm.channels.ack");
    if (ch["security"]) lcm.security_channel = r.text(ch["security"], "lcm.channels.security");
    if (ch["drives"]) lcm.drives_channel = r.text(ch["drives"], "lcm.channels.drives");
    if (ch["params"]) lcm.params_channel = r.text(ch["params"], "lcm.channels.params");
    if (ch["path"]) lcm.path_channel = r.text(ch["path"], "lcm.channels.path");
    if (ch["seal"]) lcm.seal_channel = r.text(ch["seal"], "lcm.channels.seal");
  }
}

void parse_security(const Reader& r, const YAML::Node& node, const std::string& base_dir, SecurityConfig& security) {
  const auto s = r.map(node, "security", {},
                       {"operators_dir", "model_dir", "acquire_window", "refusal_acks_per_second", "signing_key"});
  if (s["operators_dir"])
    security.operators_dir = resolve(base_dir, r.text(s["operators_dir"], "security.operators_dir"));
  if (s["model_dir"]) security.model_dir = resolve(base_dir, r.text(s["model_dir"], "security.model_dir"));
  if (s["signing_key"])
    security.signing_key = resolve(base_dir, r.text(s["signing_key"], "security.signing_key"));
  if (s["acquire_window"])
    security.acquire_window = r.positive(s["acquire_window"], "security.acquire_window", 3600.0, "s");
  if (s["refusal_acks_per_second"])
    security.refusal_acks_per_second =
        r.number(s["refusal_acks_per_second"], "security.refusal_acks_per_second", 0.0, 10000.0, "1/s");
}

DaemonConfig parse_config_checked(const std::string& text, const std::string& name,
                                  const std::string& base_dir) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::ParserException& e) {
    throw Error(name + ":" + std::to_string(e.mark.line + 1) + ":" + std::to_string(e.mark.column + 1) +
                ": not valid YAML: " + e.msg);
  }
  const Reader r(name);
  DaemonConfig c;
  c.source = name;
  r.map(root, "", {"model_file", "backend", "loop", "controller", "limits", "lcm"},
        {"sim", "canopen", "security", "jog", "homing"});

  c.model_file = resolve(base_dir, r.text(root["model_file"], "model_file"));
  c.backend = r.text(root["backend"], "backend");
  if (c.backend != "sim" && c.backend != "canopen")
    r.fail(root["backend"], "backend", "must be sim or canopen, got '" + c.backend + "'");
  if (c.backend == "sim" && !root["sim"]) r.fail(root, "sim", "missing (required with backend: sim)");
  if (c.backend == "canopen" && !root["canopen"]) r.fail(root, "canopen", "missing (required with backend: canopen)");

  if (root["sim"]) parse_sim(r, root["sim"], base_dir, c.sim);

  parse_loop(r, root["loop"], c.loop);
  parse_controller(r, root["controller"], c.controller);

  const auto m = r.map(root["limits"], "limits",
                       {"workspace_min", "workspace_max", "velocity", "acceleration", "force", "following_error"},
                       {"overspeed", "stop_deceleration", "enable_timeout", "saturation_time", "allow_velocity_step"});
  auto& limits = c.limits;
  limits.workspace_min = r.param3(m["workspace_min"], "limits.workspace_min", "limits.workspace_min");
  limits.workspace_max = r.param3(m["workspace_max"], "limits.workspace_max", "limits.workspace_max");
  for (int i = 0; i < 3; ++i)
    if (const ConstraintError e = workspace_error(limits, i); !e.empty())
      r.fail(m["workspace_max"][i], "limits.workspace_max[" + std::to_string(i) + "]", e.why);
  limits.velocity = r.param(m["velocity"], "limits.velocity", "limits.velocity");
  limits.acceleration = r.param(m["acceleration"], "limits.acceleration", "limits.acceleration");
  limits.force = r.param(m["force"], "limits.force", "limits.force");
  limits.following_error = r.param(m["following_error"], "limits.following_error", "limits.following_error");
  limits.overspeed =
      m["overspeed"] ? r.param(m["overspeed"], "limits.overspeed", "limits.overspeed") : 1.6 * limits.velocity;
  if (const ConstraintError e = overspeed_error(limits); !e.empty()) r.fail(m["overspeed"], e.key, e.why);
  if (m["stop_deceleration"])
    limits.stop_deceleration = r.param(m["stop_deceleration"], "limits.stop_deceleration", "limits.stop_deceleration");
  if (m["enable_timeout"])
    limits.enable_timeout = r.param(m["enable_timeout"], "limits.enable_timeout", "limits.enable_timeout");
  if (m["saturation_time"])
    limits.saturation_time = r.param(m["saturation_time"], "limits.saturation_time", "limits.saturation_time");
  if (m["allow_velocity_step"])
    limits.allow_velocity_step = r.boolean(m["allow_velocity_step"], "limits.allow_velocity_step");

  if (root["jog"]) {
    const auto j = r.map(root["jog"], "jog", {}, {"max_velocity", "acceleration", "keepalive", "stop_distance"});
    for (const char* key : {"max_velocity", "acceleration", "keepalive", "stop_distance"}) {
      const std::string param = std::string("jog.") + key;
      if (j[key]) find_param(param).field(c) = r.param(j[key], param, param.c_str());
    }
  }
  if (const ConstraintError e = jog_error(c.jog, limits); !e.empty()) {
    // The key it is about if the file gives it; else the jog section, or the
    // limit that the default jog breaks.
    const std::string key = e.key.substr(4);
    const YAML::Node at = root["jog"] && root["jog"][key] ? root["jog"][key] : root["jog"] ? root["jog"] : m["velocity"];
    r.fail(at, e.key, e.why);
  }

  HomingNodes homing_nodes;
  if (root["homing"])
    parse_homing(r, root["homing"], c, c.homing, homing_nodes);
  else
    c.homing.order_count = 0;  // every actuator absolute: nothing to home

  parse_lcm(r, root["lcm"], c.lcm);
  if (root["security"]) parse_security(r, root["security"], base_dir, c.security);
  if (root["canopen"])
    parse_canopen(r, root["canopen"], c.loop.rate_hz, c.loop.skip_late_slots, c.homing, c.canopen);
  check_homing_inputs(r, root, c, homing_nodes);
  return c;
}
}  // namespace

std::string read_regular_file(int fd, const std::string& path, long limit, const char* what) {
  struct stat st {};
  if (::fstat(fd, &st) != 0) throw Error(path + ": cannot read the " + what + ": " + std::strerror(errno));
  if (S_ISDIR(st.st_mode)) throw Error(path + ": the " + std::string(what) + " is a directory, not a file");
  if (!S_ISREG(st.st_mode)) throw Error(path + ": the " + std::string(what) + " is not a regular file");
  if (st.st_size > limit)
    throw Error(path + ": the " + std::string(what) + " is " + std::to_string(st.st_size) + " bytes, more than the " +
                std::to_string(limit) + " it may be");
  std::string text;
  char buf[1 << 16];
  for (;;) {
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw Error(path + ": cannot read the " + std::string(what) + ": " + std::strerror(errno));
    if (n == 0) break;
    text.append(buf, static_cast<std::size_t>(n));
    if (static_cast<long>(text.size()) > limit)
      throw Error(path + ": the " + std::string(what) + " grew beyond " + std::to_string(limit) + " bytes while read");
  }
  return text;
}

namespace {
// Opened non-blocking: a FIFO named as a file must not hang the start.
std::string read_small_file(const std::string& path, long limit, const char* what) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
  if (fd < 0) throw Error(path + ": cannot read the " + std::string(what) + ": " + std::strerror(errno));
  try {
    std::string text = read_regular_file(fd, path, limit, what);
    ::close(fd);
    return text;
  } catch (...) {
    ::close(fd);
    throw;
  }
}
}  // namespace

DaemonConfig load_config(const std::string& path) {
  const std::string text = read_small_file(path, kMaxConfigFileBytes, "configuration file");
  const std::string base = std::filesystem::path(path).parent_path().string();
  return parse_config(text, path, base.empty() ? "." : base);
}

namespace {

// openat2(RESOLVE_BENEATH) where the kernel has it (Linux 5.6); otherwise the
// canonical path must lie inside the canonical directory and the last
// component must not be a symlink (a race with a writer of the directory
// remains there: docs/security.md).
int open_beneath(int dirfd, const std::string& dir, const std::string& rel) {
  open_how how{};
  how.flags = O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY;
  how.resolve = RESOLVE_BENEATH | RESOLVE_NO_MAGICLINKS;
  const long fd = ::syscall(SYS_openat2, dirfd, rel.c_str(), &how, sizeof how);
  if (fd >= 0 || errno != ENOSYS) return static_cast<int>(fd);
  std::error_code ec;
  const auto root = std::filesystem::canonical(dir, ec);
  if (ec) return errno = ENOENT, -1;
  const auto full = std::filesystem::weakly_canonical(root / rel, ec);
  if (ec) return errno = ENOENT, -1;
  const std::string r = root.string() + "/", f = full.string();
  if (f.compare(0, r.size(), r) != 0) return errno = EXDEV, -1;
  return ::openat(dirfd, rel.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY | O_NOFOLLOW);
}

bool ends_with(const std::string& s, const char* tail) {
  const std::size_t n = std::strlen(tail);
  return s.size() >= n && s.compare(s.size() - n, n, tail) == 0;
}

}  // namespace

namespace {

// Counts nodes and depth as the parser meets them; throws at the first
// excess, before the parser goes deeper or builds anything.
class BoundedYaml : public YAML::EventHandler {
 public:
  explicit BoundedYaml(const std::string& where) : where_(where) {}
  void OnDocumentStart(const YAML::Mark&) override {}
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark& m, YAML::anchor_t) override { node(m); }
  void OnAlias(const YAML::Mark& m, YAML::anchor_t) override { node(m); }
  void OnScalar(const YAML::Mark& m, const std::string&, YAML::anchor_t, const std::string&) override { node(m); }
  void OnSequenceStart(const YAML::Mark& m, const std::string&, YAML::anchor_t, YAML::EmitterStyle::value) override {
    open(m);
  }
  void OnSequenceEnd() override { --depth_; }
  void OnMapStart(const YAML::Mark& m, const std::string&, YAML::anchor_t, YAML::EmitterStyle::value) override {
    open(m);
  }
  void OnMapEnd() override { --depth_; }

 private:
  void node(const YAML::Mark& m) {
    if (++nodes_ > kMaxModelNodes)
      fail(m, "more than " + std::to_string(kMaxModelNodes) + " YAML nodes (a model file has a few hundred)");
  }
  void open(const YAML::Mark& m) {
    node(m);
    if (++depth_ > kMaxModelDepth)
      fail(m, "nested more than " + std::to_string(kMaxModelDepth) + " levels deep (a model file nests about 5)");
  }
  [[noreturn]] void fail(const YAML::Mark& m, const std::string& why) const {
    const std::string at = "line " + std::to_string(m.line + 1) + ": " + why;
    throw ModelLoadError(where_ + ": " + at, at);
  }
  const std::string& where_;
  long nodes_ = 0;
  int depth_ = 0;
};

}  // namespace

void check_model_yaml_bounds(const std::string& text, const std::string& where) {
  std::istringstream in(text);
  BoundedYaml counter(where);
  try {
    YAML::Parser parser(in);
    while (parser.HandleNextDocument(counter)) {
    }
  } catch (const YAML::Exception& e) {
    // The parser's words may quote the file: they go to the journal (what()) only.
    throw ModelLoadError(where + ": line " + std::to_string(e.mark.line + 1) + ": not valid YAML: " + e.msg,
                         "line " + std::to_string(e.mark.line + 1) + ": not valid YAML");
  }
}

ctl::MachineModel load_model_beneath(const std::string& model_dir, const std::string& request) {
  auto refuse = [&](const std::string& why, const std::string& summary) -> ModelLoadError {
    return ModelLoadError("load_model '" + request + "' (model directory " + model_dir + "): " + why, summary);
  };
  if (request == "builtin:elkady") return ctl::MachineModel::elkady();
  if (request.empty()) throw refuse("no path", "no model path given");
  if (request.size() > 4096 || request.find('\0') != std::string::npos) throw refuse("not a path", "not a valid path");
  if (request.rfind("builtin:", 0) == 0) throw refuse("unknown builtin model", "the only builtin model is builtin:elkady");
  std::string rel = request;
  if (request.front() == '/') {
    // Absolute: accepted when it names a place beneath the directory as configured.
    const std::string base = std::filesystem::path(model_dir).lexically_normal().string();
    const std::string prefix = base.back() == '/' ? base : base + "/";
    const std::string req = std::filesystem::path(request).lexically_normal().string();
    if (req.compare(0, prefix.size(), prefix) != 0 || req.size() == prefix.size())
      throw refuse("outside the model directory", "the path is outside the model directory (security.model_dir)");
    rel = req.substr(prefix.size());
  }
  if (!ends_with(rel, ".yaml") && !ends_with(rel, ".yml"))
    throw refuse("not a .yaml or .yml file", "a model file's name ends in .yaml or .yml");
  const int dfd = ::open(model_dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd < 0)
    throw refuse(std::string("cannot open the model directory: ") + std::strerror(errno),
                 "cpmd cannot open its model directory (security.model_dir)");
  const int fd = open_beneath(dfd, model_dir, rel);
  const int e = errno;
  ::close(dfd);
  if (fd < 0) {
    const std::string why = std::strerror(e);
    if (e == EXDEV || e == ELOOP)
      throw refuse(why, "the path leads outside the model directory (.. or a symlink out)");
    if (e == ENOENT || e == ENOTDIR) throw refuse(why, "no such file in the model directory");
    if (e == EACCES || e == EPERM) throw refuse(why, "cpmd may not read that file");
    throw refuse(why, "the file cannot be opened");
  }
  std::string text;
  try {
    struct stat st {};
    if (::fstat(fd, &st) != 0) throw refuse(std::strerror(errno), "the file cannot be read");
    if (!S_ISREG(st.st_mode)) throw refuse("not a regular file", "not a regular file");
    if (st.st_size > kMaxModelFileBytes)
      throw refuse(std::to_string(st.st_size) + " bytes", "the file is bigger than a model file may be (1 MiB)");
    try {
      text = read_regular_file(fd, request, kMaxModelFileBytes, "model file");
    } catch (const Error& err) {
      throw refuse(err.what(), "the file cannot be read whole");
    }
  } catch (...) {
    ::close(fd);
    throw;
  }
  ::close(fd);
#ifdef CPM_HAVE_IO
  try {
    check_model_yaml_bounds(text, request);
  } catch (const ModelLoadError& err) {
    throw refuse(err.what(), err.summary);
  }
  try {
    return io::parse_model_file(text, request).model;
  } catch (const io::ModelFileError& err) {
    throw refuse(err.what(), (err.line > 0 ? "line " + std::to_string(err.line) + ": " : std::string()) + err.summary);
  } catch (const Error& err) {
    throw refuse(err.what(), "the model is not valid");
  }
#else
  throw refuse("this build has no model-file loader (cpm_io)", "this cpmd loads builtin:elkady only");
#endif
}

ctl::MachineModel load_model(const std::string& path) {
  if (path == "builtin:elkady") return ctl::MachineModel::elkady();
#ifdef CPM_HAVE_IO
  const std::string text = read_small_file(path, kMaxModelFileBytes, "model file");
  check_model_yaml_bounds(text, path);
  return io::parse_model_file(text, path).model;
#else
  throw Error(path + ": this build has no model-file loader (cpm_io); use builtin:elkady");
#endif
}

}  // namespace cpm::daemon

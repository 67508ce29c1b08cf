// SPDX-License-Identifier: Apache-2.0
// What the console reads and writes besides its screens (console.hpp): the
// parameter table of cpm get, cpm set's VALUE with its unit, cpm home's
// actuators, and drives_t as JSON.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "console.hpp"

namespace cpm::cli::console {

using cpm_msgs::drives_t;
using cpm_msgs::params_t;

namespace {

// The shortest text that reads back as the same double: plain from 1e-5 to
// 1e6 (120, 12691, 0.005, 0.0001; never 1.2e+02, which reads as 2
// significant digits), the exponent form beyond (1e+06).
std::string shortest(double v) {
  char b[64];
  const double a = std::fabs(v);
  const auto r = (v == 0.0 || (a >= 1e-5 && a < 1e6)) ? std::to_chars(b, b + sizeof b, v, std::chars_format::fixed)
                                                     : std::to_chars(b, b + sizeof b, v);
  return std::string(b, r.ptr);
}

std::string si_unit(std::string u) {
  if (u == "m/s2") u = "m/s^2";
  return u;
}

Json bools3(const std::int8_t* v) { return Json::array({v[0] != 0, v[1] != 0, v[2] != 0}); }

}  // namespace

// ---- cpm get

std::vector<int> select_params(const params_t& p, const std::vector<std::string>& names) {
  const int n = std::min<int>(p.count, static_cast<int>(p.name.size()));
  std::vector<int> which;
  if (names.empty()) {
    for (int i = 0; i < n; ++i) which.push_back(i);
    return which;
  }
  for (const auto& want : names) {
    int found = -1;
    for (int i = 0; i < n; ++i)
      if (p.name[static_cast<std::size_t>(i)] == want) found = i;
    if (found < 0) {
      std::string all;
      for (int i = 0; i < n; ++i) all += (i ? ", " : "") + p.name[static_cast<std::size_t>(i)];
      throw Error("cpmd has no parameter '" + want + "'; it has: " + (all.empty() ? std::string("none") : all));
    }
    which.push_back(found);
  }
  return which;
}

std::string screen_value(double v, const std::string& unit) {
  char b[64];
  const std::string u = si_unit(unit);
  if (!std::isfinite(v)) return "";
  if (u == "m") {
    if (v != 0 && std::fabs(v) < 1e-3) std::snprintf(b, sizeof b, "%.1f um", v * 1e6);
    else std::snprintf(b, sizeof b, "%.3f mm", v * 1e3);
  } else if (u == "m/s") {
    std::snprintf(b, sizeof b, std::fabs(v) < 1e-3 && v != 0 ? "%.3f mm/s" : "%.1f mm/s", v * 1e3);
  } else if (u == "m/s^2") {
    std::snprintf(b, sizeof b, "%.1f mm/s^2", v * 1e3);
  } else {
    return "";
  }
  return b;
}

Lines params_table(const params_t& p, const std::vector<int>& which, bool describe) {
  auto at = [&](const auto& v, int i, auto none) { return static_cast<std::size_t>(i) < v.size() ? v[static_cast<std::size_t>(i)] : none; };
  struct Row {
    std::string name, value, range, moving, description;
  };
  std::vector<Row> rows;
  std::size_t wn = 9, wv = 5, wr = 5;  // "parameter", "value", "range"
  for (int i : which) {
    const std::string unit = at(p.unit, i, std::string());
    const double v = at(p.value, i, NAN);
    const std::string screen = screen_value(v, unit);
    Row r{at(p.name, i, std::string()), shortest(v) + (unit.empty() ? "" : " " + unit) + (screen.empty() ? "" : " (" + screen + ")"),
          shortest(at(p.minimum, i, NAN)) + " .. " + shortest(at(p.maximum, i, NAN)) + (unit.empty() ? "" : " " + unit),
          at(p.while_moving, i, std::int8_t{0}) ? "yes" : "no", at(p.description, i, std::string())};
    wn = std::max(wn, r.name.size());
    wv = std::max(wv, r.value.size());
    wr = std::max(wr, r.range.size());
    rows.push_back(std::move(r));
  }
  auto line = [&](const std::string& a, const std::string& b, const std::string& c, const std::string& d) {
    std::string l = a + std::string(wn - a.size() + 2, ' ') + b + std::string(wv - b.size() + 2, ' ') + c +
                    std::string(wr - c.size() + 2, ' ') + d;
    return l;
  };
  Lines out{line("parameter", "value", "range", "while moving")};
  for (const auto& r : rows) {
    out.push_back(line(r.name, r.value, r.range, r.moving));
    if (describe && !r.description.empty()) out.push_back("    " + r.description);
  }
  return out;
}

Json params_json(const params_t& p, const std::vector<int>& which) {
  Json j = Json::object();
  auto at = [&](const auto& v, int i, auto none) { return static_cast<std::size_t>(i) < v.size() ? v[static_cast<std::size_t>(i)] : none; };
  for (int i : which)
    j[at(p.name, i, std::string())] = {{"value", at(p.value, i, NAN)},
                                        {"unit", at(p.unit, i, std::string())},
                                        {"minimum", at(p.minimum, i, NAN)},
                                        {"maximum", at(p.maximum, i, NAN)},
                                        {"while_moving", at(p.while_moving, i, std::int8_t{0}) != 0},
                                        {"description", at(p.description, i, std::string())}};
  return j;
}

// ---- cpm set

Quantity parse_quantity(const std::string& text) {
  std::string t;
  for (char c : text)
    if (c != ' ') t += c;
  const char* b = t.data();
  const char* e = t.data() + t.size();
  if (b != e && *b == '+') ++b;  // from_chars takes no '+'
  double v = 0;
  const auto r = std::from_chars(b, e, v);
  const std::string hint = "give the value in SI, or with mm, um, mm/s or mm/s^2 (e.g. 5mm, 0.005)";
  if (r.ec != std::errc() || r.ptr == b) throw UsageError("VALUE: '" + text + "' is not a number: " + hint);
  if (!std::isfinite(v)) throw UsageError("VALUE: '" + text + "' is not a finite number");
  const std::string suffix(r.ptr, e);
  struct Unit {
    const char* suffix;
    double scale;
    const char* si;
  };
  static const Unit units[] = {{"", 1, ""},          {"m", 1, "m"},          {"mm", 1e-3, "m"},
                               {"um", 1e-6, "m"},     {"\xC2\xB5m", 1e-6, "m"}, {"m/s", 1, "m/s"},
                               {"mm/s", 1e-3, "m/s"}, {"m/s^2", 1, "m/s^2"},  {"m/s2", 1, "m/s^2"},
                               {"mm/s^2", 1e-3, "m/s^2"}, {"mm/s2", 1e-3, "m/s^2"}};
  for (const auto& u : units)
    if (suffix == u.suffix) return {v * u.scale, u.si};
  throw UsageError("VALUE: unknown unit '" + suffix + "' in '" + text + "': " + hint);
}

double value_for(const Quantity& q, const std::string& name, const std::string& param_unit) {
  if (q.unit.empty() || param_unit.empty() || q.unit == si_unit(param_unit)) return q.value;
  throw UsageError("VALUE: " + name + " is in " + param_unit + ", the value given is in " + q.unit);
}

// ---- cpm home

std::uint8_t parse_home_axes(const std::vector<std::string>& words) {
  std::uint8_t mask = 0;
  for (const auto& w : words) {
    std::size_t i = 0;
    while (i <= w.size()) {
      std::size_t j = w.find(',', i);
      if (j == std::string::npos) j = w.size();
      const std::string a = w.substr(i, j - i);
      i = j + 1;
      if (a.empty()) continue;
      if (a == "x" || a == "1") mask |= 1;
      else if (a == "y" || a == "2") mask |= 2;
      else if (a == "z" || a == "3") mask |= 4;
      else throw UsageError("ACTUATOR: '" + a + "' is no actuator: give x, y, z or 1, 2, 3");
    }
  }
  return mask;
}

// ---- cpm drives --json

Json drives_json(const drives_t& d) {
  Json drives = Json::array();
  for (int i = 0; i < 3; ++i)
    drives.push_back({{"actuator", i + 1},
                      {"node_id", d.node_id[i]},
                      {"nmt_state", nmt_name(d.nmt_state[i])},
                      {"cia402_state", cia402_name(d.cia402_state[i])},
                      {"statusword", d.statusword[i]},
                      {"controlword", d.controlword[i]},
                      {"mode_display", d.mode_display[i]},
                      {"enabled", d.enabled[i] != 0},
                      {"fault", d.fault[i] != 0},
                      {"homed", d.homed[i] != 0},
                      {"heartbeat_age_ms", d.heartbeat_age_ms[i]},
                      {"master_faults", d.master_faults[i]},
                      {"emcy_count", d.emcy_count[i]},
                      {"last_emcy_code", d.last_emcy_code[i]},
                      {"last_emcy_register", d.last_emcy_register[i]},
                      {"position", d.position[i]},
                      {"force", d.force[i]}});
  return {{"utime", d.utime},
          {"cycle", d.cycle},
          {"backend", d.backend == drives_t::BACKEND_CANOPEN ? "canopen" : d.backend == drives_t::BACKEND_SIM ? "sim" : "unknown"},
          {"drives", drives},
          {"bus",
           {{"state", bus_state_name(d.bus_state)},
            {"error_frames", d.error_frames},
            {"tx_error_counter", d.tx_error_counter},
            {"rx_error_counter", d.rx_error_counter},
            {"rx_dropped", d.rx_dropped},
            {"tx_failures", d.tx_failures},
            {"load", d.bus_load}}},
          {"inputs",
           {{"estop", d.estop != 0},
            {"limit_low", bools3(d.limit_low)},
            {"limit_high", bools3(d.limit_high)},
            {"home_switch", bools3(d.home_switch)}}}};
}

}  // namespace cpm::cli::console

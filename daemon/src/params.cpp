// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/params.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>
#include <utility>
#include <vector>

namespace cpm::daemon {
namespace {

// The stop-distance check compares a sum of products with a figure written in
// the file: 0.05 * 0.2 + 0.05^2 / (2 * 0.5) is 0.0125 plus rounding.
constexpr double kDistanceSlack = 1e-9;  // m

// One accessor per field: the table stores plain function pointers.
#define CPM_FIELD(expr) [](DaemonConfig& c) -> double& { return c.expr; }

// Ranges: the loader's, from before this table; the jog's chosen here. The
// gains' ranges hold any law (the units differ, the bound is a sanity one).
constexpr std::array kParams = {
    Param{"limits.velocity", "m/s", nullptr, 0, 5, true, false,
          "the fastest a trajectory may move the platform", CPM_FIELD(limits.velocity)},
    Param{"limits.acceleration", "m/s^2", nullptr, 0, 100, true, false,
          "the largest acceleration of a trajectory", CPM_FIELD(limits.acceleration)},
    Param{"limits.overspeed", "m/s", nullptr, 0, 10, true, false,
          "a measured platform speed above this is a fault (above limits.velocity)", CPM_FIELD(limits.overspeed)},
    Param{"limits.force", "N", nullptr, 0, 10000, true, false,
          "the actuator force limit (the model's force limit caps it)", CPM_FIELD(limits.force)},
    Param{"limits.following_error", "m", nullptr, 0, 0.1, true, true,
          "|reference - measured| above this is a fault", CPM_FIELD(limits.following_error)},
    Param{"limits.stop_deceleration", "m/s^2", nullptr, 0, 100, true, false,
          "the deceleration of a stop", CPM_FIELD(limits.stop_deceleration)},
    Param{"limits.enable_timeout", "s", nullptr, 0, 60, true, true,
          "the drives must report enabled within this", CPM_FIELD(limits.enable_timeout)},
    Param{"limits.saturation_time", "s", nullptr, 0, 60, true, true,
          "an actuator at the force limit longer than this is a fault", CPM_FIELD(limits.saturation_time)},
    Param{"limits.workspace_min.x", "m", nullptr, 0, 2, false, false,
          "task-space soft limit, low end of x", CPM_FIELD(limits.workspace_min.x())},
    Param{"limits.workspace_min.y", "m", nullptr, 0, 2, false, false,
          "task-space soft limit, low end of y", CPM_FIELD(limits.workspace_min.y())},
    Param{"limits.workspace_min.z", "m", nullptr, 0, 2, false, false,
          "task-space soft limit, low end of z", CPM_FIELD(limits.workspace_min.z())},
    Param{"limits.workspace_max.x", "m", nullptr, 0, 2, false, false,
          "task-space soft limit, high end of x", CPM_FIELD(limits.workspace_max.x())},
    Param{"limits.workspace_max.y", "m", nullptr, 0, 2, false, false,
          "task-space soft limit, high end of y", CPM_FIELD(limits.workspace_max.y())},
    Param{"limits.workspace_max.z", "m", nullptr, 0, 2, false, false,
          "task-space soft limit, high end of z", CPM_FIELD(limits.workspace_max.z())},
    // A jog is a person's hand on the machine: 1 m/s is beyond any use.
    Param{"jog.max_velocity", "m/s", nullptr, 0, 1, true, false,
          "the fastest jog, per actuator or of the platform (within limits.velocity)", CPM_FIELD(jog.max_velocity)},
    Param{"jog.acceleration", "m/s^2", nullptr, 0, 100, true, false,
          "the acceleration that starts, changes and ends a jog", CPM_FIELD(jog.acceleration)},
    // Clients repeat a held jog at 20 Hz: a keepalive under 50 ms would stutter.
    Param{"jog.keepalive", "s", nullptr, 0.05, 5, false, false,
          "how long one jog command holds (the deadman)", CPM_FIELD(jog.keepalive)},
    Param{"jog.stop_distance", "m", nullptr, 0, 0.1, true, false,
          "a let-go jog is at rest within this of where the last command found it", CPM_FIELD(jog.stop_distance)},
    Param{"controller.kp.x", "N/m", "1/s^2", 0, 1e9, false, false,
          "proportional gain of actuator 1 (x)", CPM_FIELD(controller.gains.kp.x())},
    Param{"controller.kp.y", "N/m", "1/s^2", 0, 1e9, false, false,
          "proportional gain of actuator 2 (y)", CPM_FIELD(controller.gains.kp.y())},
    Param{"controller.kp.z", "N/m", "1/s^2", 0, 1e9, false, false,
          "proportional gain of actuator 3 (z)", CPM_FIELD(controller.gains.kp.z())},
    Param{"controller.kd.x", "N s/m", "1/s", 0, 1e7, false, false,
          "derivative gain of actuator 1 (x)", CPM_FIELD(controller.gains.kd.x())},
    Param{"controller.kd.y", "N s/m", "1/s", 0, 1e7, false, false,
          "derivative gain of actuator 2 (y)", CPM_FIELD(controller.gains.kd.y())},
    Param{"controller.kd.z", "N s/m", "1/s", 0, 1e7, false, false,
          "derivative gain of actuator 3 (z)", CPM_FIELD(controller.gains.kd.z())},
    Param{"controller.transfer_time", "s", nullptr, 0, 10, true, true,
          "a controller switch fades the force difference out over this", CPM_FIELD(controller.transfer_time)},
};
#undef CPM_FIELD

std::string num(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

// Edit distance, for the names close to a mistyped one.
std::size_t distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diag = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diag = up;
    }
  }
  return row[b.size()];
}

const char* axis_name(int axis) noexcept { return axis == 0 ? "x" : axis == 1 ? "y" : "z"; }

// The accessor hands out a reference for set_param(); reading through it changes nothing.
double value_of(const Param& p, const DaemonConfig& c) { return p.field(const_cast<DaemonConfig&>(c)); }

}  // namespace

std::span<const Param> param_table() noexcept { return kParams; }

const Param& find_param(std::string_view name) {
  for (const auto& p : kParams)
    if (name == p.name) return p;
  // Close: a few edits away, or the name is the start of some ("limits.workspace_min").
  std::string close;
  for (const auto& p : kParams) {
    const std::string_view pn = p.name;
    if (distance(name, pn) <= 3 || (!name.empty() && pn.substr(0, name.size()) == name))
      close += (close.empty() ? "" : ", ") + std::string(pn);
  }
  std::string msg = "unknown parameter '" + std::string(name) + "'";
  if (!close.empty())
    msg += "; did you mean " + close + "?";
  else
    msg += " (the parameters are limits.*, jog.*, controller.*: cpm get lists them)";
  throw Error(msg);
}

const char* param_unit(const Param& p, ctl::ControlLaw law) noexcept {
  return p.unit_computed_torque && law == ctl::ControlLaw::computed_torque ? p.unit_computed_torque : p.unit;
}

std::string param_range_error(const Param& p, double value, ctl::ControlLaw law) {
  const bool low_ok = p.minimum_excluded ? value > p.minimum : value >= p.minimum;
  if (std::isfinite(value) && low_ok && value <= p.maximum) return "";
  const std::string unit = param_unit(p, law);
  return (p.minimum_excluded ? "must be > " + num(p.minimum) + " and <= "
                             : "must be within " + num(p.minimum) + " .. ") +
         num(p.maximum) + " " + unit + ", got " + num(value);
}

double get_param(const DaemonConfig& c, std::string_view name) {
  return value_of(find_param(name), c);
}

void set_param(DaemonConfig& c, std::string_view name, double value) {
  const Param& p = find_param(name);
  if (const std::string why = param_range_error(p, value, c.controller.law); !why.empty())
    throw Error(std::string(p.name) + ": " + why);
  double& field = p.field(c);
  const double before = field;
  field = value;
  if (const ConstraintError e = param_constraint_error(c); !e.empty()) {
    field = before;
    throw Error(std::string(p.name) + " " + num(value) + " refused: " + e.key + ": " + e.why);
  }
}

ConstraintError overspeed_error(const LimitsConfig& l) {
  if (l.overspeed > l.velocity) return {};
  return {"limits.overspeed", "must be greater than limits.velocity (" + num(l.velocity) + " m/s), got " +
                                  num(l.overspeed) + " m/s"};
}

ConstraintError workspace_error(const LimitsConfig& l, int axis) {
  if (l.workspace_min[axis] < l.workspace_max[axis]) return {};
  return {std::string("limits.workspace_max.") + axis_name(axis),
          "must be greater than limits.workspace_min." + std::string(axis_name(axis)) + " (" +
              num(l.workspace_min[axis]) + " m), got " + num(l.workspace_max[axis]) + " m"};
}

ConstraintError jog_error(const JogConfig& j, const LimitsConfig& l) {
  if (j.max_velocity > l.velocity)
    return {"jog.max_velocity", "must not exceed limits.velocity (" + num(l.velocity * 1e3) + " mm/s), got " +
                                    num(j.max_velocity * 1e3) + " mm/s"};
  const double coast = j.max_velocity * j.keepalive;
  const double brake = j.max_velocity * j.max_velocity / (2.0 * j.acceleration);
  if (coast + brake <= j.stop_distance + kDistanceSlack) return {};
  std::ostringstream os;
  os << "a jog let go at jog.max_velocity " << j.max_velocity * 1e3 << " mm/s goes on for jog.keepalive "
     << j.keepalive << " s and stops at jog.acceleration " << j.acceleration * 1e3 << " mm/s^2: " << coast * 1e3
     << " + " << brake * 1e3 << " = " << (coast + brake) * 1e3 << " mm, more than jog.stop_distance "
     << j.stop_distance * 1e3 << " mm; lower max_velocity or keepalive, or raise acceleration or stop_distance";
  return {"jog.stop_distance", os.str()};
}

ConstraintError homing_motion_error(const AxisHomingConfig& a, const JogConfig& j, const LimitsConfig& l,
                                    int axis) {
  if (a.method == HomingMethod::absolute) return {};
  const std::string key = std::string("homing.axes.") + axis_name(axis) + ".";
  for (const auto& [name, v] : {std::pair{"search_velocity", a.search_velocity}, {"latch_velocity", a.latch_velocity}})
    if (std::abs(v) > j.max_velocity)
      return {key + name, "must not be faster than jog.max_velocity (" + num(j.max_velocity * 1e3) +
                              " mm/s): the actuator's zero is unknown while it homes; got " + num(v * 1e3) + " mm/s"};
  if (a.acceleration > l.acceleration)
    return {key + "acceleration",
            "must not exceed limits.acceleration (" + num(l.acceleration) + " m/s^2), got " + num(a.acceleration)};
  return {};
}

ConstraintError param_constraint_error(const DaemonConfig& c) {
  if (auto e = overspeed_error(c.limits); !e.empty()) return e;
  for (int i = 0; i < 3; ++i)
    if (auto e = workspace_error(c.limits, i); !e.empty()) return e;
  if (auto e = jog_error(c.jog, c.limits); !e.empty()) return e;
  for (int i = 0; i < 3; ++i)
    if (auto e = homing_motion_error(c.homing.axes[static_cast<std::size_t>(i)], c.jog, c.limits, i); !e.empty())
      return e;
  return {};
}

cpm_msgs::params_t params_message(const DaemonConfig& c) {
  cpm_msgs::params_t m{};
  m.utime = 0;
  m.count = static_cast<std::int16_t>(kParams.size());
  for (const auto& p : kParams) {
    m.name.emplace_back(p.name);
    m.value.push_back(value_of(p, c));
    m.unit.emplace_back(param_unit(p, c.controller.law));
    m.minimum.push_back(p.minimum);
    m.maximum.push_back(p.maximum);
    m.while_moving.push_back(p.while_moving);
    m.description.emplace_back(p.description);
  }
  return m;
}

}  // namespace cpm::daemon

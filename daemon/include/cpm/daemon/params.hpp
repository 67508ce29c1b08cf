// SPDX-License-Identifier: Apache-2.0
// The parameters an engineer may read and change while cpmd runs (`cpm get`,
// `cpm set`, control_command_t.CMD_SET_PARAM, params_t): the limits, the jog
// and the controller's gains, each with its unit, its range, whether it may
// change while the platform moves, and one line of description.
//
// The range is the one place these keys' ranges live: the YAML loader
// (config.cpp) checks the same keys against this table, so a value `cpm set`
// refuses is refused in the file too, and the other way round. Values are SI
// (m, m/s, m/s^2, N, s); the controller's gains are in the units of the law
// in force (param_unit()).
//
// Not real-time: find_param() and set_param() build their messages with
// std::string; the daemon calls them from its command thread. The gains'
// stability is not checked here (the daemon runs ctl's gain check after
// set_param()): this table checks ranges and the constraints between limits.
#pragma once

#include <span>
#include <string>
#include <string_view>

#include <cpm_msgs/params_t.hpp>

#include "cpm/control/controller.hpp"
#include "cpm/daemon/config.hpp"

namespace cpm::daemon {

struct Param {
  const char* name;         // "limits.velocity", "controller.kp.z", ...
  const char* unit;         // SI unit; for the gains: the PD laws' unit (N/m, N s/m)
  const char* unit_computed_torque;  // the gains' unit under computed torque (1/s^2, 1/s); nullptr: `unit` always
  double minimum, maximum;  // the range a value must lie in
  bool minimum_excluded;    // true: the value must be > minimum (a limit of 0 means nothing)
  // May change while the platform moves (moving, stopping, homing, jogging):
  // true only where no motion already queued was checked against the value
  // and the force applied does not change (fault thresholds and timers).
  bool while_moving;
  const char* description;
  // The value in a configuration (the const overload reads through it).
  double& (*field)(DaemonConfig&);
};

// Every parameter, in the order params_t lists them.
std::span<const Param> param_table() noexcept;

// The parameter called `name`; an unknown name throws Error naming it and the
// close names ("did you mean limits.velocity?"), or the sections when none is close.
const Param& find_param(std::string_view name);

// The unit of `p` under `law` ("N/m" or "1/s^2" for controller.kp.*).
const char* param_unit(const Param& p, ctl::ControlLaw law) noexcept;

// "" when `value` lies in p's range; else why not, with the range and the
// value, e.g. "must be > 0 and <= 5 m/s, got 7". `law` picks the gains' unit.
std::string param_range_error(const Param& p, double value,
                              ctl::ControlLaw law = ctl::ControlLaw::computed_torque);

double get_param(const DaemonConfig& c, std::string_view name);

// Sets `name` to `value` (SI units), or throws Error saying what and why (out
// of range, or a constraint between parameters it would break: overspeed
// above velocity, workspace_min below workspace_max, the jog's stop distance,
// homing speeds within the jog's) and leaves `c` as it was.
void set_param(DaemonConfig& c, std::string_view name, double value);

// A constraint between parameters that a configuration breaks: the key it
// is about (a parameter's name, or a config path such as
// "homing.axes.x.search_velocity") and why, with the figures. Empty when met.
struct ConstraintError {
  std::string key;
  std::string why;
  [[nodiscard]] bool empty() const noexcept { return why.empty(); }
};

// The first constraint between parameters that `c` breaks: what set_param()
// checks after a change. The loader checks the same functions (below) one by
// one, where it can point at the line.
ConstraintError param_constraint_error(const DaemonConfig& c);

// The constraints, one function each; the loader and param_constraint_error()
// share them.
ConstraintError overspeed_error(const LimitsConfig& l);           // limits.overspeed > limits.velocity
ConstraintError workspace_error(const LimitsConfig& l, int axis);  // workspace_min < workspace_max
// The jog: max_velocity within limits.velocity, and the distance a let-go jog
// goes before it is at rest (max_velocity * keepalive + max_velocity^2 /
// (2 acceleration); the figures in mm/s, s, mm) within stop_distance.
ConstraintError jog_error(const JogConfig& j, const LimitsConfig& l);
// Actuator `axis`'s homing moves: no faster than a jog (jog.max_velocity: the
// actuator's zero is unknown while it homes) and accelerating no harder than
// limits.acceleration. Absolute actuators have none.
ConstraintError homing_motion_error(const AxisHomingConfig& a, const JogConfig& j, const LimitsConfig& l,
                                    int axis);

// Every parameter with its value, unit (for the law in force), range,
// while_moving and description. utime is left 0: the publisher stamps it.
cpm_msgs::params_t params_message(const DaemonConfig& c);

}  // namespace cpm::daemon

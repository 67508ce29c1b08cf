// SPDX-License-Identifier: Apache-2.0
// The operator's console, tuning: `cpm get` (cpmd's parameters: limits,
// gains, jog and homing settings, from params_t) and `cpm set` (one of them,
// CMD_SET_PARAM; cpmd checks the range and the mode and says why it refuses).
#include <cstdio>

#include "cmd_console_common.hpp"
#include "console.hpp"

namespace cpm::cli::client {
namespace {

struct GetOptions {
  std::vector<std::string> names;
  bool json = false;
  Connection connection;
};

int get(const GetOptions& o) {
  const auto l = lcm_options(o.connection);
  daemon::Client c(l);
  const auto p = received(c.params(3.0), "parameters", 3.0, l, l.params_channel);
  const auto which = console::select_params(p, o.names);
  if (o.json) {
    std::printf("%s\n", json_text(console::params_json(p, which), -1).c_str());
    return 0;
  }
  for (const auto& line : console::params_table(p, which, !o.names.empty())) std::printf("%s\n", line.c_str());
  return 0;
}

struct SetOptions {
  std::string name, value;
  Connection connection;
  Operator op;
};

int set(const SetOptions& o) {
  const console::Quantity q = console::parse_quantity(o.value);  // a bad VALUE is refused before anything is sent
  const auto l = lcm_options(o.connection);
  daemon::Client c(l, operator_key(o.op));
  std::string unit;
  if (!q.unit.empty()) {
    // A unit given: it must be the parameter's, which params_t says.
    const auto p = c.params(3.0);
    if (!p)
      throw Error("cannot check the unit of " + o.value + ": no parameters from cpmd within 3 s (channel " +
                  l.params_channel + "); give the value in SI");
    for (std::size_t i = 0; i < p->name.size() && i < p->unit.size(); ++i)
      if (p->name[i] == o.name) unit = p->unit[i];
  }
  const double v = console::value_for(q, o.name, unit);
  const std::string what = "set " + o.name;
  return report(what.c_str(), c.set_param(o.name, v));
}

const Command r1{"get", "print cpmd's parameters (limits, gains, jog, homing): value, unit, range, whether it may change while moving",
                 [](CLI::App& app) -> Run {
                   auto o = std::make_shared<GetOptions>();
                   app.add_option("PARAM", o->names, "the parameters to print (e.g. limits.following_error); none: all")
                       ->type_name("PARAM");
                   app.add_flag("--json", o->json,
                                "one line of JSON: {NAME: {value, unit, minimum, maximum, while_moving, description}} "
                                "in SI units");
                   add_connection(app, o->connection);
                   return [o] { return get(*o); };
                 }};
const Command r2{"set",
                 "change a parameter of a running cpmd (exit 1 with cpmd's sentence when it refuses)",
                 [](CLI::App& app) -> Run {
                   auto o = std::make_shared<SetOptions>();
                   app.add_option("PARAM", o->name, "the parameter (cpm get lists them, e.g. limits.following_error)")
                       ->type_name("PARAM")
                       ->required();
                   app.add_option("VALUE", o->value,
                                  "the new value in SI units (m, m/s, N, ...), or with a unit suffix converted to "
                                  "SI: mm, um, mm/s, mm/s^2 (e.g. 0.006, 6mm, 6000um, 20mm/s); the suffix must fit "
                                  "the parameter's unit")
                       ->type_name("VALUE")
                       ->required();
                   add_connection(app, o->connection);
                   add_operator(app, o->op);
                   return [o] { return set(*o); };
                 }};

}  // namespace
}  // namespace cpm::cli::client

// SPDX-License-Identifier: Apache-2.0
// The operator's console, moving: `cpm home` (CMD_HOME, then the phases
// until every actuator asked is homed) and `cpm jog` (CMD_JOG from the
// keyboard, or for a script a velocity for a time).
#include <chrono>
#include <cmath>
#include <cstdio>

#include "cmd_client_common.hpp"
#include "console.hpp"
#include "console_screen.hpp"
#include "cpm/daemon/fault_report.hpp"

namespace cpm::cli::client {
namespace {

using cpm_msgs::control_command_t;
using cpm_msgs::state_t;
using Clock = std::chrono::steady_clock;

double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

std::string actuators(std::uint8_t mask) {
  std::string r;
  for (int i = 0; i < 3; ++i)
    if (mask & (1u << i)) r += (r.empty() ? "" : " ") + std::to_string(i + 1);
  return r;
}

std::uint8_t homed_mask(const state_t& s) {
  return static_cast<std::uint8_t>((s.homed[0] ? 1 : 0) | (s.homed[1] ? 2 : 0) | (s.homed[2] ? 4 : 0));
}

// ---- cpm home

struct HomeOptions {
  std::vector<std::string> axes;
  double timeout = 300;
  Connection connection;
  Operator op;
};

int home(const HomeOptions& o) {
  const std::uint8_t mask = console::parse_home_axes(o.axes);
  const std::uint8_t asked = mask ? mask : 7;
  const auto l = lcm_options(o.connection);
  daemon::Client c(l, operator_key(o.op));
  console::catch_interrupts();
  if (report("home", c.home(mask)) != 0) return 1;
  const auto t0 = Clock::now();
  bool started = false;
  int axis = -2, phase = -2;
  std::optional<std::uint8_t> homed0;
  std::optional<state_t> s;
  while (since(t0) < o.timeout) {
    if (console::interrupted()) {
      std::printf("home: interrupted: stopping the homing\n");
      report("stop", c.control(control_command_t::CMD_STOP));
      return 1;
    }
    s = c.state(1.0);
    if (!s) throw Error("no state from cpmd for 1 s");
    const std::uint8_t homed = homed_mask(*s);
    if (!homed0) homed0 = homed;
    for (int i = 0; i < 3; ++i)
      if ((homed & ~*homed0 & (1u << i)) != 0) std::printf("home: actuator %d homed\n", i + 1);
    homed0 = static_cast<std::uint8_t>(*homed0 | homed);
    if (s->mode == state_t::MODE_HOMING) {
      started = true;
      if (s->homing_axis != axis || s->homing_phase != phase) {
        axis = s->homing_axis;
        phase = s->homing_phase;
        if (axis >= 0 && axis <= 2)
          std::printf("home: actuator %d: %s\n", axis + 1, console::homing_phase_name(s->homing_phase));
        std::fflush(stdout);
      }
    }
    if (s->mode == state_t::MODE_FAULT) break;
    if (started && s->mode != state_t::MODE_HOMING) break;
    // Never seen homing after a second: it ended at once (absolute encoders) or did not start.
    if (!started && since(t0) > 1.0) break;
  }
  if (s && s->mode != state_t::MODE_FAULT && (homed_mask(*s) & asked) == asked) {
    std::printf("home: actuators %s homed; mode %s\n", actuators(asked).c_str(), daemon::mode_text(s->mode));
    return 0;
  }
  const std::uint8_t missing = s ? static_cast<std::uint8_t>(asked & ~homed_mask(*s)) : asked;
  std::printf("home: actuator%s %s not homed", missing & (missing - 1) ? "s" : "", actuators(missing).c_str());
  if (s && s->faults) std::printf(": %s\n", daemon::fault_report(*s).c_str());
  else if (since(t0) >= o.timeout) std::printf(": not done after %.0f s (--timeout)\n", o.timeout);
  else std::printf(" (mode %s)\n", s ? daemon::mode_text(s->mode) : "unknown");
  return 1;
}

// ---- cpm jog

struct JogOptions {
  std::string axis;  // "": none given
  std::optional<std::string> velocity;
  std::string frame = "actuator";
  std::optional<double> duration;
  Connection connection;
  Operator op;
};

constexpr double kJogPeriod = 0.05;  // 20 Hz: well inside jog.keepalive

int jog_for(const JogOptions& o) {
  double v[3] = {0, 0, 0};
  const std::string& text = *o.velocity;
  if (text.find(',') != std::string::npos) {
    if (!o.axis.empty()) throw UsageError("--axis goes with one velocity; --velocity VX,VY,VZ gives all three");
    const Vec3 p = cli::parse_point("--velocity", text);
    for (int i = 0; i < 3; ++i) v[i] = p[i];
  } else {
    if (o.axis.empty()) throw UsageError("--velocity V needs --axis x|y|z|1|2|3 (or give VX,VY,VZ)");
    double x = 0;
    if (!CLI::detail::lexical_cast(text, x) || !std::isfinite(x))
      throw UsageError("--velocity: '" + text + "' is not a finite number");
    const std::uint8_t bit = console::parse_home_axes({o.axis});  // x|1 -> 1, y|2 -> 2, z|3 -> 4
    v[bit == 1 ? 0 : bit == 2 ? 1 : 2] = x;
  }
  const std::int8_t frame = o.frame == "machine" ? control_command_t::JOG_MACHINE : control_command_t::JOG_ACTUATOR;
  const auto l = lcm_options(o.connection);
  daemon::Client c(l, operator_key(o.op));
  console::catch_interrupts();
  // Where the jog starts, in its frame (actuator displacements or the platform's position).
  const bool machine = frame == control_command_t::JOG_MACHINE;
  auto where = [machine](const state_t& s) {
    const double* p = machine ? s.position : s.d;
    return std::array<double, 3>{p[0], p[1], p[2]};
  };
  const auto s0 = c.state(1.0);
  const auto ack = c.wait_ack(c.jog(frame, v), 2.0);
  if (report("jog", ack) != 0) return 1;
  const auto t0 = Clock::now();
  int sent = 1;
  while (!console::interrupted()) {
    c.handle(std::max(0.0, sent * kJogPeriod - since(t0)));
    if (since(t0) >= *o.duration) break;
    c.jog(frame, v);
    ++sent;
    if (const auto& a = c.last_jog_ack(); a && !a->accepted) {
      std::printf("jog: REJECTED: %s (mode %s)\n", a->message.c_str(), daemon::mode_text(a->mode));
      return 1;
    }
  }
  if (console::interrupted()) {
    const double zero[3] = {0, 0, 0};
    c.jog(frame, zero);
    c.handle(0.05);
    std::printf("jog: interrupted after %d commands: stopped\n", sent);
    return 1;
  }
  // A zero jog ends it now: without it the platform would coast on until
  // cpmd's deadman (jog.keepalive) and go further than V * S.
  const double seconds = since(t0);
  const auto s_end = c.latest_state();
  const double zero[3] = {0, 0, 0};
  c.jog(frame, zero);
  std::printf("jog: %d commands over %.2f s (20 a second), then a stop\n", sent, seconds);
  // Where it came to rest.
  std::optional<state_t> s;
  for (const auto t1 = Clock::now(); since(t1) < 2.0;)
    if ((s = c.state(0.5)) && s->mode != state_t::MODE_JOGGING) break;
  if (s) {
    std::printf("%s\n", state_line(*s).c_str());
    if (s0 && s_end)
      std::printf("jog: %s\n", console::jog_distance_text(where(*s0), where(*s_end), where(*s), seconds, machine).c_str());
  }
  return 0;
}

int jog_keys(const JogOptions& o) {
  const auto l = lcm_options(o.connection);
  daemon::Client c(l, operator_key(o.op));
  console::JogPad pad;
  if (const auto p = c.params(1.5))
    for (std::size_t i = 0; i < p->name.size() && i < p->value.size(); ++i)
      if (p->name[i] == "jog.max_velocity") pad.set_max_speed(p->value[i]);
  auto screen = console::Screen::open();
  if (!screen) throw UsageError("cpm jog needs a terminal; for a script give --velocity and --for");
  const auto t0 = Clock::now();
  std::string note;
  std::array<double, 3> last{0, 0, 0};
  double last_sent = -1;
  std::optional<std::array<double, 3>> held;  // what a held key sends
  while (!console::interrupted() && !pad.quit()) {
    for (int k; (k = screen->key(0)) >= 0;) {
      const std::string m = pad.press(console::Screen::jog_key(k), since(t0));
      if (!m.empty()) note = m;
      else if (console::Screen::jog_key(k) != console::JogPad::Key::none) note.clear();
    }
    const double now = since(t0);
    const auto cmd = pad.command(now);
    // A new velocity at once, the same again every period while held.
    if (cmd && (*cmd != last || now - last_sent >= kJogPeriod)) {
      c.jog(pad.frame(), cmd->data());
      last = *cmd;
      last_sent = now;
    }
    held = pad.holding(now) ? cmd : std::nullopt;
    screen->draw(console::render_jog(c.latest_state(), pad, c.last_jog_ack(), held, note, screen->width(),
                                     screen->height()));
    c.handle(0.02);
  }
  // On the way out: the deadman would stop it, a zero jog stops it now.
  if (last != std::array<double, 3>{0, 0, 0}) {
    const double zero[3] = {0, 0, 0};
    c.jog(pad.frame(), zero);
    c.handle(0.05);
  }
  return 0;
}

int jog(const JogOptions& o) {
  if (o.velocity || o.duration) {
    if (!o.velocity) throw UsageError("--for needs --velocity");
    if (!o.duration) throw UsageError("--velocity needs --for S (how long to jog)");
    return jog_for(o);
  }
  if (!o.axis.empty()) throw UsageError("--axis goes with --velocity and --for");
  return jog_keys(o);
}

const Command r1{"home", "home actuators of a running cpmd (x|y|z|1|2|3 ...; none: all, in the configured order)",
                 [](CLI::App& app) -> Run {
                   auto o = std::make_shared<HomeOptions>();
                   app.add_option("ACTUATOR", o->axes, "the actuators to home: x, y, z or 1, 2, 3; none: every actuator")
                       ->type_name("ACTUATOR");
                   add_number(app, "--timeout", o->timeout, "S", "give up waiting after S seconds");
                   add_connection(app, o->connection);
                   add_operator(app, o->op);
                   return [o] { return home(*o); };
                 }};
const Command r2{"jog",
                 "jog a running cpmd's actuators or platform from the keyboard (arrows, PgUp/PgDn; or --velocity "
                 "--for for scripts)",
                 [](CLI::App& app) -> Run {
                   auto o = std::make_shared<JogOptions>();
                   add_choice(app, "--axis", o->axis, {"x", "y", "z", "1", "2", "3"},
                              "for a script: the one actuator (frame actuator) or platform axis (frame machine) to "
                              "jog at --velocity V")
                       ->default_str("none");
                   add_choice(app, "--frame", o->frame, {"actuator", "machine"},
                              "for a script: actuator (velocities of d1, d2, d3; before homing too) or machine "
                              "(the platform's velocity, z down; needs every actuator homed)");
                   app.add_option("--velocity", o->velocity,
                                  "for a script: V in m/s with --axis, or VX,VY,VZ in m/s (e.g. 0.01 or 0.01,0,0)")
                       ->type_name("V|VX,VY,VZ");
                   add_number(app, "--for", o->duration, "S",
                              "for a script: send the jog 20 times a second for S seconds, then a stop; the distance "
                              "is printed split into the S seconds and the stop")
                       ->default_str("none: jog from the keyboard");
                   add_connection(app, o->connection);
                   add_operator(app, o->op);
                   app.footer(
                       "Keys, in a terminal: Left/Right x, Down/Up y, PgUp z- (up), PgDn z+ (down: z is down in\n"
                       "the machine frame); 1 2 3 select an actuator (actuator frame: only it moves, by its own\n"
                       "axis's keys; before homing too); c the machine frame (Cartesian; cpmd refuses it until\n"
                       "every actuator is homed); + - the speed (1 2 5 10 20 50 mm/s, capped by cpmd's\n"
                       "jog.max_velocity); space stop; q quit. The jog is sent 20 times a second while a key's\n"
                       "auto-repeat keeps coming. Terminals send no key-up: when the repeat stops, nothing more is\n"
                       "sent and cpmd's deadman (jog.keepalive) stops the platform within jog.stop_distance.\n\n" +
                       (app.get_parent() ? app.get_parent()->get_footer() : std::string()));
                   return [o] { return jog(*o); };
                 }};

}  // namespace
}  // namespace cpm::cli::client

// SPDX-License-Identifier: Apache-2.0
// Client subcommands for the state machine: status, enable, disable, stop,
// reset, controller, load-model, stats. They talk to a running cpmd over LCM.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <sstream>
#include <thread>

#include "cmd_client_common.hpp"
#include "console.hpp"
#include "cpm/daemon/fault_report.hpp"
#include "cpm/daemon/loop.hpp"

namespace cpm::cli::client {

using cpm_msgs::control_command_t;
using cpm_msgs::state_t;

Vec3 parse_point(const std::string& what, const std::string& text) {
  return cli::parse_point(what, text, /*allow_non_finite=*/true);  // the daemon must refuse NaN
}

std::string state_line(const state_t& s) {
  char b[256];
  std::snprintf(b, sizeof b, "%-9s p = (%8.3f, %8.3f, %8.3f) mm  err %8.1f um  F = (%6.1f, %6.1f, %6.1f) N%s%s",
                daemon::mode_text(s.mode), s.position[0] * 1e3, s.position[1] * 1e3, s.position[2] * 1e3,
                s.position_error_norm * 1e6, s.force[0], s.force[1], s.force[2], s.faults ? "  FAULT " : "",
                s.faults ? daemon::fault_text(s.faults).c_str() : "");
  return b;
}

state_t wait_segment(daemon::Client& c, std::int64_t id, double timeout_s, bool progress) {
  const auto t_end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  state_t last{};
  bool seen_playing = false;
  auto last_print = std::chrono::steady_clock::now();
  while (std::chrono::steady_clock::now() < t_end) {
    auto s = c.state(1.0);
    if (!s) throw Error("no state from cpmd for 1 s");
    last = *s;
    if (s->segment_id == id) seen_playing = true;
    if (progress && std::chrono::steady_clock::now() - last_print > std::chrono::milliseconds(100)) {
      last_print = std::chrono::steady_clock::now();
      const double f = s->segment_duration > 0 ? std::min(1.0, s->segment_elapsed / s->segment_duration) : 1.0;
      const int w = 30, fill = static_cast<int>(f * w);
      std::fprintf(stderr, "\r[%s%s] %5.1f%% %s", std::string(fill, '#').c_str(), std::string(w - fill, '.').c_str(),
                   100 * f, state_line(*s).c_str());
    }
    if (s->last_segment_id == id || s->mode == state_t::MODE_FAULT || s->mode == state_t::MODE_DISABLED ||
        (seen_playing && s->segment_id != id && s->mode == state_t::MODE_HOLDING))
      break;
  }
  if (progress) std::fprintf(stderr, "\n");
  return last;
}

namespace {

Json json_state(const state_t& s) {
  auto arr = [](const double* v) { return Json::array({v[0], v[1], v[2]}); };
  Json faults = Json::array();
  std::istringstream is(daemon::fault_text(s.faults));
  for (std::string part; std::getline(is, part, ',');) faults.push_back(part);
  const auto* why = reinterpret_cast<const char*>(s.fault_text);
  return {{"mode", daemon::mode_text(s.mode)},
          {"t", s.t},
          {"cycle", s.cycle},
          {"position", arr(s.position)},
          {"velocity", arr(s.velocity)},
          {"position_ref", arr(s.position_ref)},
          {"position_error", s.position_error_norm},
          {"d", arr(s.d)},
          {"force", arr(s.force)},
          {"faults", faults},
          {"fault_text", std::string(why, strnlen(why, sizeof s.fault_text))},
          {"first_fault", s.first_fault ? daemon::fault_bit_name(static_cast<std::uint32_t>(s.first_fault)) : ""},
          {"fault_report", daemon::fault_report(s)},
          {"controller", ctl::law_name(static_cast<ctl::ControlLaw>(s.controller))},
          {"segment_id", s.segment_id},
          {"queue_depth", s.queue_depth},
          {"last_segment", {{"id", s.last_segment_id}, {"rmse", s.last_segment_rmse}, {"max", s.last_segment_max}}},
          {"loop",
           {{"cycles", s.cycles},
            {"overruns", s.overruns},
            {"skipped", s.skipped},
            {"max_latency_ns", s.max_latency_ns},
            {"max_cycle_ns", s.max_cycle_ns}}}};
}

struct StateOptions {
  bool json = false;
  Connection connection;
};

int status(const StateOptions& o) {
  const bool json = o.json;
  const auto l = lcm_options(o.connection);
  daemon::Client c(l);
  auto s = c.state(2.0);
  if (!s && c.verifying() && c.verifier()->refused_total() > 0)
    throw Error("no verified state from cpmd within 2 s: " + std::to_string(c.verifier()->refused_total()) +
                " state messages refused (said above); an unsigned cpmd's state cannot be verified");
  if (!s) throw Error("no state from cpmd within 2 s (is it running? LCM " + l.url + ", channel " + l.state_channel + ")");
  if (json) {
    std::printf("%s\n", json_text(json_state(*s), -1).c_str());
    return 0;
  }
  const std::string homed = console::not_homed_mark(*s);
  std::printf("%s%s%s\n", state_line(*s).c_str(), homed.empty() ? "" : "\n", homed.c_str());
  const console::Lines more = console::status_lines(*s);
  std::printf("%s\n", more[0].c_str());
  if (s->faults) std::printf("first fault: %s\n", daemon::fault_report(*s).c_str());
  if (c.verifying())
    std::printf("state signed by cpmd and verified (boot id %lld, counter %lld)\n", static_cast<long long>(s->boot_id),
                static_cast<long long>(s->sign_counter));
  else
    std::printf("state NOT VERIFIED: no public key of cpmd (--daemon-key)\n");
  for (std::size_t i = 1; i < more.size(); ++i) std::printf("%s\n", more[i].c_str());
  return 0;
}

struct CommandOptions {
  bool no_wait = false;
  Connection connection;
  Operator op;
  std::string law, model;
  std::optional<double> kp, kd;
};

int simple(const CommandOptions& o, std::int8_t cmd, const char* what) {
  const bool no_wait = o.no_wait;
  const auto l = lcm_options(o.connection);
  auto key = cmd == control_command_t::CMD_STOP ? operator_key_if_usable(o.op) : operator_key(o.op);
  daemon::Client c(l, key);
  const auto ack = c.control(cmd);
  const int rc = report(what, ack);
  if (rc == 0 && !no_wait && (cmd == control_command_t::CMD_ENABLE || cmd == control_command_t::CMD_STOP)) {
    // Wait for the drives to be enabled / the stop to finish.
    for (int i = 0; i < 300; ++i) {
      auto s = c.state(1.0);
      if (!s) break;
      if (s->mode == state_t::MODE_HOLDING || s->mode == state_t::MODE_FAULT || s->mode == state_t::MODE_DISABLED) {
        std::printf("%s\n", state_line(*s).c_str());
        return s->mode == state_t::MODE_HOLDING ? 0 : 1;
      }
    }
  }
  return rc;
}

int controller(const CommandOptions& o) {
  control_command_t cmd{};
  cmd.command = control_command_t::CMD_SELECT_CONTROLLER;
  const double kp = o.kp.value_or(NAN), kd = o.kd.value_or(NAN);
  const auto l = lcm_options(o.connection);
  auto key = operator_key(o.op);
  const auto law = ctl::law_from_name(o.law);
  cmd.law = static_cast<std::int8_t>(*law);
  const auto g = ctl::table3_gains(*law);
  cmd.use_table3_gains = std::isnan(kp) && std::isnan(kd);
  for (int i = 0; i < 3; ++i) {
    cmd.kp[i] = std::isnan(kp) ? g.kp[i] : kp;
    cmd.kd[i] = std::isnan(kd) ? g.kd[i] : kd;
  }
  daemon::Client c(l, key);
  return report("controller", c.control(cmd));
}

int load_model(const CommandOptions& o) {
  const auto l = lcm_options(o.connection);
  auto key = operator_key(o.op);
  control_command_t cmd{};
  cmd.command = control_command_t::CMD_LOAD_MODEL;
  cmd.model_path = o.model;
  daemon::Client c(l, key);
  return report("load-model", c.control(cmd, 10.0));
}

int stats(const StateOptions& o) {
  const bool json = o.json;
  const auto l = lcm_options(o.connection);
  daemon::Client c(l);
  auto s = c.stats(3.0);
  if (!s) throw Error("no statistics from cpmd within 3 s (channel " + l.stats_channel + ")");
  static const char* names[daemon::kSeries] = {"wake-up latency", "read backend", "estimate", "trajectory",
                                               "inverse kinematics", "controller", "safety", "write backend",
                                               "publish", "whole cycle"};
  auto pct = [&](int k, double q) { return console::percentile_us(*s, k, q); };
  if (json) {
    // Microseconds, rounded as on screen: 1 ns for the mean and maximum, the
    // histogram's 1 us bins for the percentiles.
    auto us = [](double v, double per_us) { return std::round(v * per_us) / per_us; };
    Json series = Json::object();
    for (int k = 0; k < daemon::kSeries; ++k)
      series[names[k]] = {{"mean_us", us(s->count[k] ? s->sum_ns[k] / s->count[k] * 1e-3 : 0.0, 1e3)},
                          {"p99_us", us(pct(k, 0.99), 1.0)},
                          {"p999_us", us(pct(k, 0.999), 1.0)},
                          {"max_us", us(s->max_ns[k] * 1e-3, 1e3)}};
    const Json j{{"rate_hz", s->rate_hz},
                 {"cycles", s->cycles},
                 {"overruns", s->overruns},
                 {"skipped", s->skipped},
                 {"realtime", static_cast<bool>(s->realtime)},
                 {"series", series}};
    std::printf("%s\n", json_text(j, -1).c_str());
    return 0;
  }
  std::printf("loop %.0f Hz, %s, memory %slocked: %lld cycles (%.1f s), %lld overruns, %lld slots skipped\n",
              s->rate_hz, s->realtime ? "SCHED_FIFO" : "normal scheduling", s->memory_locked ? "" : "NOT ",
              static_cast<long long>(s->cycles), s->cycles / s->rate_hz, static_cast<long long>(s->overruns),
              static_cast<long long>(s->skipped));
  std::printf("%-20s %10s %10s %10s %10s %10s   (us; percentiles to the histogram's 1 us bins)\n", "", "min", "mean",
              "p99", "p99.9", "max");
  for (int k = 0; k < daemon::kSeries; ++k)
    if (s->count[k] == 0)
      std::printf("%-20s %10s %10s %10s %10s %10s\n", names[k], "-", "-", "-", "-", "none yet");
    else if (s->max_ns[k] >= INT32_MAX)  // saturated: the true maximum is unknown
      std::printf("%-20s %10.2f %10.2f %10.0f %10.0f %10s\n", names[k], s->min_ns[k] * 1e-3,
                  s->sum_ns[k] / s->count[k] * 1e-3, pct(k, 0.99), pct(k, 0.999), "> 2.1 s");
    else
      std::printf("%-20s %10.2f %10.2f %10.0f %10.0f %10.2f\n", names[k], s->min_ns[k] * 1e-3,
                  s->sum_ns[k] / s->count[k] * 1e-3, pct(k, 0.99), pct(k, 0.999), s->max_ns[k] * 1e-3);
  if (auto sec = c.security(1.5))
    std::printf("security: %d operators; refused %lld without an operator, %lld with a wrong MAC, %lld beyond the "
                "role, %lld replayed, %lld not from the holder; %lld undecodable; %lld stops from anyone\n",
                sec->operators, static_cast<long long>(sec->refused_no_operator),
                static_cast<long long>(sec->refused_bad_mac), static_cast<long long>(sec->refused_role),
                static_cast<long long>(sec->refused_replay), static_cast<long long>(sec->refused_not_holder),
                static_cast<long long>(sec->undecodable), static_cast<long long>(sec->stops_from_anyone));
  return 0;
}

int keygen(const std::string& file) {
  daemon::write_key_file(file, daemon::generate_key());
  std::printf("%s: a new operator key (32 random bytes, hex, mode 0600). cpmd needs the same key as\n"
              "operators.d/NAME.key (owned by cpmd's user, mode 0600) and NAME's role in operators.d/roles.yaml\n"
              "(docs/security.md).\n",
              file.c_str());
  return 0;
}

Setup state_command(int (*run)(const StateOptions&), const char* json_help) {
  return [run, json_help](CLI::App& app) -> Run {
    auto o = std::make_shared<StateOptions>();
    app.add_flag("--json", o->json, json_help);
    add_connection(app, o->connection);
    return [o, run] { return run(*o); };
  };
}

// A command to cpmd; `wait`: --no-wait is offered.
Setup control_command(std::int8_t cmd, const char* what, bool wait) {
  return [cmd, what, wait](CLI::App& app) -> Run {
    auto o = std::make_shared<CommandOptions>();
    if (wait) app.add_flag("--no-wait", o->no_wait, "return once cpmd accepted, without waiting for the mode to settle");
    add_connection(app, o->connection);
    add_operator(app, o->op);
    return [o, cmd, what] { return simple(*o, cmd, what); };
  };
}

const Command r1{"status", "print the state of a running cpmd (--json for machines)",
                 state_command(status, "one line of JSON (SI units: m, m/s, N, s) instead of text")};
const Command r2{"enable", "enable the drives (disabled -> enabling -> holding)",
                 control_command(control_command_t::CMD_ENABLE, "enable", true)};
const Command r3{"disable", "disable the drives (a moving machine stops first)",
                 control_command(control_command_t::CMD_DISABLE, "disable", false)};
const Command r4{"stop", "stop the motion and clear the trajectory queue (any operator, or none)",
                 control_command(control_command_t::CMD_STOP, "stop", true)};
const Command r5{"reset", "reset a latched fault (the setpoint resyncs to the measured position)",
                 control_command(control_command_t::CMD_RESET, "reset", false)};
const Command r6{"controller", "select the control law and gains of a running cpmd", [](CLI::App& app) -> Run {
                   auto o = std::make_shared<CommandOptions>();
                   add_choice(app, "LAW", o->law, law_names(), "the control law")->required();
                   add_number(app, "--kp", o->kp, "K", "proportional gain on every axis: N/m for the PD laws, 1/s^2 for computed_torque")
                       ->default_str("Table 3's gain of the law");
                   add_number(app, "--kd", o->kd, "K", "derivative gain on every axis: N s/m for the PD laws, 1/s for computed_torque")
                       ->default_str("Table 3's gain of the law");
                   add_connection(app, o->connection);
                   add_operator(app, o->op);
                   return [o] { return controller(*o); };
                 }};
const Command r7{"load-model", "load a model file into a running cpmd (when disabled)", [](CLI::App& app) -> Run {
                   auto o = std::make_shared<CommandOptions>();
                   app.add_option("MODEL", o->model,
                                  "the model file's path in cpmd's model directory (security.model_dir), or builtin:elkady")
                       ->type_name("MODEL.yaml")
                       ->required();
                   add_connection(app, o->connection);
                   add_operator(app, o->op);
                   return [o] { return load_model(*o); };
                 }};
const Command r9{"keygen", "make a new operator key file (32 random bytes, hex, mode 0600; never overwrites)",
                 [](CLI::App& app) -> Run {
                   auto file = std::make_shared<std::string>();
                   app.add_option("FILE", *file, "the key file to create (e.g. ~/.config/cpm/operator.key)")
                       ->type_name("FILE")
                       ->required();
                   return [file] { return keygen(*file); };
                 }};
const Command r10{"daemon-keygen",
                  "make cpmd's signing key (as keygen) and write its public half, which clients verify state with",
                  [](CLI::App& app) -> Run {
                    auto files = std::make_shared<std::pair<std::string, std::string>>();
                    app.add_option("KEY", files->first, "cpmd's key file to create (security.signing_key; mode 0600)")
                        ->type_name("FILE")
                        ->required();
                    app.add_option("PUBLIC", files->second, "its public half (e.g. ~/.config/cpm/cpmd.pub)")
                        ->type_name("FILE")
                        ->required();
                    return [files] {
                      const daemon::Key k = daemon::generate_key();
                      daemon::write_key_file(files->first, k);
                      daemon::write_public_key_file(files->second, daemon::public_key_of(k));
                      std::printf("%s: cpmd's signing key (security.signing_key in cpmd.yaml); %s: its public half, "
                                  "for every client (--daemon-key, or ~/.config/cpm/cpmd.pub)\n",
                                  files->first.c_str(), files->second.c_str());
                      return 0;
                    };
                  }};
const Command r8{"stats", "print cpmd's loop timing: wake-up latency and per-phase times",
                 state_command(stats, "one line of JSON (times in µs) instead of the table")};

}  // namespace
}  // namespace cpm::cli::client

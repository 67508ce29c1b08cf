// SPDX-License-Identifier: Apache-2.0
// cpm run FILE.ngc: a G-code program on the machine (docs/path.md). The
// whole program is read, checked against the workspace and the limits and
// planned here first (path::prepare_program), so that a bad program is
// refused with its lines and columns before anything is sent; --dry-run
// stops there and prints the plan's figures. Otherwise the program's
// segments go to cpmd over LCM (path_command_t, in chunks), cpmd plans and
// checks it again and plays it, and this shows the progress until it ends.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "cmd_client_common.hpp"
#include "cpm/daemon/fault_report.hpp"
#include "cpm/daemon/path_message.hpp"
#include "cpm/path/program.hpp"

namespace cpm::cli {
namespace {

using cpm_msgs::ack_t;
using cpm_msgs::state_t;

struct Options {
  std::string file;
  bool dry_run = false, no_wait = false;
  std::optional<std::string> json, model, origin, start;
  double tolerance = 0.05, jerk = 1000.0;
  client::Connection connection;
  client::Operator op;
};

std::string read_text(const std::string& path) {
  std::ifstream f(path);
  if (!f) throw Error(path + ": cannot read");
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

// What the daemon would plan with: its config's limits and model, or the defaults.
struct Setup {
  std::optional<daemon::DaemonConfig> daemon;
  std::string config_path;  // where the limits came from ("" none)
  std::string model_path;
  std::unique_ptr<ctl::Machine> machine;
  path::MachineLimits limits;
  path::ProgramOptions program;
};

Setup setup(const Options& o) {
  Setup s;
  // cpmd's config gives the soft limits it will check: --config, else the
  // shipped one, so that what the dry run passes cpmd does not refuse.
  const std::optional<std::string> config = o.connection.config ? o.connection.config : default_daemon_config_path();
  if (config) {
    s.daemon = daemon::load_config(*config);
    s.config_path = *config;
  }
  s.model_path = o.model ? *o.model : s.daemon ? s.daemon->model_file : model_or_default(std::nullopt);
  ctl::MachineModel model = daemon::load_model(s.model_path);
  if (s.daemon) {
    // As cpmd does with its model: the configured force limit caps the model's.
    const daemon::LimitsConfig& L = s.daemon->limits;
    model.force_limit = std::min(model.force_limit, L.force);
    s.limits.velocity = L.velocity;
    s.limits.acceleration = L.acceleration;
    s.limits.force = L.force;
    s.limits.soft = path::SoftLimits{L.workspace_min, L.workspace_max};
  }
  s.machine = std::make_unique<ctl::Machine>(model);
  s.program.name = o.file;
  if (o.origin) s.program.frame.origin = parse_point("--origin", *o.origin);
  if (o.start) s.program.start = parse_point("--start", *o.start);
  s.program.tolerance = o.tolerance * 1e-3;
  s.program.soft = s.limits.soft;
  s.program.planner = path::planner_options(s.limits, *s.machine, path::PlanMode::actuator_aware, o.jerk);
  return s;
}

const char* axis_name(int i) { return i == 0 ? "x" : i == 1 ? "y" : "z"; }

int largest(const Vec3& v) {
  int i = 0;
  v.cwiseAbs().maxCoeff(&i);
  return i;
}

std::string report_text(const Setup& s, const path::PreparedProgram& p) {
  const path::PlanSummary& m = p.plan->summary();
  const path::PlannerOptions& po = s.program.planner;
  std::ostringstream o;
  char b[512];
  std::snprintf(b, sizeof b, "%s: %zu moves, %zu segments, path tolerance %.3f mm\n", s.program.name.c_str(),
                p.program.moves.size(), p.queue.segments().size(), p.queue.tolerance() * 1e3);
  o << b;
  std::snprintf(b, sizeof b,
                "plan: actuator-aware on %s; |v| and each actuator within %.0f mm/s, each actuator's force within "
                "%.1f N (%.0f %% of %.1f N kept for feedback), acceleration %.0f m/s^2, jerk %.0f m/s^3\n",
                s.model_path.c_str(), po.cartesian.velocity * 1e3,
                po.actuators.force.maxCoeff() * (1 - po.actuators.force_reserve), po.actuators.force_reserve * 100,
                po.actuators.force.maxCoeff(), po.actuators.acceleration.maxCoeff(), po.cartesian.jerk);
  o << b;
  std::snprintf(b, sizeof b, "planned time %.3f s, length %.1f mm, peak speed %.1f mm/s (%.0f mm/min), peak "
                "acceleration %.0f mm/s^2\n", m.duration, m.length * 1e3, m.peak_speed * 1e3, m.peak_speed * 6e4,
                m.peak_acceleration * 1e3);
  o << b;
  if (s.daemon) {
    const path::SoftLimits& L = s.limits.soft;
    std::snprintf(b, sizeof b, "soft limits (cpmd's, %s; machine frame): x %.1f..%.1f, y %.1f..%.1f, z %.1f..%.1f mm\n",
                  s.config_path.c_str(), L.min.x() * 1e3, L.max.x() * 1e3, L.min.y() * 1e3, L.max.y() * 1e3,
                  L.min.z() * 1e3, L.max.z() * 1e3);
  } else {
    std::snprintf(b, sizeof b, "soft limits NOT checked: no --config and no cpmd.yaml found (strokes only)\n");
  }
  o << b;
  o << "actuator                 1 (x)      2 (y)      3 (z)    largest\n";
  const auto row = [&](const char* name, const Vec3& v, double k, const char* unit) {
    std::snprintf(b, sizeof b, "%-18s %10.1f %10.1f %10.1f    %d (%s) %s\n", name, v.x() * k, v.y() * k, v.z() * k,
                  largest(v) + 1, axis_name(largest(v)), unit);
    o << b;
  };
  row("peak speed", m.peak_actuator_speed, 1e3, "mm/s");
  row("peak acceleration", m.peak_actuator_acceleration, 1e3, "mm/s^2");
  row("peak force", m.peak_actuator_force, 1.0, "N");
  o << "every actuator within its limits: " << (m.actuators_within_limits ? "yes" : "NO") << "\n";
  if (m.limited.empty()) {
    o << "the feed is held below the programmed one nowhere\n";
  } else {
    o << "where the feed is held below the programmed one, and by what:\n"
         "  line   from (mm)     to (mm)  held by                actuator  slowest (mm/min)  programmed (mm/min)\n";
    for (const path::LimitedStretch& l : m.limited) {
      std::snprintf(b, sizeof b, "  %4d  %10.1f  %10.1f  %-22s %8s  %16.0f  %19.0f\n", path::line_of(*p.plan, l.segment),
                    l.s_begin * 1e3, l.s_end * 1e3, path::limit_name(l.by),
                    l.axis >= 0 ? std::to_string(l.axis + 1).c_str() : "", l.speed * 6e4, l.feed * 6e4);
      o << b;
    }
  }
  if (m.short_limited > 0) {
    std::snprintf(b, sizeof b, "  (and %d stretches shorter than 1 mm, not listed: corners' blends a little below the feed)\n",
                  m.short_limited);
    o << b;
  }
  std::snprintf(b, sizeof b, "planning: %.1f ms (%d repairs)\n", p.plan_seconds * 1e3, m.repairs);
  o << b;
  return o.str();
}

Json report_json(const Setup& s, const path::PreparedProgram& p) {
  const path::PlanSummary& m = p.plan->summary();
  const auto v3 = [](const Vec3& v) { return Json::array({v.x(), v.y(), v.z()}); };
  Json limited = Json::array();
  for (const path::LimitedStretch& l : m.limited)
    limited.push_back({{"line", path::line_of(*p.plan, l.segment)},
                       {"from_m", l.s_begin},
                       {"to_m", l.s_end},
                       {"by", path::limit_name(l.by)},
                       {"actuator", l.axis >= 0 ? Json(l.axis + 1) : Json(nullptr)},
                       {"slowest_m_s", l.speed},
                       {"programmed_m_s", l.feed}});
  return {{"program", s.program.name},
          {"model", s.model_path},
          {"moves", p.program.moves.size()},
          {"segments", p.queue.segments().size()},
          {"tolerance_m", p.queue.tolerance()},
          {"duration_s", m.duration},
          {"length_m", m.length},
          {"peak_speed_m_s", m.peak_speed},
          {"peak_acceleration_m_s2", m.peak_acceleration},
          {"peak_actuator_speed_m_s", v3(m.peak_actuator_speed)},
          {"peak_actuator_acceleration_m_s2", v3(m.peak_actuator_acceleration)},
          {"peak_actuator_force_n", v3(m.peak_actuator_force)},
          {"actuators_within_limits", m.actuators_within_limits},
          {"limited", limited},
          {"short_limited", m.short_limited},
          {"repairs", m.repairs},
          {"planning_s", p.plan_seconds}};
}

volatile std::sig_atomic_t interrupted = 0;
void on_interrupt(int) { interrupted = 1; }

// Progress of the program (segment `id`) until it ends; Ctrl-C stops the machine.
int follow(daemon::Client& c, std::int64_t id, const std::string& name) {
  interrupted = 0;
  const auto old = std::signal(SIGINT, on_interrupt);
  state_t last{};
  bool seen = false;
  auto printed = std::chrono::steady_clock::now();
  for (;;) {
    if (interrupted) {
      std::signal(SIGINT, old);
      std::fprintf(stderr, "\ninterrupted: stopping the machine\n");
      (void)client::report("stop", c.control(cpm_msgs::control_command_t::CMD_STOP));
      return 130;
    }
    const auto s = c.state(1.0);
    if (!s) {
      std::signal(SIGINT, old);
      throw Error("no state from cpmd for 1 s");
    }
    last = *s;
    seen = seen || s->segment_id == id;
    if (s->segment_id == id && std::chrono::steady_clock::now() - printed > std::chrono::milliseconds(100)) {
      printed = std::chrono::steady_clock::now();
      const double f = s->segment_duration > 0 ? std::min(1.0, s->segment_elapsed / s->segment_duration) : 1.0;
      std::fprintf(stderr, "\r%s line %-6d %5.1f %%  %7.1f / %.1f s  error %6.1f um ", name.c_str(), s->program_line,
                   100 * f, s->segment_elapsed, s->segment_duration, s->position_error_norm * 1e6);
    }
    if (s->last_segment_id == id || s->mode == state_t::MODE_FAULT || s->mode == state_t::MODE_DISABLED ||
        (seen && s->segment_id != id && s->mode != state_t::MODE_MOVING))
      break;
  }
  std::signal(SIGINT, old);
  std::fprintf(stderr, "\n");
  if (last.last_segment_id == id) {
    std::printf("%s: done; tracking error over the program: RMS %.1f um, max %.1f um (%d cycles)\n", name.c_str(),
                last.last_segment_rmse * 1e6, last.last_segment_max * 1e6, last.last_segment_cycles);
    return 0;
  }
  std::printf("%s: did not finish: %s\n", name.c_str(),
              last.faults ? daemon::fault_report(last).c_str() : client::state_line(last).c_str());
  return 1;
}

// Send the program (its queue from where the machine is) and follow it.
int send(const Options& o, const Setup& s, const std::string& text) {
  daemon::Client c(client::lcm_options(o.connection), client::operator_key(o.op));
  const auto st = c.state(2.0);
  if (!st) throw Error("no state from cpmd within 2 s (is it running?)");
  if (st->mode != state_t::MODE_HOLDING && st->mode != state_t::MODE_MOVING)
    throw Error(std::string("cpmd is ") + daemon::mode_text(st->mode) + ": a program runs when holding or moving (cpm enable)");
  // From the queue's end: the program's first move starts there.
  path::ProgramOptions po = s.program;
  po.start = client::vec3_of(st->queue_end);
  const path::PreparedProgram p = path::read_checked_program(text, *s.machine, po);
  const std::vector<cpm_msgs::path_command_t> chunks = daemon::path_chunks(p.queue, c.next_id());
  std::int64_t id = 0;
  for (const cpm_msgs::path_command_t& chunk : chunks) {
    id = c.send_path(chunk);
    // The last chunk is answered once cpmd has planned the whole program.
    const ack_t a = c.wait_ack(id, chunk.last ? 120.0 : 2.0);
    if (!a.accepted) {
      std::printf("%s: REJECTED by cpmd: %s (mode %s)\n", o.file.c_str(), a.message.c_str(), daemon::mode_text(a.mode));
      return 1;
    }
  }
  std::printf("%s: %zu segments sent in %zu chunks; cpmd planned and queued it\n", o.file.c_str(),
              p.queue.segments().size(), chunks.size());
  if (o.no_wait) return 0;
  return follow(c, id, o.file);
}

int run(const Options& o) {
  const Setup s = setup(o);
  const std::string text = read_text(o.file);
  std::optional<path::PreparedProgram> p;
  try {
    // Everything checked and planned before anything is sent.
    p.emplace(path::prepare_program(text, *s.machine, s.program));
  } catch (const path::ProgramError& e) {
    std::fprintf(stderr, "%s\ncpm run: %s refused, nothing sent\n", e.what(), o.file.c_str());
    return 1;
  }
  if (o.json) write_json(*o.json, report_json(s, *p));
  if (o.dry_run) {
    std::printf("%s", report_text(s, *p).c_str());
    return 0;
  }
  std::printf("%s: planned here: %.3f s, %zu segments; sending it to cpmd\n", o.file.c_str(),
              p->plan->summary().duration, p->queue.segments().size());
  try {
    return send(o, s, text);
  } catch (const path::ProgramError& e) {
    std::fprintf(stderr, "%s\ncpm run: %s refused from where the machine is, nothing sent\n", e.what(), o.file.c_str());
    return 1;
  }
}

const Command reg{
    "run", "check, plan and run a G-code program on a running cpmd (--dry-run: check and plan only)",
    [](CLI::App& app) -> Run {
      auto o = std::make_shared<Options>();
      app.add_option("FILE", o->file, "the G-code program (RS274NGC subset, docs/path.md)")
          ->type_name("FILE.ngc")
          ->required();
      app.add_flag("--dry-run", o->dry_run,
                   "read, check and plan only, without cpmd: planned time, peak actuator speeds, accelerations and "
                   "forces, where the feed is held and by what");
      app.add_option("--json", o->json, "also write the plan's figures as JSON to FILE (SI units)")->type_name("FILE");
      add_model_option(app, o->model, "the model to plan with (default: the daemon config's model_file)");
      add_number(app, "--tolerance", o->tolerance, "MM", "path tolerance in mm, unless the program sets one (G64 P)");
      add_number(app, "--jerk", o->jerk, "M/S3", "jerk along the path in m/s^3");
      app.add_option("--origin", o->origin, "program zero in the machine frame, in m (the program's Z is up)")
          ->type_name("X,Y,Z")
          ->default_str("0.425,0.425,0.300");
      app.add_option("--start", o->start, "--dry-run: where the platform starts, machine frame in m")
          ->type_name("X,Y,Z")
          ->default_str("program zero");
      app.add_flag("--no-wait", o->no_wait, "return once cpmd accepted the program, without waiting for its end");
      client::add_connection(app, o->connection);
      client::add_operator(app, o->op);
      return [o] { return run(*o); };
    }};

}  // namespace
}  // namespace cpm::cli

// SPDX-License-Identifier: Apache-2.0
// Client subcommands that send trajectories to a running cpmd: move, circle, stream.
#include <cmath>
#include <fstream>
#include <sstream>
#include <thread>
#include <vector>

#include "cmd_client_common.hpp"
#include "stream_file.hpp"
#include "cpm/daemon/fault_report.hpp"
#include "cpm/daemon/loop.hpp"
#include "cpm/daemon/params.hpp"
#include "cpm/daemon/server.hpp"
#include "cpm/daemon/stream_trajectory.hpp"

namespace cpm::cli::client {
namespace {

using cpm_msgs::ack_t;
using cpm_msgs::state_t;
using cpm_msgs::trajectory_command_t;

void print_result(const state_t& s, std::int64_t id) {
  if (s.last_segment_id == id)
    std::printf("tracking error over the segment: RMS %.1f um, max %.1f um (%d cycles)\n", s.last_segment_rmse * 1e6,
                s.last_segment_max * 1e6, s.last_segment_cycles);
  else
    std::printf("the segment did not finish: %s\n", state_line(s).c_str());
}

trajectory_command_t move_cmd(const Vec3& to, double v, double a, double j) {
  trajectory_command_t m{};
  m.kind = trajectory_command_t::KIND_MOVE;
  for (int i = 0; i < 3; ++i) m.target[i] = to[i];
  m.max_velocity = v;
  m.max_acceleration = a;
  m.max_jerk = j;
  return m;
}

struct Options {
  bool no_wait = false, paper = false, cw = false, no_approach = false, dry_run = false;
  Connection connection;
  Operator op;
  std::string target, file, plane = "xy";
  double vmax = 0.1, amax = 1.0, jmax = 50.0, approach_vmax = 0.1;
  std::optional<std::string> centre, model;
  std::optional<double> radius, speed, time, ramp, start_angle;
};

int move(const Options& o) {
  const auto l = lcm_options(o.connection);
  auto key = operator_key(o.op);
  const Vec3 to = parse_point("target", o.target);
  const bool no_wait = o.no_wait;
  daemon::Client c(l, key);
  const auto ack = c.trajectory(move_cmd(to, o.vmax, o.amax, o.jmax));
  if (report("move", ack) != 0) return 1;
  if (no_wait) return 0;
  const state_t s = wait_segment(c, ack.id, 600.0, true);
  print_result(s, ack.id);
  return s.last_segment_id == ack.id ? 0 : 1;
}

int circle(const Options& o) {
  const bool paper = o.paper;
  ctl::CircleSpec spec;  // Elkady's circle by default
  if (!paper) spec.ramp_time = o.ramp.value_or(0.5);
  if (o.centre) spec.centre = parse_point("--centre", *o.centre);
  spec.radius = o.radius.value_or(spec.radius);
  spec.angular_speed = o.speed.value_or(spec.angular_speed);
  if (o.cw) spec.angular_speed = -std::abs(spec.angular_speed);
  spec.cruise_time = o.time.value_or(spec.cruise_time);
  spec.start_angle = o.start_angle.value_or(spec.start_angle);
  const int pl = o.plane == "xy" ? 0 : o.plane == "yz" ? 1 : 2;
  spec.plane = static_cast<ctl::CirclePlane>(pl);
  CircleOptions co;
  co.paper = paper;
  co.approach = !o.no_approach;
  co.approach_vmax = o.approach_vmax;
  co.wait = !o.no_wait;
  const auto l = lcm_options(o.connection);
  auto key = operator_key(o.op);
  daemon::Client c(l, key);
  return play_circle(c, spec, co);
}

}  // namespace

int play_circle(daemon::Client& c, const ctl::CircleSpec& spec, const CircleOptions& o, state_t* end) {
  trajectory_command_t m{};
  m.kind = trajectory_command_t::KIND_CIRCLE;
  for (int i = 0; i < 3; ++i) m.centre[i] = spec.centre[i];
  m.radius = spec.radius;
  m.plane = static_cast<std::int8_t>(spec.plane);
  m.angular_speed = spec.angular_speed;
  m.start_angle = spec.start_angle;
  m.cruise_time = spec.cruise_time;
  m.ramp_time = spec.ramp_time;
  // Elkady's test starts at full speed from rest: cpmd grants the step only
  // on its simulator (or a bench that allows it); every other circle ramps in.
  m.allow_velocity_step = o.paper;
  const Vec3 start = ctl::CircleTrajectory(spec).sample(0.0).p;

  auto s = c.state(2.0);
  if (!s) throw Error("no state from cpmd within 2 s");
  const Vec3 qend = vec3_of(s->queue_end);
  if (o.approach && (qend - start).norm() > 1e-6) {
    std::printf("approach: moving to the circle's start (%.3f, %.3f, %.3f) mm\n", start.x() * 1e3, start.y() * 1e3,
                start.z() * 1e3);
    const auto ack = c.trajectory(move_cmd(start, o.approach_vmax, 1.0, 50.0));
    if (report("approach move", ack) != 0) return 1;
    const state_t r = wait_segment(c, ack.id, 600.0, false);
    if (r.last_segment_id != ack.id) {
      print_result(r, ack.id);
      return 1;
    }
    // Let the platform settle at the start, as the paper's test starts at rest.
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
  }
  const auto ack = c.trajectory(m);
  if (report(o.paper ? "paper circle" : "circle", ack) != 0) return 1;
  if (!o.wait) return 0;
  const state_t r = wait_segment(c, ack.id, 600.0, true);
  print_result(r, ack.id);
  if (end) *end = r;
  return r.last_segment_id == ack.id ? 0 : 1;
}

// The stream file's checks (stream_file.hpp), shared with cpm excite.
// CSV with columns t,x,y,z and optionally vx,vy,vz (SI).
StreamRows read_stream(const std::string& path) {
  std::ifstream f(path);
  if (!f) throw Error(path + ": cannot read");
  std::string line;
  std::vector<std::string> cols;
  StreamRows out;
  auto& rows = out.rows;
  int lineno = 0;
  while (std::getline(f, line)) {
    ++lineno;
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> cells;
    std::istringstream is(line);
    std::string cell;
    while (std::getline(is, cell, ',')) cells.push_back(cell);
    if (cols.empty()) {
      cols = cells;
      continue;
    }
    std::array<double, 7> r{0, 0, 0, 0, NAN, NAN, NAN};
    const char* names[7] = {"t", "x", "y", "z", "vx", "vy", "vz"};
    for (int k = 0; k < 7; ++k)
      for (std::size_t j = 0; j < cols.size() && j < cells.size(); ++j)
        if (cols[j] == names[k]) {
          char* end = nullptr;
          r[k] = std::strtod(cells[j].c_str(), &end);
          if (*end != '\0' || !std::isfinite(r[k]))
            throw Error(path + ":" + std::to_string(lineno) + ": column " + names[k] + ": not a finite number");
        }
    rows.push_back(r);
    out.line.push_back(lineno);
  }
  for (const char* need : {"t", "x", "y", "z"})
    if (std::find(cols.begin(), cols.end(), need) == cols.end())
      throw Error(path + ": missing column '" + need + "'");
  if (rows.size() < 2) throw Error(path + ": needs at least two setpoints");
  const std::size_t n = rows.size();
  // Velocities: given, or central differences (rest at both ends).
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k)
      if (std::isnan(rows[i][4 + k]))
        rows[i][4 + k] = (i == 0 || i + 1 == n) ? 0.0
                                                : (rows[i + 1][1 + k] - rows[i - 1][1 + k]) / (rows[i + 1][0] - rows[i - 1][0]);
  return out;
}

// A file that ends at speed would leave the queue to run dry at that speed
// (cpmd then stops on limits.stop_deceleration and latches stream_underrun).
// Rather than refuse it, a stop is appended: constant deceleration at half
// limits.acceleration, at the file's last time step, along the last velocity
// (a parabola, which the stream's cubic Hermite pieces play exactly). It is
// checked with the rest. Returns the stop's duration (s), 0 when none.
double append_stop(StreamRows& s, double acceleration_limit) {
  auto& rows = s.rows;
  const std::size_t n = rows.size();
  const Vec3 p0(rows[n - 1][1], rows[n - 1][2], rows[n - 1][3]);
  const Vec3 v0(rows[n - 1][4], rows[n - 1][5], rows[n - 1][6]);
  if (v0.norm() <= daemon::ControlLoop::kStreamRestSpeed) return 0.0;
  const double h = rows[n - 1][0] - rows[n - 2][0];
  const int steps = std::max(2, static_cast<int>(std::ceil(v0.norm() / (0.5 * acceleration_limit) / h)));
  const double T = steps * h;
  for (int k = 1; k <= steps; ++k) {
    const double t = k * h;
    const Vec3 p = p0 + v0 * (t - t * t / (2 * T));
    const Vec3 v = v0 * (1 - t / T);
    rows.push_back({rows[n - 1][0] + t, p.x(), p.y(), p.z(), k == steps ? 0.0 : v.x(), k == steps ? 0.0 : v.y(),
                    k == steps ? 0.0 : v.z()});
    s.line.push_back(0);
  }
  return T;
}

// cpmd's messages: at most kMaxPoints setpoints each, consecutive ones
// sharing a row so that position and velocity go on across them.
constexpr std::size_t kChunkRows = daemon::StreamTrajectory::kMaxPoints;
std::vector<trajectory_command_t> stream_chunks(const StreamRows& s, std::vector<std::size_t>& first_row) {
  const auto& rows = s.rows;
  const std::size_t n = rows.size();
  std::vector<trajectory_command_t> out;
  for (std::size_t s0 = 0; s0 + 1 < n; s0 += kChunkRows - 1) {
    const std::size_t cnt = std::min<std::size_t>(kChunkRows, n - s0);
    trajectory_command_t m{};
    m.kind = trajectory_command_t::KIND_STREAM;
    m.count = static_cast<std::int16_t>(cnt);
    for (std::size_t i = 0; i < cnt; ++i) {
      m.time[i] = rows[s0 + i][0] - rows[s0][0];
      for (int k = 0; k < 3; ++k) {
        m.position[i][k] = rows[s0 + i][1 + k];
        m.velocity[i][k] = rows[s0 + i][4 + k];
      }
    }
    out.push_back(m);
    first_row.push_back(s0);
  }
  return out;
}

static std::string row_name(const StreamRows& s, std::size_t i) {
  if (s.line[i] == 0) return "the stop appended after the last row";
  return "row " + std::to_string(i + 1) + " (line " + std::to_string(s.line[i]) + ")";
}

// The whole file through the checks cpmd makes on each stream segment
// (daemon::validate_segment: soft limits, the machine's workspace, speed
// and acceleration), before anything is sent. On a refusal, the first
// stretch between two rows that fails on its own names the row (t, the
// time in cpmd's message, counts from the stretch's start). Returns
// "" when every segment passes, else what and where.
std::string check_stream(const StreamRows& s, const std::vector<trajectory_command_t>& chunks,
                         const std::vector<std::size_t>& first_row, const ctl::Machine& machine,
                         const daemon::LimitsConfig& L, double dt) {
  // The approach ends at rest: the first row must start there (cpmd's start check).
  {
    const daemon::Validation v = daemon::validate_segment(chunks[0], client::vec3_of(chunks[0].position[0]), machine, L, dt);
    if (v.ok) {
      const daemon::StartCheck c = daemon::check_start(*v.segment.get(), Vec3::Zero(), L, dt);
      if (!c.ok())
        return row_name(s, 0) + ": starts at " + std::to_string(c.velocity_step * 1e3) + " mm/s and " +
               std::to_string(c.acceleration * 1e3) + " mm/s^2, from rest: a step the acceleration limit " +
               std::to_string(L.acceleration) + " m/s^2 does not allow in one period";
    }
  }
  for (std::size_t c = 0; c < chunks.size(); ++c) {
    const trajectory_command_t& m = chunks[c];
    const daemon::Validation v = daemon::validate_segment(m, client::vec3_of(m.position[0]), machine, L, dt);
    if (v.ok) continue;
    // A stream's piece between two rows depends on those two rows only. A
    // chunk's last row is checked at its start only (cpmd samples a chunk's
    // end as the point at rest), so the search runs into the next chunk's
    // first stretch.
    const std::size_t last = std::min(first_row[c] + static_cast<std::size_t>(m.count), s.rows.size() - 1);
    for (std::size_t from = first_row[c]; from < last; ++from) {
      trajectory_command_t two{};
      two.kind = trajectory_command_t::KIND_STREAM;
      two.count = 2;
      for (int j = 0; j < 2; ++j) {
        const auto& r = s.rows[from + static_cast<std::size_t>(j)];
        two.time[j] = r[0] - s.rows[from][0];
        for (int k = 0; k < 3; ++k) {
          two.position[j][k] = r[1 + k];
          two.velocity[j][k] = r[4 + k];
        }
      }
      const daemon::Validation w = daemon::validate_segment(two, client::vec3_of(two.position[0]), machine, L, dt);
      if (!w.ok) {
        // cpmd's message says when, from the stretch's start: at 0 the
        // stretch's first row (its own velocity), else the row it ends at.
        const std::size_t at = w.message.find("t = ");
        const bool first = at != std::string::npos && std::strtod(w.message.c_str() + at + 4, nullptr) == 0.0;
        char span[96];
        std::snprintf(span, sizeof span, ", the stretch from t = %.4f s to %.4f s: ", s.rows[from][0], s.rows[from + 1][0]);
        return row_name(s, first ? from : from + 1) + span + w.message;
      }
    }
    return "rows " + std::to_string(first_row[c] + 1) + ".." + std::to_string(first_row[c] + m.count) + ": " + v.message;
  }
  return {};
}

// cpmd's limits as it publishes them (params_t), over the configured ones.
void apply_published_limits(const cpm_msgs::params_t& p, daemon::DaemonConfig& cfg) {
  for (int i = 0; i < p.count; ++i) {
    const std::string& name = p.name[static_cast<std::size_t>(i)];
    if (name.rfind("limits.", 0) != 0) continue;
    const double v = p.value[static_cast<std::size_t>(i)];
    try {
      daemon::set_param(cfg, name, v);
    } catch (const Error&) {
      // Set in an order the defaults' constraints refuse (a workspace moved
      // past the default's other end): set the value plainly, as cpmd holds it.
      if (name == "limits.velocity") cfg.limits.velocity = v;
      else if (name == "limits.acceleration") cfg.limits.acceleration = v;
      else if (name.rfind("limits.workspace_m", 0) == 0) {
        const int axis = name.back() - 'x';
        (name.find("_min.") != std::string::npos ? cfg.limits.workspace_min : cfg.limits.workspace_max)[axis] = v;
      }
    }
  }
}

namespace {

int stream(const Options& o) {
  StreamRows s = read_stream(o.file);
  const std::size_t file_rows = s.rows.size();
  daemon::DaemonConfig cfg;
  if (o.connection.config) cfg = daemon::load_config(*o.connection.config);
  const std::string model_path = o.model ? *o.model : o.connection.config ? cfg.model_file : model_or_default(std::nullopt);
  ctl::MachineModel model = daemon::load_model(model_path);
  model.force_limit = std::min(model.force_limit, cfg.limits.force);
  const ctl::Machine machine(model);
  const double dt = 1.0 / cfg.loop.rate_hz;

  // Checked with --config's limits (or, --dry-run without it, the defaults)
  // before cpmd is even reached; else with those cpmd publishes now (cpm set
  // may have changed them): in either case before anything is sent.
  std::optional<daemon::Client> c;
  if (!o.dry_run && !o.connection.config) {
    c.emplace(lcm_options(o.connection), operator_key(o.op));
    {
      const auto p = c->params(3.0);
      if (!p) throw Error("no parameter table from cpmd within 3 s (is it running?); give --config to check offline");
      apply_published_limits(*p, cfg);
    }
  }
  const double stop_time = append_stop(s, cfg.limits.acceleration);
  std::vector<std::size_t> first_row;
  const std::vector<trajectory_command_t> chunks = stream_chunks(s, first_row);
  if (const std::string bad = check_stream(s, chunks, first_row, machine, cfg.limits, dt); !bad.empty()) {
    std::fprintf(stderr, "%s: %s\ncpm stream: %s refused, nothing sent (limits.velocity %.1f mm/s, "
                 "limits.acceleration %.0f mm/s^2)\n", o.file.c_str(), bad.c_str(), o.file.c_str(),
                 cfg.limits.velocity * 1e3, cfg.limits.acceleration * 1e3);
    return 1;
  }
  if (stop_time > 0.0) {
    const auto& last = s.rows[file_rows - 1];
    std::printf("%s: ends at %.1f mm/s: a stop of %.3f s at half limits.acceleration is appended\n", o.file.c_str(),
                Vec3(last[4], last[5], last[6]).norm() * 1e3, stop_time);
  }
  std::printf("%s: %zu rows, %.3f s, within limits.velocity %.1f mm/s, limits.acceleration %.0f mm/s^2, the soft "
              "limits and the workspace\n", o.file.c_str(), file_rows, s.rows.back()[0] - s.rows.front()[0],
              cfg.limits.velocity * 1e3, cfg.limits.acceleration * 1e3);
  if (o.dry_run) return 0;
  if (!c) c.emplace(lcm_options(o.connection), operator_key(o.op));
  PlayOptions p;
  p.approach = !o.no_approach;
  p.approach_vmax = std::min(o.approach_vmax, cfg.limits.velocity);
  p.approach_amax = std::min(1.0, cfg.limits.acceleration);
  p.wait = !o.no_wait;
  return play_stream(*c, s, chunks, first_row, p);
}

}  // namespace

int play_stream(daemon::Client& c, const StreamRows& s, const std::vector<trajectory_command_t>& chunks,
                const std::vector<std::size_t>& first_row, const PlayOptions& o) {
  // The approach, as `cpm circle` makes it: a jerk-limited move from where the queue ends.
  const Vec3 start = client::vec3_of(chunks[0].position[0]);
  auto st = c.state(2.0);
  if (!st) throw Error("no state from cpmd within 2 s");
  if (o.approach && (vec3_of(st->queue_end) - start).norm() > 1e-6) {
    std::printf("approach: moving to the file's first point (%.3f, %.3f, %.3f) mm\n", start.x() * 1e3,
                start.y() * 1e3, start.z() * 1e3);
    const auto ack = c.trajectory(move_cmd(start, o.approach_vmax, o.approach_amax, 50.0));
    if (report("approach move", ack) != 0) return 1;
    const state_t r = wait_segment(c, ack.id, 600.0, false);
    if (r.last_segment_id != ack.id) {
      print_result(r, ack.id);
      return 1;
    }
  }
  if (o.on_approached) o.on_approached();
  std::int64_t last_id = -1;
  int segments = 0;
  for (std::size_t k = 0; k < chunks.size(); ++k) {
    for (;;) {
      ack_t ack{};
      try {
        ack = c.trajectory(chunks[k]);
      } catch (const Error&) {
        // A sender that fell behind (paused, starved): cpmd may have run
        // dry and latched stream_underrun meanwhile; say so if it did.
        const auto now = c.state(2.0);
        if (!now || !now->faults) throw;
        std::printf("stream: rows from %zu on not sent; cpmd: %s\n", first_row[k] + 1, daemon::fault_report(*now).c_str());
        return 1;
      }
      if (ack.accepted) {
        last_id = ack.id;
        ++segments;
        break;
      }
      if (ack.reason == ack_t::REASON_QUEUE_FULL || ack.reason == ack_t::REASON_BUSY) {
        c.handle(0.05);
        continue;
      }
      std::printf("stream: segment starting at row %zu REJECTED: %s\n", first_row[k] + 1, ack.message.c_str());
      return 1;
    }
  }
  std::printf("stream: %zu setpoints sent as %d segments\n", s.rows.size(), segments);
  if (!o.wait) return 0;
  const state_t r = wait_segment(c, last_id, 3600.0, true);
  print_result(r, last_id);
  return r.last_segment_id == last_id ? 0 : 1;
}

namespace {

// --no-wait, where cpmd is, and who commands it: every motion command has them.
void add_common(CLI::App& app, Options& o) {
  app.add_flag("--no-wait", o.no_wait, "return once cpmd accepted, without waiting for the motion to end");
  add_connection(app, o.connection);
  add_operator(app, o.op);
}

const Command r1{"move", "move a running cpmd's platform to X,Y,Z (jerk-limited straight line)", [](CLI::App& app) -> Run {
                   auto o = std::make_shared<Options>();
                   app.add_option("TARGET", o->target, "where to in m (e.g. 0.45,0.40,0.35)")->type_name("X,Y,Z")->required();
                   add_number(app, "--vmax", o->vmax, "M/S", "velocity limit in m/s");
                   add_number(app, "--amax", o->amax, "M/S2", "acceleration limit in m/s^2");
                   add_number(app, "--jmax", o->jmax, "M/S3", "jerk limit in m/s^3");
                   add_common(app, *o);
                   return [o] { return move(*o); };
                 }};
const Command r2{"circle", "run a circle on a running cpmd (--paper: Elkady's test) and print the tracking error",
                 [](CLI::App& app) -> Run {
                   auto o = std::make_shared<Options>();
                   const ctl::CircleSpec c;
                   auto* paper = app.add_flag("--paper", o->paper, "Elkady's circle: full speed from the start, no ramp");
                   app.add_option("--centre", o->centre, "circle centre in m")
                       ->type_name("X,Y,Z")
                       ->default_str("0.425,0.425,0.300");
                   add_number(app, "--radius", o->radius, "M", "circle radius in m (e.g. 0.150)")
                       ->default_str(CLI::detail::to_string(c.radius));
                   add_number(app, "--speed", o->speed, "RAD/S", "angular speed in rad/s, > 0 counter-clockwise")
                       ->default_str(CLI::detail::to_string(c.angular_speed));
                   app.add_flag("--cw", o->cw, "run clockwise");
                   add_number(app, "--time", o->time, "S", "time at full speed in s")
                       ->default_str(CLI::detail::to_string(c.cruise_time));
                   add_number(app, "--ramp", o->ramp, "S", "time to reach and leave full speed in s")
                       ->default_str("0.5")
                       ->excludes(paper);
                   add_choice(app, "--plane", o->plane, {"xy", "yz", "zx"}, "the circle's plane");
                   add_number(app, "--start-angle", o->start_angle, "RAD", "start angle in rad from the plane's first axis")
                       ->default_str("0");
                   app.add_flag("--no-approach", o->no_approach, "do not move to the circle's start first");
                   add_number(app, "--approach-vmax", o->approach_vmax, "M/S", "velocity of the approach move in m/s");
                   add_common(app, *o);
                   return [o] { return circle(*o); };
                 }};
const Command r3{"stream", "check a CSV of timed setpoints (t,x,y,z[,vx,vy,vz]) against cpmd's limits, approach its first point and stream it (--dry-run: check only)", [](CLI::App& app) -> Run {
                   auto o = std::make_shared<Options>();
                   app.add_option("FILE", o->file,
                                  "CSV with columns t,x,y,z and optionally vx,vy,vz (s, m, m/s); velocities missing "
                                  "are central differences")
                       ->type_name("FILE.csv")
                       ->required();
                   app.add_flag("--dry-run", o->dry_run,
                                "check the whole file against the limits (--config's, else the defaults) and stop");
                   add_model_option(app, o->model, "the model whose workspace the file is checked in (default: the "
                                                   "daemon config's model_file)");
                   app.add_flag("--no-approach", o->no_approach, "do not move to the file's first point first");
                   add_number(app, "--approach-vmax", o->approach_vmax, "M/S", "velocity of the approach move in m/s");
                   add_common(app, *o);
                   return [o] { return stream(*o); };
                 }};

}  // namespace
}  // namespace cpm::cli::client

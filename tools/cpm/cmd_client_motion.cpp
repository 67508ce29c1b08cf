// Client subcommands that send trajectories to a running cpmd: move, circle, stream.
#include <cmath>
#include <fstream>
#include <sstream>
#include <thread>
#include <vector>

#include "cmd_client_common.hpp"

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
  bool no_wait = false, paper = false, cw = false, no_approach = false;
  Connection connection;
  Operator op;
  std::string target, file, plane = "xy";
  double vmax = 0.1, amax = 1.0, jmax = 50.0, approach_vmax = 0.1;
  std::optional<std::string> centre;
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
  trajectory_command_t m{};
  m.kind = trajectory_command_t::KIND_CIRCLE;
  ctl::CircleSpec spec;  // Elkady's circle by default
  if (!paper) spec.ramp_time = o.ramp.value_or(0.5);
  if (o.centre) spec.centre = parse_point("--centre", *o.centre);
  spec.radius = o.radius.value_or(spec.radius);
  spec.angular_speed = o.speed.value_or(spec.angular_speed);
  if (o.cw) spec.angular_speed = -std::abs(spec.angular_speed);
  spec.cruise_time = o.time.value_or(spec.cruise_time);
  spec.start_angle = o.start_angle.value_or(spec.start_angle);
  const int pl = o.plane == "xy" ? 0 : o.plane == "yz" ? 1 : 2;
  const bool approach = !o.no_approach;
  const double vapp = o.approach_vmax;
  const bool no_wait = o.no_wait;
  const auto l = lcm_options(o.connection);
  auto key = operator_key(o.op);
  for (int i = 0; i < 3; ++i) m.centre[i] = spec.centre[i];
  m.radius = spec.radius;
  m.plane = static_cast<std::int8_t>(pl);
  m.angular_speed = spec.angular_speed;
  m.start_angle = spec.start_angle;
  m.cruise_time = spec.cruise_time;
  m.ramp_time = spec.ramp_time;
  // Elkady's test starts at full speed from rest: cpmd grants the step only
  // on its simulator (or a bench that allows it); every other circle ramps in.
  m.allow_velocity_step = paper;
  spec.plane = static_cast<ctl::CirclePlane>(pl);
  const Vec3 start = ctl::CircleTrajectory(spec).sample(0.0).p;

  daemon::Client c(l, key);
  auto s = c.state(2.0);
  if (!s) throw Error("no state from cpmd within 2 s");
  const Vec3 end = vec3_of(s->queue_end);
  if (approach && (end - start).norm() > 1e-6) {
    std::printf("approach: moving to the circle's start (%.3f, %.3f, %.3f) mm\n", start.x() * 1e3, start.y() * 1e3,
                start.z() * 1e3);
    const auto ack = c.trajectory(move_cmd(start, vapp, 1.0, 50.0));
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
  if (report(paper ? "paper circle" : "circle", ack) != 0) return 1;
  if (no_wait) return 0;
  const state_t r = wait_segment(c, ack.id, 600.0, true);
  print_result(r, ack.id);
  return r.last_segment_id == ack.id ? 0 : 1;
}

// CSV with columns t,x,y,z and optionally vx,vy,vz (SI).
int stream(const Options& o) {
  const bool no_wait = o.no_wait;
  const auto l = lcm_options(o.connection);
  auto key = operator_key(o.op);
  const std::string& path = o.file;
  std::ifstream f(path);
  if (!f) throw Error(path + ": cannot read");
  std::string line;
  std::vector<std::string> cols;
  std::vector<std::array<double, 7>> rows;
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
  daemon::Client c(l, key);
  std::int64_t last_id = -1;
  int segments = 0;
  for (std::size_t s0 = 0; s0 + 1 < n; s0 += 99) {
    const std::size_t cnt = std::min<std::size_t>(100, n - s0);
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
    for (;;) {
      const auto ack = c.trajectory(m);
      if (ack.accepted) {
        last_id = ack.id;
        ++segments;
        break;
      }
      if (ack.reason == ack_t::REASON_QUEUE_FULL || ack.reason == ack_t::REASON_BUSY) {
        c.handle(0.05);
        continue;
      }
      std::printf("stream: segment starting at row %zu REJECTED: %s\n", s0 + 1, ack.message.c_str());
      return 1;
    }
  }
  std::printf("stream: %zu setpoints sent as %d segments\n", n, segments);
  if (no_wait) return 0;
  const state_t r = wait_segment(c, last_id, 3600.0, true);
  print_result(r, last_id);
  return r.last_segment_id == last_id ? 0 : 1;
}

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
const Command r3{"stream", "stream timed setpoints from a CSV (t,x,y,z[,vx,vy,vz]) to a running cpmd", [](CLI::App& app) -> Run {
                   auto o = std::make_shared<Options>();
                   app.add_option("FILE", o->file,
                                  "CSV with columns t,x,y,z and optionally vx,vy,vz (s, m, m/s); velocities missing "
                                  "are central differences")
                       ->type_name("FILE.csv")
                       ->required();
                   add_common(app, *o);
                   return [o] { return stream(*o); };
                 }};

}  // namespace
}  // namespace cpm::cli::client

// SPDX-License-Identifier: Apache-2.0
// cpm-path-report: a G-code contour (by default the square-diamond-circle
// test contour) planned with the actuator-aware planner and with Cartesian
// limits only, each run through the in-process closed loop (the plant and
// the computed-torque controller on the model file), and the contouring
// figures of each: contour error along the path, feed achieved against
// programmed, peak actuator forces, cycle time. Writes report.md,
// report.html (with the plots), and the plots as contour.svg, error.svg,
// feed.svg and forces.svg into --out.
#include <CLI/CLI.hpp>

#include <array>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>

#include "cpm/io/model_file.hpp"
#include "cpm/path/contour.hpp"
#include "cpm/path/gcode.hpp"
#include "cpm/path/planner.hpp"
#include "cpm/path/program.hpp"
#include "cpm/path/test_paths.hpp"
#include "cpm/sim/closed_loop.hpp"
#include "svg.hpp"

namespace {

using namespace cpm;
using namespace cpm::path;

struct Options {
  std::string model = "config/machine.yaml", truth, program, out = "path-report";
  double side = 250.0, feed = 12000.0, tolerance = 0.05, fast = 30.0, jerk = 1000.0;
};

struct Run {
  std::string name;
  PlannerOptions planner;
  std::optional<Plan> plan;
  double plan_ms = 0.0;
  sim::RunResult result;
  ContourFigures fig;
};

std::string read_text(const std::string& path) {
  std::ifstream f(path);
  if (!f) throw Error("cannot read " + path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

void run(Run& r, const PathQueue& q, const ctl::Machine& model, const ctl::Machine& truth) {
  const auto t0 = std::chrono::steady_clock::now();
  r.plan.emplace(plan_path(q, model, r.planner));
  r.plan_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  const ctl::Controller c(model, ctl::ControlLaw::computed_torque, ctl::table3_gains(ctl::ControlLaw::computed_torque));
  sim::Plant plant(truth, sim::PlantOptions{});
  r.result = sim::run_closed_loop(c, plant, *r.plan, sim::LoopOptions{});
  std::vector<RunSample> samples;
  for (const sim::LogRow& row : r.result.log) samples.push_back(RunSample{row.t, row.p, row.p_dot, row.force});
  r.fig = contour(q, *r.plan, samples, r.planner.cartesian.velocity);
}

std::vector<Run> runs(const Options& o, const ctl::Machine& model) {
  std::vector<Run> rs(3);
  for (Run& r : rs) {
    r.planner.cartesian.jerk = o.jerk;
    r.planner.actuators.force = Vec3::Constant(model.force_limit());
  }
  rs[0].name = "actuator-aware";
  rs[1].name = "Cartesian only, 5 m/s²";
  rs[1].planner.mode = PlanMode::cartesian_only;
  rs[2].name = "Cartesian only, " + std::to_string(static_cast<int>(o.fast)) + " m/s²";
  rs[2].planner.mode = PlanMode::cartesian_only;
  rs[2].planner.cartesian.acceleration = o.fast;
  return rs;
}

std::string vec(const Vec3& v, int digits = 1) {
  char b[96];
  std::snprintf(b, sizeof b, "%.*f / %.*f / %.*f", digits, v.x(), digits, v.y(), digits, v.z());
  return b;
}

std::string table(const std::vector<Run>& rs) {
  std::ostringstream o;
  o << "| plan | cycle time (s) | planned peak force x/y/z (N) | within the drives' limits | run peak force x/y/z (N) "
       "| saturated periods | contour error max / rms (µm) | of it the plan's rounding (µm) | tracking max (µm) "
       "| feed held (% of distance) | planning (ms), repairs |\n"
       "|---|---|---|---|---|---|---|---|---|---|---|\n";
  char b[512];
  for (const Run& r : rs) {
    const PlanSummary& s = r.plan->summary();
    std::snprintf(b, sizeof b, "| %s | %.3f | %s | %s | %s | %ld | %.1f / %.2f | %.1f | %.1f | %.1f | %.1f, %d |\n",
                  r.name.c_str(), s.duration, vec(s.peak_actuator_force).c_str(),
                  s.actuators_within_limits ? "yes" : "**no**", vec(r.fig.peak_force).c_str(),
                  r.result.metrics.saturated_samples, r.fig.max_error * 1e6, r.fig.rms_error * 1e6,
                  r.fig.max_rounding * 1e6, r.fig.max_tracking * 1e6, r.fig.feed_held * 100, r.plan_ms, s.repairs);
    o << b;
  }
  return o.str();
}

std::string limited_table(const Plan& p, const PathQueue& q) {
  std::ostringstream o;
  o << "| from (mm) | to (mm) | line | held by | actuator | slowest (mm/min) | programmed (mm/min) |\n|---|---|---|---|---|---|---|\n";
  char b[256];
  for (const LimitedStretch& l : p.summary().limited) {
    const int line = l.segment >= 0 ? q.segments()[static_cast<std::size_t>(l.segment)].line : 0;
    std::snprintf(b, sizeof b, "| %.1f | %.1f | %d | %s | %s | %.0f | %.0f |\n", l.s_begin * 1e3, l.s_end * 1e3, line,
                  limit_name(l.by), l.axis >= 0 ? std::to_string(l.axis + 1).c_str() : "", l.speed * 6e4, l.feed * 6e4);
    o << b;
  }
  return o.str();
}

}  // namespace

namespace {

// About n points of a run's series on feed moves: of every bucket of
// samples its lowest and its highest, so that no dip at a corner is lost.
template <class F>
report::Line series(const ContourFigures& f, F y, const std::string& colour, const std::string& label, std::size_t n = 800) {
  report::Line l{{}, {}, colour, label};
  const std::size_t bucket = std::max<std::size_t>(1, 2 * f.points.size() / n);
  for (std::size_t a = 0; a < f.points.size(); a += bucket) {
    std::size_t lo = f.points.size(), hi = lo;
    for (std::size_t k = a; k < std::min(a + bucket, f.points.size()); ++k) {
      if (f.points[k].rapid) continue;
      if (lo == f.points.size() || y(f.points[k]) < y(f.points[lo])) lo = k;
      if (hi == f.points.size() || y(f.points[k]) > y(f.points[hi])) hi = k;
    }
    if (lo == f.points.size()) continue;
    for (std::size_t k : {std::min(lo, hi), std::max(lo, hi)}) {
      l.x.push_back(f.points[k].along * 1e3);
      l.y.push_back(y(f.points[k]));
    }
  }
  return l;
}

// The run's path with its distance to the programmed path magnified so
// that the largest shows as 2 % of the contour's size, coloured by it.
std::string coloured(const Run& r, const PathQueue& q, const ProgramFrame& frame) {
  report::ColouredPath c;
  const double top = std::max(r.fig.max_error * 1e6, 1e-3);
  const Geometry prog = programmed(q);
  Eigen::AlignedBox3d box;
  for (const Piece& pc : prog.pieces)
    for (int k = 0; k <= 8; ++k) box.extend(pc.at(pc.length * k / 8).p);
  const double size = box.diagonal().head<2>().maxCoeff();
  const double gain = std::max(1.0, std::round(0.02 * size / std::max(r.fig.max_error, 1e-9)));
  char title[160];
  std::snprintf(title, sizeof title, "contour error, %s: the path as run, its error x%.0f (program X, Y)", r.name.c_str(), gain);
  c.title = title;
  c.unit = "µm";
  for (const ContourPoint& p : r.fig.points) {
    if (p.rapid) continue;
    const Vec3 x = frame.to_program(p.nearest + gain * (p.p - p.nearest)) * 1e3;
    // Keep a point 1 mm on from the last, or where the colour changes.
    if (!c.x.empty() && std::hypot(x.x() - c.x.back(), x.y() - c.y.back()) < 1.0 &&
        std::abs(p.error * 1e6 - c.value.back()) < 0.1 * top)
      continue;
    c.x.push_back(x.x());
    c.y.push_back(x.y());
    c.value.push_back(p.error * 1e6);
  }
  for (const Piece& pc : prog.pieces) {
    if (pc.feed <= 0.0) continue;
    for (int k = 0; k <= 40; ++k) {
      const Vec3 x = frame.to_program(pc.at(pc.length * k / 40).p) * 1e3;
      c.px.push_back(x.x());
      c.py.push_back(x.y());
    }
  }
  c.top = top;
  return report::coloured_path(c);
}

// The charts: contour error and feed along the path, forces in time.
std::array<std::string, 3> plots(const std::vector<Run>& rs) {
  const std::array<const char*, 3> colours{"#1f5fbf", "#c2410c", "#6b21a8"};
  std::vector<report::Line> err, feed;
  for (std::size_t k = 0; k < rs.size(); ++k) {
    err.push_back(series(rs[k].fig, [](const ContourPoint& p) { return p.error * 1e6; }, colours[k], rs[k].name));
    feed.push_back(series(rs[k].fig, [](const ContourPoint& p) { return p.feed * 6e4; }, colours[k], rs[k].name));
  }
  feed.push_back(series(rs[0].fig, [](const ContourPoint& p) { return p.programmed * 6e4; }, "#888", "programmed"));
  report::Line fx{{}, {}, "#b91c1c", "actuator 1"}, fy{{}, {}, "#15803d", "actuator 2"}, fz{{}, {}, "#1d4ed8", "actuator 3"};
  const auto& log = rs[0].result.log;
  for (std::size_t k = 0; k < log.size(); k += std::max<std::size_t>(1, log.size() / 2500)) {
    const sim::LogRow& row = log[k];
    for (report::Line* l : {&fx, &fy, &fz}) l->x.push_back(row.t);
    fx.y.push_back(row.force.x()), fy.y.push_back(row.force.y()), fz.y.push_back(row.force.z());
  }
  return {report::chart("contour error along the path", "path (mm)", "error (µm)", err),
          report::chart("feed achieved against programmed", "path (mm)", "feed (mm/min)", feed),
          report::chart("actuator commands, " + rs[0].name, "t (s)", "force (N)", {fx, fy, fz})};
}

std::string header(const Options& o, const std::string& name) {
  std::ostringstream h;
  h << "Program: " << name << "; path tolerance " << o.tolerance << " mm; jerk " << o.jerk
    << " m/s³. Model (the controller's and the planner's): `" << o.model << "`; true machine: `"
    << (o.truth.empty() ? o.model : o.truth) << "`. Closed loop: computed torque with Elkady's Table 3 gains at 1 kHz, "
    << "the plant integrated by RK4 ×10 under zero-order hold (sim::run_closed_loop).\n\n"
    << "Contour error: distance from the true platform position to the programmed path (as written, before "
       "blending), on feed moves. Tracking: distance to the plan's reference at the same time. Feed held: share "
       "of the distance run on feed moves at ≥ 95 % of the programmed feed.\n\n";
  return h.str();
}

void write(const Options& o, const std::string& name, const std::vector<Run>& rs, const PathQueue& q) {
  std::filesystem::create_directories(o.out);
  const ProgramFrame frame;
  const std::string head = header(o, name), runs_md = table(rs), lim = limited_table(*rs[0].plan, q);
  std::ofstream(o.out + "/report.md") << "# Path report\n\n" << head << runs_md << "\n## Where the actuator-aware plan "
                                      << "runs below the programmed feed, and why\n\n" << lim;
  const std::string path_svg = coloured(rs[0], q, frame);
  const std::array<std::string, 3> charts = plots(rs);
  std::ofstream(o.out + "/contour.svg") << path_svg;
  std::ofstream(o.out + "/error.svg") << charts[0];
  std::ofstream(o.out + "/feed.svg") << charts[1];
  std::ofstream(o.out + "/forces.svg") << charts[2];
  std::ofstream html(o.out + "/report.html");
  html << "<!doctype html><meta charset='utf-8'><title>Path report</title><style>body{font-family:sans-serif;"
          "max-width:1200px;margin:16px}pre{white-space:pre-wrap}</style><h1>Path report</h1><pre>"
       << head << runs_md << "</pre>" << path_svg << charts[0] << charts[1] << charts[2]
       << "<h2>Where the actuator-aware plan runs below the programmed feed</h2><pre>" << lim << "</pre>";
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{"Contouring figures of a G-code contour planned with and without the actuator limits, in simulation"};
  app.add_option("--model", o.model, "model file of the controller and the planner")->capture_default_str();
  app.add_option("--truth", o.truth, "model file of the true machine (default: --model)");
  app.add_option("--program", o.program, "G-code file (default: the square-diamond-circle contour)");
  app.add_option("--side", o.side, "side of the square-diamond-circle contour (mm)")->capture_default_str();
  app.add_option("--feed", o.feed, "its feed (mm/min)")->capture_default_str();
  app.add_option("--tolerance", o.tolerance, "path tolerance (mm), unless the program sets one (G64 P)")->capture_default_str();
  app.add_option("--fast", o.fast, "Cartesian acceleration of the third, unsafe plan (m/s²)")->capture_default_str();
  app.add_option("--jerk", o.jerk, "jerk along the path (m/s³)")->capture_default_str();
  app.add_option("--out", o.out, "output folder")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  try {
    const ctl::Machine model(io::load_model_file(o.model).model);
    const ctl::Machine truth(o.truth.empty() ? model.model() : io::load_model_file(o.truth).model);
    const std::string name = o.program.empty() ? "square-diamond-circle, side " + std::to_string(o.side) + " mm, F" +
                                                     std::to_string(o.feed) + " mm/min"
                                               : o.program;
    ProgramOptions po;
    po.name = o.program.empty() ? "contour" : o.program;
    po.tolerance = o.tolerance * 1e-3;
    const PathQueue q =
        read_checked_program(o.program.empty() ? square_diamond_circle(o.side, o.feed) : read_text(o.program), model, po)
            .queue;
    std::vector<Run> rs = runs(o, model);
    for (Run& r : rs) run(r, q, model, truth);
    write(o, name, rs, q);
    std::printf("%s", table(rs).c_str());
    std::printf("wrote %s/report.md, report.html, contour.svg, error.svg, feed.svg, forces.svg\n", o.out.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cpm-path-report: %s\n", e.what());
    return 1;
  }
  return 0;
}

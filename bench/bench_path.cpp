// SPDX-License-Identifier: Apache-2.0
// Speed of the path planner (issue 18): a 10 000-segment program must plan
// in well under 1 s; and of one real-time sample of the prepared plan,
// which must not depend on the program's length (that is tested by
// counting in tests/path/test_sampling.cpp; this shows the time).
#include <benchmark/benchmark.h>

#include <sstream>

#include "cpm/daemon/path_message.hpp"
#include "cpm/path/gcode.hpp"
#include "cpm/path/planner.hpp"
#include "cpm/path/program.hpp"
#include "cpm/path/test_paths.hpp"

namespace {

using namespace cpm;

const ctl::Machine& machine() {
  static const ctl::Machine m(ctl::MachineModel::elkady());
  return m;
}

// CAM-like: 10 000 lines of 2 mm in a zigzag raster at 6 m/min, 0.05 mm tolerance.
path::PathQueue program(int segments) {
  return path::zigzag(segments, 2e-3, 100, Vec3(0.425, 0.395, 0.300), 0.1, 5e-5);
}

void plan(benchmark::State& state, path::PlanMode mode) {
  const path::PathQueue q = program(static_cast<int>(state.range(0)));
  path::PlannerOptions o;
  o.mode = mode;
  for (auto _ : state) {
    const path::Plan p = path::plan_path(q, machine(), o);
    benchmark::DoNotOptimize(p.knots().data());
  }
  state.counters["segments"] = static_cast<double>(state.range(0));
  state.counters["motion_s"] = path::plan_path(q, machine(), o).duration();
}
BENCHMARK_CAPTURE(plan, actuator_aware, path::PlanMode::actuator_aware)->Arg(10000)->Arg(1000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(plan, cartesian_only, path::PlanMode::cartesian_only)->Arg(10000)->Unit(benchmark::kMillisecond);

// What `cpm run FILE.ngc` does before anything moves (path::prepare_program):
// read the program, check it against the workspace, plan it, and check the
// plan at every knot.
void read_check_plan_gcode(benchmark::State& state) {
  const path::PathQueue q = program(10000);
  const path::ProgramFrame frame;
  std::ostringstream text;
  text.setf(std::ios::fixed);
  text.precision(4);
  text << "G21 G17 G90 G64 P0.05 F6000\n";
  const Vec3 s = frame.to_program(q.start()) * 1e3;
  text << "G0 X" << s.x() << " Y" << s.y() << " Z" << s.z() << "\n";
  for (const path::Segment& seg : q.segments()) {
    const Vec3 e = frame.to_program(seg.end) * 1e3;
    text << "G1 X" << e.x() << " Y" << e.y() << "\n";
  }
  const std::string gcode = text.str();
  path::ProgramOptions o;
  o.planner = path::planner_options(path::MachineLimits{}, machine());
  for (auto _ : state) {
    const path::PreparedProgram p = path::prepare_program(gcode, machine(), o);
    benchmark::DoNotOptimize(p.plan->duration());
  }
}
BENCHMARK(read_check_plan_gcode)->Unit(benchmark::kMillisecond);

// What cpmd does with a program sent to its path queue, in its worker
// thread: the chunks assembled (path_command_t, 100 segments each), the
// whole program planned with the daemon's limits, the plan checked at every
// knot against the workspace and the soft limits.
void cpmd_path_queue(benchmark::State& state) {
  const path::PathQueue q = program(static_cast<int>(state.range(0)));
  const auto chunks = daemon::path_chunks(q, 1);
  const path::PlannerOptions o = path::planner_options(path::MachineLimits{}, machine());
  double motion = 0.0;
  for (auto _ : state) {
    daemon::PathAssembly a;
    for (const auto& c : chunks) benchmark::DoNotOptimize(a.add(c).size());
    const path::Plan p = path::plan_path(a.take(), machine(), o);
    benchmark::DoNotOptimize(path::check_plan(p, machine(), path::SoftLimits{}).has_value());
    motion = p.duration();
  }
  state.counters["segments"] = static_cast<double>(state.range(0));
  state.counters["chunks"] = static_cast<double>(chunks.size());
  state.counters["motion_s"] = motion;
}
BENCHMARK(cpmd_path_queue)->Arg(10000)->Unit(benchmark::kMillisecond);
BENCHMARK(cpmd_path_queue)->Arg(100000)->Iterations(1)->Unit(benchmark::kMillisecond);

// One sample of a prepared plan, as the control cycle takes it.
void sample(benchmark::State& state) {
  const path::Plan p = path::plan_path(program(static_cast<int>(state.range(0))), machine(), path::PlannerOptions{});
  double t = 0.0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(p.sample(t));
    t = t + 1e-3 < p.duration() ? t + 1e-3 : 0.0;
  }
}
BENCHMARK(sample)->Arg(10)->Arg(10000);

}  // namespace

// Speed of the path planner (issue 18): a 10 000-segment program must plan
// in well under 1 s; and of one real-time sample of the prepared plan,
// which must not depend on the program's length (that is tested by
// counting in tests/path/test_sampling.cpp; this shows the time).
#include <benchmark/benchmark.h>

#include <sstream>

#include "cpm/path/gcode.hpp"
#include "cpm/path/planner.hpp"
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

// What `cpm run FILE.ngc` will do before anything moves: read the
// program, check it against the workspace, and plan it.
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
  for (auto _ : state) {
    const path::Program prog = path::read_program(gcode);
    path::check_workspace(prog, machine(), frame);
    const path::Plan p = path::plan_path(path::to_queue(prog, frame, 0.0), machine(), path::PlannerOptions{});
    benchmark::DoNotOptimize(p.duration());
  }
}
BENCHMARK(read_check_plan_gcode)->Unit(benchmark::kMillisecond);

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

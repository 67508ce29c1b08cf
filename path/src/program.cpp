// SPDX-License-Identifier: Apache-2.0
// From text to a checked plan (program.hpp).
#include "cpm/path/program.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "cpm/kinematics/workspace.hpp"
#include "cpm/path/planner.hpp"

namespace cpm::path {

PlannerOptions planner_options(const MachineLimits& limits, const ctl::Machine& machine, PlanMode mode, double jerk) {
  PlannerOptions o;
  o.mode = mode;
  o.cartesian.velocity = limits.velocity;
  o.cartesian.acceleration = limits.acceleration;
  o.cartesian.jerk = jerk;
  o.actuators.velocity = Vec3::Constant(limits.velocity);
  o.actuators.force = Vec3::Constant(std::min(limits.force, machine.force_limit()));
  return o;
}

int line_of(const Plan& plan, int segment) noexcept {
  const auto& lines = plan.geometry().lines;
  return segment >= 0 && static_cast<std::size_t>(segment) < lines.size() ? lines[static_cast<std::size_t>(segment)] : 0;
}

std::optional<PlanFault> check_plan(const Plan& plan, const ctl::Machine& machine, const SoftLimits& soft,
                                    const ProgramFrame* frame) {
  const auto n = static_cast<long>(plan.knots().size());
  for (long k = 0; k <= n; ++k) {
    const double t = std::min(static_cast<double>(k) * plan.knot_period(), plan.duration());
    const PathSample s = plan.sample_path(t);
    const Vec3& p = s.ref.p;
    std::string why;
    if (Status st = kin::check_pose(machine.kinematics(), machine.model().strokes, p, kin::KinematicInputs{}); !st)
      why = describe(st);
    if (why.empty()) why = soft_limit_text(p, soft, frame, 1e-9);
    if (!why.empty()) return PlanFault{t, p, s.segment, line_of(plan, s.segment), why};
  }
  return std::nullopt;
}

PreparedProgram read_checked_program(std::string_view text, const ctl::Machine& machine, const ProgramOptions& o) {
  ReaderOptions ro;
  ro.name = o.name;
  ro.start = o.frame.to_program(o.start.value_or(o.frame.origin));
  PreparedProgram out;
  out.program = read_program(text, ro);
  check_workspace(out.program, machine, o.frame, o.soft, o.name);
  out.queue = to_queue(out.program, o.frame, o.tolerance);
  return out;
}

PreparedProgram prepare_program(std::string_view text, const ctl::Machine& machine, const ProgramOptions& o) {
  PreparedProgram out = read_checked_program(text, machine, o);
  const auto t0 = std::chrono::steady_clock::now();
  out.plan.emplace(plan_path(out.queue, machine, o.planner));
  out.plan_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (const auto f = check_plan(*out.plan, machine, o.soft, &o.frame)) {
    const Vec3 q = o.frame.to_program(f->p) * 1e3;
    char b[160];
    std::snprintf(b, sizeof b, "the planned path passes X%.4f Y%.4f Z%.4f (mm) at t = %.3f s, outside the workspace: ",
                  q.x(), q.y(), q.z(), f->t);
    throw ProgramError(o.name, {Diagnostic{f->line, 0, b + f->why}});
  }
  return out;
}

}  // namespace cpm::path

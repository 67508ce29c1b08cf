// SPDX-License-Identifier: Apache-2.0
// The test contour in simulation (issue 18): the square-diamond-circle at a
// feed the machine holds on straight lines, planned with the actuator
// limits and run through the in-process closed loop (the plant and the
// computed-torque controller on config/machine.yaml): no actuator beyond
// its limit, corners slowed by look-ahead rather than by faults, and the
// contour error within the path tolerance plus what the controller adds.
#include <gtest/gtest.h>

#include "cpm/io/model_file.hpp"
#include "cpm/path/contour.hpp"
#include "cpm/path/gcode.hpp"
#include "cpm/path/test_paths.hpp"
#include "cpm/sim/closed_loop.hpp"
#include "path_fixtures.hpp"

namespace cpm::path::test {
namespace {

struct Outcome {
  sim::RunResult run;
  ContourFigures fig;
  double duration = 0.0;
  bool planned_within = false;
};

Outcome fly(const ctl::Machine& m, const PathQueue& q, const PlannerOptions& o) {
  const Plan plan = plan_path(q, m, o);
  const ctl::Controller c(m, ctl::ControlLaw::computed_torque, ctl::table3_gains(ctl::ControlLaw::computed_torque));
  sim::Plant plant(m, sim::PlantOptions{});
  Outcome out;
  out.run = sim::run_closed_loop(c, plant, plan, sim::LoopOptions{});
  std::vector<RunSample> samples;
  for (const sim::LogRow& r : out.run.log) samples.push_back(RunSample{r.t, r.p, r.p_dot, r.force});
  out.fig = contour(q, plan, samples, o.cartesian.velocity);
  out.duration = plan.duration();
  out.planned_within = plan.summary().actuators_within_limits;
  return out;
}

class Contour : public ::testing::Test {
 protected:
  static constexpr double kTolerance = 50e-6;  // m
  const ctl::Machine machine{io::load_model_file("config/machine.yaml").model};
  const PathQueue queue = to_queue(read_program(square_diamond_circle(200.0, 12000.0)), ProgramFrame{}, kTolerance);
};

TEST_F(Contour, ActuatorAwarePlanHoldsTheContourWithinTheDrives) {
  const Outcome a = fly(machine, queue, PlannerOptions{});
  ASSERT_TRUE(a.run.ok()) << describe(a.run.fault);
  EXPECT_EQ(a.run.metrics.saturated_samples, 0);
  EXPECT_LT(a.fig.peak_force.maxCoeff(), machine.force_limit());
  // Within the path tolerance plus 10 um for the controller (with the
  // model exact it adds about 1 um normal to the path; its lag along the
  // path, the tracking error, is no contour error).
  EXPECT_LE(a.fig.max_error, kTolerance + 10e-6);
  EXPECT_GE(a.fig.feed_held, 0.9);
}

TEST_F(Contour, CartesianPlansAreSlowerOrOverloadTheDrives) {
  const Outcome a = fly(machine, queue, PlannerOptions{});
  PlannerOptions o;
  o.mode = PlanMode::cartesian_only;  // the daemon's 5 m/s^2
  const Outcome slow = fly(machine, queue, o);
  EXPECT_GT(slow.duration, a.duration);
  EXPECT_TRUE(slow.planned_within);
  o.cartesian.acceleration = 30.0;  // as fast, but blind to the drives
  const Outcome fast = fly(machine, queue, o);
  EXPECT_FALSE(fast.planned_within);
  EXPECT_GT(fast.run.metrics.saturated_samples, 0);
  EXPECT_GT(fast.fig.max_error, kTolerance + 10e-6);
}

}  // namespace
}  // namespace cpm::path::test

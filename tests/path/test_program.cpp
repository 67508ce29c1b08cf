// SPDX-License-Identifier: Apache-2.0
// A program from text to a checked plan in one call (path/program.hpp): the
// same plan as reading, checking and planning step by step, the daemon's
// limits mapped onto the planner's options, every fault of a bad program
// with its line and column, and a plan checked at every knot against the
// soft limits.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "cpm/path/program.hpp"
#include "cpm/path/planner.hpp"
#include "cpm/path/test_paths.hpp"
#include "path_fixtures.hpp"

namespace cpm::path {
namespace {

std::string file_text(const std::string& name) {
  std::ifstream f(std::string(CPM_PATH_PROGRAMS) + "/" + name);
  EXPECT_TRUE(f) << name;
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

ProgramOptions options(const ctl::Machine& m) {
  ProgramOptions o;
  o.planner = planner_options(MachineLimits{}, m);
  return o;
}

TEST(Program, LimitsMapOntoThePlannersOptions) {
  MachineLimits L;
  L.velocity = 0.3;
  L.acceleration = 4.0;
  L.force = 90.0;
  const PlannerOptions o = planner_options(L, test::elkady(), PlanMode::actuator_aware, 500.0);
  EXPECT_EQ(o.mode, PlanMode::actuator_aware);
  EXPECT_EQ(o.cartesian.velocity, 0.3);
  EXPECT_EQ(o.cartesian.acceleration, 4.0);
  EXPECT_EQ(o.cartesian.jerk, 500.0);
  EXPECT_EQ(o.actuators.velocity, Vec3::Constant(0.3));
  EXPECT_EQ(o.actuators.force, Vec3::Constant(90.0));
  // The model's force limit caps a larger configured one.
  L.force = 1e4;
  EXPECT_EQ(planner_options(L, test::elkady()).actuators.force, Vec3::Constant(test::elkady().force_limit()));
}

TEST(Program, SameAsReadingCheckingAndPlanningStepByStep) {
  const ctl::Machine& m = test::elkady();
  const std::string text = square_diamond_circle(100.0, 6000.0);
  const ProgramOptions o = options(m);
  const PreparedProgram p = prepare_program(text, m, o);
  ASSERT_TRUE(p.plan);
  const Program prog = read_program(text);
  const Plan plan = plan_path(to_queue(prog, ProgramFrame{}, o.tolerance), m, o.planner);
  EXPECT_EQ(p.program.moves.size(), prog.moves.size());
  EXPECT_EQ(p.plan->summary().duration, plan.summary().duration);
  EXPECT_EQ(p.plan->summary().peak_actuator_force, plan.summary().peak_actuator_force);
  EXPECT_EQ(p.plan->knots().size(), plan.knots().size());
  EXPECT_DOUBLE_EQ(p.queue.tolerance(), 5e-5);
  EXPECT_TRUE(p.plan->summary().actuators_within_limits);
  EXPECT_GT(p.plan_seconds, 0.0);
  // The program's lines reach the plan: every limited stretch names one.
  ASSERT_FALSE(p.plan->summary().limited.empty());
  for (const LimitedStretch& l : p.plan->summary().limited) EXPECT_GT(line_of(*p.plan, l.segment), 0);
}

TEST(Program, TheStartIsWhereThePlatformIs) {
  const ctl::Machine& m = test::elkady();
  ProgramOptions o = options(m);
  o.start = Vec3(0.40, 0.45, 0.31);
  const PreparedProgram p = prepare_program("G21 G90 G1 X10 Y0 Z0 F600\n", m, o);
  EXPECT_LT((p.queue.start() - *o.start).norm(), 1e-12);
  EXPECT_LT((p.plan->sample(0.0).p - *o.start).norm(), 1e-12);
  EXPECT_LT((p.queue.end() - o.frame.to_machine(Vec3(0.010, 0, 0))).norm(), 1e-12);
}

// Each bad program's one fault, where it is.
struct Bad {
  const char* file;
  int line, column;
  const char* words;
};

TEST(Program, BadProgramsAreRefusedWithLineAndColumn) {
  const ctl::Machine& m = test::elkady();
  for (const Bad& b : {Bad{"bad/unknown_word.ngc", 4, 11, "Q"}, Bad{"bad/inconsistent_radius.ngc", 5, 13, "radius"},
                       Bad{"bad/outside_workspace.ngc", 5, 4, "outside the workspace"},
                       Bad{"bad/zero_feed.ngc", 5, 1, "feed"}}) {
    ProgramOptions o = options(m);
    o.name = b.file;
    try {
      (void)prepare_program(file_text(b.file), m, o);
      ADD_FAILURE() << b.file << " was accepted";
    } catch (const ProgramError& e) {
      ASSERT_EQ(e.diagnostics().size(), 1u) << e.what();
      EXPECT_EQ(e.diagnostics()[0].line, b.line) << e.what();
      EXPECT_EQ(e.diagnostics()[0].column, b.column) << e.what();
      EXPECT_NE(e.diagnostics()[0].message.find(b.words), std::string::npos) << e.what();
      const std::string where = std::string(b.file) + ":" + std::to_string(b.line) + ":" + std::to_string(b.column) + ":";
      EXPECT_EQ(std::string(e.what()).rfind(where, 0), 0u) << e.what();
    }
  }
}

TEST(Program, ThePlanIsCheckedAtEveryKnot) {
  const ctl::Machine& m = test::elkady();
  // A square whose third side runs along y = +50 mm: soft limits just below
  // it refuse the plan there, at the line of that side.
  ProgramOptions o = options(m);
  const PreparedProgram p = prepare_program(
      "G21 G90 G17 F3000\nG1 X-50 Y-50\nX50\nY50\nX-50\nY-50\n", m, o);
  EXPECT_FALSE(check_plan(*p.plan, m, SoftLimits{}));
  SoftLimits soft;
  soft.max.y() = o.frame.origin.y() + 0.0499;
  const auto f = check_plan(*p.plan, m, soft);
  ASSERT_TRUE(f);
  EXPECT_GT(f->p.y(), soft.max.y());
  EXPECT_EQ(f->line, 4);  // Y50: the corner's blend reaches the limit first, on its way up
  EXPECT_NE(f->why.find("soft limits on y"), std::string::npos);
  // Every knot before it was inside.
  for (double t = 0.0; t < f->t - 1e-9; t += p.plan->knot_period()) ASSERT_LE(p.plan->sample(t).p.y(), soft.max.y());
}

}  // namespace
}  // namespace cpm::path

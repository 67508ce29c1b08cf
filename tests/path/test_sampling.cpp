// SPDX-License-Identifier: Apache-2.0
// The real-time side of a plan: sampling allocates nothing, throws nothing,
// and costs the same on a program of 10 segments as on one of 10 000 (its
// work is counted, not timed: speed is for the benchmarks).
#include <gtest/gtest.h>

#include <type_traits>

#include "cpm/path/test_paths.hpp"
#include "path_fixtures.hpp"
#include "support/allocation_counter.hpp"

namespace cpm::path::test {
namespace {

static_assert(noexcept(std::declval<const Plan&>().sample(0.0)));
static_assert(noexcept(std::declval<const Plan&>().sample_path(0.0, nullptr)));

TEST(Sampling, AllocatesNothing) {
  const Plan plan = plan_path(square(0.2, 0.3, 1e-4), elkady(), PlannerOptions{});
  const ctl::Trajectory& traj = plan;  // as the loop holds it
  double sum = 0.0;
  const cpm::test::CountAllocations count;
  for (double t = -0.1; t < plan.duration() + 0.1; t += 1e-4) {
    const PathSample s = plan.sample_path(t);
    sum += s.ref.p.x() + traj.sample(t).v.y() + s.s;
  }
  EXPECT_EQ(count.count(), 0u);
  EXPECT_TRUE(std::isfinite(sum));
}

TEST(Sampling, CountingWorks) {
  // The counter sees an allocation, or the test above proves nothing.
  const cpm::test::CountAllocations count;
  auto* v = new std::vector<double>(10);
  delete v;
  EXPECT_GE(count.count(), 1u);
}

struct Work {
  int max_steps = 0, max_pieces = 0;
  long samples = 0;
};

// The most work one sample takes, over the first and middle two seconds.
Work work(const Plan& plan) {
  Work w;
  for (double t0 : {0.0, plan.duration() / 2})
    for (double t = t0; t < t0 + 2.0 && t < plan.duration(); t += 1e-4) {
      SampleCost c;
      (void)plan.sample_path(t, &c);
      w.max_steps = std::max(w.max_steps, c.search_steps);
      w.max_pieces = std::max(w.max_pieces, c.pieces_evaluated);
      ++w.samples;
    }
  return w;
}

TEST(Sampling, CostDoesNotGrowWithTheProgram) {
  const Vec3 centre = kCentre + Vec3(0, -0.03, 0);
  const Plan small = plan_path(zigzag(10, 2e-3, 100, centre, 0.1, 5e-5), elkady(), PlannerOptions{});
  const Plan large = plan_path(zigzag(10000, 2e-3, 100, centre, 0.1, 5e-5), elkady(), PlannerOptions{});
  ASSERT_GT(large.geometry().pieces.size(), 900 * small.geometry().pieces.size() / 10);
  const Work a = work(small), b = work(large);
  EXPECT_EQ(a.max_pieces, 1);
  EXPECT_EQ(b.max_pieces, 1);
  // The search runs only among the pieces passed between two knots (1 ms
  // apart): here a line's end, a short blend and the next line's start,
  // two steps, whatever the program's length.
  EXPECT_LE(a.max_steps, 2);
  EXPECT_LE(b.max_steps, a.max_steps);
  EXPECT_GT(b.samples, 30000);
}

}  // namespace
}  // namespace cpm::path::test

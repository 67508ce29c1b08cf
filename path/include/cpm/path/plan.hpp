// SPDX-License-Identifier: Apache-2.0
// A prepared plan: the speed chosen along the path, as knots of the path
// parameter s(t) every knot_period, built before motion (planner.hpp). The
// real-time cycle samples it by time: the knot's index is t / knot_period,
// s and its two derivatives come from the quintic Hermite interpolant of
// the two knots around t, and the piece holding s is found by binary search
// among the pieces the path passes between those two knots (one or two
// unless the pieces are shorter than the distance covered in one period).
// So the cost of a sample does not grow with the program; it allocates
// nothing and throws nothing.
//
// Frame and units: the machine frame (m, z down), t in s from the plan's
// start. Before 0 the start is held, after duration() the end, at rest.
#pragma once

#include <vector>

#include "cpm/control/trajectory.hpp"
#include "cpm/path/geometry.hpp"
#include "cpm/path/limits.hpp"

namespace cpm::path {

// One knot of s(t): the path parameter (m), its rate (m/s) and acceleration
// (m/s^2), and the piece holding s.
struct Knot {
  double s = 0.0, v = 0.0, a = 0.0;
  int piece = 0;
};

// A sample with where it is on the path.
struct PathSample {
  ctl::TrajectorySample ref;  // p (m), v (m/s), a (m/s^2) of the platform centre
  double s = 0.0;             // path parameter (m)
  double s_dot = 0.0;         // m/s along s
  int piece = 0;              // index into geometry().pieces
  int segment = -1;           // the programmed segment (PathQueue::segments()) it belongs to
};

// Work done by one sample, for the test that it does not grow with the
// program: the binary search's steps and the pieces evaluated.
struct SampleCost {
  int search_steps = 0;
  int pieces_evaluated = 0;
};

// Where the feed was held below the programmed one, and by what.
struct LimitedStretch {
  double s_begin = 0.0, s_end = 0.0;  // m
  int segment = -1;                   // programmed segment at the slowest point
  Limit by = Limit::none;
  int axis = -1;                      // the actuator, for actuator limits
  double speed = 0.0;                 // lowest planned speed there (m/s)
  double feed = 0.0;                  // programmed feed there (m/s)
};

// Figures of the plan as prepared, checked at every knot with the
// machine's inverse kinematics and inverse dynamics (independent of how
// the planner bounded them).
struct PlanSummary {
  PlanMode mode = PlanMode::actuator_aware;
  double duration = 0.0;            // s, to the first knot at rest at the end
  double length = 0.0;              // m of path
  double peak_speed = 0.0;          // |v| (m/s)
  double peak_acceleration = 0.0;   // |a| (m/s^2)
  double peak_jerk = 0.0;           // along the path, |d3s/dt3| between knots (m/s^3)
  Vec3 peak_actuator_speed = Vec3::Zero();         // m/s
  Vec3 peak_actuator_acceleration = Vec3::Zero();  // m/s^2
  Vec3 peak_actuator_force = Vec3::Zero();         // N commanded, feedforward
  double filter_time = 0.0;         // s: the jerk filter's window
  double tangential_acceleration = 0.0;  // m/s^2 the jerk filter was sized for
  int repairs = 0;                  // rounds of local slowing after a check failed
  // Whether every knot is within the actuator limits (the planned force
  // within (1 - reserve) of the drives'): always true of an actuator_aware
  // plan; a cartesian_only plan may not be.
  bool actuators_within_limits = true;
  // Stretches along the path; neighbours less than 1 mm apart and held by
  // the same are one; those shorter than 1 mm (but stops) are only counted.
  std::vector<LimitedStretch> limited;
  int short_limited = 0;
};

class Plan final : public ctl::Trajectory {
 public:
  Plan(Geometry geometry, std::vector<Knot> knots, double knot_period, PlanSummary summary);

  [[nodiscard]] double duration() const noexcept override { return duration_; }
  [[nodiscard]] ctl::TrajectorySample sample(double t) const noexcept override { return sample_path(t).ref; }
  // The same with the place on the path; `cost` (optional) counts the work.
  [[nodiscard]] PathSample sample_path(double t, SampleCost* cost = nullptr) const noexcept;

  [[nodiscard]] const Geometry& geometry() const noexcept { return geometry_; }
  [[nodiscard]] const std::vector<Knot>& knots() const noexcept { return knots_; }
  [[nodiscard]] double knot_period() const noexcept { return dt_; }
  [[nodiscard]] const PlanSummary& summary() const noexcept { return summary_; }

 private:
  Geometry geometry_;
  std::vector<Knot> knots_;
  double dt_;
  double duration_;
  PlanSummary summary_;
};

}  // namespace cpm::path

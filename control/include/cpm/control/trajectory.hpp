// SPDX-License-Identifier: Apache-2.0
// Reference trajectories of the platform centre in the machine frame
// (m, m/s, m/s^2). A trajectory is prepared (and validated) before the loop;
// sampling it is noexcept and allocation-free.
#pragma once

#include <array>

#include "cpm/control/machine.hpp"

namespace cpm::ctl {

struct TrajectorySample {
  Vec3 p = Vec3::Zero();
  Vec3 v = Vec3::Zero();
  Vec3 a = Vec3::Zero();
};

class Trajectory {
 public:
  virtual ~Trajectory() = default;
  [[nodiscard]] virtual double duration() const noexcept = 0;
  // Sample at time t (s) from the start. Before 0 the start is held, after
  // duration() the end, both at rest (v = a = 0).
  [[nodiscard]] virtual TrajectorySample sample(double t) const noexcept = 0;
};

// The plane a circle lies in, by the two machine axes that span it.
enum class CirclePlane { xy, yz, zx };

struct CircleSpec {
  Vec3 centre = Vec3(0.425, 0.425, 0.300);
  double radius = 0.175;          // m
  CirclePlane plane = CirclePlane::xy;
  double angular_speed = 1.5707963267948966;  // rad/s; > 0 is counter-clockwise (from first to second axis)
  double start_angle = 0.0;       // rad, from the plane's first axis
  double cruise_time = 4.0;       // s at full angular speed
  double ramp_time = 0.0;         // s to reach (and leave) full speed; 0 = start and stop abruptly
};

// A circle at constant angular speed, optionally entered and left by a smooth
// ramp of the angular speed (quintic: zero acceleration at both ends of the
// ramp, so the commanded force has no step).
// Elkady's circle is CircleSpec{} with ramp_time = 0: the reference starts
// at 0.275 m/s while the machine is at rest.
class CircleTrajectory final : public Trajectory {
 public:
  explicit CircleTrajectory(const CircleSpec& spec);  // throws Error on bad spec
  [[nodiscard]] double duration() const noexcept override;
  [[nodiscard]] TrajectorySample sample(double t) const noexcept override;
  [[nodiscard]] const CircleSpec& spec() const noexcept { return spec_; }

 private:
  // Angle travelled, its rate and acceleration at time t.
  void angle(double t, double& s, double& s_dot, double& s_dd) const noexcept;
  CircleSpec spec_;
  int axis_a_ = 0, axis_b_ = 1;
};

// Limits of a point-to-point move along its straight path.
struct MotionLimits {
  double velocity = 0.1;       // m/s
  double acceleration = 1.0;   // m/s^2
  double jerk = 50.0;          // m/s^3
  void validate() const;
};

// A rest-to-rest straight move with a jerk-limited (seven-phase) speed
// profile that respects the velocity, acceleration and jerk limits and is
// time-optimal for them.
class PointToPoint final : public Trajectory {
 public:
  PointToPoint(const Vec3& from, const Vec3& to, const MotionLimits& limits);  // throws Error
  [[nodiscard]] double duration() const noexcept override { return t_end_; }
  [[nodiscard]] TrajectorySample sample(double t) const noexcept override;
  [[nodiscard]] double peak_velocity() const noexcept { return v_peak_; }
  [[nodiscard]] double peak_acceleration() const noexcept { return a_peak_; }

 private:
  Vec3 from_, dir_;
  double length_ = 0, v_peak_ = 0, a_peak_ = 0, t_end_ = 0;
  // Seven phases of constant jerk: start time, jerk, and the path state
  // (s, s_dot, s_dd) at the start of each.
  std::array<double, 8> t0_{}, jerk_{}, s0_{}, v0_{}, a0_{};
};

// Check that a trajectory stays where the machine can go: every sample at
// step `dt` (and the end point) finite, inside the strokes, within the limbs'
// reach and away from singularity; and, for limits given > 0, within the
// velocity and acceleration limits. Throws Error saying when (s), where (mm)
// and which limit.
void validate_trajectory(const Trajectory& traj, const Machine& machine, double dt,
                         double max_speed = 0.0, double max_acceleration = 0.0);

}  // namespace cpm::ctl

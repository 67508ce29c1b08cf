// SPDX-License-Identifier: Apache-2.0
// A trajectory through timed setpoints (a chunk of a setpoint stream),
// interpolated by cubic Hermite splines on the given positions and
// velocities. Fixed capacity, so it can be copied into the real-time queue
// without allocation.
#pragma once

#include <array>

#include "cpm/control/trajectory.hpp"

namespace cpm::daemon {

class StreamTrajectory final : public ctl::Trajectory {
 public:
  static constexpr int kMaxPoints = 100;
  StreamTrajectory() = default;
  // t (s, t[0] = 0, strictly increasing), p (m), v (m/s); 2 <= n <= kMaxPoints.
  // Throws Error naming the point and what is wrong.
  StreamTrajectory(int n, const double* t, const double (*p)[3], const double (*v)[3]);
  [[nodiscard]] double duration() const noexcept override { return n_ > 0 ? t_[n_ - 1] : 0.0; }
  // Before 0 and from the end on: the end points, at rest; at 0 the first
  // point with its velocity.
  [[nodiscard]] ctl::TrajectorySample sample(double t) const noexcept override;
  [[nodiscard]] int size() const noexcept { return n_; }
  // The velocity given at the last point (m/s): non-zero means the stream
  // goes on, and the commander owes the next chunk before this one ends.
  [[nodiscard]] Vec3 end_velocity() const noexcept { return n_ > 0 ? v_[n_ - 1] : Vec3::Zero(); }

 private:
  int n_ = 0;
  std::array<double, kMaxPoints> t_{};
  std::array<Vec3, kMaxPoints> p_{}, v_{};
};

}  // namespace cpm::daemon

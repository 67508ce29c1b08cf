// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/ramp.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace cpm::daemon {

void Ramp::reset(const Vec3& at) noexcept {
  p = at;
  v.setZero();
  a.setZero();
}

double Ramp::stopping_distance(double accel) const noexcept {
  const double s = v.norm();
  return accel > 0.0 ? s * s / (2.0 * accel) : 0.0;
}

void Ramp::step(const Vec3& v_target, double accel, const Vec3& lo, const Vec3& hi, double dt) noexcept {
  // The speed toward an end that can still stop before it. Discretely: the
  // position advances by the mean of two velocities, so a velocity v_1 after
  // this step leaves v_1 dt/2 + v_1^2/(2a) to stop in from the position
  // after the step; keep it within the distance left.
  Vec3 target = v_target;
  for (int i = 0; i < 3; ++i) {
    const double up = hi[i] - p[i], down = p[i] - lo[i];
    const double ad = accel * dt;
    auto cap = [&](double room) {
      if (!std::isfinite(room)) return std::numeric_limits<double>::infinity();
      if (room <= 0.0) return 0.0;
      // v dt/2 + v^2/(2a) <= room  ->  v <= -a dt/2 + sqrt((a dt/2)^2 + 2 a room)
      return std::max(0.0, -0.5 * ad + std::sqrt(0.25 * ad * ad + 2.0 * accel * room));
    };
    target[i] = std::clamp(target[i], -cap(down), cap(up));
  }
  Vec3 dv = target - v;
  const double n = dv.norm(), most = accel * dt;
  if (n > most && n > 0.0) dv *= most / n;
  const Vec3 v0 = v;
  v += dv;
  p += 0.5 * (v0 + v) * dt;
  a = dv / dt;
  // Never outside: a rounding or a box that moved inward stops the coordinate there.
  for (int i = 0; i < 3; ++i) {
    if (p[i] > hi[i]) {
      p[i] = hi[i];
      if (v[i] > 0.0) v[i] = 0.0;
    } else if (p[i] < lo[i]) {
      p[i] = lo[i];
      if (v[i] < 0.0) v[i] = 0.0;
    }
  }
}

void Ramp::step_to(const Vec3& target, double speed, double accel, double dt) noexcept {
  // Per coordinate, the discrete braking curve. The position advances by
  // the new velocity (p += v dt); from v1 the steps of accel * dt down to
  // rest then cover at most v1^2 / (2 accel) - v1 dt / 2 + accel dt^2 / 8
  // (the last term bounds the partial step), so the largest v1 that can
  // still stop within the distance e left satisfies
  //   v1^2 / (2 accel) + v1 dt / 2 <= e - accel dt^2 / 8.
  // Once e is within one period at a speed it can stop from at once, it
  // lands on the target exactly.
  const double ad = accel * dt;
  const Vec3 v0 = v;
  for (int i = 0; i < 3; ++i) {
    const double e = target[i] - p[i];
    const double room = std::abs(e);
    if (room == 0.0 && v0[i] == 0.0) continue;
    const double land = std::copysign(room / dt, e);
    if (room / dt <= ad && std::abs(land - v0[i]) <= ad) {
      v[i] = land;
      p[i] = target[i];
      continue;
    }
    const double r = std::max(0.0, room - 0.125 * accel * dt * dt);
    const double brake = -0.5 * ad + std::sqrt(0.25 * ad * ad + 2.0 * accel * r);
    v[i] = std::clamp(std::copysign(std::min(speed, brake), e), v0[i] - ad, v0[i] + ad);
    p[i] += v[i] * dt;
  }
  a = (v - v0) / dt;
}

}  // namespace cpm::daemon

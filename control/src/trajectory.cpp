// SPDX-License-Identifier: Apache-2.0
#include "cpm/control/trajectory.hpp"

#include <cmath>
#include <sstream>

namespace cpm::ctl {
namespace {

// Quintic ramp of the speed: h(0) = 0, h(1) = 1, h'(0) = h'(1) = 0.
inline double ramp_h(double x) { return x * x * x * (10.0 + x * (-15.0 + 6.0 * x)); }
inline double ramp_dh(double x) { return 30.0 * x * x * (1.0 + x * (-2.0 + x)); }
inline double ramp_H(double x) { return x * x * x * x * (2.5 + x * (-3.0 + x)); }  // integral of h

}  // namespace

CircleTrajectory::CircleTrajectory(const CircleSpec& s) : spec_(s) {
  if (!s.centre.allFinite()) throw Error("circle: centre must be finite");
  if (!std::isfinite(s.radius) || !(s.radius > 0.0))
    throw Error("circle: radius must be a finite length > 0 m, got " + std::to_string(s.radius));
  if (!std::isfinite(s.angular_speed) || s.angular_speed == 0.0)
    throw Error("circle: angular speed must be finite and non-zero");
  if (!std::isfinite(s.start_angle)) throw Error("circle: start angle must be finite");
  if (!std::isfinite(s.cruise_time) || s.cruise_time < 0.0)
    throw Error("circle: cruise time must be >= 0 s");
  if (!std::isfinite(s.ramp_time) || s.ramp_time < 0.0)
    throw Error("circle: ramp time must be >= 0 s");
  if (s.cruise_time + s.ramp_time <= 0.0) throw Error("circle: duration must be > 0 s");
  switch (s.plane) {
    case CirclePlane::xy: axis_a_ = 0; axis_b_ = 1; break;
    case CirclePlane::yz: axis_a_ = 1; axis_b_ = 2; break;
    case CirclePlane::zx: axis_a_ = 2; axis_b_ = 0; break;
  }
}

double CircleTrajectory::duration() const noexcept {
  return 2.0 * spec_.ramp_time + spec_.cruise_time;
}

void CircleTrajectory::angle(double t, double& s, double& s_dot, double& s_dd) const noexcept {
  const double w = spec_.angular_speed;
  const double R = spec_.ramp_time;
  const double C = spec_.cruise_time;
  s_dot = s_dd = 0.0;
  if (t <= 0.0) {
    s = 0.0;
    // Without a ramp the circle starts at full speed at t = 0 (Elkady's test).
    if (t == 0.0 && R == 0.0) s_dot = w;
    return;
  }
  if (t >= 2.0 * R + C) {
    s = w * (R + C);
    return;
  }
  if (t < R) {
    const double x = t / R;
    s = w * R * ramp_H(x);
    s_dot = w * ramp_h(x);
    s_dd = w / R * ramp_dh(x);
  } else if (t <= R + C) {
    s = w * (0.5 * R + (t - R));
    s_dot = w;
  } else {
    const double x = (2.0 * R + C - t) / R;
    s = w * (R + C) - w * R * ramp_H(x);
    s_dot = w * ramp_h(x);
    s_dd = -w / R * ramp_dh(x);
  }
}

TrajectorySample CircleTrajectory::sample(double t) const noexcept {
  double s, s_dot, s_dd;
  angle(t, s, s_dot, s_dd);
  const double a = spec_.start_angle + s;
  const double c = std::cos(a), sn = std::sin(a);
  const double r = spec_.radius;
  TrajectorySample out;
  out.p = spec_.centre;
  out.p[axis_a_] += r * c;
  out.p[axis_b_] += r * sn;
  out.v[axis_a_] = -r * sn * s_dot;
  out.v[axis_b_] = r * c * s_dot;
  out.a[axis_a_] = -r * sn * s_dd - r * c * s_dot * s_dot;
  out.a[axis_b_] = r * c * s_dd - r * sn * s_dot * s_dot;
  return out;
}

void MotionLimits::validate() const {
  auto check = [](double v, const char* what, const char* unit) {
    if (!std::isfinite(v) || !(v > 0.0))
      throw Error(std::string("motion limits: ") + what + " must be a finite value > 0 " + unit);
  };
  check(velocity, "velocity", "m/s");
  check(acceleration, "acceleration", "m/s^2");
  check(jerk, "jerk", "m/s^3");
}

PointToPoint::PointToPoint(const Vec3& from, const Vec3& to, const MotionLimits& lim)
    : from_(from) {
  if (!from.allFinite() || !to.allFinite()) throw Error("point-to-point: end points must be finite");
  lim.validate();
  length_ = (to - from).norm();
  dir_ = length_ > 0.0 ? Vec3((to - from) / length_) : Vec3::Zero();
  const double A = lim.acceleration, Jm = lim.jerk;
  // Acceleration phase for a peak speed V: duration Ta, distance V Ta / 2.
  auto accel_time = [&](double V, double& Tj) {
    if (V >= A * A / Jm) {
      Tj = A / Jm;
      return V / A + Tj;
    }
    Tj = std::sqrt(V / Jm);
    return 2.0 * Tj;
  };
  double V = lim.velocity, Tj = 0.0;
  double Ta = accel_time(V, Tj);
  if (V * Ta > length_) {
    // The move is too short to reach full speed: the largest V with V Ta(V) = length.
    V = 0.5 * A * (-A / Jm + std::sqrt(A * A / (Jm * Jm) + 4.0 * length_ / A));
    if (V < A * A / Jm) V = std::cbrt(length_ * length_ * Jm / 4.0);
    Ta = accel_time(V, Tj);
  }
  const double Tv = V > 0.0 ? std::max(0.0, (length_ - V * Ta) / V) : 0.0;
  v_peak_ = V;
  a_peak_ = Jm * Tj;
  const double dur[7] = {Tj, Ta - 2.0 * Tj, Tj, Tv, Tj, Ta - 2.0 * Tj, Tj};
  const double jerk[7] = {Jm, 0.0, -Jm, 0.0, -Jm, 0.0, Jm};
  t0_[0] = s0_[0] = v0_[0] = a0_[0] = 0.0;
  for (int k = 0; k < 7; ++k) {
    const double h = std::max(0.0, dur[k]);
    jerk_[k] = jerk[k];
    t0_[k + 1] = t0_[k] + h;
    a0_[k + 1] = a0_[k] + jerk[k] * h;
    v0_[k + 1] = v0_[k] + a0_[k] * h + 0.5 * jerk[k] * h * h;
    s0_[k + 1] = s0_[k] + v0_[k] * h + 0.5 * a0_[k] * h * h + jerk[k] * h * h * h / 6.0;
  }
  t_end_ = t0_[7];
  // Rounding leaves the end a hair off: the last state is forced to the target.
  if (length_ > 0.0 && std::abs(s0_[7] - length_) > 1e-9 * std::max(1.0, length_))
    throw Error("point-to-point: internal profile error");
}

TrajectorySample PointToPoint::sample(double t) const noexcept {
  TrajectorySample out;
  if (t <= 0.0 || length_ == 0.0) {
    out.p = from_;
    return out;
  }
  if (t >= t_end_) {
    out.p = from_ + dir_ * length_;
    return out;
  }
  int k = 0;
  while (k < 6 && t >= t0_[k + 1]) ++k;
  const double h = t - t0_[k];
  const double j = jerk_[k];
  const double a = a0_[k] + j * h;
  const double v = v0_[k] + a0_[k] * h + 0.5 * j * h * h;
  const double s = s0_[k] + v0_[k] * h + 0.5 * a0_[k] * h * h + j * h * h * h / 6.0;
  out.p = from_ + dir_ * s;
  out.v = dir_ * v;
  out.a = dir_ * a;
  return out;
}

void validate_trajectory(const Trajectory& traj, const Machine& machine, double dt,
                         double max_speed, double max_acceleration) {
  if (!(dt > 0.0) || !std::isfinite(dt)) throw Error("trajectory check: step must be > 0 s");
  const double T = traj.duration();
  if (!std::isfinite(T) || T < 0.0) throw Error("trajectory: duration is not a finite time >= 0 s");
  if (T / dt > 1e8) throw Error("trajectory: duration is absurdly long for the check step");
  const long n = static_cast<long>(std::ceil(T / dt));
  kin::KinematicInputs in;
  for (long k = 0; k <= n; ++k) {
    const double t = std::min(T, k * dt);
    const TrajectorySample s = traj.sample(t);
    std::ostringstream where;
    where << "trajectory at t = " << t << " s, p = (" << s.p.x() * 1e3 << ", " << s.p.y() * 1e3
          << ", " << s.p.z() * 1e3 << ") mm: ";
    if (!s.p.allFinite() || !s.v.allFinite() || !s.a.allFinite())
      throw Error(where.str() + "a position, velocity or acceleration is not finite");
    if (Status st = kin::check_pose(machine.kinematics(), machine.model().strokes, s.p, in); !st)
      throw Error(where.str() + describe(st));
    if (max_speed > 0.0 && s.v.norm() > max_speed * (1.0 + 1e-9)) {
      where << "speed " << s.v.norm() << " m/s exceeds the limit " << max_speed << " m/s";
      throw Error(where.str());
    }
    if (max_acceleration > 0.0 && s.a.norm() > max_acceleration * (1.0 + 1e-9)) {
      where << "acceleration " << s.a.norm() << " m/s^2 exceeds the limit " << max_acceleration
            << " m/s^2";
      throw Error(where.str());
    }
  }
}

}  // namespace cpm::ctl

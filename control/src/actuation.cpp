// SPDX-License-Identifier: Apache-2.0
#include "cpm/control/actuation.hpp"

#include <cmath>
#include <sstream>

namespace cpm::ctl {

void check_delay_fits(double tau, double rate_hz) {
  if (!std::isfinite(tau) || tau < 0.0 || !std::isfinite(rate_hz) || !(rate_hz > 0.0))
    throw Error("actuation_delay: tau must be >= 0 s and the rate > 0 Hz");
  // The command acting at t_k is ceil(tau / T) periods old; the one given at
  // t_k is kept too.
  const double periods = std::ceil(tau * rate_hz - 1e-9);
  if (periods + 2 > kCommandHistoryCapacity) {
    std::ostringstream os;
    os << "actuation_delay " << tau * 1e3 << " ms at " << rate_hz << " Hz is " << periods
       << " periods; the command history keeps " << kCommandHistoryCapacity - 2
       << ": lower the rate or the delay";
    throw Error(os.str());
  }
}

void CommandHistory::reset(const Vec3& before) noexcept {
  head_ = 0;
  size_ = 0;
  before_ = {-std::numeric_limits<double>::infinity(), before};
}

void CommandHistory::push(double t, const Vec3& force) noexcept {
  Entry& slot = buf_[static_cast<std::size_t>(head_)];
  if (size_ == kCommandHistoryCapacity) before_ = slot;  // the oldest, about to be overwritten
  else ++size_;
  slot = {t, force};
  head_ = (head_ + 1) % kCommandHistoryCapacity;
}

void CommandHistory::amend_last(const Vec3& force) noexcept {
  if (size_ == 0) return;
  buf_[static_cast<std::size_t>((head_ - 1 + kCommandHistoryCapacity) % kCommandHistoryCapacity)].force = force;
}

const Vec3* CommandHistory::acting(double s, double tau, double snap) const noexcept {
  for (int k = 0; k < size_; ++k)
    if (at(k).t + tau <= s + snap) return &at(k).force;
  // Older than every kept command: the one before them, if it had started.
  return before_.t + tau <= s + snap ? &before_.force : nullptr;
}

double CommandHistory::next_switch(double a, double b, double tau, double snap) const noexcept {
  double first = b;
  for (int k = 0; k < size_; ++k) {
    const double w = at(k).t + tau;
    if (w <= a + snap) break;  // newest first: the rest switched earlier
    if (w < b - snap) first = w;
  }
  return first;
}

namespace {

// One classical RK4 step of length h under a constant command. The same
// arithmetic as the plant always had, so that tau = 0 changes nothing.
Status rk4(const Machine& m, const kin::KinematicInputs& in, const Vec3& force, double h, Vec3& p,
           Vec3& v) noexcept {
  Vec3 a1, a2, a3, a4;
  if (Status s = m.forward_dynamics(p, v, force, in, a1); !s) return s;
  const Vec3 v1 = v;
  const Vec3 v2 = v + 0.5 * h * a1;
  if (Status s = m.forward_dynamics(p + 0.5 * h * v1, v2, force, in, a2); !s) return s;
  const Vec3 v3 = v + 0.5 * h * a2;
  if (Status s = m.forward_dynamics(p + 0.5 * h * v2, v3, force, in, a3); !s) return s;
  const Vec3 v4 = v + h * a3;
  if (Status s = m.forward_dynamics(p + h * v3, v4, force, in, a4); !s) return s;
  p += h / 6.0 * (v1 + 2.0 * v2 + 2.0 * v3 + v4);
  v += h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4);
  return {};
}

}  // namespace

Status integrate_delayed(const Machine& m, const kin::KinematicInputs& in, const CommandHistory& history,
                         double tau, double t0, double duration, int steps, Vec3& p, Vec3& v) noexcept {
  if (!std::isfinite(t0) || !std::isfinite(tau) || !std::isfinite(duration) || !(duration > 0.0) || steps < 1)
    return Status::failure(Fault::not_finite);
  const double h = duration / steps;
  // Switching instants this close to a step boundary are rounding of an
  // integer delay (t_j + n T against t_k): take them at the boundary.
  const double snap = 1e-6 * h;
  Vec3 q = p, w = v;
  for (int i = 0; i < steps; ++i) {
    const double a = t0 + i * h;
    const double b = t0 + (i + 1) * h;
    for (double x = a; x < b;) {
      const double y = history.next_switch(x, b, tau, snap);
      // The force over [x, y) is the one acting at its middle: no switch
      // lies strictly inside, and one snapped to an end is decided clearly.
      const Vec3* f = history.acting(0.5 * (x + y), tau);
      if (!f) return Status::failure(Fault::history_short, -1, tau);
      // The whole step keeps exactly h (b - a may differ from it in the last bit).
      if (Status s = rk4(m, in, *f, (x == a && y == b) ? h : y - x, q, w); !s) return s;
      x = y;
    }
  }
  p = q;
  v = w;
  return {};
}

}  // namespace cpm::ctl

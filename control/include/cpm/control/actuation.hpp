// SPDX-License-Identifier: Apache-2.0
// Dead time between a force command and the force it makes (the
// actuation_delay effect of docs/effects.md): the command given at t_k acts over
// [t_k + tau, t_k+1 + tau) instead of [t_k, t_k+1).
//
// Both sides of the loop need the same two things: the plant, to apply the
// commands late (sim::Plant), and the controller, to predict where the
// platform will be when its next command starts to act (ctl::Controller).
// So both keep a CommandHistory of the commands they gave, stamped with the
// time each was given, and integrate the forward dynamics through it with
// integrate_delayed(), which switches the held force at the exact instant
// t_j + tau, inside an RK4 sub-step if it falls there.
//
// Everything here is allocation-free and noexcept (the control cycle and the
// plant step use it); the history is a fixed-capacity ring.
#pragma once

#include <array>
#include <limits>

#include "cpm/control/machine.hpp"

namespace cpm::ctl {

// Commands kept: enough for the largest delay docs/effects.md allows (0.05 s) at
// the highest loop rate the daemon accepts (10 kHz), plus the command that
// is acting and the one being given. 16 KiB.
inline constexpr int kCommandHistoryCapacity = 502;

// Throws Error when a delay of tau (s) at this loop rate (Hz) needs more
// commands than a CommandHistory keeps: checked where a model meets a rate
// (daemon start, model load, sim::run_closed_loop), never in the cycle.
void check_delay_fits(double tau, double rate_hz);

class CommandHistory {
 public:
  // Forget every command; until the first one acts the actuators apply
  // `before` (N per actuator): zero for drives that were off.
  void reset(const Vec3& before = Vec3::Zero()) noexcept;
  // The command (N per actuator) given at time t (s). Times must not
  // decrease. When the ring is full the oldest command is dropped; it
  // stays known as the force before the others.
  void push(double t, const Vec3& force) noexcept;
  // The last command pushed was changed after it was made (a controller
  // switch's force difference added): record what was really given.
  void amend_last(const Vec3& force) noexcept;

  // The force acting at time s under the delay tau: the latest command with
  // t_j + tau <= s (switching instants within `snap` of s count as reached).
  // nullptr when that command was dropped (the history is too short).
  [[nodiscard]] const Vec3* acting(double s, double tau, double snap = 0.0) const noexcept;
  // The first switching instant t_j + tau in (a + snap, b - snap), or b.
  [[nodiscard]] double next_switch(double a, double b, double tau, double snap) const noexcept;

  [[nodiscard]] int size() const noexcept { return size_; }
  // The k-th newest command (k = 0: the last pushed), k < size().
  [[nodiscard]] double time(int k) const noexcept { return at(k).t; }
  [[nodiscard]] const Vec3& force(int k) const noexcept { return at(k).force; }

 private:
  struct Entry {
    double t = 0.0;
    Vec3 force = Vec3::Zero();
  };
  [[nodiscard]] const Entry& at(int k) const noexcept {
    return buf_[static_cast<std::size_t>((head_ - 1 - k + 2 * kCommandHistoryCapacity) % kCommandHistoryCapacity)];
  }
  std::array<Entry, kCommandHistoryCapacity> buf_{};
  int head_ = 0;  // where the next command goes
  int size_ = 0;
  Entry before_{-std::numeric_limits<double>::infinity(), Vec3::Zero()};
};

// Integrate the forward dynamics of `m` from (p, v) at t0 over `duration`
// (s) in `steps` equal RK4 steps, under the commands of `history` delayed by
// tau (s). A switching instant inside a step splits that step in two, so
// the force is exactly piecewise constant; instants within 1e-6 of a step of
// a step boundary are taken at the boundary (an integer delay then never
// splits). With tau = 0 and the command of t0 last pushed, this is the
// plain zero-order hold, bit for bit. `in` gives the kinematic inputs
// (direction, time) held over the interval. On failure p and v are left as
// they were.
Status integrate_delayed(const Machine& m, const kin::KinematicInputs& in, const CommandHistory& history,
                         double tau, double t0, double duration, int steps, Vec3& p, Vec3& v) noexcept;

}  // namespace cpm::ctl

// SPDX-License-Identifier: Apache-2.0
// The plant: the true machine, which may differ from the controller's model
// in its kinematic parameters, masses and effects.
//
// State: platform point p (m) and velocity p_dot (m/s) in the machine frame.
// Input: the actuator forces commanded (N), held constant over a control
// period (zero-order hold) while the state is integrated by RK4 in equal
// sub-steps. When the truth has an actuation_delay tau, the command given
// at step k acts over [t_k + tau, t_k+1 + tau): the plant keeps the
// commands it was given (ctl::CommandHistory, fixed capacity) and switches
// the held force at the exact instant t_k + tau, splitting the RK4 sub-step
// it falls in. Before the first command acts, the force given to reset()
// acts (zero by default: drives that were off). Output: what the drives' encoders read (m, m/s), with optional
// quantisation and noise.
//
// Forward dynamics, per sub-step stage:
//   d = IK_true(p), d_dot = J^-1 p_dot,
//   F_d = (1 + k) F_cmd - effects(d, d_dot),
//   p_dd = M^-1 (J^-T F_d - G p_dot - K).
#pragma once

#include <array>
#include <cstdint>
#include <random>

#include "cpm/control/actuation.hpp"
#include "cpm/control/machine.hpp"

namespace cpm::sim {

using ctl::Machine;

struct EncoderModel {
  double resolution = 0.0;       // position quantum (m); 0 = ideal
  double position_noise = 0.0;   // standard deviation (m)
  double velocity_noise = 0.0;   // standard deviation (m/s)
  std::uint64_t seed = 1;
  void validate() const;
};

struct PlantOptions {
  int substeps = 10;                 // RK4 steps per control period
  EncoderModel encoder;
  double direction_threshold = 1e-6; // |d_dot| (m/s) above which an axis has a direction of motion
  void validate() const;
};

struct EncoderReading {
  Vec3 d = Vec3::Zero();
  Vec3 d_dot = Vec3::Zero();
};

class Plant {
 public:
  Plant(const Machine& truth, const PlantOptions& options);  // keeps a reference to truth

  // Place the platform at p with velocity p_dot, at time 0, and forget the
  // commands: until the first one acts under the delay, the actuators apply
  // force_before (N). Fails outside the workspace.
  Status reset(const Vec3& p, const Vec3& p_dot = Vec3::Zero(),
               const Vec3& force_before = Vec3::Zero()) noexcept;
  // Forget the commands given: `acting` (N per actuator) acts until the next
  // command does (under the truth's delay). For drives that are given
  // commands while the brakes hold the platform (a reset would also rewind
  // the clock and the directions of motion).
  void forget_commands(const Vec3& acting) noexcept { commands_.reset(acting); }
  // Advance by dt (s) under the commanded actuator forces held constant
  // (from t + tau when the truth has an actuation delay tau). Fails when the
  // command acting is older than the history keeps (a tau of more than
  // ctl::kCommandHistoryCapacity - 2 steps).
  // Fails (and keeps the last good state) when the platform leaves the
  // strokes or the limbs' reach.
  Status step(const Vec3& force_command, double dt) noexcept;
  // The encoders now: the true actuator positions through the true
  // kinematics (with its backlash, cyclic error ...), quantised, with noise.
  EncoderReading read() noexcept;
  // Platform acceleration for a state and command (the forward dynamics).
  Status acceleration(const Vec3& p, const Vec3& p_dot, const Vec3& force_command,
                      Vec3& p_dd) const noexcept;

  [[nodiscard]] const Vec3& position() const noexcept { return p_; }
  [[nodiscard]] const Vec3& velocity() const noexcept { return p_dot_; }
  [[nodiscard]] double time() const noexcept { return t_; }
  [[nodiscard]] const kin::KinematicInputs& kinematic_inputs() const noexcept { return kin_in_; }
  // True actuator positions and velocities (no encoder model).
  Status actuator_state(Vec3& d, Vec3& d_dot) const noexcept;
  [[nodiscard]] const Machine& truth() const noexcept { return *truth_; }

 private:
  const Machine* truth_;
  PlantOptions opt_;
  Vec3 p_ = Vec3::Zero(), p_dot_ = Vec3::Zero();
  double t_ = 0.0;
  kin::KinematicInputs kin_in_;
  ctl::CommandHistory commands_;  // the commands given, stamped with their time (for the delay)
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
};

}  // namespace cpm::sim

// SPDX-License-Identifier: Apache-2.0
// Whether a control law with given gains can hold the machine at the loop's
// rate: the check the daemon makes before it takes a law or gains (issue 17),
// on its command thread, never in the control cycle. Pure; it allocates.
//
// Each actuator is checked as one mass m under the law, sampled at T = 1 /
// rate_hz with a zero-order hold, the command acting from t + tau (the
// model's actuation delay, any multiple or fraction of T), and the velocity
// as cpmd gets it (VelocityMeasurement):
//   x_k+1 = Phi x_k + B1 u_k-n-1 + B0 u_k-n,  tau = (n + f) T,
//   u_k = -kp x_k - kd v_k,
// the first f T of a period under the older command, the rest under the newer
// (the ZOH integral split there). Its characteristic polynomial is
//   z^(n+1) (z - 1)^2 + kp [(z - 1) b_x(z) + T b_v(z)] + kd (z - 1) b_v(z)
// (exact velocity; with the difference, u = -(kp + kd (1 - 1/z) / T) x and one
// more power of z), b(z) = B0 z + B1. The loop holds when every root lies
// within max_spectral_radius(rate_hz) (Schur-Cohn test, docs/model.md "Gains
// the daemon refuses").
//
//  * PD laws act on the actuators (kp N/m, kd N s/m): m is the effective
//    mass, the diagonal of the actuator-space inertia J^T M J (J = dp/dd,
//    the calibrated kinematics), over a grid of poses on the strokes; the
//    lightest and the heaviest both count. The coupling between actuators is
//    ignored (docs/model.md says what that costs).
//  * Computed torque normalises by M (kp 1/s^2, kd 1/s): m = 1.
//  * The check gives no credit for the controller's prediction across the
//    delay: that makes the loop the undelayed one only while the model is
//    exact, and the bound must hold when it is not.
//  * pd, without the model's gravity, holds the weight by its stiffness
//    alone: its static deflection |holding force| / kp must stay within
//    max_sag.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "cpm/control/controller.hpp"

namespace cpm::ctl {

// How the controller's velocity relates to the encoder positions.
enum class VelocityMeasurement : std::uint8_t {
  difference,  // (d_k - d_k-1) / T: cpmd on CANopen drives (positions sampled at SYNC); the stricter of the two
  exact,       // the velocity at the sample (the simulator's encoders)
};

// The slowest closed-loop pole a check accepts decays with this time
// constant (s): |z| < exp(-T / kSlowestTimeConstant), 0.999 at 1 kHz. A loop
// slower than that does not hold the machine against anything, and the
// bound keeps every pole a little inside the unit circle.
inline constexpr double kSlowestTimeConstant = 1.0;
double max_spectral_radius(double rate_hz) noexcept;

// Whether a law with these gains can hold the machine at the loop's rate.
struct GainVerdict {
  bool ok = true;
  std::string reason;            // "" when ok; else one sentence with the figures (N/m, N s/m, 1/s^2, 1/s, kg, mm, Hz)
  int axis = -1;                 // the actuator (0..2) the verdict is about, -1 none
  double spectral_radius = 0.0;  // largest |z| of the sampled closed loop over the axes and masses checked
  double sag = 0.0;              // largest static deflection under the platform's weight (m); 0 for laws with gravity
  Vec3 mass_min = Vec3::Zero();  // effective mass range per actuator over the workspace (kg); 1 for computed torque
  Vec3 mass_max = Vec3::Zero();
  // Per actuator, the range of each gain, the other as given, over which every
  // pole stays within max_spectral_radius for both masses (kp at the given
  // kd, kd at the given kp; units of the law; 0, 0 when there is none).
  Vec3 kp_min = Vec3::Zero(), kp_max = Vec3::Zero();
  Vec3 kd_min = Vec3::Zero(), kd_max = Vec3::Zero();
};

// rate_hz: the loop's rate (Hz, > 0); max_sag: the largest static deflection
// allowed (m, > 0; the daemon's limits.following_error). Throws Error for a
// bad rate or max_sag, or when no pose of the strokes is in the workspace;
// bad gains give a verdict.
GainVerdict check_gains(const Machine& model, ControlLaw law, const Gains& gains, double rate_hz, double max_sag,
                        VelocityMeasurement velocity = VelocityMeasurement::difference);

// One actuator's sampled loop, the pieces check_gains is made of.
struct AxisLoop {
  double mass = 1.0;    // kg (1 for computed torque)
  double period = 1e-3; // T (s)
  double delay = 0.0;   // tau (s), >= 0
  VelocityMeasurement velocity = VelocityMeasurement::difference;
};
// The closed loop's characteristic polynomial, lowest power first.
void loop_polynomial(const AxisLoop& loop, double kp, double kd, std::vector<double>& coefficients);
// Largest |z| of its roots (to 1e-10 relative).
double loop_spectral_radius(const AxisLoop& loop, double kp, double kd);

}  // namespace cpm::ctl

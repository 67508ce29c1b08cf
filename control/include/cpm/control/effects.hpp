// SPDX-License-Identifier: Apache-2.0
// The dynamic effects of docs/effects.md: forces the actuators must
// supply beyond Elkady's rigid-body model.
//
// The plant obeys, per actuator i (forces in N, d in m, v = d_dot in m/s):
//     (1 + k_i) F_commanded,i = [J^T (M q_dd + G q_d + K)]_i + sum_effects f_i(d_i, v_i)
// where k_i is the force_gain effect, and payload_mass / inertia_error change
// the constants A, B, C, E of M, G, K (Delta m (q_dd - g) is exactly
// Delta A = Delta m / 2, Delta E = Delta m g).
//
// An effect is plain data (type, axis, up to four parameters) so that a
// model holds a fixed-capacity list of them and the control cycle evaluates
// them without allocating.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace cpm::ctl {

// Adding an effect: its type below, its row in the library (kInfo in
// effects.cpp), its force and gradient (effect_force, effect_force_gradient),
// and how identification fits it (the fitter table, identification/src/candidates.cpp).
enum class DynamicEffectType : std::uint8_t {
  viscous_friction,   // b (N s/m):            b v
  coulomb_friction,   // f_c (N):              f_c sgn_eps(v)
  stribeck_friction,  // f_s (N), v_s (m/s):   f_s exp(-(v/v_s)^2) sgn_eps(v)
  cogging,            // a (N), lambda (m), phi (rad): a sin(2 pi d / lambda + phi)
  spring,             // k (N/m), d_ref (m):   k (d - d_ref)
  force_gain,         // k (1): the drive applies (1 + k) F_commanded
  payload_mass,       // dm (kg), all axes:    dm (q_dd - g)
  inertia_error,      // dA (kg), dB (kg m^2), dC (N m), dE (N), all axes
  actuation_delay,    // tau (s), all axes: the drive applies the command of t_k over
                      // [t_k + tau, t_k+1 + tau) (dead time: a synchronous PDO acts at the next SYNC)
  actuator_inertia,   // m (kg), per axis:     m d_dd, the rotor, coupling and screw only that
                      // actuator carries; acts through the inertia (Machine), not effect_force
};
inline constexpr int kDynamicEffectTypes = 10;

// sgn_eps(v) = tanh(v / eps), the smooth sign of docs/effects.md.
inline constexpr double kSignEpsilon = 1e-3;  // m/s

struct EffectParameter {
  const char* name;
  const char* unit;
  double lower;   // physical bound (inclusive unless the name says otherwise)
  double upper;
  bool nonlinear; // found by search in identification (lambda, v_s), not by least squares
};

// What an effect's force depends on besides its parameters. Identification
// reads it to name the measurement that would tell two effects apart (two
// effects that depend on the same things look alike in any data).
struct EffectDependence {
  bool direction;  // the sign of the axis velocity
  bool speed;      // the magnitude of the axis velocity
  bool position;   // the axis displacement d
  bool force;      // the commanded force or the acceleration (drive gain, rigid-body constants, timing)
};

struct DynamicEffectInfo {
  DynamicEffectType type;
  const char* name;       // stable name of docs/effects.md
  bool per_axis;          // acts on one axis (true) or on the machine as a whole
  EffectDependence depends_on;
  int n_params;
  std::array<EffectParameter, 4> params;
  const char* cause;      // one line: the physical cause
  const char* signature;  // one line: what it looks like in the force residual
};

const DynamicEffectInfo& info(DynamicEffectType t) noexcept;
std::optional<DynamicEffectType> dynamic_effect_from_name(std::string_view name) noexcept;

struct DynamicEffect {
  DynamicEffectType type = DynamicEffectType::viscous_friction;
  std::int8_t axis = -1;             // 0..2 for per-axis effects, -1 for machine-wide ones
  std::array<double, 4> param{};     // in the order of info(type).params

  // Throws Error naming the effect, axis and parameter when a value is out
  // of its physical bounds or not finite.
  void validate() const;
  [[nodiscard]] std::string label() const;  // "coulomb_friction[axis 2]"
};

// The force an additive effect adds on its axis at displacement d and
// velocity v (0 for force_gain, payload_mass, inertia_error and
// actuator_inertia, which act through the drive gain, the rigid-body
// constants and the inertia matrix).
double effect_force(const DynamicEffect& e, double d, double v) noexcept;

// d(effect_force)/d(param[j]) for j < n_params: the regressor that
// identification uses. Linear parameters give an exact column; for nonlinear
// ones (lambda, v_s, phi) it is the local derivative.
double effect_force_gradient(const DynamicEffect& e, int j, double d, double v) noexcept;

// A fixed-capacity list of effects: built before the loop, read in it.
class DynamicEffects {
 public:
  static constexpr int kCapacity = 32;
  void add(const DynamicEffect& e);  // validates; throws Error when full or invalid
  [[nodiscard]] int size() const noexcept { return count_; }
  [[nodiscard]] const DynamicEffect& operator[](int i) const noexcept { return items_[i]; }
  [[nodiscard]] const DynamicEffect* begin() const noexcept { return items_.data(); }
  [[nodiscard]] const DynamicEffect* end() const noexcept { return items_.data() + count_; }
  void clear() noexcept { count_ = 0; }

 private:
  std::array<DynamicEffect, kCapacity> items_{};
  int count_ = 0;
};

}  // namespace cpm::ctl

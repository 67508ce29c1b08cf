// SPDX-License-Identifier: Apache-2.0
// The kinematic effects of docs/effects.md by name: their parameters,
// units, bounds and a one-line cause and signature, and access to their
// values in a LimbKinematicEffects. The equations are in plane_model.cpp.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string_view>

#include "cpm/kinematics/plane_model.hpp"

namespace cpm::kin {

enum class KinematicEffectType : std::uint8_t {
  backlash,             // b (m)
  cyclic_error,         // a (m), lambda (m), phi (rad)
  guide_angular_error,  // k_a, k_b (rad/m)
  limb_twist,           // alpha (rad)
  thermal_drift,        // e (1), tau (s)
  actuator_scale,       // s (1)
};
inline constexpr int kKinematicEffectTypes = 6;

struct KinematicEffectParameter {
  const char* name;
  const char* unit;
  double lower, upper;  // physical bounds
  bool nonlinear;       // found by search in identification (lambda, tau)
};

struct KinematicEffectInfo {
  KinematicEffectType type;
  const char* name;
  int n_params;
  std::array<KinematicEffectParameter, 3> params;
  bool needs_direction;  // needs dir_i columns in the data
  bool needs_time;       // needs the t column
  const char* cause;
  const char* signature;
};

const KinematicEffectInfo& info(KinematicEffectType t) noexcept;
std::optional<KinematicEffectType> kinematic_effect_from_name(std::string_view name) noexcept;

// Read and write the parameters of one effect of one limb, in info() order.
std::array<double, 3> get_params(const LimbKinematicEffects& e, KinematicEffectType t) noexcept;
void set_params(LimbKinematicEffects& e, KinematicEffectType t,
                const std::array<double, 3>& values) noexcept;

}  // namespace cpm::kin

// SPDX-License-Identifier: Apache-2.0
#include "cpm/kinematics/kinematic_effects.hpp"

#include <numbers>

namespace cpm::kin {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

constexpr KinematicEffectInfo kInfo[kKinematicEffectTypes] = {
    {KinematicEffectType::backlash, "backlash", 1, {{{"b", "m", 0.0, 5e-3, false}}}, true, false,
     "lost motion in the screw nut or coupling when the axis reverses",
     "an error that jumps by b with the direction of motion, the same all along the axis"},
    {KinematicEffectType::cyclic_error, "cyclic_error", 3,
     {{{"a", "m", 0.0, 1e-3, false}, {"lambda", "m", 1e-3, 0.05, true},
       {"phi", "rad", -kTwoPi, kTwoPi, false}}},
     false, false, "lead-screw pitch or encoder periodic error",
     "an error periodic in the axis position with a fixed wavelength (often the screw lead)"},
    {KinematicEffectType::guide_angular_error, "guide_angular_error", 2,
     {{{"k_a", "rad/m", -0.1, 0.1, false}, {"k_b", "rad/m", -0.1, 0.1, false}}}, false, false,
     "a guide rail that is not straight: the carriage pitches or yaws as it travels",
     "an error in the other two coordinates growing with the square of the axis position"},
    {KinematicEffectType::limb_twist, "limb_twist", 1, {{{"alpha", "rad", -0.05, 0.05, false}}},
     false, false, "a small twist between the revolute axes at A_i and M_i (Kim's future work)",
     "an error along the limb's axis that follows the sine of its elbow angle"},
    {KinematicEffectType::thermal_drift, "thermal_drift", 2,
     {{{"e", "1", -1e-3, 1e-3, false}, {"tau", "s", 1.0, 1e6, true}}}, false, true,
     "the lead screw grows as it warms",
     "a scale error on the axis that grows with time towards e, on the time scale tau"},
    {KinematicEffectType::actuator_scale, "actuator_scale", 1, {{{"s", "1", -0.05, 0.05, false}}},
     false, false, "lead-screw pitch or encoder scale different from nominal",
     "an error proportional to the axis position (absorbed by c_i in a calibrated model)"},
};

}  // namespace

const KinematicEffectInfo& info(KinematicEffectType t) noexcept {
  return kInfo[static_cast<int>(t)];
}

std::optional<KinematicEffectType> kinematic_effect_from_name(std::string_view name) noexcept {
  for (const auto& i : kInfo)
    if (name == i.name) return i.type;
  return std::nullopt;
}

std::array<double, 3> get_params(const LimbKinematicEffects& e, KinematicEffectType t) noexcept {
  switch (t) {
    case KinematicEffectType::backlash: return {e.backlash, 0, 0};
    case KinematicEffectType::cyclic_error:
      return {e.cyclic_amplitude, e.cyclic_wavelength, e.cyclic_phase};
    case KinematicEffectType::guide_angular_error: return {e.guide_ka, e.guide_kb, 0};
    case KinematicEffectType::limb_twist: return {e.twist, 0, 0};
    case KinematicEffectType::thermal_drift: return {e.thermal_expansion, e.thermal_time_constant, 0};
    case KinematicEffectType::actuator_scale: return {e.actuator_scale, 0, 0};
  }
  return {};
}

void set_params(LimbKinematicEffects& e, KinematicEffectType t,
                const std::array<double, 3>& v) noexcept {
  switch (t) {
    case KinematicEffectType::backlash: e.backlash = v[0]; break;
    case KinematicEffectType::cyclic_error:
      e.cyclic_amplitude = v[0];
      e.cyclic_wavelength = v[1];
      e.cyclic_phase = v[2];
      break;
    case KinematicEffectType::guide_angular_error:
      e.guide_ka = v[0];
      e.guide_kb = v[1];
      break;
    case KinematicEffectType::limb_twist: e.twist = v[0]; break;
    case KinematicEffectType::thermal_drift:
      e.thermal_expansion = v[0];
      e.thermal_time_constant = v[1];
      break;
    case KinematicEffectType::actuator_scale: e.actuator_scale = v[0]; break;
  }
}

}  // namespace cpm::kin

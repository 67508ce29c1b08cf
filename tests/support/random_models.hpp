// SPDX-License-Identifier: Apache-2.0
// Random but plausible machines for property tests: calibrated planes of
// Kim's size (tenths of a degree, a few tenths of a mm), optionally with
// kinematic effects. Deterministic for a given seed.
#pragma once

#include <random>

#include "cpm/kinematics/plane_model.hpp"

namespace cpm::test {

inline Vec3 random_unit_near(const Vec3& axis, double max_tilt, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-max_tilt, max_tilt);
  return (axis + Vec3(u(rng), u(rng), u(rng))).normalized();
}

inline kin::KinematicModel random_calibrated_kinematics(std::mt19937_64& rng, bool with_effects) {
  kin::KinematicModel m = kin::KinematicModel::nominal();
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 3; ++i) {
    m.planes[i].normal = random_unit_near(Vec3::Unit(i), 5e-3, rng);
    m.planes[i].scale = 1.0 + 2e-3 * u(rng);
    m.planes[i].offset = 5e-4 * u(rng);
    if (with_effects) {
      kin::LimbKinematicEffects& e = m.effects[i];
      e.backlash = 2e-5 * (1.0 + u(rng));
      e.cyclic_amplitude = 5e-6 * (1.0 + u(rng));
      e.cyclic_wavelength = 5e-3 * (2.0 + u(rng));
      e.cyclic_phase = 3.0 * u(rng);
      e.guide_ka = 1e-3 * u(rng);
      e.guide_kb = 1e-3 * u(rng);
      e.twist = 1e-3 * u(rng);
      e.thermal_expansion = 5e-5 * u(rng);
      e.thermal_time_constant = 600.0;
      e.actuator_scale = 1e-4 * u(rng);
    }
  }
  m.validate();
  return m;
}

// A point well inside the reachable workspace (strokes and limbs).
inline Vec3 random_platform_point(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> x(0.27, 0.58), z(0.25, 0.48);
  return Vec3(x(rng), x(rng), z(rng));
}

}  // namespace cpm::test

// SPDX-License-Identifier: Apache-2.0
// The machine model the benchmarks time the control cycle on: what a model
// carries after the README's workflow (calibrate, diagnose, fit), so that a
// cycle pays for every branch a calibrated machine takes, not the nominal
// shortcut.
#pragma once

#include "cpm/control/machine.hpp"

namespace cpm::bench {

// Calibrated planes (squareness, scale and offset errors of Kim's order of
// magnitude), kinematic effects (backlash, a cyclic error) and dynamic
// effects on every axis (viscous and Coulomb friction) plus cogging on one.
inline ctl::MachineModel calibrated_model_with_effects() {
  ctl::MachineModel m = ctl::MachineModel::elkady();
  m.kinematics.planes[0].normal = Vec3(1.0, 2e-3, -1e-3).normalized();
  m.kinematics.planes[1].normal = Vec3(-2e-3, 1.0, 1e-3).normalized();
  m.kinematics.planes[2].normal = Vec3(1e-3, 1e-3, 1.0).normalized();
  for (int i = 0; i < 3; ++i) {
    m.kinematics.planes[i].scale = 1.0 + 1e-4 * (i + 1);
    m.kinematics.planes[i].offset = 1e-4 * (i - 1);
    ctl::add_effect(m, "viscous_friction", i, {8.0});
    ctl::add_effect(m, "coulomb_friction", i, {3.0});
  }
  ctl::add_effect(m, "backlash", 0, {5e-6});
  ctl::add_effect(m, "cyclic_error", 1, {3e-6, 0.016, 0.3});
  ctl::add_effect(m, "cogging", 2, {0.5, 0.02, 0.0});
  return m;
}

}  // namespace cpm::bench

// SPDX-License-Identifier: Apache-2.0
// The machine the identify tests plant (Coulomb friction 3 N on axis 1,
// viscous friction 20 N s/m on axis 3, a 0.4 kg payload, an actuation delay),
// and the check that a fitted model names each within 2 % (the delay: or
// 3 standard errors). One check for the loop in process, through the bus and
// through cpmd, so the three tests ask the same of the identification.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <map>
#include <string>

#include "cpm/control/effects.hpp"
#include "cpm/control/machine.hpp"

namespace cpm::test {

// fitted: the model's effects (any range of ctl::DynamicEffect); delay_s: the
// planted delay (s); delay_se: the fit's standard error of it (s). se: the
// fit's standard errors by parameter name (the model file's `fitted` names,
// e.g. "effects.inertia_error.dA"); a parameter given there is named when
// within 2 % or within 3 of them (issue 28's "within 2 % (or within 3σ)").
template <class Effects>
void expect_planted_effects_named(const Effects& fitted, double delay_s, double delay_se, const std::string& context = "",
                                  const std::map<std::string, double>& se = {}) {
  auto tol = [&se](const char* name, double two_percent) {
    const auto it = se.find(name);
    return it == se.end() ? two_percent : std::max(two_percent, 3.0 * it->second);
  };
  bool coulomb = false, viscous = false, payload = false, delay = false;
  for (const ctl::DynamicEffect& e : fitted) {
    std::printf("fitted %s: %.5g %.5g %.5g %.5g\n", e.label().c_str(), e.param[0], e.param[1], e.param[2], e.param[3]);
    if (e.type == ctl::DynamicEffectType::coulomb_friction && e.axis == 0) {
      coulomb = true;
      EXPECT_NEAR(e.param[0], 3.0, tol("effects.coulomb_friction.axis1.f_c", 0.06)) << context;
    }
    if (e.type == ctl::DynamicEffectType::viscous_friction && e.axis == 2) {
      viscous = true;
      EXPECT_NEAR(e.param[0], 20.0, tol("effects.viscous_friction.axis3.b", 0.4)) << context;
    }
    if (e.type == ctl::DynamicEffectType::payload_mass) {
      payload = true;
      EXPECT_NEAR(e.param[0], 0.4, tol("effects.payload_mass.dm", 0.008)) << context;
    }
    // The payload in the base refit: dA = m / 2, dE = m g.
    if (e.type == ctl::DynamicEffectType::inertia_error) {
      payload = true;
      EXPECT_NEAR(e.param[0], 0.2, tol("effects.inertia_error.dA", 0.004)) << context;
      EXPECT_NEAR(e.param[3], 0.4 * ctl::kGravity, tol("effects.inertia_error.dE", 0.02 * 0.4 * ctl::kGravity)) << context;
    }
    if (e.type == ctl::DynamicEffectType::actuation_delay) {
      delay = true;
      std::printf("actuation_delay %.4f ms +- %.4f ms (planted %.1f ms)\n", e.param[0] * 1e3, delay_se * 1e3,
                  delay_s * 1e3);
      EXPECT_NEAR(e.param[0], delay_s, std::max(0.02 * delay_s, 3.0 * delay_se)) << context;
    }
  }
  EXPECT_TRUE(coulomb) << context;
  EXPECT_TRUE(viscous) << context;
  EXPECT_TRUE(payload) << context;
  EXPECT_TRUE(delay) << context;
}

}  // namespace cpm::test

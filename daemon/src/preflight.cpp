// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/preflight.hpp"

#include <cmath>
#include <cstdio>
#include <string>

#include "cpm/daemon/server.hpp"

namespace cpm::daemon {

namespace {

std::string mm(double m) {
  char b[32];
  std::snprintf(b, sizeof b, "%.3f mm", m * 1e3);
  return b;
}

}  // namespace

void preflight(const DaemonConfig& cfg, const ctl::Machine& model, const Backend& backend) {
  const ctl::GainVerdict law = check_daemon_gains(cfg, model, cfg.controller.law, cfg.controller.gains);
  if (!law.ok) throw Error(cfg.source + ": controller: " + law.reason);
  if (!cfg.homing.all_absolute()) {
    // The actuator law is a PD law with the weight held: checked as pd_gravity.
    const ctl::GainVerdict act =
        check_daemon_gains(cfg, model, ctl::ControlLaw::pd_gravity, cfg.homing.actuator_gains);
    if (!act.ok) throw Error(cfg.source + ": homing.actuator_gains: " + act.reason);
  }
  const kin::Strokes& s = model.model().strokes;
  for (int i = 0; i < 3; ++i) {
    const AxisHomingConfig& h = cfg.homing.axes[static_cast<std::size_t>(i)];
    if (h.method == HomingMethod::absolute) continue;
    const std::string key = cfg.source + ": homing.axes." + std::string(1, "xyz"[i]);
    auto within = [&](double d, const char* what) {
      if (d < s.min[i] || d > s.max[i])
        throw Error(key + "." + what + ": " + mm(d) + " is outside the actuator's stroke [" + mm(s.min[i]) + ", " +
                    mm(s.max[i]) + "] of the model");
    };
    within(h.home_position, "home_position");
    if (!std::isnan(h.final_position)) within(h.final_position, "final_position");
    if (h.method == HomingMethod::drive && !backend.drive_homing_supported(i))
      throw Error(key + ".method: drive homing, but the " + backend.name() +
                  " backend cannot run this actuator's drive in its homing mode");
  }
}

}  // namespace cpm::daemon

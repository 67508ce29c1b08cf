// SPDX-License-Identifier: Apache-2.0
// The gpio-sim chip of the SIL runner (tests/sil/sil-env.sh): inputs driven
// by pull, outputs read back. Shared by the SIL daemon tests.
#pragma once

#include <fstream>
#include <string>

#include "sil/sil_check.hpp"

namespace sil {

struct Gpio {
  std::string sysfs = env_or("CPM_SIL_GPIO_SYSFS", "");
  // Offsets of sil-env.sh's CPM_SIL_GPIO_LINES.
  static constexpr int estop = 0, enable = 1, limit_x_max = 3, brake_z = 8;
  void pull(int line, bool up) const {
    std::ofstream(sysfs + "/sim_gpio" + std::to_string(line) + "/pull") << (up ? "pull-up" : "pull-down");
  }
  int value(int line) const {
    std::ifstream f(sysfs + "/sim_gpio" + std::to_string(line) + "/value");
    int v = -1;
    f >> v;
    return v;
  }
  // The e-stop chain closed and no limit switch actuated (lines 2-7).
  void healthy() const {
    pull(estop, true);
    for (int l = 2; l <= 7; ++l) pull(l, false);
  }
};

}  // namespace sil

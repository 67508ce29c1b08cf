// SPDX-License-Identifier: Apache-2.0
// The shipped configuration files' text, for the configuration and parameter tests.
#pragma once

#include <fstream>
#include <sstream>
#include <string>

namespace cpm::daemon::test {

// config/NAME in the source tree.
inline std::string config_file(const std::string& name) {
  std::ifstream f(std::string(CPM_SOURCE_DIR) + "/config/" + name);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

}  // namespace cpm::daemon::test

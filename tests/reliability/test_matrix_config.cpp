// SPDX-License-Identifier: Apache-2.0
// Fault matrix rows outside the cycle: an invalid configuration or model
// file is refused before anything is powered, naming file:line:column and
// the key; and the systemd unit restarts cpmd after a crash into a state
// that is disabled and braked (restart safety, the unit's half).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>

#include "cpm/daemon/config.hpp"

namespace cpm::daemon::test {
namespace {

std::string read_file(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

std::string shipped() { return read_file(std::string(CPM_SOURCE_DIR) + "/config/sim.yaml"); }

void expect_refused(const std::string& text, const std::string& where, const std::string& words) {
  try {
    (void)parse_config(text, "sim.yaml", std::string(CPM_SOURCE_DIR) + "/config");
    ADD_FAILURE() << "accepted; expected " << words;
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_TRUE(std::regex_search(m, std::regex(where))) << m;
    EXPECT_NE(m.find(words), std::string::npos) << m;
  }
}

// Row: configuration invalid. Refused at start with file:line:column: key.
TEST(FaultMatrixConfig, InvalidConfigurationIsRefusedWithItsPlace) {
  const std::string t = shipped();
  expect_refused(std::regex_replace(t, std::regex("following_error: 0.005"), "following_error: -1"),
                 "^sim\\.yaml:\\d+:\\d+: ", "limits.following_error");
  expect_refused(std::regex_replace(t, std::regex("rate_hz: 1000"), "rate_hz: .nan"), "^sim\\.yaml:\\d+:\\d+: ",
                 "loop.rate_hz");
  expect_refused(std::regex_replace(t, std::regex("  enable_timeout: 0.5 "), "  enable_timeout: 0.5\n  saturation_time: 0 "),
                 "^sim\\.yaml:\\d+:\\d+: ", "limits.saturation_time");
  expect_refused(std::regex_replace(t, std::regex("backend: sim"), "backend: sim\nbogus: 1"), "^sim\\.yaml:\\d+:\\d+: ",
                 "bogus: unknown key");
  expect_refused(t.substr(0, t.size() / 2) + "\n  - [unbalanced", "^sim\\.yaml", "");
}

TEST(FaultMatrixConfig, SaturationTimeIsConfigurable) {
  const std::string t = std::regex_replace(shipped(), std::regex("  enable_timeout: 0.5 "),
                                           "  enable_timeout: 0.5\n  saturation_time: 0.35 ");
  const DaemonConfig c = parse_config(t, "sim.yaml", std::string(CPM_SOURCE_DIR) + "/config");
  EXPECT_EQ(c.limits.saturation_time, 0.35);
  EXPECT_EQ(parse_config(shipped(), "sim.yaml", std::string(CPM_SOURCE_DIR) + "/config").limits.saturation_time, 0.2);
}

// Row: model file invalid (or missing). Refused naming the file.
TEST(FaultMatrixConfig, InvalidModelFileIsRefusedNamingIt) {
  const auto dir = std::filesystem::temp_directory_path() / ("cpm-reliab-model-" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  const std::string bad = (dir / "bad.yaml").string();
  std::ofstream(bad) << "this: is: not a model\n";
  EXPECT_THROW(
      {
        try {
          (void)load_model(bad);
        } catch (const Error& e) {
          EXPECT_NE(std::string(e.what()).find("bad.yaml"), std::string::npos) << e.what();
          throw;
        }
      },
      Error);
  EXPECT_THROW((void)load_model((dir / "missing.yaml").string()), Error);
  std::filesystem::remove_all(dir);
}

// Restart safety, the unit's half: systemd restarts cpmd after SIGKILL
// (on-failure covers "killed by a signal") and after a watchdog timeout, and
// the start path runs the configuration check first; nothing in the start
// command enables the drives (cpmd always starts disabled: test_restart).
TEST(RestartSafety, SystemdUnitRestartsAfterACrashAndStartsChecked) {
  const std::string u = read_file(std::string(CPM_SOURCE_DIR) + "/systemd/cpmd.service.in");
  ASSERT_FALSE(u.empty());
  std::smatch m;
  ASSERT_TRUE(std::regex_search(u, m, std::regex("\\nRestart=(\\S+)")));
  EXPECT_TRUE(m[1] == "on-failure" || m[1] == "always" || m[1] == "on-abnormal") << m[1];
  EXPECT_TRUE(std::regex_search(u, std::regex("\\nWatchdogSec=\\d")));
  EXPECT_TRUE(std::regex_search(u, std::regex("\\nType=notify")));
  EXPECT_TRUE(std::regex_search(u, std::regex("\\nExecStartPre=.*--check")));
  EXPECT_TRUE(std::regex_search(u, std::regex("\\nKillSignal=SIGTERM")));  // a stop disables the drives first
  ASSERT_TRUE(std::regex_search(u, m, std::regex("\\nExecStart=([^\\n]*)")));
  EXPECT_EQ(std::string(m[1]).find("enable"), std::string::npos) << m[1];
  // A restart loop is bounded in time (RestartSec) so a broken drive bus is not hammered.
  EXPECT_TRUE(std::regex_search(u, std::regex("\\nRestartSec=\\d")));
}

}  // namespace
}  // namespace cpm::daemon::test

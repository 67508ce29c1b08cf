// The daemon's configuration is strict: what is unknown, missing, mistyped or
// out of range is refused with the file, line:column and the key's path.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "cpm/daemon/config.hpp"

namespace cpm::daemon {
namespace {

std::string sim_yaml() {
  std::ifstream f(std::string(CPM_SOURCE_DIR) + "/config/sim.yaml");
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

std::string replace(std::string s, const std::string& from, const std::string& to) {
  const auto at = s.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return s.replace(at, from.size(), to);
}

std::string error_of(const std::string& text) {
  try {
    parse_config(text, "t.yaml");
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(Config, ShippedSimConfigLoads) {
  const DaemonConfig c = load_config(std::string(CPM_SOURCE_DIR) + "/config/sim.yaml");
  EXPECT_EQ(c.backend, "sim");
  EXPECT_EQ(c.loop.rate_hz, 1000.0);
  EXPECT_EQ(c.controller.law, ctl::ControlLaw::computed_torque);
  EXPECT_EQ(c.controller.gains.kp.x(), 2550.25);
  EXPECT_NE(c.lcm.url.find("ttl=0"), std::string::npos);
  EXPECT_TRUE(c.sim.initial_position.isApprox(Vec3(0.6, 0.425, 0.3)));
  const DaemonConfig d = load_config(std::string(CPM_SOURCE_DIR) + "/config/cpmd.yaml");
  EXPECT_EQ(d.model_file, std::string(CPM_SOURCE_DIR) + "/config/machine.yaml");  // relative to the file
}

TEST(Config, UnknownKeyIsRefusedWithItsPath) {
  const std::string e = error_of(replace(sim_yaml(), "  velocity: 0.5", "  velocity: 0.5\n  velocty_max: 1"));
  EXPECT_NE(e.find("limits.velocty_max: unknown key"), std::string::npos) << e;
  EXPECT_NE(e.find("t.yaml:"), std::string::npos) << e;
  const std::string top = error_of(sim_yaml() + "\nextra: 1\n");
  EXPECT_NE(top.find("extra: unknown key"), std::string::npos) << top;
}

TEST(Config, MissingKeyIsRefused) {
  const std::string e = error_of(replace(sim_yaml(), "  following_error: 0.005", ""));
  EXPECT_NE(e.find("limits.following_error: missing"), std::string::npos) << e;
  const std::string e2 = error_of(replace(sim_yaml(), "  rate_hz: 1000", ""));
  EXPECT_NE(e2.find("loop.rate_hz: missing"), std::string::npos) << e2;
}

TEST(Config, WrongTypeIsRefusedWithLineAndColumn) {
  const std::string e = error_of(replace(sim_yaml(), "rate_hz: 1000", "rate_hz: fast"));
  EXPECT_NE(e.find("loop.rate_hz: expected a number, got 'fast'"), std::string::npos) << e;
  // line:column of the value
  EXPECT_NE(e.find("t.yaml:"), std::string::npos);
  const std::string e2 = error_of(replace(sim_yaml(), "workspace_min: [0.235, 0.235, 0.2378]", "workspace_min: [0.235, 0.235]"));
  EXPECT_NE(e2.find("limits.workspace_min: expected a list of three numbers"), std::string::npos) << e2;
  const std::string e3 = error_of(replace(sim_yaml(), "lock_memory: true", "lock_memory: maybe"));
  EXPECT_NE(e3.find("loop.lock_memory: expected true or false"), std::string::npos) << e3;
}

TEST(Config, OutOfRangeIsRefused) {
  EXPECT_NE(error_of(replace(sim_yaml(), "velocity: 0.5", "velocity: -1")).find("limits.velocity: must be"),
            std::string::npos);
  EXPECT_NE(error_of(replace(sim_yaml(), "priority: 80", "priority: 120")).find("loop.priority: must be within 0 .. 99"),
            std::string::npos);
  EXPECT_NE(error_of(replace(sim_yaml(), "law: computed_torque", "law: pid")).find("controller.law: must be"),
            std::string::npos);
  EXPECT_NE(error_of(replace(sim_yaml(), "backend: sim", "backend: ethercat")).find("backend: must be sim or canopen"),
            std::string::npos);
  const std::string e = error_of(replace(sim_yaml(), "workspace_max: [0.615, 0.615, 0.5168]", "workspace_max: [0.615, 0.2, 0.5168]"));
  EXPECT_NE(e.find("limits.workspace_max[1]: must be greater"), std::string::npos) << e;
  const std::string bad_yaml = error_of("loop: [unclosed");
  EXPECT_NE(bad_yaml.find("not valid YAML"), std::string::npos) << bad_yaml;
}

}  // namespace
}  // namespace cpm::daemon

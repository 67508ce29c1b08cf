// SPDX-License-Identifier: Apache-2.0
// The daemon's configuration is strict: what is unknown, missing, mistyped or
// out of range is refused with the file, line:column and the key's path.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>

#include "config_files.hpp"
#include "cpm/daemon/config.hpp"

namespace cpm::daemon {
namespace {

std::string sim_yaml() { return test::config_file("sim.yaml"); }

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

// --- issue 17: homing, jogging, safe commands -------------------------------

// The 1-based line of the first occurrence of `needle` in `text`.
int line_of(const std::string& text, const std::string& needle) {
  const auto at = text.find(needle);
  EXPECT_NE(at, std::string::npos) << needle;
  return 1 + static_cast<int>(std::count(text.begin(), text.begin() + static_cast<long>(at), '\n'));
}

// `text` is refused at the line of `at` with `path: ` and `why` in the message.
void expect_refused(const std::string& text, const std::string& at, const std::string& path, const std::string& why) {
  const std::string e = error_of(text);
  const std::string where = "t.yaml:" + std::to_string(line_of(text, at)) + ":";
  EXPECT_EQ(e.rfind(where, 0), 0u) << "expected " << where << " in: " << e;
  EXPECT_NE(e.find(path + ": "), std::string::npos) << e;
  EXPECT_NE(e.find(why), std::string::npos) << e;
}

// sim.yaml with home switches on x and y (none on z) and index marks every 5 mm.
std::string sim_with_switches() {
  return replace(sim_yaml(), "  enable_delay: 0.005",
                 "  enable_delay: 0.005\n  home_switch: [0.02, 0.02, null]\n  index_pitch: 0.005");
}

// A homing section where x is given by `x` (one key per line, indented 6).
std::string homing_x(const std::string& x) {
  return sim_with_switches() + "\nhoming:\n  axes:\n    x:\n" + x;
}
const std::string kSwitchX =
    "      method: switch\n      search_velocity: -0.02\n      latch_velocity: 0.002\n      home_position: 0.02\n";

TEST(Config, NewKeysHaveTheirDefaults) {
  const DaemonConfig c = parse_config(sim_yaml(), "t.yaml");
  EXPECT_FALSE(c.limits.allow_velocity_step);
  EXPECT_EQ(c.controller.transfer_time, 0.5);
  EXPECT_EQ(c.jog.max_velocity, 0.05);
  EXPECT_EQ(c.jog.acceleration, 0.5);
  EXPECT_EQ(c.jog.keepalive, 0.2);
  EXPECT_EQ(c.jog.stop_distance, 0.015);  // what the defaults need (12.5 mm) and a margin
  EXPECT_TRUE(c.homing.all_absolute());
  EXPECT_EQ(c.homing.order_count, 0);  // nothing to home
  EXPECT_TRUE(c.sim.encoder_zero.isZero());
  EXPECT_TRUE(c.sim.home_switch.array().isNaN().all());
  EXPECT_EQ(c.sim.index_pitch, 0.0);
  EXPECT_EQ(c.lcm.drives_channel, "CPMD_DRIVES");
  EXPECT_EQ(c.lcm.params_channel, "CPMD_PARAMS");
}

TEST(Config, NewKeysAreTakenWithTheirValues) {
  std::string t = replace(sim_yaml(), "  enable_timeout: 0.5        # s",
                          "  enable_timeout: 0.5\n  allow_velocity_step: true");
  t = replace(t, "  kd: [101, 101, 101]", "  kd: [101, 101, 101]\n  transfer_time: 1.5");
  t = replace(t, "security: CPMD_SECURITY}", "security: CPMD_SECURITY, drives: MY_DRIVES, params: MY_PARAMS}");
  t = replace(t, "  encoder: {", "  encoder_zero: [0.0372, -0.0213, 0.0518]\n  home_switch: [0.02, 0.03, .nan]\n"
                                 "  index_pitch: 0.004\n  encoder: {");
  t += "\njog: {max_velocity: 0.04, acceleration: 1.0, keepalive: 0.1, stop_distance: 0.01}\n";
  t += "homing:\n  axes:\n    x: {method: switch, search_velocity: -0.03, home_position: 0.02}\n"
       "    y: {method: switch, search_velocity: -0.03, home_position: 0.03}\n"
       "    z: {method: absolute}\n";
  t = replace(t, "encoder_zero: [0.0372, -0.0213, 0.0518]", "encoder_zero: [0.0372, -0.0213, 0]");
  const DaemonConfig c = parse_config(t, "t.yaml");
  EXPECT_TRUE(c.limits.allow_velocity_step);
  EXPECT_EQ(c.controller.transfer_time, 1.5);
  EXPECT_EQ(c.lcm.drives_channel, "MY_DRIVES");
  EXPECT_EQ(c.lcm.params_channel, "MY_PARAMS");
  EXPECT_EQ(c.jog.max_velocity, 0.04);
  EXPECT_EQ(c.jog.acceleration, 1.0);
  EXPECT_EQ(c.jog.keepalive, 0.1);
  EXPECT_EQ(c.jog.stop_distance, 0.01);  // 4 mm coasting + 0.8 mm braking
  EXPECT_EQ(c.sim.encoder_zero, Vec3(0.0372, -0.0213, 0));
  EXPECT_EQ(c.sim.home_switch.x(), 0.02);
  EXPECT_EQ(c.sim.home_switch.y(), 0.03);
  EXPECT_TRUE(std::isnan(c.sim.home_switch.z()));  // .nan: none
  EXPECT_EQ(c.sim.index_pitch, 0.004);
  EXPECT_FALSE(c.homing.all_absolute());
  EXPECT_EQ(c.homing.axes[0].method, HomingMethod::switch_);
  EXPECT_EQ(c.homing.axes[1].method, HomingMethod::switch_);
  EXPECT_EQ(c.homing.axes[2].method, HomingMethod::absolute);
  EXPECT_EQ(c.homing.axes[1].search_velocity, -0.03);
  EXPECT_EQ(c.homing.axes[1].home_position, 0.03);
  // Without homing.order: the homed actuators, z first, then x, y.
  ASSERT_EQ(c.homing.order_count, 2);
  EXPECT_EQ(c.homing.order[0], 0);
  EXPECT_EQ(c.homing.order[1], 1);
  // The defaults of what was not given.
  EXPECT_EQ(c.homing.axes[0].latch_velocity, 0.002);
  EXPECT_TRUE(std::isnan(c.homing.axes[0].final_position));
  EXPECT_EQ(c.homing.actuator_gains.kp, Vec3::Constant(12691.0));
  EXPECT_EQ(c.homing.actuator_gains.kd, Vec3::Constant(436.0));
  EXPECT_STREQ(homing_method_name(c.homing.axes[0].method), "switch");
  // "None" in YAML: null, ~ or .nan per element.
  const DaemonConfig none =
      parse_config(replace(sim_yaml(), "  encoder: {", "  home_switch: [~, null, .nan]\n  encoder: {"), "t.yaml");
  EXPECT_TRUE(none.sim.home_switch.array().isNaN().all());
}

TEST(Config, ShippedSimHomingConfigLoads) {
  const DaemonConfig c = load_config(std::string(CPM_SOURCE_DIR) + "/config/sim-homing.yaml");
  EXPECT_EQ(c.sim.encoder_zero, Vec3(0.0372, -0.0213, 0.0518));
  EXPECT_EQ(c.sim.home_switch, Vec3(0.02, 0.02, 0.0215));
  EXPECT_EQ(c.sim.index_pitch, 0.005);
  ASSERT_EQ(c.homing.order_count, 3);
  EXPECT_EQ(c.homing.order, (std::array<int, 3>{2, 0, 1}));
  for (const auto& a : c.homing.axes) {
    EXPECT_EQ(a.method, HomingMethod::switch_);
    EXPECT_LT(a.search_velocity, 0.0);  // towards the switches at the low ends
  }
  // x and y home on their switch's edge, z on the first index mark above its edge.
  EXPECT_EQ(c.homing.axes[0].home_position, c.sim.home_switch.x());
  EXPECT_EQ(c.homing.axes[1].home_position, c.sim.home_switch.y());
  EXPECT_TRUE(c.homing.axes[2].use_index);
  EXPECT_NEAR(c.homing.axes[2].home_position, std::ceil(c.sim.home_switch.z() / c.sim.index_pitch) * c.sim.index_pitch,
              1e-12);
  EXPECT_EQ(c.homing.axes[2].final_position, 0.1);
}

// canopen.yaml's commented example, uncommented: z by its drive, x and y on switches with the index.
std::string canopen_with_homing() {
  std::string t = test::config_file("canopen.yaml");
  std::string out;
  std::istringstream in(t);
  bool in_homing = false;
  for (std::string line; std::getline(in, line);) {
    for (const char* g : {"    # home_x:", "    # home_y:", "    # index_x:", "    # index_y:"})
      if (line.rfind(g, 0) == 0) line = "    " + line.substr(6);
    if (line.rfind("# homing:", 0) == 0) in_homing = true;
    if (in_homing && line.empty()) in_homing = false;
    if (in_homing) line = line.substr(2);
    out += line + "\n";
  }
  return out;
}

TEST(Config, CanopenHomingExampleLoadsAndConfiguresTheDrive) {
  const DaemonConfig plain = load_config(std::string(CPM_SOURCE_DIR) + "/config/canopen.yaml");
  EXPECT_TRUE(plain.homing.all_absolute());  // the shipped file: commented out, behaviour unchanged
  for (const auto& d : plain.canopen.master.drives) EXPECT_FALSE(d.homing.enabled);

  const DaemonConfig c = parse_config(canopen_with_homing(), "t.yaml", std::string(CPM_SOURCE_DIR) + "/config");
  EXPECT_EQ(c.homing.axes[0].method, HomingMethod::switch_);
  EXPECT_TRUE(c.homing.axes[0].use_index);
  EXPECT_EQ(c.homing.axes[2].method, HomingMethod::drive);
  EXPECT_TRUE(c.canopen.gpio[hal::Line::home_x].present);
  EXPECT_TRUE(c.canopen.gpio[hal::Line::index_y].present);
  const auto& z = c.canopen.master.drives[2].homing;
  EXPECT_TRUE(z.enabled);
  EXPECT_EQ(z.method, 17);
  EXPECT_EQ(z.speed_search_mps, 0.02);
  EXPECT_EQ(z.speed_zero_mps, 0.002);
  EXPECT_EQ(z.acceleration_mps2, 0.2);
  EXPECT_EQ(z.offset_m, 0.005);
  EXPECT_FALSE(c.canopen.master.drives[0].homing.enabled);  // homed by the daemon, not the drive
}

TEST(Config, NewKeysOutOfRangeAreRefusedWithLineAndPath) {
  const std::string kd = "  kd: [101, 101, 101]";
  expect_refused(replace(sim_yaml(), kd, kd + "\n  transfer_time: 0"), "transfer_time: 0", "controller.transfer_time",
                 "must be > 0 and <= 10 s, got 0");
  expect_refused(replace(sim_yaml(), kd, kd + "\n  transfer_time: 12"), "transfer_time: 12",
                 "controller.transfer_time", "got 12");
  const std::string et = "  enable_timeout: 0.5        # s";
  expect_refused(replace(sim_yaml(), et, et + "\n  allow_velocity_step: sometimes"), "allow_velocity_step",
                 "limits.allow_velocity_step", "expected true or false");
  expect_refused(sim_yaml() + "\njog:\n  keepalive: 0.01\n", "keepalive: 0.01", "jog.keepalive",
                 "must be within 0.05 .. 5 s");
  expect_refused(sim_yaml() + "\njog:\n  max_velocty: 0.01\n", "max_velocty", "jog.max_velocty", "unknown key");
  expect_refused(replace(sim_yaml(), "  encoder: {", "  home_switch: [0.02, 0.02]\n  encoder: {"), "home_switch",
                 "sim.home_switch", "expected a list of three numbers");
  expect_refused(replace(sim_yaml(), "  encoder: {", "  home_switch: [0.02, up, 0.02]\n  encoder: {"), "home_switch",
                 "sim.home_switch[1]", "expected a number, got 'up'");
  expect_refused(replace(sim_yaml(), "  encoder: {", "  index_pitch: 0.00005\n  encoder: {"), "index_pitch",
                 "sim.index_pitch", "at least 0.1 mm");
  expect_refused(replace(sim_yaml(), "security: CPMD_SECURITY}", "security: CPMD_SECURITY, drive: X}"),
                 "security: CPMD_SECURITY", "lcm.channels.drive", "unknown key");
}

TEST(Config, JogThatCannotStopInItsDistanceIsRefusedWithTheFigures) {
  // 60 mm/s for 0.2 s is 12 mm, and 3.6 mm to stop at 500 mm/s^2: 15.6 mm > 12.5 mm.
  const std::string t = sim_yaml() + "\njog:\n  max_velocity: 0.06\n  stop_distance: 0.0125\n";
  expect_refused(t, "stop_distance: 0.0125\n", "jog.stop_distance", "jog.max_velocity 60 mm/s");
  const std::string e = error_of(t);
  for (const char* figure : {"jog.keepalive 0.2 s", "12 + 3.6 = 15.6 mm", "jog.stop_distance 12.5 mm"})
    EXPECT_NE(e.find(figure), std::string::npos) << figure << " in " << e;
  // Without stop_distance in the file, the error points at the section.
  expect_refused(sim_yaml() + "\njog:\n  keepalive: 0.3\n", "keepalive: 0.3", "jog.stop_distance", "17.5 mm");
  // Faster than a trajectory may go.
  expect_refused(replace(sim_yaml() + "\njog:\n  max_velocity: 0.6\n  stop_distance: 0.1\n  acceleration: 10\n"
                                       "  keepalive: 0.05\n", "overspeed: 0.8", "overspeed: 1.0"),
                 "max_velocity: 0.6", "jog.max_velocity", "must not exceed limits.velocity (500 mm/s)");
  // The default jog (50 mm/s) is faster than a limits.velocity of 40 mm/s: said at limits.velocity.
  expect_refused(replace(replace(sim_yaml(), "  velocity: 0.5 ", "  velocity: 0.04 "), "overspeed: 0.8", "overspeed: 0.1"),
                 "velocity: 0.04", "jog.max_velocity", "must not exceed limits.velocity (40 mm/s)");
}

TEST(Config, HomingKeysAreCheckedForTheirMethod) {
  // Accepted as written.
  const DaemonConfig c = parse_config(homing_x(kSwitchX + "      use_index: true\n      final_position: 0.1\n"
                                                          "      max_travel: 0.3\n      timeout: 20\n"
                                                          "      acceleration: 0.3\n"),
                                      "t.yaml");
  const auto& x = c.homing.axes[0];
  EXPECT_EQ(x.search_velocity, -0.02);
  EXPECT_EQ(x.latch_velocity, 0.002);
  EXPECT_EQ(x.home_position, 0.02);
  EXPECT_TRUE(x.use_index);
  EXPECT_EQ(x.final_position, 0.1);
  EXPECT_EQ(x.max_travel, 0.3);
  EXPECT_EQ(x.timeout, 20);
  EXPECT_EQ(x.acceleration, 0.3);

  // A key of another method is refused by name, so a typo of the method cannot pass.
  expect_refused(homing_x(kSwitchX + "      drive_method: 17\n"), "drive_method", "homing.axes.x.drive_method",
                 "not used by method switch");
  expect_refused(homing_x("      method: absolute\n      home_position: 0.1\n"), "home_position",
                 "homing.axes.x.home_position", "not used by method absolute");
  expect_refused(homing_x(kSwitchX + "      use_idx: true\n"), "use_idx", "homing.axes.x.use_idx", "unknown key");
  expect_refused(homing_x("      method: magnetic\n"), "magnetic", "homing.axes.x.method",
                 "must be absolute, switch or drive, got 'magnetic'");
  expect_refused(homing_x("      search_velocity: -0.02\n"), "search_velocity", "homing.axes.x.method", "missing");
  expect_refused(homing_x("      method: switch\n      search_velocity: -0.02\n"), "method: switch",
                 "homing.axes.x.home_position", "missing");
  expect_refused(sim_with_switches() + "\nhoming:\n  order: [x]\n", "order", "homing.axes", "missing");
}

TEST(Config, HomingValuesOutOfRangeAreRefused) {
  const std::string head = "      method: switch\n      home_position: 0.02\n";
  expect_refused(homing_x(head + "      search_velocity: 0\n"), "search_velocity: 0", "homing.axes.x.search_velocity",
                 "must not be 0");
  expect_refused(homing_x(head + "      search_velocity: -0.02\n      latch_velocity: 0.02\n"), "latch_velocity",
                 "homing.axes.x.latch_velocity",
                 "must be slower than |search_velocity| (20 mm/s), got 20 mm/s");
  // Faster than the jog (50 mm/s): the actuator's zero is unknown while it homes.
  expect_refused(homing_x(head + "      search_velocity: -0.08\n"), "search_velocity", "homing.axes.x.search_velocity",
                 "must not be faster than jog.max_velocity (50 mm/s)");
  expect_refused(homing_x(kSwitchX + "      acceleration: 6\n"), "acceleration: 6", "homing.axes.x.acceleration",
                 "must not exceed limits.acceleration (5 m/s^2)");
  // 0.45 m at 20 mm/s take 22.5 s.
  expect_refused(homing_x(kSwitchX + "      timeout: 10\n"), "timeout: 10", "homing.axes.x.timeout", "22.5 s");
  expect_refused(homing_x(kSwitchX + "      final_position: far\n"), "final_position", "homing.axes.x.final_position",
                 "expected a number");
  expect_refused(homing_x(kSwitchX) + "  actuator_gains: {kp: [0, 1, 1], kd: [1, 1, 1]}\n", "actuator_gains",
                 "homing.actuator_gains.kp[0]", "must be > 0 N/m");
}

TEST(Config, HomingOrderListsEveryHomedActuatorOnce) {
  const std::string two = homing_x(kSwitchX) + "    y:\n" + std::string(kSwitchX);
  const DaemonConfig c = parse_config(two + "  order: [2, x]\n", "t.yaml");
  ASSERT_EQ(c.homing.order_count, 2);
  EXPECT_EQ(c.homing.order[0], 1);
  EXPECT_EQ(c.homing.order[1], 0);
  expect_refused(two + "  order: [x, y, x]\n", "order", "homing.order[2]", "actuator x is listed twice");
  expect_refused(two + "  order: [x]\n", "order", "homing.order", "actuator y is homed (method switch) but not listed");
  expect_refused(two + "  order: [x, y, z]\n", "order", "homing.order[2]", "actuator z is absolute");
  expect_refused(two + "  order: [x, w]\n", "order", "homing.order[1]", "expected an actuator: x, y, z or 1, 2, 3");
}

TEST(Config, HomingNeedsWhatItsMethodUses) {
  // drive: only the CANopen backend's drives home themselves.
  expect_refused(homing_x("      method: drive\n      drive_method: 17\n      search_velocity: 0.02\n"
                          "      home_position: 0.0\n"),
                 "method: drive", "homing.axes.x.method", "drive needs backend: canopen");
  // switch on the simulator: a sim.home_switch for that actuator (z has none).
  expect_refused(sim_with_switches() + "\nhoming:\n  axes:\n    z:\n" + kSwitchX, "method: switch",
                 "homing.axes.z.method", "sim.home_switch[2] is none");
  expect_refused(replace(homing_x(kSwitchX + "      use_index: true\n"), "  index_pitch: 0.005", "  index_pitch: 0"),
                 "use_index", "homing.axes.x.use_index", "sim.index_pitch is 0");
  // An incremental encoder on an absolute actuator would put the platform where it is not.
  expect_refused(replace(homing_x(kSwitchX), "  index_pitch: 0.005", "  index_pitch: 0.005\n  encoder_zero: [0, 0.01, 0]"),
                 "encoder_zero", "sim.encoder_zero[1]", "actuator y is absolute");

  // On the CANopen backend: the GPIO lines.
  const std::string t = canopen_with_homing();
  expect_refused(replace(t, "    home_y:        {chip: gpiochip0, name: home_y}", ""), "    y: {method: switch",
                 "homing.axes.y.method", "canopen.gpio.home_y is not given");
  expect_refused(replace(t, "    index_x:       {chip: gpiochip0, name: index_x}", ""), "use_index: true",
                 "homing.axes.x.use_index", "canopen.gpio.index_x is not given");
  expect_refused(replace(t, "drive_method: 17", "drive_method: 15"), "drive_method: 15", "homing.axes.z.drive_method",
                 "must be a CiA 402 homing method");
  expect_refused(replace(t, "drive_method: 17, search_velocity: 0.02", "drive_method: 17, search_velocity: -0.02"),
                 "drive_method: 17, search_velocity: -0.02", "homing.axes.z.search_velocity", "the drive's method");
  expect_refused(replace(t, "search_velocity: 0.02, latch_velocity: 0.002,\n", "search_velocity: 0.02, latch_velocity: 0.002,\n"
                                                                               "        use_index: true,\n"),
                 "        use_index: true,\n", "homing.axes.z.use_index", "not used by method drive");
}

}  // namespace
}  // namespace cpm::daemon

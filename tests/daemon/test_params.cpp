// SPDX-License-Identifier: Apache-2.0
// The parameters `cpm get` / `cpm set` use: each name reaches its field, a
// refused change leaves the configuration as it was, and the YAML loader and
// the table refuse the same values.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <iomanip>
#include <map>
#include <sstream>

#include "config_files.hpp"
#include "cpm/daemon/params.hpp"

namespace cpm::daemon {
namespace {

std::string sim_yaml() { return test::config_file("sim.yaml"); }

DaemonConfig shipped() { return parse_config(sim_yaml(), "sim.yaml"); }

std::map<std::string, double> all_values(const DaemonConfig& c) {
  std::map<std::string, double> v;
  for (const auto& p : param_table()) v[p.name] = get_param(c, p.name);
  return v;
}

std::string refusal(DaemonConfig& c, const std::string& name, double value) {
  const auto before = all_values(c);
  try {
    set_param(c, name, value);
  } catch (const Error& e) {
    EXPECT_EQ(all_values(c), before) << "a refused " << name << " changed the configuration";
    return e.what();
  }
  ADD_FAILURE() << name << " = " << value << " was accepted";
  return "";
}

// Each name the issue asks for, the field it must reach (read here, not
// through the table), and a value the shipped sim.yaml accepts.
struct Expected {
  const char* name;
  double value;
  std::function<double(const DaemonConfig&)> field;
};
const std::vector<Expected>& expected() {
  static const std::vector<Expected> e = {
      {"limits.velocity", 0.4, [](const DaemonConfig& c) { return c.limits.velocity; }},
      {"limits.acceleration", 3.0, [](const DaemonConfig& c) { return c.limits.acceleration; }},
      {"limits.overspeed", 0.9, [](const DaemonConfig& c) { return c.limits.overspeed; }},
      {"limits.force", 100.0, [](const DaemonConfig& c) { return c.limits.force; }},
      {"limits.following_error", 0.002, [](const DaemonConfig& c) { return c.limits.following_error; }},
      {"limits.stop_deceleration", 1.5, [](const DaemonConfig& c) { return c.limits.stop_deceleration; }},
      {"limits.enable_timeout", 1.0, [](const DaemonConfig& c) { return c.limits.enable_timeout; }},
      {"limits.saturation_time", 0.3, [](const DaemonConfig& c) { return c.limits.saturation_time; }},
      {"limits.workspace_min.x", 0.25, [](const DaemonConfig& c) { return c.limits.workspace_min.x(); }},
      {"limits.workspace_min.y", 0.26, [](const DaemonConfig& c) { return c.limits.workspace_min.y(); }},
      {"limits.workspace_min.z", 0.27, [](const DaemonConfig& c) { return c.limits.workspace_min.z(); }},
      {"limits.workspace_max.x", 0.60, [](const DaemonConfig& c) { return c.limits.workspace_max.x(); }},
      {"limits.workspace_max.y", 0.59, [](const DaemonConfig& c) { return c.limits.workspace_max.y(); }},
      {"limits.workspace_max.z", 0.50, [](const DaemonConfig& c) { return c.limits.workspace_max.z(); }},
      {"jog.max_velocity", 0.04, [](const DaemonConfig& c) { return c.jog.max_velocity; }},
      {"jog.acceleration", 0.8, [](const DaemonConfig& c) { return c.jog.acceleration; }},
      {"jog.keepalive", 0.1, [](const DaemonConfig& c) { return c.jog.keepalive; }},
      {"jog.stop_distance", 0.02, [](const DaemonConfig& c) { return c.jog.stop_distance; }},
      {"controller.kp.x", 2000.0, [](const DaemonConfig& c) { return c.controller.gains.kp.x(); }},
      {"controller.kp.y", 2100.0, [](const DaemonConfig& c) { return c.controller.gains.kp.y(); }},
      {"controller.kp.z", 2200.0, [](const DaemonConfig& c) { return c.controller.gains.kp.z(); }},
      {"controller.kd.x", 90.0, [](const DaemonConfig& c) { return c.controller.gains.kd.x(); }},
      {"controller.kd.y", 91.0, [](const DaemonConfig& c) { return c.controller.gains.kd.y(); }},
      {"controller.kd.z", 92.0, [](const DaemonConfig& c) { return c.controller.gains.kd.z(); }},
      {"controller.transfer_time", 0.25, [](const DaemonConfig& c) { return c.controller.transfer_time; }},
  };
  return e;
}

TEST(Params, TheTableHoldsEveryParameterOnce) {
  ASSERT_EQ(param_table().size(), expected().size());
  for (const auto& e : expected()) EXPECT_STREQ(find_param(e.name).name, e.name);
  for (const auto& p : param_table()) {
    EXPECT_LT(p.minimum, p.maximum) << p.name;
    EXPECT_NE(std::string(p.description), "") << p.name;
  }
}

TEST(Params, GetAfterSetReachesTheField) {
  for (const auto& e : expected()) {
    DaemonConfig c = shipped();
    const auto before = all_values(c);
    ASSERT_NE(e.field(c), e.value) << e.name << ": pick a value that changes something";
    set_param(c, e.name, e.value);
    EXPECT_EQ(e.field(c), e.value) << e.name;
    EXPECT_EQ(get_param(c, e.name), e.value) << e.name;
    // Nothing else moved.
    auto after = all_values(c);
    after[e.name] = before.at(e.name);
    EXPECT_EQ(after, before) << e.name;
  }
}

TEST(Params, OutOfRangeIsRefusedAndLeavesTheConfigUnchanged) {
  DaemonConfig c = shipped();
  EXPECT_NE(refusal(c, "limits.velocity", 6).find("limits.velocity: must be > 0 and <= 5 m/s, got 6"),
            std::string::npos);
  EXPECT_NE(refusal(c, "limits.velocity", 0).find("must be > 0"), std::string::npos);
  EXPECT_NE(refusal(c, "limits.following_error", std::nan("")).find("got nan"), std::string::npos);
  EXPECT_NE(refusal(c, "limits.force", INFINITY).find("limits.force: must be"), std::string::npos);
  EXPECT_NE(refusal(c, "jog.keepalive", 0.01).find("jog.keepalive: must be within 0.05 .. 5 s"), std::string::npos);
  EXPECT_NE(refusal(c, "controller.kd.y", -1).find("controller.kd.y: must be within 0 .. 1e+07 1/s, got -1"),
            std::string::npos);
  EXPECT_NE(refusal(c, "limits.workspace_max.z", 2.5).find("must be within 0 .. 2 m"), std::string::npos);
}

TEST(Params, BrokenConstraintsAreRefusedAndLeaveTheConfigUnchanged) {
  DaemonConfig c = shipped();  // velocity 0.5, overspeed 0.8, workspace x 0.235 .. 0.615
  EXPECT_NE(refusal(c, "limits.overspeed", 0.4).find("limits.overspeed: must be greater than limits.velocity (0.5 m/s)"),
            std::string::npos);
  EXPECT_NE(refusal(c, "limits.velocity", 0.9).find("limits.overspeed: must be greater than limits.velocity (0.9 m/s)"),
            std::string::npos);
  EXPECT_NE(refusal(c, "limits.workspace_min.x", 0.7).find("must be greater than limits.workspace_min.x (0.7 m)"),
            std::string::npos);
  EXPECT_NE(refusal(c, "limits.workspace_max.y", 0.235).find("limits.workspace_max.y: must be greater"),
            std::string::npos);
  // The jog (50 mm/s, 0.2 s, 500 mm/s^2: 12.5 mm) must stop within its distance (15 mm).
  const std::string fast = refusal(c, "jog.max_velocity", 0.06);
  EXPECT_NE(fast.find("jog.max_velocity 60 mm/s"), std::string::npos) << fast;
  EXPECT_NE(fast.find("12 + 3.6 = 15.6 mm, more than jog.stop_distance 15 mm"), std::string::npos) << fast;
  EXPECT_NE(refusal(c, "jog.keepalive", 0.3).find("15 + 2.5 = 17.5 mm"), std::string::npos);
  EXPECT_NE(refusal(c, "jog.acceleration", 0.2).find("10 + 6.25 = 16.25 mm"), std::string::npos);
  EXPECT_NE(refusal(c, "jog.stop_distance", 0.01).find("12.5 mm, more than jog.stop_distance 10 mm"),
            std::string::npos);
  EXPECT_NE(refusal(c, "limits.velocity", 0.04).find("jog.max_velocity: must not exceed limits.velocity (40 mm/s)"),
            std::string::npos);
  // A change that keeps every constraint is taken: the order of changes matters, not the pair.
  set_param(c, "limits.overspeed", 1.2);
  set_param(c, "limits.velocity", 0.9);
  EXPECT_EQ(c.limits.velocity, 0.9);
}

TEST(Params, HomingMovesStayWithinTheJogAndTheAcceleration) {
  std::string t = sim_yaml();
  const std::string delay = "  enable_delay: 0.005";
  t.replace(t.find(delay), delay.size(), delay + "\n  home_switch: [0.02, 0.02, 0.02]");
  t += "\nhoming:\n  axes:\n    y: {method: switch, search_velocity: -0.04, home_position: 0.02, acceleration: 0.5}\n";
  DaemonConfig c = parse_config(t, "t.yaml");
  EXPECT_NE(refusal(c, "jog.max_velocity", 0.03).find("homing.axes.y.search_velocity: must not be faster than "
                                                      "jog.max_velocity (30 mm/s)"),
            std::string::npos);
  EXPECT_NE(refusal(c, "limits.acceleration", 0.4).find("homing.axes.y.acceleration: must not exceed limits.acceleration"),
            std::string::npos);
}

TEST(Params, UnknownNamesAreRefusedWithTheCloseOnes) {
  auto message = [](const std::string& name) {
    try {
      (void)find_param(name);
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(message("limits.velocty").find("unknown parameter 'limits.velocty'; did you mean limits.velocity?"),
            std::string::npos);
  const std::string ws = message("limits.workspace_min");
  for (const char* n : {"limits.workspace_min.x", "limits.workspace_min.y", "limits.workspace_min.z"})
    EXPECT_NE(ws.find(n), std::string::npos) << ws;
  EXPECT_NE(message("controller.kp.w").find("controller.kp.x"), std::string::npos);
  EXPECT_NE(message("spindle.speed").find("limits.*, jog.*, controller.*"), std::string::npos);
  DaemonConfig c = shipped();
  EXPECT_THROW((void)get_param(c, "limits.speed"), Error);
  EXPECT_NE(refusal(c, "jog.speed", 0.01).find("unknown parameter"), std::string::npos);
}

TEST(Params, TheGainsUnitIsTheLawsOne) {
  const Param& kp = find_param("controller.kp.z");
  const Param& kd = find_param("controller.kd.z");
  EXPECT_STREQ(param_unit(kp, ctl::ControlLaw::computed_torque), "1/s^2");
  EXPECT_STREQ(param_unit(kd, ctl::ControlLaw::computed_torque), "1/s");
  for (auto law : {ctl::ControlLaw::pd, ctl::ControlLaw::pd_gravity, ctl::ControlLaw::pd_feedforward}) {
    EXPECT_STREQ(param_unit(kp, law), "N/m");
    EXPECT_STREQ(param_unit(kd, law), "N s/m");
  }
  EXPECT_STREQ(param_unit(find_param("limits.force"), ctl::ControlLaw::pd), "N");
}

TEST(Params, TheMessageCarriesEveryParameterInTheLawsUnits) {
  DaemonConfig c = shipped();
  set_param(c, "limits.following_error", 0.003);
  auto m = params_message(c);
  ASSERT_EQ(m.count, static_cast<int>(expected().size()));
  ASSERT_EQ(m.name.size(), expected().size());
  ASSERT_EQ(m.description.size(), expected().size());
  std::map<std::string, std::size_t> at;
  for (std::size_t i = 0; i < m.name.size(); ++i) at[m.name[i]] = i;
  for (const auto& e : expected()) ASSERT_TRUE(at.count(e.name)) << e.name;
  const std::size_t fe = at["limits.following_error"], v = at["limits.velocity"], kp = at["controller.kp.x"];
  EXPECT_EQ(m.value[fe], 0.003);
  EXPECT_EQ(m.unit[fe], "m");
  EXPECT_TRUE(m.while_moving[fe]);   // a fault threshold
  EXPECT_FALSE(m.while_moving[v]);   // the queued motion was checked against it
  EXPECT_EQ(m.value[kp], 2550.25);   // sim.yaml's Table 3 gains for computed torque
  EXPECT_EQ(m.unit[kp], "1/s^2");
  EXPECT_EQ(m.maximum[v], 5.0);
  c.controller.law = ctl::ControlLaw::pd;
  m = params_message(c);
  EXPECT_EQ(m.unit[kp], "N/m");
  // The LCM encoding takes it (every array as long as count).
  std::vector<std::uint8_t> buf(static_cast<std::size_t>(m.getEncodedSize()));
  EXPECT_GT(m.encode(buf.data(), 0, static_cast<int>(buf.size())), 0);
}

// Where a parameter is written in sim.yaml: the value `v` put in its place.
std::string with_value(const std::string& name, double v) {
  std::ostringstream num;
  num << std::setprecision(17) << v;
  std::string t = sim_yaml();
  auto set_line = [&](const std::string& section, const std::string& key) {
    const std::string line = "\n  " + key + ": ";
    const auto s = t.find("\n" + section + ":");
    const auto at = t.find(line, s);
    const auto next = t.find("\n\n", s);
    if (at != std::string::npos && at < next)
      t.replace(at, t.find('\n', at + 1) - at, line + num.str());
    else
      t.insert(t.find('\n', s + 1), line + num.str());
  };
  auto set_element = [&](const std::string& key, int i) {
    const auto at = t.find("  " + key + ": [");
    const auto open = t.find('[', at), close = t.find(']', at);
    std::vector<std::string> e;
    std::stringstream ss(t.substr(open + 1, close - open - 1));
    for (std::string x; std::getline(ss, x, ',');) e.push_back(x);
    e[static_cast<std::size_t>(i)] = num.str();
    t.replace(open + 1, close - open - 1, e[0] + "," + e[1] + "," + e[2]);
  };
  const auto dot = name.find('.'), last = name.rfind('.');
  const std::string section = name.substr(0, dot);
  if (section == "jog") return t + "\njog:\n  " + name.substr(dot + 1) + ": " + num.str() + "\n";
  if (last != dot) {
    set_element(name.substr(dot + 1, last - dot - 1), name[last + 1] - 'x');
    return t;
  }
  set_line(section, name.substr(dot + 1));
  return t;
}

TEST(Params, TheLoaderAndTheTableRefuseTheSameValues) {
  const DaemonConfig base = shipped();
  for (const auto& p : param_table()) {
    const double step = std::max(1e-9, std::abs(p.maximum) * 1e-6);
    for (double v : {p.maximum + step, p.minimum_excluded ? p.minimum : p.minimum - step}) {
      const std::string why = param_range_error(p, v, base.controller.law);
      ASSERT_NE(why, "") << p.name << " " << v;
      std::string loader;
      try {
        (void)parse_config(with_value(p.name, v), "t.yaml");
      } catch (const Error& e) {
        loader = e.what();
      }
      EXPECT_NE(loader.find(why), std::string::npos) << p.name << " = " << v << ": the loader said: " << loader;
      DaemonConfig c = base;
      EXPECT_THROW(set_param(c, p.name, v), Error) << p.name << " " << v;
    }
  }
  // And the file writes what the test thinks it writes: a value inside the range is loaded.
  EXPECT_EQ(parse_config(with_value("limits.saturation_time", 0.7), "t.yaml").limits.saturation_time, 0.7);
  EXPECT_EQ(parse_config(with_value("controller.kd.y", 80), "t.yaml").controller.gains.kd.y(), 80);
  EXPECT_EQ(parse_config(with_value("limits.workspace_max.z", 0.5), "t.yaml").limits.workspace_max.z(), 0.5);
  EXPECT_EQ(parse_config(with_value("jog.keepalive", 0.1), "t.yaml").jog.keepalive, 0.1);
  EXPECT_EQ(parse_config(with_value("controller.transfer_time", 2), "t.yaml").controller.transfer_time, 2);
}

}  // namespace
}  // namespace cpm::daemon

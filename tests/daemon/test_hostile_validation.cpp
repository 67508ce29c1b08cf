// SPDX-License-Identifier: Apache-2.0
// Hostile trajectory commands against the validator the LCM thread runs on
// every segment (validate_segment): every non-finite value in every field,
// huge, zero and negative durations, out-of-order setpoint streams, bad
// kinds, planes and counts. Each is refused with a reason and a message that
// says what; none throws, none hangs (a huge duration is refused before the
// validator samples the segment).
#include <gtest/gtest.h>

#include <cfloat>
#include <cmath>
#include <functional>
#include <limits>

#include "cpm/daemon/server.hpp"

namespace cpm::daemon {
namespace {

using cpm_msgs::ack_t;
using cpm_msgs::trajectory_command_t;

const Vec3 kP1(0.600, 0.425, 0.300);

struct Hostile : ::testing::Test {
  ctl::Machine machine{ctl::MachineModel::elkady()};
  LimitsConfig limits;
  Validation check(const trajectory_command_t& c, const Vec3& start = kP1) {
    return validate_segment(c, start, machine, limits, 1e-3);
  }
  static trajectory_command_t move() {
    trajectory_command_t m{};
    m.kind = trajectory_command_t::KIND_MOVE;
    m.target[0] = 0.45, m.target[1] = 0.40, m.target[2] = 0.35;
    m.max_velocity = 0.1, m.max_acceleration = 1.0, m.max_jerk = 50.0;
    return m;
  }
  static trajectory_command_t circle() {  // Elkady's circle from P1
    trajectory_command_t m{};
    m.kind = trajectory_command_t::KIND_CIRCLE;
    m.centre[0] = 0.425, m.centre[1] = 0.425, m.centre[2] = 0.300;
    m.radius = 0.175, m.angular_speed = M_PI / 2, m.cruise_time = 4.0;
    return m;
  }
  static trajectory_command_t stream(int n = 5) {  // from P1 along -x, at rest at both ends
    trajectory_command_t m{};
    m.kind = trajectory_command_t::KIND_STREAM;
    m.count = static_cast<std::int16_t>(n);
    for (int i = 0; i < n; ++i) {
      const double s = static_cast<double>(i) / (n - 1);
      m.time[i] = 0.5 * s;
      m.position[i][0] = kP1.x() - 0.01 * s * s * (3 - 2 * s);
      m.position[i][1] = kP1.y();
      m.position[i][2] = kP1.z();
      m.velocity[i][0] = -0.01 * 6 * s * (1 - s) / 0.5;
    }
    return m;
  }
  void expect_refused(const trajectory_command_t& c, std::int16_t reason, const std::string& what,
                      const std::string& needle = "") {
    const Validation v = check(c);
    EXPECT_FALSE(v.ok) << what;
    EXPECT_EQ(v.reason, reason) << what << ": " << v.message;
    EXPECT_FALSE(v.message.empty()) << what;
    if (!needle.empty()) {
      EXPECT_NE(v.message.find(needle), std::string::npos) << what << ": " << v.message;
    }
  }
};

TEST_F(Hostile, TheBaseCommandsAreAccepted) {
  // Otherwise every refusal below could come from something else.
  for (const auto& c : {move(), circle(), stream()}) {
    const Validation v = check(c);
    EXPECT_TRUE(v.ok) << v.message;
  }
}

// Every double of every kind, set to NaN, +inf and -inf in turn.
TEST_F(Hostile, NonFiniteInAnyFieldIsRefusedAsInvalid) {
  const double bad[] = {std::numeric_limits<double>::quiet_NaN(), INFINITY, -INFINITY};
  struct Field {
    const char* name;
    std::function<trajectory_command_t(double)> make;
  };
  std::vector<Field> fields;
  for (int i = 0; i < 3; ++i) {
    fields.push_back({"move.target", [i](double x) { auto m = move(); m.target[i] = x; return m; }});
    fields.push_back({"circle.centre", [i](double x) { auto m = circle(); m.centre[i] = x; return m; }});
  }
  fields.push_back({"move.max_velocity", [](double x) { auto m = move(); m.max_velocity = x; return m; }});
  fields.push_back({"move.max_acceleration", [](double x) { auto m = move(); m.max_acceleration = x; return m; }});
  fields.push_back({"move.max_jerk", [](double x) { auto m = move(); m.max_jerk = x; return m; }});
  fields.push_back({"circle.radius", [](double x) { auto m = circle(); m.radius = x; return m; }});
  fields.push_back({"circle.angular_speed", [](double x) { auto m = circle(); m.angular_speed = x; return m; }});
  fields.push_back({"circle.start_angle", [](double x) { auto m = circle(); m.start_angle = x; return m; }});
  fields.push_back({"circle.cruise_time", [](double x) { auto m = circle(); m.cruise_time = x; return m; }});
  fields.push_back({"circle.ramp_time", [](double x) { auto m = circle(); m.ramp_time = x; return m; }});
  for (int p = 0; p < 5; ++p) {
    fields.push_back({"stream.time", [p](double x) { auto m = stream(); m.time[p] = x; return m; }});
    for (int i = 0; i < 3; ++i) {
      fields.push_back({"stream.position", [p, i](double x) { auto m = stream(); m.position[p][i] = x; return m; }});
      fields.push_back({"stream.velocity", [p, i](double x) { auto m = stream(); m.velocity[p][i] = x; return m; }});
    }
  }
  int refused = 0;
  for (const auto& f : fields)
    for (double x : bad) {
      expect_refused(f.make(x), ack_t::REASON_INVALID, std::string(f.name) + " = " + std::to_string(x));
      ++refused;
    }
  EXPECT_EQ(refused, 3 * (6 + 8 + 5 * 7));
}

TEST_F(Hostile, HugeDurationsAreRefusedBeforeSampling) {
  // Each of these would take the validator hours (or forever) to sample at
  // 1 kHz; the test itself would time out if they were sampled.
  for (double T : {601.0, 1e9, 1e300, DBL_MAX}) {
    auto c = circle();
    c.radius = 0.01;
    c.centre[0] = kP1.x() - 0.01;
    c.cruise_time = T;
    expect_refused(c, ack_t::REASON_LIMIT, "circle cruise_time " + std::to_string(T), "600");
    auto r = circle();
    r.ramp_time = T / 2;
    expect_refused(r, ack_t::REASON_LIMIT, "circle ramp_time " + std::to_string(T));
    auto s = stream();
    s.time[4] = T;
    expect_refused(s, ack_t::REASON_LIMIT, "stream of " + std::to_string(T) + " s");
  }
  // A move whose limits make it last for ages.
  auto m = move();
  m.max_velocity = 1e-12;
  const Validation v = check(m);
  EXPECT_FALSE(v.ok);
  EXPECT_TRUE(v.reason == ack_t::REASON_LIMIT || v.reason == ack_t::REASON_INVALID) << v.message;
  m = move();
  m.max_acceleration = 1e-300;
  EXPECT_FALSE(check(m).ok);
  m = move();
  m.max_jerk = DBL_MIN;
  EXPECT_FALSE(check(m).ok);
}

TEST_F(Hostile, ZeroAndNegativeDurationsAreRefused) {
  auto c = circle();
  c.cruise_time = -1.0;
  expect_refused(c, ack_t::REASON_INVALID, "negative cruise", "cruise time");
  c = circle();
  c.ramp_time = -0.1;
  expect_refused(c, ack_t::REASON_INVALID, "negative ramp", "ramp time");
  c = circle();
  c.cruise_time = 0.0;
  expect_refused(c, ack_t::REASON_INVALID, "zero duration", "duration");
  for (double v : {0.0, -0.1, -DBL_MAX}) {
    auto m = move();
    m.max_velocity = v;
    expect_refused(m, ack_t::REASON_INVALID, "move max_velocity " + std::to_string(v));
  }
  auto s = stream();
  s.time[0] = -0.1;  // must be 0
  expect_refused(s, ack_t::REASON_INVALID, "stream starting before 0");
  s = stream();
  s.time[0] = 0.1;
  expect_refused(s, ack_t::REASON_INVALID, "stream starting after 0");
}

TEST_F(Hostile, OutOfOrderSetpointsAreRefusedNamingThePoint) {
  auto s = stream();
  std::swap(s.time[2], s.time[3]);
  expect_refused(s, ack_t::REASON_INVALID, "swapped times", "point 3");
  s = stream();
  s.time[3] = s.time[2];  // duplicated
  expect_refused(s, ack_t::REASON_INVALID, "duplicated time", "point 3");
  s = stream();
  s.time[4] = -s.time[4];
  expect_refused(s, ack_t::REASON_INVALID, "time running backwards", "point 4");
}

TEST_F(Hostile, BadKindPlaneAndCountAreRefused) {
  for (int kind : {-128, 0, 4, 127}) {
    auto m = move();
    m.kind = static_cast<std::int8_t>(kind);
    expect_refused(m, ack_t::REASON_INVALID, "kind " + std::to_string(kind), "kind");
  }
  for (int plane : {-1, 3, 127}) {
    auto c = circle();
    c.plane = static_cast<std::int8_t>(plane);
    expect_refused(c, ack_t::REASON_INVALID, "plane " + std::to_string(plane), "plane");
  }
  for (int count : {-32768, -1, 0, 1, 101, 32767}) {
    auto s = stream();
    s.count = static_cast<std::int16_t>(count);
    expect_refused(s, ack_t::REASON_INVALID, "count " + std::to_string(count), "count");
  }
}

}  // namespace
}  // namespace cpm::daemon

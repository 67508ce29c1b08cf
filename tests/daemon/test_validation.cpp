// SPDX-License-Identifier: Apache-2.0
// Trajectory commands are validated before the loop sees them: finite,
// inside the workspace and the soft limits, within the speed and acceleration
// limits, continuous with the queue. And the setpoint-stream interpolation.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>

#include "cpm/daemon/server.hpp"

namespace cpm::daemon {
namespace {

using cpm_msgs::ack_t;
using cpm_msgs::trajectory_command_t;

struct Fixture : ::testing::Test {
  ctl::Machine machine{ctl::MachineModel::elkady()};
  LimitsConfig limits;
  const Vec3 p1{0.600, 0.425, 0.300};
  Validation check(const trajectory_command_t& c, const Vec3& start) {
    return validate_segment(c, start, machine, limits, 1e-3);
  }
  static trajectory_command_t move(const Vec3& to, double v = 0.1) {
    trajectory_command_t m{};
    m.kind = trajectory_command_t::KIND_MOVE;
    for (int i = 0; i < 3; ++i) m.target[i] = to[i];
    m.max_velocity = v;
    m.max_acceleration = 1.0;
    m.max_jerk = 50.0;
    return m;
  }
  static trajectory_command_t paper_circle() {
    trajectory_command_t m{};
    m.kind = trajectory_command_t::KIND_CIRCLE;
    m.centre[0] = 0.425;
    m.centre[1] = 0.425;
    m.centre[2] = 0.300;
    m.radius = 0.175;
    m.angular_speed = M_PI / 2;
    m.cruise_time = 4.0;
    return m;
  }
};

TEST_F(Fixture, PaperCircleAndMoveAccepted) {
  Validation v = check(paper_circle(), p1);
  ASSERT_TRUE(v.ok) << v.message;
  EXPECT_LT((v.segment.end - p1).norm(), 1e-9);  // a whole turn
  EXPECT_DOUBLE_EQ(v.segment.get()->duration(), 4.0);
  v = check(move(Vec3(0.45, 0.40, 0.35)), p1);
  ASSERT_TRUE(v.ok) << v.message;
  EXPECT_TRUE(v.segment.end.isApprox(Vec3(0.45, 0.40, 0.35)));
}

TEST_F(Fixture, NaNRefused) {
  const Validation v = check(move(Vec3(NAN, 0.4, 0.35)), p1);
  EXPECT_FALSE(v.ok);
  EXPECT_EQ(v.reason, ack_t::REASON_INVALID);
  EXPECT_NE(v.message.find("not finite"), std::string::npos);
  auto c = paper_circle();
  c.radius = INFINITY;
  EXPECT_EQ(check(c, p1).reason, ack_t::REASON_INVALID);
}

TEST_F(Fixture, OutsideWorkspaceRefusedWithWhere) {
  Validation v = check(move(Vec3(0.9, 0.4, 0.35)), p1);  // beyond the x stroke
  EXPECT_FALSE(v.ok);
  EXPECT_EQ(v.reason, ack_t::REASON_WORKSPACE);
  EXPECT_NE(v.message.find("900.000"), std::string::npos) << v.message;
  // Inside the strokes but outside the soft limits.
  limits.workspace_max.y() = 0.5;
  auto c = paper_circle();
  v = check(c, p1);
  EXPECT_FALSE(v.ok);
  EXPECT_EQ(v.reason, ack_t::REASON_WORKSPACE);
  EXPECT_NE(v.message.find("soft limits on y"), std::string::npos) << v.message;
}

TEST_F(Fixture, TooFastRefused) {
  Validation v = check(move(Vec3(0.45, 0.40, 0.35), 3.0), p1);
  EXPECT_FALSE(v.ok);
  EXPECT_EQ(v.reason, ack_t::REASON_LIMIT);
  EXPECT_NE(v.message.find("limits.velocity"), std::string::npos) << v.message;
  auto c = paper_circle();
  c.angular_speed = 10.0;  // 1.75 m/s
  v = check(c, p1);
  EXPECT_EQ(v.reason, ack_t::REASON_LIMIT);
  // Centripetal acceleration over the limit, speed under it.
  limits.acceleration = 0.3;  // the paper circle needs 0.43 m/s^2
  v = check(paper_circle(), p1);
  EXPECT_FALSE(v.ok);
  EXPECT_EQ(v.reason, ack_t::REASON_LIMIT) << v.message;
}

TEST_F(Fixture, DiscontinuousRefused) {
  const Validation v = check(paper_circle(), p1 + Vec3(0, 0.01, 0));
  EXPECT_FALSE(v.ok);
  EXPECT_EQ(v.reason, ack_t::REASON_NOT_CONTINUOUS);
}

TEST(StreamTrajectory, HermiteReproducesACubicExactly) {
  // p(t) = a + b t + c t^2 + d t^3 on each axis: Hermite on exact samples is exact.
  auto p = [](double t, int i) { return 0.3 + 0.01 * i + 0.02 * t - 0.05 * t * t + 0.03 * t * t * t; };
  auto v = [](double t, int) { return 0.02 - 0.10 * t + 0.09 * t * t; };
  auto acc = [](double t, int) { return -0.10 + 0.18 * t; };
  double t[5] = {0, 0.1, 0.35, 0.5, 1.0}, P[5][3], V[5][3];
  for (int k = 0; k < 5; ++k)
    for (int i = 0; i < 3; ++i) {
      P[k][i] = p(t[k], i);
      V[k][i] = v(t[k], i);
    }
  const StreamTrajectory s(5, t, P, V);
  EXPECT_DOUBLE_EQ(s.duration(), 1.0);
  for (double tt : {0.05, 0.2, 0.42, 0.77, 0.99}) {
    const auto x = s.sample(tt);
    for (int i = 0; i < 3; ++i) {
      EXPECT_NEAR(x.p[i], p(tt, i), 1e-14);
      EXPECT_NEAR(x.v[i], v(tt, i), 1e-12);
      EXPECT_NEAR(x.a[i], acc(tt, i), 1e-10);
    }
  }
  const auto end = s.sample(2.0);
  EXPECT_NEAR(end.p[0], p(1.0, 0), 1e-15);
  EXPECT_EQ(end.v.norm(), 0.0);
}

TEST(StreamTrajectory, BadTimesRefusedWithThePoint) {
  double t[3] = {0, 0.2, 0.2}, P[3][3] = {}, V[3][3] = {};
  try {
    StreamTrajectory s(3, t, P, V);
    FAIL() << "accepted non-increasing times";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("point 2"), std::string::npos) << e.what();
  }
  t[0] = 0.1;
  EXPECT_THROW(StreamTrajectory(2, t, P, V), Error);
}

}  // namespace
}  // namespace cpm::daemon

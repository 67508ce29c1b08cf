// SPDX-License-Identifier: Apache-2.0
// One actuator's homing sequence (homing.hpp) against a simulated actuator
// that follows its ramped reference, with a home switch and index marks
// planted at known places: the zero it finds must put the actuator at
// home_position on the switch's edge (or the index after it), whatever the
// encoder's unknown zero, from either side; and each failure must say so.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "cpm/daemon/homing.hpp"
#include "cpm/daemon/ramp.hpp"

namespace cpm::daemon {
namespace {

constexpr double kDt = 1e-3;

// The actuator: its true displacement d follows the reference exactly (the
// loop's tracking is tested elsewhere); the encoder reads d - zero.
struct Actuator {
  double zero = 0.0371;          // unknown to the sequence
  double switch_below = 0.010;   // switch actuated while d < this
  bool switch_works = true;
  double index_pitch = 0.0;      // index marks at k * pitch (0: none)
  double index_width = 0.0002;
  Ramp ramp;                     // in raw terms + offset, as the loop keeps it
  double offset = 0.0;           // what homing added
  double d() const { return ramp.p.x() - offset + zero; }  // true displacement
  bool home_switch() const { return switch_works && d() < switch_below; }
  bool index() const {
    if (index_pitch <= 0) return false;
    const double r = std::remainder(d(), index_pitch);
    return std::abs(r) < 0.5 * index_width;
  }
};

struct HomingRun {
  AxisHoming::Outcome outcome = AxisHoming::Outcome::running;
  double seconds = 0.0;
  double max_speed = 0.0;
  double event_d = std::nan("");  // true d when the offset was taken
};

HomingRun home(Actuator& a, const AxisHomingConfig& cfg, double t_limit = 120.0) {
  AxisHoming h;
  a.ramp.reset(Vec3(a.d() - a.zero + a.offset, 0, 0));
  h.start(cfg, 0.0, a.home_switch());
  HomingRun r;
  AxisHoming::Request req;
  for (long k = 0; k * kDt < t_limit; ++k) {
    AxisHoming::Inputs in;
    in.t = static_cast<double>(k) * kDt;
    in.raw = a.d() - a.zero;
    in.reference = a.ramp.p.x() - a.offset;
    in.reference_at_rest = a.ramp.v.x() == 0.0;
    in.home_switch = a.home_switch();
    in.index = a.index();
    r.outcome = h.step(in, req);
    if (h.event_seen() && a.offset != h.offset()) {
      a.ramp.p.x() += h.offset() - a.offset;
      a.offset = h.offset();
      r.event_d = a.d();
    }
    if (r.outcome != AxisHoming::Outcome::running) {
      r.seconds = in.t;
      return r;
    }
    if (req.kind == AxisHoming::Request::Kind::position)
      a.ramp.step_to(Vec3(req.position + a.offset, 0, 0), req.speed, cfg.acceleration, kDt);
    else
      a.ramp.step(Vec3(req.velocity, 0, 0), cfg.acceleration, Ramp::unbounded_low(), Ramp::unbounded_high(), kDt);
    r.max_speed = std::max(r.max_speed, std::abs(a.ramp.v.x()));
  }
  r.seconds = t_limit;
  return r;
}

AxisHomingConfig switch_config() {
  AxisHomingConfig c;
  c.method = HomingMethod::switch_;
  c.search_velocity = -0.02;
  c.latch_velocity = 0.002;
  c.acceleration = 0.2;
  c.home_position = 0.010;  // the switch's edge, in the machine's terms
  c.max_travel = 0.45;
  c.timeout = 60.0;
  return c;
}

TEST(Homing, FromAboveTheSwitchTheZeroPutsTheSwitchEdgeAtHomePosition) {
  for (const double start_d : {0.150, 0.0125, 0.390}) {
    Actuator a;
    a.ramp.reset(Vec3(start_d - a.zero, 0, 0));
    const HomingRun r = home(a, switch_config());
    ASSERT_EQ(r.outcome, AxisHoming::Outcome::homed) << start_d;
    // The event is the switch's release met at the latch speed: within one
    // period's travel at 2 mm/s of the true edge.
    EXPECT_NEAR(r.event_d, a.switch_below, 0.002 * kDt + 1e-12) << start_d;
    // What the actuator now reads is the truth, to that resolution.
    EXPECT_NEAR(a.ramp.p.x(), a.d(), 0.002 * kDt + 1e-12);
    EXPECT_LE(r.max_speed, 0.02 + 1e-12);
    std::printf("homing from d = %.1f mm: %.2f s, zero found %.4f mm off the truth\n", start_d * 1e3, r.seconds,
                (a.ramp.p.x() - a.d()) * 1e3);
  }
}

TEST(Homing, StartingOnTheSwitchLeavesItFirstThenHomesOnTheSameEdge) {
  Actuator a;
  a.ramp.reset(Vec3(0.004 - a.zero, 0, 0));  // d = 4 mm: the switch is actuated
  ASSERT_TRUE(a.home_switch());
  const HomingRun r = home(a, switch_config());
  ASSERT_EQ(r.outcome, AxisHoming::Outcome::homed);
  EXPECT_NEAR(r.event_d, a.switch_below, 0.002 * kDt + 1e-12);
}

TEST(Homing, WithAnIndexTheZeroIsAtTheFirstMarkPastTheSwitch) {
  Actuator a;
  a.index_pitch = 0.004;   // marks at 12 mm, 16 mm, ... past the switch edge at 10 mm
  a.ramp.reset(Vec3(0.2 - a.zero, 0, 0));
  AxisHomingConfig c = switch_config();
  c.use_index = true;
  c.home_position = 0.012;
  const HomingRun r = home(a, c);
  ASSERT_EQ(r.outcome, AxisHoming::Outcome::homed);
  // The first mark reached moving up from the edge: 12 mm less half its width.
  EXPECT_NEAR(r.event_d, 0.012 - 0.5 * a.index_width, 0.002 * kDt + 1e-12);
  EXPECT_NEAR(a.ramp.p.x() - a.d(), 0.5 * a.index_width, 0.002 * kDt + 1e-12);
}

TEST(Homing, TheFinalMoveEndsAtRestWhereConfigured) {
  Actuator a;
  a.ramp.reset(Vec3(0.3 - a.zero, 0, 0));
  AxisHomingConfig c = switch_config();
  c.final_position = 0.100;
  const HomingRun r = home(a, c);
  ASSERT_EQ(r.outcome, AxisHoming::Outcome::homed);
  EXPECT_DOUBLE_EQ(a.ramp.p.x(), 0.100);  // the reference, in homed terms
  EXPECT_NEAR(a.d(), 0.100, 0.002 * kDt + 1e-12);
  EXPECT_TRUE(a.ramp.at_rest());
}

TEST(Homing, ASwitchThatNeverActuatesFailsAfterMaxTravelWithTheFigures) {
  Actuator a;
  a.switch_works = false;
  a.ramp.reset(Vec3(0.2 - a.zero, 0, 0));
  AxisHomingConfig c = switch_config();
  c.max_travel = 0.25;
  const HomingRun r = home(a, c);
  ASSERT_EQ(r.outcome, AxisHoming::Outcome::failed);
  // It went no farther than max_travel plus one period.
  EXPECT_NEAR(0.2 - a.d(), 0.25, 0.02 * kDt + 1e-9);
}

TEST(Homing, FailuresNameTheirCause) {
  {  // stuck switch: actuated everywhere
    Actuator a;
    a.switch_below = 10.0;
    a.ramp.reset(Vec3(0.2 - a.zero, 0, 0));
    AxisHomingConfig c = switch_config();
    c.max_travel = 0.05;
    AxisHoming h;
    a.ramp.reset(Vec3(a.d() - a.zero, 0, 0));
    h.start(c, 0.0, true);
    AxisHoming::Request req;
    AxisHoming::Outcome o = AxisHoming::Outcome::running;
    for (int k = 0; k < 100000 && o == AxisHoming::Outcome::running; ++k) {
      AxisHoming::Inputs in;
      in.t = k * kDt;
      in.raw = a.d() - a.zero;
      in.home_switch = true;
      o = h.step(in, req);
      a.ramp.step(Vec3(req.velocity, 0, 0), c.acceleration, Ramp::unbounded_low(), Ramp::unbounded_high(), kDt);
    }
    EXPECT_EQ(o, AxisHoming::Outcome::failed);
    EXPECT_STREQ(h.failure().cause, "switch_stuck");
    EXPECT_DOUBLE_EQ(h.failure().limit, 0.05);
  }
  {  // timeout: a slow search
    Actuator a;
    a.ramp.reset(Vec3(0.4 - a.zero, 0, 0));
    AxisHomingConfig c = switch_config();
    c.timeout = 2.0;  // 390 mm at 20 mm/s takes 19.5 s
    const HomingRun r = home(a, c);
    EXPECT_EQ(r.outcome, AxisHoming::Outcome::failed);
    EXPECT_NEAR(r.seconds, 2.0, 2 * kDt);
  }
}

TEST(Homing, ADriveThatHomesItselfIsWaitedForAndItsErrorIsAFailure) {
  AxisHomingConfig c;
  c.method = HomingMethod::drive;
  c.drive_method = 19;
  c.timeout = 5.0;
  for (const DriveHoming end : {DriveHoming::attained, DriveHoming::error}) {
    AxisHoming h;
    h.start(c, 0.0, false);
    AxisHoming::Request req;
    AxisHoming::Outcome o = AxisHoming::Outcome::running;
    int k = 0;
    for (; k < 1000 && o == AxisHoming::Outcome::running; ++k) {
      AxisHoming::Inputs in;
      in.t = k * kDt;
      in.drive = k < 3 ? DriveHoming::idle : (k < 500 ? DriveHoming::running : end);
      o = h.step(in, req);
      if (o == AxisHoming::Outcome::running) {
        EXPECT_EQ(req.kind, AxisHoming::Request::Kind::drive);
      }
    }
    EXPECT_EQ(k, 501);
    if (end == DriveHoming::attained) {
      EXPECT_EQ(o, AxisHoming::Outcome::homed);
      EXPECT_EQ(h.offset(), 0.0);  // the drive's own counts moved
    } else {
      EXPECT_EQ(o, AxisHoming::Outcome::failed);
      EXPECT_STREQ(h.failure().cause, "drive_error");
    }
  }
}

}  // namespace
}  // namespace cpm::daemon

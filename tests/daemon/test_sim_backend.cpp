// SPDX-License-Identifier: Apache-2.0
// The simulator backend's homing inputs, stepped by hand: incremental
// encoders read d - encoder_zero, the home switch and the index marks are
// seen where they are in the true d, within one period's travel; and the
// diagnostics of the commissioning view.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include <cpm_msgs/drives_t.hpp>

#include "cpm/daemon/config.hpp"
#include "cpm/daemon/sim_backend.hpp"

namespace cpm::daemon {
namespace {

constexpr double kPeriod = 1e-3;
using D = cpm_msgs::drives_t;

// The nominal machine: d = p - d0, d0 = (0.225, 0.225, 0.2268) m (docs/model.md).
const Vec3 kD0(0.225, 0.225, 0.2268);

std::unique_ptr<SimBackend> backend(const SimBackendOptions& o) {
  auto b = std::make_unique<SimBackend>(std::make_unique<ctl::Machine>(ctl::MachineModel::elkady()), o);
  b->start(kPeriod);
  return b;
}

Vec3 true_d(const SimBackend& b) {
  Vec3 d, v;
  EXPECT_TRUE(b.plant().actuator_state(d, v));
  return d;
}

// Cycle by cycle: drives enabled, actuator `axis` led along a ramp of d at
// `speed` (m/s) by a PD law on top of the force that holds the platform, the
// others held where they are.
struct Rig {
  std::unique_ptr<SimBackend> b;
  std::int64_t k = 0;
  BackendInput in{};
  Vec3 target;
  explicit Rig(const SimBackendOptions& o) : b(backend(o)) {
    EXPECT_EQ(b->read(k, in), BackendResult::ok);
    target = true_d(*b);
  }
  void cycle(int axis, double speed) {
    target[axis] += speed * kPeriod;
    Vec3 d, d_dot, hold;
    EXPECT_TRUE(b->plant().actuator_state(d, d_dot));
    EXPECT_TRUE(b->plant().truth().holding_command(b->plant().position(), b->plant().kinematic_inputs(), hold));
    Vec3 v_ref = Vec3::Zero();
    v_ref[axis] = speed;
    BackendOutput out{};
    out.enable = true;
    for (int i = 0; i < 3; ++i) out.force[i] = hold[i] + 12691.0 * (target[i] - d[i]) + 436.0 * (v_ref[i] - d_dot[i]);
    EXPECT_EQ(b->write(k, out), BackendResult::ok);
    ++k;
    EXPECT_EQ(b->read(k, in), BackendResult::ok);
  }
};

TEST(SimBackend, EncodersReadDMinusEncoderZero) {
  SimBackendOptions o;
  o.initial_position = Vec3(0.600, 0.425, 0.300);
  auto absolute = backend(o);
  o.encoder_zero = Vec3(0.0372, -0.0213, 0.0518);
  auto incremental = backend(o);
  BackendInput a{}, i{};
  ASSERT_EQ(absolute->read(0, a), BackendResult::ok);
  ASSERT_EQ(incremental->read(0, i), BackendResult::ok);
  const Vec3 d = o.initial_position - kD0;  // (0.375, 0.200, 0.0732)
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(a.position[k], d[k], 1e-12);
    EXPECT_NEAR(i.position[k], d[k] - o.encoder_zero[k], 1e-12);
    EXPECT_EQ(i.velocity[k], a.velocity[k]);
    // Nothing configured: no switch, no index.
    EXPECT_FALSE(a.home_switch[k]);
    EXPECT_FALSE(a.index_pulse[k]);
  }
}

// Along a ramp of actuator 1 (x), the reads at which the switch or an index
// mark is first seen, with the true d there and the travel of that period.
struct Seen {
  double d, travel;
};

TEST(SimBackend, HomeSwitchIsSeenAtItsEdgeWithinOnePeriodsTravel) {
  SimBackendOptions o;
  o.initial_position = Vec3(0.2675, 0.425, 0.300);  // d1 = 42.5 mm
  o.home_switch = Vec3(0.020, std::nan(""), 0.030);  // x at 20 mm; none on y; z's (at 30 mm) left below it
  o.encoder_zero = Vec3(0.0372, 0, 0);              // the switch is in d, not in what the encoder reads
  Rig r(o);
  EXPECT_FALSE(r.in.home_switch[0]);
  EXPECT_FALSE(r.in.home_switch[2]);  // d3 = 73.2 mm
  std::vector<Seen> on, off;
  double last = true_d(*r.b).x();
  bool was = false;
  // Search: down at 20 mm/s to 15 mm.
  for (int n = 0; n < 1400; ++n) {
    r.cycle(0, -0.020);
    const double d = true_d(*r.b).x();
    if (r.in.home_switch[0] && !was) on.push_back({d, std::abs(d - last)});
    was = r.in.home_switch[0];
    EXPECT_EQ(r.in.home_switch[0], d < 0.020) << d;
    EXPECT_FALSE(r.in.home_switch[1]);
    EXPECT_FALSE(r.in.home_switch[2]);
    last = d;
  }
  ASSERT_EQ(on.size(), 1u);
  EXPECT_LT(on[0].d, 0.020);
  EXPECT_GT(on[0].d, 0.020 - on[0].travel - 1e-12);
  EXPECT_GT(on[0].travel, 1e-5);  // it did move about 20 um per period
  // Latch: up at 2 mm/s off the switch.
  for (int n = 0; n < 4000 && was; ++n) {
    r.cycle(0, 0.002);
    const double d = true_d(*r.b).x();
    if (!r.in.home_switch[0]) off.push_back({d, std::abs(d - last)});
    was = r.in.home_switch[0];
    last = d;
  }
  ASSERT_EQ(off.size(), 1u) << "the switch was not left";
  EXPECT_GE(off[0].d, 0.020);
  EXPECT_LT(off[0].d, 0.020 + off[0].travel + 1e-12);
  EXPECT_LT(off[0].travel, 5e-6);  // about 2 um per period: the edge within that
  // What the encoder reads there is d - encoder_zero.
  EXPECT_NEAR(r.in.position[0], off[0].d - 0.0372, 1e-12);
  // The switch of z (at 30 mm, d3 at 73.2 mm) never was actuated.
  EXPECT_FALSE(r.in.home_switch[2]);
}

TEST(SimBackend, IndexMarksAreSeenOncePerPassWhateverTheSpeed) {
  SimBackendOptions o;
  o.initial_position = Vec3(0.2675, 0.425, 0.300);  // d1 = 42.5 mm
  o.index_pitch = 0.005;
  Rig r(o);
  EXPECT_FALSE(r.in.index_pulse[0]);
  // At 47.3 mm/s a period's travel (47.3 um, not a divisor of the pitch) is
  // almost five times the mark's width: a level read each period would miss
  // most marks; the crossing is caught.
  std::vector<Seen> fast;
  double last = true_d(*r.b).x();
  bool was = false;
  for (int n = 0; n < 600; ++n) {  // to about 14.1 mm
    r.cycle(0, -0.0473);
    const double d = true_d(*r.b).x();
    if (r.in.index_pulse[0] && !was) fast.push_back({d, std::abs(d - last)});
    was = r.in.index_pulse[0];
    last = d;
  }
  // Marks at 40, 35, 30, 25, 20, 15 mm, each seen once, within a period's travel past it.
  ASSERT_EQ(fast.size(), 6u);
  for (std::size_t m = 0; m < fast.size(); ++m) {
    const double mark = 0.040 - 0.005 * static_cast<double>(m);
    EXPECT_LE(fast[m].d, mark + SimBackendOptions::kIndexHalfWidth) << m;
    EXPECT_GT(fast[m].d, mark - fast[m].travel - 1e-12) << m;
    EXPECT_GT(fast[m].travel, 4e-5);
  }
  // Back up at the latch speed, 2 mm/s, from about 14.1 mm: the next mark up
  // (15 mm) is seen within the mark's half width of it.
  std::vector<Seen> slow;
  for (int n = 0; n < 5000 && slow.size() < 1; ++n) {
    r.cycle(0, 0.002);
    const double d = true_d(*r.b).x();
    if (r.in.index_pulse[0] && !was) slow.push_back({d, std::abs(d - last)});
    was = r.in.index_pulse[0];
    last = d;
  }
  ASSERT_EQ(slow.size(), 1u);
  EXPECT_NEAR(slow[0].d, 0.015, SimBackendOptions::kIndexHalfWidth + 1e-12);
}

TEST(SimBackend, DiagnosticsShowTheDrivesStateEstopAndSwitches) {
  SimBackendOptions o;
  o.initial_position = Vec3(0.2675, 0.425, 0.300);
  o.home_switch = Vec3(0.050, std::nan(""), std::nan(""));  // x (42.5 mm) is on its switch
  Rig r(o);
  BackendDiagnostics g;
  r.b->diagnostics(g);
  EXPECT_EQ(g.backend, D::BACKEND_SIM);
  EXPECT_EQ(g.bus_state, D::BUS_NONE);
  EXPECT_TRUE(g.home_switch[0]);
  EXPECT_FALSE(g.home_switch[1]);
  for (const auto& d : g.drive) {
    EXPECT_EQ(d.node_id, 0);  // not a CANopen drive
    EXPECT_EQ(d.cia402, D::CIA402_SWITCH_ON_DISABLED);
    EXPECT_EQ(d.statusword, 0x0250);
  }
  for (int n = 0; n < 10; ++n) r.cycle(0, 0.0);  // enable_delay 5 ms
  r.b->diagnostics(g);
  for (const auto& d : g.drive) {
    EXPECT_EQ(d.cia402, D::CIA402_OPERATION_ENABLED);
    EXPECT_EQ(d.mode_display, 10);  // as in cyclic synchronous torque
  }
  EXPECT_FALSE(g.estop);
  r.b->inject_drive_fault(1);
  r.b->set_estop(true);
  r.cycle(0, 0.0);
  r.b->diagnostics(g);
  EXPECT_EQ(g.drive[1].cia402, D::CIA402_FAULT);
  EXPECT_EQ(g.drive[0].cia402, D::CIA402_SWITCH_ON_DISABLED);  // the e-stop cut the power
  EXPECT_TRUE(g.estop);
}

// config/sim-homing.yaml asks each actuator in turn to run past its switch
// (by the stop from the search speed) and then to its final position: every
// pose on the way is one the true machine reaches (the backend refuses to
// start the plant anywhere else).
TEST(SimBackend, TheShippedHomingConfigOnlyAsksForReachablePoses) {
  const DaemonConfig c = load_config(std::string(CPM_SOURCE_DIR) + "/config/sim-homing.yaml");
  Vec3 d = c.sim.initial_position - kD0;
  int poses = 0;
  auto reachable = [&](const Vec3& at) {
    SimBackendOptions o;
    o.initial_position = at + kD0;
    EXPECT_NO_THROW(backend(o)) << "d = " << at.transpose();
    ++poses;
  };
  for (int k = 0; k < c.homing.order_count; ++k) {
    const int i = c.homing.order[static_cast<std::size_t>(k)];
    const auto& a = c.homing.axes[static_cast<std::size_t>(i)];
    ASSERT_LT(a.search_velocity, 0.0);
    d[i] = c.sim.home_switch[i] - a.search_velocity * a.search_velocity / (2 * a.acceleration);
    reachable(d);
    d[i] = a.home_position;
    reachable(d);
    d[i] = a.final_position;
    reachable(d);
  }
  EXPECT_EQ(poses, 9);
}

}  // namespace
}  // namespace cpm::daemon

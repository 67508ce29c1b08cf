// SPDX-License-Identifier: Apache-2.0
// Operating the machine (issue 17), cycle by cycle on the simulator backend:
// jogging with its deadman and the workspace's edge, trajectories that must
// start with the motion the queue ends with, and a controller switched while
// the platform is held without the force jumping.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>

#include "cpm/daemon/preflight.hpp"
#include "loop_fixture.hpp"
#include "server_fixture.hpp"

namespace cpm::daemon {
namespace {

using cpm_msgs::ack_t;
using cpm_msgs::control_command_t;
using cpm_msgs::state_t;
using cpm_msgs::trajectory_command_t;
using test::LoopHarness;

Command jog_command(std::int8_t frame, const Vec3& v) {
  Command c;
  c.kind = CommandKind::jog;
  c.jog_frame = frame;
  c.jog_velocity = v;
  return c;
}

Vec3 measured(const LoopHarness& h) { return h.position(); }
Vec3 reference(const LoopHarness& h) {
  const auto& s = h.state();
  return Vec3(s.position_ref[0], s.position_ref[1], s.position_ref[2]);
}

TEST(Jog, WhenTheKeepAliveStopsAtFullSpeedThePlatformStopsWithinTheConfiguredDistance) {
  LoopHarness h;
  h.to_holding();
  const JogConfig& j = h.cfg.jog;
  const Vec3 v(-j.max_velocity, 0, 0);
  // Keep-alives every 50 ms for 1 s: full speed long before the last.
  Vec3 at_last;
  for (int n = 0; n < 20; ++n) {
    const Ack a = h.command(jog_command(control_command_t::JOG_MACHINE, v));
    ASSERT_TRUE(a.accepted) << a.message;
    at_last = measured(h);
    if (n < 19) h.run(49);
  }
  ASSERT_EQ(h.mode(), Mode::jogging);
  EXPECT_NEAR(h.state().velocity[0], -j.max_velocity, 2e-4);
  int cycles = 0;
  while (h.mode() == Mode::jogging && cycles < 5000) {
    h.run(1);
    ++cycles;
  }
  ASSERT_EQ(h.mode(), Mode::holding);
  h.run(300);  // settled
  const double travelled = (measured(h) - at_last).norm();
  // The closed form: the keep-alive's time at full speed, then v^2 / 2a.
  const double expected = j.max_velocity * j.keepalive + j.max_velocity * j.max_velocity / (2 * j.acceleration);
  std::printf("jog at %.0f mm/s, deadman let go: at rest %.3f mm on (closed form %.3f mm, jog.stop_distance %.3f mm) "
              "after %.0f ms\n",
              j.max_velocity * 1e3, travelled * 1e3, expected * 1e3, j.stop_distance * 1e3, cycles * 1.0);
  EXPECT_LE(travelled, j.stop_distance);
  EXPECT_NEAR(travelled, expected, 1e-4);
  EXPECT_NEAR(cycles * 1e-3, j.keepalive + j.max_velocity / j.acceleration, 3e-3);
}

TEST(Jog, StopsAtTheWorkspaceEdgeAndAJogOutwardThereIsRefused) {
  LoopHarness h;
  h.to_holding();
  const double edge = h.cfg.limits.workspace_max.x();  // 15 mm from P1
  double farthest = 0.0;
  for (int n = 0; n < 60; ++n) {
    (void)h.command(jog_command(control_command_t::JOG_MACHINE, Vec3(h.cfg.jog.max_velocity, 0, 0)));
    for (int i = 0; i < 49; ++i) {
      h.run(1);
      farthest = std::max(farthest, reference(h).x());
    }
  }
  EXPECT_LE(farthest, edge);
  EXPECT_NEAR(reference(h).x(), edge, 1e-6);
  EXPECT_EQ(h.state().faults, 0);
  // At the edge: outward refused, nothing moves; inward accepted.
  h.run(400);
  ASSERT_EQ(h.mode(), Mode::holding);
  const Ack out = h.command(jog_command(control_command_t::JOG_MACHINE, Vec3(0.01, 0.0, 0)));
  EXPECT_FALSE(out.accepted);
  EXPECT_EQ(out.refusal, Refusal::workspace);
  std::printf("jog outward at the edge: %s\n", out.message);
  EXPECT_EQ(h.mode(), Mode::holding);
  const Ack in = h.command(jog_command(control_command_t::JOG_MACHINE, Vec3(-0.01, 0.0, 0)));
  EXPECT_TRUE(in.accepted) << in.message;
}

// Jog with keep-alives every 49 cycles for `keepalives` of them; the
// farthest reference and measured coordinate `axis` reached in direction `sign`.
struct JogRun {
  double farthest_ref = -1e9, farthest_measured = -1e9;
};
JogRun jog_for(LoopHarness& h, std::int8_t frame, const Vec3& v, int keepalives, int axis, double sign) {
  JogRun r;
  for (int n = 0; n < keepalives; ++n) {
    (void)h.command(jog_command(frame, v));
    for (int i = 0; i < 49; ++i) {
      h.run(1);
      r.farthest_ref = std::max(r.farthest_ref, sign * reference(h)[axis]);
      r.farthest_measured = std::max(r.farthest_measured, sign * measured(h)[axis]);
    }
  }
  return r;
}

// Jog toward +x at full speed, a keep-alive every 20 cycles, until the
// reference rests on the +x face; the jog is still held then (its
// keep-alive window open). False if it never got there.
bool jog_to_rest_on_the_x_edge(LoopHarness& h, std::int8_t frame) {
  const double edge = h.cfg.limits.workspace_max.x();
  for (int n = 0; n < 60; ++n) {
    if (!h.command(jog_command(frame, Vec3(h.cfg.jog.max_velocity, 0, 0))).accepted) return false;
    for (int i = 0; i < 20; ++i) {
      h.run(1);
      if (h.state().velocity_ref[0] == 0.0 && reference(h).x() > edge - 1e-6) return true;
    }
  }
  return false;
}

TEST(Jog, AnActuatorJogOnceHomedStopsAtTheWorkspaceEdgeNotAtTheStroke) {
  LoopHarness h;
  h.to_holding();
  ASSERT_EQ(h.state().control_space, state_t::SPACE_TASK);
  const double edge = h.cfg.limits.workspace_max.x();
  // The stroke of actuator 1 goes past the workspace's edge: the stroke alone would not stop it.
  ASSERT_GT(h.machine.model().strokes.max.x() + h.machine.model().kinematics.d0.x(), edge + 1e-3);
  const JogRun r = jog_for(h, control_command_t::JOG_ACTUATOR, Vec3(h.cfg.jog.max_velocity, 0, 0), 60, 0, 1.0);
  std::printf("actuator 1 jogged at %.0f mm/s toward +x: reference stopped at x = %.4f mm, platform at most "
              "%.4f mm (edge %.3f mm), faults %u\n",
              h.cfg.jog.max_velocity * 1e3, reference(h).x() * 1e3, r.farthest_measured * 1e3, edge * 1e3,
              static_cast<unsigned>(h.state().faults));
  EXPECT_EQ(h.state().faults, 0) << reinterpret_cast<const char*>(h.state().fault_text);
  EXPECT_LE(r.farthest_ref, edge + 1e-9);
  EXPECT_LE(r.farthest_measured, edge + ControlLoop::kSoftLimitSlack);
  EXPECT_NEAR(reference(h).x(), edge, 1e-6);  // at the edge, not short of it
  // At rest there: an actuator jog outward is refused, inward taken.
  h.run(400);
  ASSERT_EQ(h.mode(), Mode::holding);
  const Ack out = h.command(jog_command(control_command_t::JOG_ACTUATOR, Vec3(0.01, 0, 0)));
  EXPECT_FALSE(out.accepted);
  EXPECT_EQ(out.refusal, Refusal::workspace);
  EXPECT_NE(std::string(out.message).find("workspace"), std::string::npos) << out.message;
  std::printf("actuator jog outward at the edge: %s\n", out.message);
  EXPECT_EQ(h.mode(), Mode::holding);
  const Ack back = h.command(jog_command(control_command_t::JOG_ACTUATOR, Vec3(-0.01, 0, 0)));
  EXPECT_TRUE(back.accepted) << back.message;
}

TEST(Jog, AFrameChangeAtTheEdgeStartsWhereTheActuatorJogCameToRest) {
  LoopHarness h;
  h.to_holding();
  // Toward the +x face with keep-alives until the reference rests on it,
  // the jog still held (its keep-alive window open).
  ASSERT_TRUE(jog_to_rest_on_the_x_edge(h, control_command_t::JOG_ACTUATOR));
  ASSERT_EQ(h.mode(), Mode::jogging);
  // The machine frame inward: from the rest point, not the old hold point,
  // and the actuator jog's +x target is not carried into it.
  const Vec3 rest = reference(h);
  const Ack in = h.command(jog_command(control_command_t::JOG_MACHINE, Vec3(-0.01, 0, 0)));
  ASSERT_TRUE(in.accepted) << in.message;
  const double first = (reference(h) - rest).norm();
  EXPECT_LT(first, 1e-4);
  double largest_step = 0.0;
  Vec3 last = reference(h);
  for (int i = 0; i < 200; ++i) {
    h.run(1);
    largest_step = std::max(largest_step, (reference(h) - last).norm());
    last = reference(h);
  }
  std::printf("frame change at the edge: first reference %.4f mm from the rest point, largest step %.4f mm/cycle\n",
              first * 1e3, largest_step * 1e3);
  EXPECT_LE(largest_step, 0.01 * 1e-3 * 1.001);  // 10 mm/s for 1 ms at most: no jump
  EXPECT_LT(reference(h).x(), rest.x() - 1e-3);
  EXPECT_EQ(h.state().faults, 0) << reinterpret_cast<const char*>(h.state().fault_text);
}

TEST(Jog, ARefusedActuatorJogAtTheEdgeDoesNotTakeOverTheMachineJogsMotion) {
  LoopHarness h;
  h.to_holding();
  const double edge = h.cfg.limits.workspace_max.x();
  ASSERT_TRUE(jog_to_rest_on_the_x_edge(h, control_command_t::JOG_MACHINE));
  ASSERT_EQ(h.mode(), Mode::jogging);
  // The machine jog's +x target must not drive the actuators once the frame
  // changes, even though the actuator jog itself is refused.
  const Ack out = h.command(jog_command(control_command_t::JOG_ACTUATOR, Vec3(0.01, 0, 0)));
  EXPECT_FALSE(out.accepted);
  EXPECT_EQ(out.refusal, Refusal::workspace);
  double farthest = 0.0;
  for (int i = 0; i < 500; ++i) {
    h.run(1);
    farthest = std::max(farthest, reference(h).x());
  }
  EXPECT_LE(farthest, edge + 1e-9);
  EXPECT_EQ(h.mode(), Mode::holding);
  EXPECT_EQ(h.state().faults, 0) << reinterpret_cast<const char*>(h.state().fault_text);
}

TEST(Jog, AnActuatorWhosePlaneIsNotSquareToItsAxisIsStoppedWhereThePlatformMeetsAnotherFace) {
  // Limb 1's plane tilted 5 mrad toward y: moving actuator 2 by dy moves the
  // platform by -tan(5 mrad) dy in x. From 0.2 mm inside the +x face, a jog
  // of actuator 2 toward -y meets that face after about 40 mm.
  ctl::MachineModel tilted = ctl::MachineModel::elkady();
  const double a = 5e-3;
  tilted.kinematics.planes[0].normal = Vec3(std::cos(a), std::sin(a), 0.0);
  LoopHarness h(test::test_config(), 0.005, tilted, tilted);
  h.to_holding();
  const double edge = h.cfg.limits.workspace_max.x();
  const Vec3 start(edge - 2e-4, h.queue_end().y(), h.queue_end().z());
  ASSERT_TRUE(h.command(h.move_to(start)).accepted);
  for (int i = 0; i < 20000 && h.mode() != Mode::holding; ++i) h.run(1);
  h.run(300);
  ASSERT_EQ(h.mode(), Mode::holding);
  const double y0 = reference(h).y();
  const JogRun r = jog_for(h, control_command_t::JOG_ACTUATOR, Vec3(0, -h.cfg.jog.max_velocity, 0), 40, 0, 1.0);
  const double dy = reference(h).y() - y0;
  std::printf("tilted plane: actuator 2 jogged toward -y stopped after %.3f mm of y (closed form %.3f mm) with x = "
              "%.4f mm, platform at most %.4f mm (edge %.3f mm)\n",
              dy * 1e3, -2e-4 / std::tan(a) * 1e3, reference(h).x() * 1e3, r.farthest_measured * 1e3, edge * 1e3);
  EXPECT_EQ(h.state().faults, 0) << reinterpret_cast<const char*>(h.state().fault_text);
  EXPECT_LE(r.farthest_ref, edge + 1e-6);
  EXPECT_LE(r.farthest_measured, edge + ControlLoop::kSoftLimitSlack);
  EXPECT_NEAR(dy, -2e-4 / std::tan(a), 1e-3);  // stopped by the x face, not the y one
  // At rest there: toward -y refused, toward +y (x moves inward) taken.
  h.run(400);
  ASSERT_EQ(h.mode(), Mode::holding);
  const Ack out = h.command(jog_command(control_command_t::JOG_ACTUATOR, Vec3(0, -0.01, 0)));
  EXPECT_FALSE(out.accepted);
  EXPECT_EQ(out.refusal, Refusal::workspace);
  const Ack in = h.command(jog_command(control_command_t::JOG_ACTUATOR, Vec3(0, 0.01, 0)));
  EXPECT_TRUE(in.accepted) << in.message;
}

TEST(Jog, FasterThanTheJogLimitIsRefused) {
  LoopHarness h;
  h.to_holding();
  const Ack a = h.command(jog_command(control_command_t::JOG_MACHINE, Vec3(0, -2 * h.cfg.jog.max_velocity, 0)));
  EXPECT_FALSE(a.accepted);
  EXPECT_EQ(a.refusal, Refusal::limit);
  EXPECT_EQ(h.mode(), Mode::holding);
}

TEST(Homed, BeforeHomingOnlyActuatorJogsAreTakenAndTheyMoveOneActuator) {
  DaemonConfig c = test::test_config();
  c.homing.axes[1].method = HomingMethod::switch_;  // y needs homing
  LoopHarness h(c);
  EXPECT_EQ(h.state().control_space, state_t::SPACE_ACTUATOR);
  EXPECT_FALSE(h.state().homed[1]);
  h.to_holding();
  const Ack seg = h.command(h.move_to(h.queue_end() + Vec3(-0.01, 0, 0)));
  EXPECT_FALSE(seg.accepted);
  EXPECT_EQ(seg.refusal, Refusal::not_homed);
  const Ack cart = h.command(jog_command(control_command_t::JOG_MACHINE, Vec3(-0.01, 0, 0)));
  EXPECT_FALSE(cart.accepted);
  EXPECT_EQ(cart.refusal, Refusal::not_homed);
  const Vec3 d0(h.state().d[0], h.state().d[1], h.state().d[2]);
  const Ack jog = h.command(jog_command(control_command_t::JOG_ACTUATOR, Vec3(0, 0.01, 0)));
  ASSERT_TRUE(jog.accepted) << jog.message;
  h.run(150);  // within the keep-alive, then the deadman
  h.run(600);
  EXPECT_EQ(h.mode(), Mode::holding);
  const Vec3 d1(h.state().d[0], h.state().d[1], h.state().d[2]);
  // 10 mm/s for 0.2 s plus the ramps: about 2 mm on d2, the others held.
  EXPECT_NEAR(d1.y() - d0.y(), 0.01 * 0.2 + 0.01 * 0.01 / (2 * h.cfg.jog.acceleration), 2e-4);
  EXPECT_NEAR(d1.x(), d0.x(), 2e-5);
  EXPECT_NEAR(d1.z(), d0.z(), 2e-5);
  EXPECT_EQ(h.state().faults, 0);
}

Command circle_segment(const Vec3& start, const ctl::CircleSpec& spec, bool allow_step) {
  Command c;
  c.kind = CommandKind::segment;
  c.source = 2;
  const ctl::CircleTrajectory circle{spec};
  c.segment.start = start;
  c.segment.end = circle.sample(circle.duration()).p;
  c.segment.traj = circle;
  c.segment.allow_step = allow_step;
  return c;
}

TEST(StartCheck, AVelocityStepIsRefusedByTheLoopUnlessGranted) {
  LoopHarness h;
  h.to_holding();
  // Elkady's circle: 275 mm/s at t = 0, from rest.
  const Ack refused = h.command(circle_segment(h.queue_end(), ctl::CircleSpec{}, false));
  EXPECT_FALSE(refused.accepted);
  EXPECT_EQ(refused.refusal, Refusal::not_continuous);
  EXPECT_EQ(h.mode(), Mode::holding);
  EXPECT_TRUE(h.command(circle_segment(h.queue_end(), ctl::CircleSpec{}, true)).accepted);
  // A ramped circle starts at rest: no grant needed.
  LoopHarness g;
  g.to_holding();
  ctl::CircleSpec ramped;
  ramped.ramp_time = 0.5;
  EXPECT_TRUE(g.command(circle_segment(g.queue_end(), ramped, false)).accepted);
}

// The server's view: the paper's circle on the simulator with the flag,
// refused on the CANopen backend whatever the flag, unless the bench says so.
struct PaperCase {
  const char* backend;
  bool bench_allows;
  bool flag;
  bool accepted;
};

TEST(StartCheck, ThePapersCircleIsAcceptedOnlyOnTheSimulatorWithTheFlagOrOnABenchThatAllowsIt) {
  for (const PaperCase pc : {PaperCase{"sim", false, false, false}, PaperCase{"sim", false, true, true},
                             PaperCase{"canopen", false, true, false}, PaperCase{"canopen", false, false, false},
                             PaperCase{"canopen", true, true, true}}) {
    DaemonConfig cfg = test::ServerCell::config();
    cfg.backend = pc.backend;  // the server's judgement only: the loop runs on the simulator here
    cfg.limits.allow_velocity_step = pc.bench_allows;
    test::ServerCell cell(cfg);
    const std::int64_t s = cell.acquire(7);
    ASSERT_NE(s, 0);
    ASSERT_TRUE(cell.control(control_command_t::CMD_ENABLE, s, 1).accepted);
    cell.cycles(30);
    trajectory_command_t m{};
    m.id = cell.next_id++;
    m.session = s;
    m.seq = 2;
    m.kind = trajectory_command_t::KIND_CIRCLE;
    m.centre[0] = 0.425, m.centre[1] = 0.425, m.centre[2] = 0.300;
    m.radius = 0.175, m.angular_speed = M_PI / 2, m.cruise_time = 4.0;
    m.allow_velocity_step = pc.flag;
    const ack_t a = cell.send(cfg.lcm.trajectory_channel, m);
    EXPECT_EQ(a.accepted, pc.accepted) << pc.backend << " bench " << pc.bench_allows << " flag " << pc.flag << ": "
                                       << a.message;
    if (!a.accepted) {
      EXPECT_EQ(a.reason, ack_t::REASON_NOT_CONTINUOUS);
      EXPECT_NE(a.message.find("274.9 mm/s"), std::string::npos) << a.message;  // pi/2 rad/s x 175 mm
      if (std::string(pc.backend) == "canopen" && pc.flag) std::printf("canopen, flag set: %s\n", a.message.c_str());
    }
  }
}

// Runs the platform held at P1 and switches the law mid-way: how far the
// platform moves, and the largest change of force between two cycles.
struct Switch {
  double moved = 0.0, force_step = 0.0, settled = 0.0;
};
Switch switch_while_holding(ctl::ControlLaw to) {
  LoopHarness h;
  h.to_holding();
  h.run(500);
  const Vec3 held = measured(h);
  Switch r;
  auto force = [&] { return Vec3(h.state().force[0], h.state().force[1], h.state().force[2]); };
  Vec3 last = force();
  Command c;
  c.kind = CommandKind::select_controller;
  c.controller.emplace(h.machine, to, ctl::table3_gains(to));
  EXPECT_TRUE(h.command(c).accepted);
  for (int i = 0; i < 3000; ++i) {
    r.force_step = std::max(r.force_step, (force() - last).cwiseAbs().maxCoeff());
    last = force();
    r.moved = std::max(r.moved, (measured(h) - held).norm());
    h.run(1);
  }
  r.settled = (measured(h) - held).norm();
  EXPECT_EQ(h.state().faults, 0);
  return r;
}

TEST(ControllerSwitch, WhileHoldingThePlatformMovesLessThanTenMicrometresAndTheForceDoesNotJump) {
  for (const auto law : {ctl::ControlLaw::pd_gravity, ctl::ControlLaw::pd_feedforward}) {
    const Switch s = switch_while_holding(law);
    std::printf("computed_torque -> %s while holding: moved at most %.3f um, largest force change in one cycle %.4f N\n",
                ctl::law_name(law), s.moved * 1e6, s.force_step);
    EXPECT_LT(s.moved, 10e-6);
    EXPECT_LT(s.force_step, 0.5);
  }
}

TEST(ControllerSwitch, WhereTheLawsDisagreeTheForceIsFadedNotStepped) {
  // A payload the model does not know: each law holds it with its own static
  // error, so at the switch the new law asks for another force. Faded, the
  // force changes by little per cycle; with a transfer time of one period it
  // steps by the difference.
  ctl::MachineModel truth = ctl::MachineModel::elkady();
  ctl::add_effect(truth, "payload_mass", -1, {0.5});
  auto largest_step = [&](double transfer_time) {
    DaemonConfig c = test::test_config();
    c.controller.transfer_time = transfer_time;
    LoopHarness h(c, 0.005, truth);
    h.to_holding();
    h.run(1500);
    auto force = [&] { return Vec3(h.state().force[0], h.state().force[1], h.state().force[2]); };
    Command sw;
    sw.kind = CommandKind::select_controller;
    sw.controller.emplace(h.machine, ctl::ControlLaw::pd_gravity, ctl::table3_gains(ctl::ControlLaw::pd_gravity));
    Vec3 last = force();
    double step = 0.0;
    EXPECT_TRUE(h.command(sw).accepted);
    for (int i = 0; i < 1500; ++i) {
      step = std::max(step, (force() - last).cwiseAbs().maxCoeff());
      last = force();
      h.run(1);
    }
    return step;
  };
  const double faded = largest_step(0.5), stepped = largest_step(1e-3);
  std::printf("switch with a 0.5 kg payload the model lacks: largest force change in one cycle %.3f N faded over 0.5 s, "
              "%.3f N over one period\n", faded, stepped);
  EXPECT_GT(stepped, 1.0);
  EXPECT_LT(faded, 0.1 * stepped);
}

TEST(ControllerSwitch, ToALawWithoutGravityTheForceFadesAndThePlatformSagsSmoothly) {
  // pd holds the weight only by its stiffness: it sags E / kp (about 3 mm at
  // Table 3's 12691 N/m), but over the transfer time, not in one cycle.
  const Switch s = switch_while_holding(ctl::ControlLaw::pd);
  std::printf("computed_torque -> pd while holding: sag %.3f mm, largest force change in one cycle %.4f N\n",
              s.settled * 1e3, s.force_step);
  EXPECT_LT(s.force_step, 0.5);
  EXPECT_GT(s.settled, 2e-3);
}

}  // namespace
}  // namespace cpm::daemon

namespace cpm::daemon {
namespace {

// What cpmd refuses at start when the configuration, the model and the
// backend do not fit together (preflight.hpp).
TEST(Preflight, RefusesWhatCannotBeRunSafelyWithTheKey) {
  const ctl::Machine machine{ctl::MachineModel::elkady()};
  SimBackend sim(std::make_unique<ctl::Machine>(ctl::MachineModel::elkady()), SimBackendOptions{});
  auto refusal = [&](const DaemonConfig& c) -> std::string {
    try {
      preflight(c, machine, sim);
    } catch (const Error& e) {
      return e.what();
    }
    return "";
  };
  DaemonConfig ok = test::test_config();
  ok.source = "t.yaml";
  EXPECT_EQ(refusal(ok), "");
  DaemonConfig c = ok;
  c.homing.axes[0].method = HomingMethod::switch_;
  c.homing.axes[0].home_position = 0.45;  // the stroke is [0, 400] mm
  EXPECT_NE(refusal(c).find("homing.axes.x.home_position: 450.000 mm is outside the actuator's stroke [0.000 mm, 400.000 mm]"),
            std::string::npos)
      << refusal(c);
  c = ok;
  c.homing.axes[2].method = HomingMethod::drive;
  EXPECT_NE(refusal(c).find("homing.axes.z.method: drive homing, but the sim backend cannot"), std::string::npos)
      << refusal(c);
  c = ok;
  c.controller.law = ctl::ControlLaw::pd;
  c.controller.gains.kp = Vec3::Constant(100.0);
  c.controller.gains.kd = Vec3::Constant(436.0);
  EXPECT_NE(refusal(c).find("t.yaml: controller: pd: kp_z = 100 N/m would let z sag"), std::string::npos) << refusal(c);
  c = ok;
  c.homing.axes[1].method = HomingMethod::switch_;
  c.homing.actuator_gains.kd = Vec3::Constant(1e5);
  EXPECT_NE(refusal(c).find("homing.actuator_gains: "), std::string::npos) << refusal(c);
}

}  // namespace
}  // namespace cpm::daemon

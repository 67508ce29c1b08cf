// SPDX-License-Identifier: Apache-2.0
// What `cpm identify --apply` does, through cpmd's CANopen path in process:
// the daemon's loop, the canopen backend and the hal master on the fake bus,
// three synchronous virtual drives around a true machine with Coulomb
// friction on axis 1, viscous friction on axis 3 and a 0.4 kg payload, none
// of them in the model cpmd runs. The drives apply each torque from the SYNC
// after the one it was computed from: the bus adds one period of actuation
// delay, which no model had either. The designed experiment (cpm excite's)
// streamed in chunks while the state is recorded (cpm record's converter),
// the loop on that log, the new model loaded (disabled, load-model, enabled)
// and the paper's circle before and after. The steps are cpm identify's,
// without its LCM client: the fake bus has no LCM, and this host's kernel no
// vcan for the SIL guest's (docs/identification.md).
#include <gtest/gtest.h>

#include <cstdio>

#include "canopen/circle.hpp"
#include "canopen/record_log.hpp"
#include "cpm/identification/excitation.hpp"
#include "cpm/identification/model_loop.hpp"
#include "support/planted_effects.hpp"

namespace cpm::daemon::test {
namespace {

// The experiment as stream chunks of the daemon (cubic Hermite through the
// design's rows every `step` s), played from rest at its start to rest at its end.
void play_experiment(Rig& r, const ident::MultiSine& m, double step) {
  const auto rows = ident::excitation_rows(m, 1.0 / step);
  constexpr int n = StreamTrajectory::kMaxPoints;
  std::size_t at = 0;
  const auto cycles = static_cast<long>(std::lround((m.duration() + 1.0) * r.cfg.loop.rate_hz));
  for (long k = 0; k < cycles && r.mode() != Mode::fault; ++k) {
    while (at + 1 < rows.size() && r.state().queue_depth < 3) {
      const int len = static_cast<int>(std::min<std::size_t>(n, rows.size() - at));
      double t[n], p[n][3], v[n][3];
      for (int i = 0; i < len; ++i) {
        const auto& row = rows[at + static_cast<std::size_t>(i)];
        t[i] = row[0] - rows[at][0];
        for (int j = 0; j < 3; ++j) p[i][j] = row[1 + static_cast<std::size_t>(j)], v[i][j] = row[4 + static_cast<std::size_t>(j)];
      }
      Command c;
      c.kind = CommandKind::segment;
      c.segment.traj.emplace<StreamTrajectory>(len, t, p, v);
      c.segment.start = r.queue_end();
      c.segment.end = Vec3(p[len - 1][0], p[len - 1][1], p[len - 1][2]);
      ASSERT_TRUE(r.command(c).accepted) << "chunk at row " << at;
      at += static_cast<std::size_t>(len - 1);
    }
    r.step();
  }
  ASSERT_NE(r.mode(), Mode::fault) << r.fault_text();
}

TEST(IdentifyThroughTheBus, TheLoopNamesTheBusDelayAndThePlantedEffectsAndTheCircleErrorFalls) {
  const DaemonConfig cfg = config_500hz_with_velocity();
  const double T = 1.0 / cfg.loop.rate_hz;
  ctl::MachineModel truth = ctl::MachineModel::elkady();
  ctl::add_effect(truth, "coulomb_friction", 0, {3.0});
  ctl::add_effect(truth, "viscous_friction", 2, {20.0});
  ctl::add_effect(truth, "payload_mass", -1, {0.4});
  sim::EncoderModel encoder;
  encoder.position_noise = 1e-6;
  encoder.velocity_noise = 2e-4;
  encoder.seed = 5;
  Rig r(cfg, true, sim::DriveTiming::synchronous, ctl::MachineModel::elkady(), encoder, {}, truth);
  const ctl::CircleTrajectory circle{ctl::CircleSpec{}};

  // The paper's circle with the model as given.
  const CircleFigures before = circle_through_bus(r, circle);
  ASSERT_TRUE(before.ok) << r.fault_text();

  // The experiment: cpm excite's design for the model cpmd runs, 10 s.
  ident::ExcitationOptions eo;
  eo.period = 4.0;
  eo.periods = 2;
  eo.harmonics = 4;
  eo.iterations = 40;
  ident::ExcitationLimits L;
  L.velocity = cfg.limits.velocity;
  L.acceleration = cfg.limits.acceleration;
  const ident::ExcitationDesign D = ident::design_excitation(ctl::Machine(ctl::MachineModel::elkady()), L, eo);
  ASSERT_TRUE(r.command(r.move_to(D.trajectory.centre(), 0.1)).accepted);
  ASSERT_GE(r.run_until([&] { return r.mode() == Mode::holding; }, 20 * static_cast<int>(cfg.loop.rate_hz)), 0);
  cli::StateToMotion rows;
  r.on_state = [&](const cpm_msgs::state_t& s) { rows.add(s); };
  play_experiment(r, D.trajectory, 0.01);
  r.on_state = nullptr;
  const io::MotionData log = rows.finish("", "the designed experiment through the fake CANopen bus");

  // The loop on the log.
  const ident::LoopResult R = ident::run_loop(io::DataSet(log), ctl::MachineModel::elkady());
  std::fputs(ident::loop_text(R).c_str(), stdout);
  double delay_se = -1.0;
  for (const auto& f : R.fitted)
    if (f.name == "effects.actuation_delay.tau") delay_se = f.std_error;
  cpm::test::expect_planted_effects_named(R.model.effects, T, delay_se);  // the bus: one period

  // The new model into cpmd (disabled), and the circle again.
  auto load = [&](const ctl::Machine& m) {
    EXPECT_TRUE(r.simple(CommandKind::disable).accepted);
    r.run(5);
    Command c;
    c.kind = CommandKind::load_model;
    c.machine = &m;
    c.controller.emplace(m, cfg.controller.law, cfg.controller.gains);
    EXPECT_TRUE(r.command(c).accepted);
    r.run(5);
  };
  auto circle_again = [&](const ctl::Machine& m) {
    load(m);
    r.to_holding();
    EXPECT_TRUE(r.command(r.move_to(circle.sample(0.0).p, 0.1)).accepted);
    EXPECT_GE(r.run_until([&] { return r.mode() == Mode::holding; }, 20 * static_cast<int>(cfg.loop.rate_hz)), 0);
    // Disabled at the circle's start: the circle starts, as the first did, from enable.
    EXPECT_TRUE(r.simple(CommandKind::disable).accepted);
    r.run(static_cast<int>(0.5 * cfg.loop.rate_hz));
    return circle_through_bus(r, circle);
  };
  const ctl::Machine identified(R.model);
  const CircleFigures after = circle_again(identified);
  ASSERT_TRUE(after.ok) << r.fault_text();
  ctl::MachineModel true_with_bus = truth;
  ctl::add_effect(true_with_bus, "actuation_delay", -1, {T});
  const ctl::Machine true_model(true_with_bus);
  const CircleFigures best = circle_again(true_model);
  ASSERT_TRUE(best.ok) << r.fault_text();
  std::printf("the paper's circle through the bus: %.1f um RMS with the model as given, %.1f um with the identified "
              "model, %.1f um with the true model and the bus's delay (settled: %.2f, %.2f, %.2f um)\n",
              before.rmse * 1e6, after.rmse * 1e6, best.rmse * 1e6, before.settled * 1e6, after.settled * 1e6,
              best.settled * 1e6);
  EXPECT_LT(after.rmse, 0.6 * before.rmse);
  EXPECT_LT(after.rmse, 2.0 * best.rmse + 0.5e-6);
}

}  // namespace
}  // namespace cpm::daemon::test

// SPDX-License-Identifier: Apache-2.0
// A model file with user effects (docs/effects.md, "Effects you add") loaded
// the way cpmd loads its model, and the loop compensating them on the
// simulator: the paper's circle with the effect in the truth, the loop's
// model without it and with it.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "cpm/daemon/config.hpp"
#include "cpm/io/model_file.hpp"
#include "loop_fixture.hpp"

namespace cpm::daemon::test {
namespace {

// Truth: a cable carrier on axis 2 dragged by axis 1 (c * v1) and a local
// force excess of 6 N on axis 2 over 40 mm of its travel.
ctl::MachineModel with_user_effects() {
  ctl::MachineModel m = ctl::MachineModel::elkady();
  ctl::add_user_effect(m, "expression:2:c*v1:c=25");
  ctl::add_user_effect(m, "table:2:d2:0.15,0.17,0.19,0.21:0,6,6,0");
  return m;
}

double circle_rmse(const ctl::MachineModel& truth, const ctl::MachineModel& believed) {
  LoopHarness h(test_config(), 0.005, truth, believed);
  h.to_holding();
  Command c;
  c.kind = CommandKind::segment;
  c.source = 2;
  const ctl::CircleTrajectory circle{ctl::CircleSpec{}};
  c.segment.start = h.queue_end();
  c.segment.end = circle.sample(circle.duration()).p;
  c.segment.traj = circle;
  c.segment.allow_step = true;
  const Ack a = h.command(c);
  EXPECT_TRUE(a.accepted) << a.message;
  for (int i = 0; i < 20000 && h.state().last_segment_id != a.id; ++i) h.run(1);
  EXPECT_EQ(h.state().last_segment_id, a.id) << "the circle did not finish";
  EXPECT_EQ(h.state().faults, 0);
  return h.state().last_segment_rmse;
}

TEST(UserEffectsModel, CpmdLoadsThemAndTheLoopCompensatesThem) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "cpm_user_effects_model";
  std::filesystem::create_directories(dir);
  io::ModelFile mf;
  mf.model = with_user_effects();
  const std::string path = (dir / "user.yaml").string();
  io::save_model_file(path, mf);
  // cpmd's two readers: the configured model and a model asked for over LCM.
  const ctl::MachineModel loaded = load_model(path);
  const ctl::MachineModel beneath = load_model_beneath(dir.string(), "user.yaml");
  ASSERT_EQ(loaded.user_effects.size(), 2u);
  EXPECT_TRUE(loaded.user_effects == mf.model.user_effects);
  EXPECT_TRUE(beneath.user_effects == mf.model.user_effects);
  std::filesystem::remove_all(dir);

  const double without = circle_rmse(loaded, ctl::MachineModel::elkady());
  const double with = circle_rmse(loaded, loaded);
  const double clean = circle_rmse(ctl::MachineModel::elkady(), ctl::MachineModel::elkady());
  std::printf("[ figures  ] paper circle through cpmd's loop, truth with c*v1 (25 N s/m) and a 6 N bump on axis 2: "
              "RMSE %.3f um with the model without them, %.3f um with them (%.3f um on a machine without them)\n",
              without * 1e6, with * 1e6, clean * 1e6);
  EXPECT_LT(with, 0.5 * without);
  EXPECT_LT(with, 1.5 * clean);
}

}  // namespace
}  // namespace cpm::daemon::test

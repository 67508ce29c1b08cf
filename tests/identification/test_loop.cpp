// The user's loop as one command (loop.hpp): several effects planted at once,
// the loop names every one, and the waterfall ends within 20 % of the noise
// floor, on a motion log and on ball-bar data.
#include <gtest/gtest.h>

#include <algorithm>

#include "cpm/identification/kinematic.hpp"
#include "cpm/identification/loop.hpp"
#include "identification/kin_data.hpp"
#include "identification/sim_data.hpp"

namespace cpm::ident {
namespace {

bool added(const LoopResult& R, const std::string& effect, int axis) {
  return std::any_of(R.added.begin(), R.added.end(),
                     [&](const FitRequest& r) { return r.effect == effect && r.axis == axis; });
}

TEST(Loop, ThreeDynamicEffectsAtOnceAreAddedOneByOneDownToTheNoiseFloor) {
  test::SimSpec s;
  s.duration = 16.0;
  s.seed = 77;
  s.effects = {{"coulomb_friction", 0, {0.6}}, {"actuation_delay", -1, {1e-3}}, {"viscous_friction", 2, {2.0}}};
  const LoopResult R = run_loop(io::DataSet(test::simulate(s)), ctl::MachineModel::elkady());
  std::fputs(loop_text(R).c_str(), stdout);
  EXPECT_TRUE(added(R, "coulomb_friction", 0));
  EXPECT_TRUE(added(R, "actuation_delay", -1));
  EXPECT_TRUE(added(R, "viscous_friction", 2));
  EXPECT_EQ(R.added.size(), 3u);
  EXPECT_FALSE(R.outside_library);
  ASSERT_GE(R.steps.size(), 4u);
  // The waterfall falls at every step and ends within 20 % of the noise floor.
  for (std::size_t j = 1; j < R.steps.size(); ++j) EXPECT_LT(R.steps[j].rms, R.steps[j - 1].rms) << j;
  EXPECT_LE(R.steps.back().rms, 1.2 * R.steps.back().noise_floor);
  // The model it leaves carries the delay and the two frictions.
  const ctl::Machine m(R.model);
  EXPECT_NEAR(m.actuation_delay(), 1e-3, 1e-4);
  EXPECT_NE(loop_html(R, "sim").find("<svg"), std::string::npos);
}

TEST(Loop, TwoKinematicEffectsAtOnceOnBallBarDataAreBothAdded) {
  // Backlash on axis 1 and a cyclic error on axis 2, on Kim's machine, two bar radii, both directions.
  const std::vector<test::PlantedKinematic> planted = {{"backlash", 0, {6e-6, 0, 0}},
                                                      {"cyclic_error", 1, {4e-6, 0.016, 0.3}}};
  test::KinSimOptions so;
  so.seed = 5;
  const io::BallbarData b = test::kim_ballbar(planted, test::hemisphere_poses({0.100, 0.150}, 6, 16, 7), so);
  const LoopResult R = run_loop(io::DataSet(b), ctl::MachineModel::elkady());
  std::fputs(loop_text(R).c_str(), stdout);
  EXPECT_TRUE(added(R, "backlash", 0));
  EXPECT_TRUE(added(R, "cyclic_error", 1));
  ASSERT_GE(R.steps.size(), 3u);
  EXPECT_LE(R.steps.back().rms, 1.2 * R.steps.back().noise_floor);
}

}  // namespace
}  // namespace cpm::ident

// SPDX-License-Identifier: Apache-2.0
// `cpm identify` on cpmd's simulator, as a user runs it (the built programs,
// each in its own process): a true machine with Coulomb friction on axis 1,
// viscous friction on axis 3 and a 0.4 kg payload, none of them in the
// model; the experiment from `cpm excite`; the new model names each within 2 %,
// and with --apply the paper's circle's error falls to within 2x of the true model's.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include "cpm/daemon/client.hpp"
#include "cpm/io/model_file.hpp"
#include "support/daemon_process.hpp"
#include "tools/cpm_command.hpp"
#include "tools/cpmd_holding.hpp"
#include "support/planted_effects.hpp"

namespace cpm {
namespace {

using cpm_msgs::control_command_t;
using cpm_msgs::state_t;

TEST(IdentifyOnCpmd, TheExperimentRecordedAndTheLoopNameEveryPlantedEffect) {
  const test::TempDir dir("identify");
  test::OperatorsDir ops(dir / "operators.d");
  const daemon::Credentials eng = ops.add("eng", daemon::Role::engineer);
  // The true machine: the shipped model with the three effects added.
  io::ModelFile truth = io::load_model_file(std::string(CPM_SOURCE_DIR) + "/config/machine.yaml");
  ctl::add_effect(truth.model, "coulomb_friction", 0, {3.0});
  ctl::add_effect(truth.model, "viscous_friction", 2, {20.0});
  ctl::add_effect(truth.model, "payload_mass", -1, {0.4});
  ctl::add_effect(truth.model, "actuation_delay", -1, {1e-3});
  const std::string truth_path = dir / "truth.yaml";
  io::save_model_file(truth_path, truth);
  const std::string cfg_path = test::sim_config(dir.path(), "sim.yaml", ops.path(),
                                                {{"truth_model_file: [^ \\n]+", "truth_model_file: " + truth_path},
                                                 {"position_noise: 0.0", "position_noise: 1.0e-6"},
                                                 {"velocity_noise: 0.0", "velocity_noise: 2.0e-4"}},
                                                dir.path());
  const auto cfg = daemon::load_config(cfg_path);
  auto d = test::start_cpmd(cfg_path, dir / "cpmd.log");
  daemon::Client c(cfg.lcm, eng);
  std::optional<state_t> s = test::enable_and_hold(c, *d);
  ASSERT_TRUE(s);
  ASSERT_TRUE(c.release());

  const std::string model = std::string(CPM_SOURCE_DIR) + "/config/machine.yaml";
  const std::string exc = dir / "exc.csv";
  const auto e = test::run_command(std::string(CPM_EXE) + " excite --config " + cfg_path + " --out " + exc +
                           " --period 4 --periods 2 --harmonics 4 --iterations 40",
                       dir / "excite.out");
  ASSERT_EQ(e.status, 0) << e.out;
  const std::string better = dir / "better.yaml";
  const auto r = test::run_command(std::string(CPM_EXE) + " identify " + exc + " --model " + model + " --out " + better +
                           " --log " + (dir / "log.csv") + " --url '" + cfg.lcm.url + "' --key " + ops.key_path("eng") +
                           " --operator eng --apply",
                       dir / "identify.out");
  std::printf("%s", r.out.c_str());
  ASSERT_EQ(r.status, 0) << r.out << d->log();
  EXPECT_NE(r.out.find("within cpmd's limits"), std::string::npos) << r.out;
  const io::ModelFile got = io::load_model_file(better);
  double delay_se = -1.0;
  // Issue 28's "within 2 % (or within 3 sigma)", as sil.daemon.identify judges: at 2 % alone a dA
  // of 0.2045 (planted 0.2) failed a clean-clone CI run on 2026-11-28.
  std::map<std::string, double> se;
  for (const io::FittedParameter& f : got.fitted) {
    if (f.name == "effects.actuation_delay.tau") delay_se = f.std_error;
    se[f.name] = f.std_error;
  }
  test::expect_planted_effects_named(got.model.effects, 1e-3, delay_se, r.out, se);  // the delay: one period of cpmd's loop

  // --apply: the paper's circle before and after, and the same circle with the true model in cpmd.
  double before = 0, after = 0;
  const auto at = r.out.find("the paper's circle, tracking error: ");
  ASSERT_NE(at, std::string::npos) << r.out;
  ASSERT_EQ(std::sscanf(r.out.c_str() + at, "the paper's circle, tracking error: %lf um RMS with the model as given, %lf",
                        &before, &after), 2) << r.out;
  c.acquire();
  ASSERT_TRUE(c.control(control_command_t::CMD_DISABLE).accepted);
  for (int i = 0; i < 50 && (!s || s->mode != state_t::MODE_DISABLED); ++i) s = c.state(0.2);
  control_command_t load{};
  load.command = control_command_t::CMD_LOAD_MODEL;
  load.model_path = truth_path;
  ASSERT_TRUE(c.control(load, 10.0).accepted);
  ASSERT_TRUE(c.control(control_command_t::CMD_ENABLE).accepted);
  for (int i = 0; i < 100 && s->mode != state_t::MODE_HOLDING; ++i) s = c.state(0.2);
  ASSERT_TRUE(c.release());
  const auto t = test::run_command(std::string(CPM_EXE) + " circle --paper --url '" + cfg.lcm.url + "' --key " + ops.key_path("eng") +
                           " --operator eng",
                       dir / "truth.out");
  double true_rms = 0;
  const auto tr = t.out.find("tracking error over the segment: RMS ");
  ASSERT_NE(tr, std::string::npos) << t.out;
  ASSERT_EQ(std::sscanf(t.out.c_str() + tr, "tracking error over the segment: RMS %lf", &true_rms), 1);
  std::printf("paper circle: %.1f um RMS with the model as given, %.1f um with the identified model, %.1f um with the "
              "true model\n", before, after, true_rms);
  // Within 2x of the true model's (0.5 um: the floor of the simulator's encoders); and it fell.
  // (The paper's circle starts at full speed from rest: that step's transient, 2.2 mm at most
  // with any of the three models, is most of the RMS.)
  EXPECT_LT(after, 2.0 * true_rms + 0.5);
  EXPECT_LT(after, 0.6 * before);
}

}  // namespace
}  // namespace cpm

// SPDX-License-Identifier: Apache-2.0
// cpm run against cpmd, each in its own process (the harness of every
// process-level test, support/daemon_process.hpp, in a private network
// namespace when it may): a G-code program is checked and planned by cpm,
// sent in chunks, planned again and played by cpmd on its simulator; cpm
// follows it to the end and prints the tracking error. And Ctrl-C on a
// running program stops the machine.
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <thread>

#include "cpm/daemon/client.hpp"
#include "cpm/path/test_paths.hpp"
#include "support/daemon_process.hpp"

namespace cpm::daemon {
namespace {

using cpm_msgs::state_t;

struct Rig {
  cpm::test::TempDir dir{"path-e2e"};
  cpm::test::OperatorsDir ops{dir / "operators.d"};
  Credentials alice = ops.add("alice", Role::engineer);
  std::string config = cpm::test::sim_config(dir.path(), "sim.yaml", ops.path());
  DaemonConfig cfg = load_config(config);
  std::unique_ptr<cpm::test::Process> cpmd = cpm::test::start_cpmd(config, dir / "cpmd.log");

  std::vector<std::string> cpm_argv(const std::vector<std::string>& args) const {
    std::vector<std::string> argv{CPM_EXE};
    argv.insert(argv.end(), args.begin(), args.end());
    argv.insert(argv.end(), {"--config", config, "--key", ops.key_path("alice"), "--operator", "alice"});
    return argv;
  }
  // Run cpm to its end; its output in `out`.
  int cpm(const std::vector<std::string>& args, std::string* out, double timeout_s = 120) const {
    cpm::test::Process p(cpm_argv(args), dir / "cpm.log", /*stdout_log=*/true);
    const auto rc = p.wait_exit_for(timeout_s);
    *out = p.log();
    return rc ? *rc : -1;
  }
  std::optional<state_t> state() const {
    Client watcher(cfg.lcm);
    return watcher.state(2.0);
  }
  void start() {
    Client watcher(cfg.lcm);
    for (int i = 0; i < 100; ++i)
      if (watcher.state(0.2)) return;
    FAIL() << "cpmd published no state:\n" << cpmd->log();
  }
};

TEST(PathEndToEnd, CpmRunPlaysAProgramOnCpmd) {
  Rig r;
  r.start();
  std::string out;
  ASSERT_EQ(r.cpm({"enable"}, &out), 0) << out;
  const std::string prog = r.dir / "contour.ngc";
  std::ofstream(prog) << path::square_diamond_circle(100.0, 6000.0);
  ASSERT_EQ(r.cpm({"run", prog}, &out), 0) << out << r.cpmd->log();
  EXPECT_NE(out.find("cpmd planned and queued it"), std::string::npos) << out;
  EXPECT_NE(out.find("done; tracking error over the program: RMS"), std::string::npos) << out;
  EXPECT_NE(out.find("line 8 "), std::string::npos) << out;  // the progress showed the program's lines
  const auto s = r.state();
  ASSERT_TRUE(s);
  EXPECT_EQ(s->mode, state_t::MODE_HOLDING);
  EXPECT_EQ(s->faults, 0);
  EXPECT_GT(s->last_segment_cycles, 1000);
  EXPECT_LT(s->last_segment_max, 1e-4);  // the tracking error, as in-process
}

TEST(PathEndToEnd, CtrlCStopsTheMachine) {
  Rig r;
  r.start();
  std::string out;
  ASSERT_EQ(r.cpm({"enable"}, &out), 0) << out;
  const std::string prog = r.dir / "contour.ngc";
  std::ofstream(prog) << path::square_diamond_circle(100.0, 3000.0);  // about 20 s
  cpm::test::Process p(r.cpm_argv({"run", prog}), r.dir / "cpm.log", /*stdout_log=*/true);
  // Wait until the program plays, then interrupt cpm.
  Client watcher(r.cfg.lcm);
  bool moving = false;
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (!moving && std::chrono::steady_clock::now() < end) {
    const auto s = watcher.state(0.1);
    moving = s && s->mode == state_t::MODE_MOVING && s->segment_elapsed > 1.0;
  }
  ASSERT_TRUE(moving) << p.log();
  p.signal(SIGINT);
  const auto rc = p.wait_exit_for(10);
  ASSERT_TRUE(rc);
  EXPECT_EQ(*rc, 130) << p.log();
  EXPECT_NE(p.log().find("interrupted: stopping the machine"), std::string::npos) << p.log();
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const auto s = r.state();
  ASSERT_TRUE(s);
  EXPECT_EQ(s->mode, state_t::MODE_HOLDING);
  EXPECT_EQ(s->segment_id, -1);
  EXPECT_EQ(s->faults, 0);
}

}  // namespace
}  // namespace cpm::daemon

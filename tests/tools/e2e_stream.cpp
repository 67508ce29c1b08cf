// SPDX-License-Identifier: Apache-2.0
// `cpm stream` on cpmd's simulator, as a user runs it (the built programs,
// each in its own process; a private network namespace when the test may
// make one, support/daemon_process.hpp): a good file is approached from
// where the platform is and played to its end, a stop appended where it
// ends at speed; a file over the speed limit is refused with cpmd's
// published limits and nothing moves.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

#include "cpm/daemon/client.hpp"
#include "support/daemon_process.hpp"
#include "tools/cpm_command.hpp"
#include "tools/cpmd_holding.hpp"
#include "tools/stream_files.hpp"

namespace cpm {
namespace {

using cpm_msgs::control_command_t;
using cpm_msgs::state_t;

Vec3 v3(const double* p) { return Vec3(p[0], p[1], p[2]); }

TEST(StreamOnCpmd, AGoodFileIsApproachedAndPlayedAFastOneRefusedWithNothingMoved) {
  test::EngineerOnCpmd rig("stream");
  ASSERT_TRUE(rig.holding);
  std::optional<state_t> s = rig.holding;
  const Vec3 at_start = v3(s->position);
  ASSERT_TRUE(rig.client.release());  // cpm commands from here; this client only reads the state
  const auto& dir = rig.dir;
  const auto& cfg = rig.cfg;
  auto& c = rig.client;

  const std::string cpm = std::string(CPM_EXE) + " stream" + rig.as_engineer() + " ";
  // Over the limit at row 9802 (a 30 s file): refused, with the limits cpmd
  // publishes (no --config), before any approach.
  const test::MultiSine fast = test::over_at(9802, cfg.limits.velocity);
  ASSERT_GT(fast.k, 0);
  fast.write(dir / "fast.csv", 30001);
  const auto bad = test::run_command(cpm + (dir / "fast.csv"), dir / "fast.out");
  EXPECT_EQ(bad.status, 1) << bad.out;
  EXPECT_NE(bad.out.find("row 9802 (line 9803)"), std::string::npos) << bad.out;
  EXPECT_NE(bad.out.find("nothing sent"), std::string::npos) << bad.out;
  EXPECT_EQ(bad.out.find("approach"), std::string::npos) << bad.out;
  s = c.state(1.0);
  ASSERT_TRUE(s);
  EXPECT_EQ(s->mode, state_t::MODE_HOLDING);
  EXPECT_LT((v3(s->position) - at_start).norm(), 1e-6);

  // A good 4 s file that ends at speed, away from where the platform is.
  test::MultiSine good;
  good.k = 0.5;
  good.write(dir / "good.csv", 4001);
  double p_end[3], v_end[3], a_end[3];
  good.at(4.0, p_end, v_end, a_end);
  const auto ok = test::run_command(cpm + (dir / "good.csv"), dir / "good.out");
  EXPECT_EQ(ok.status, 0) << ok.out << rig.cpmd->log();
  EXPECT_NE(ok.out.find("approach: moving to the file's first point"), std::string::npos) << ok.out;
  EXPECT_NE(ok.out.find("a stop of"), std::string::npos) << ok.out;
  // The newest state (those queued while cpm ran are read first).
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(1);
  while (std::chrono::steady_clock::now() < until)
    if (auto n = c.state(0.1); n && n->cycle > s->cycle) s = n;
  ASSERT_TRUE(s);
  EXPECT_EQ(s->mode, state_t::MODE_HOLDING) << ok.out;
  EXPECT_EQ(s->faults, 0u) << ok.out;
  // At rest beyond the file's last point, along its last velocity, by the
  // stop's distance v^2 / (2 * 2.5 m/s^2).
  const Vec3 v(v_end[0], v_end[1], v_end[2]);
  const Vec3 want = Vec3(p_end[0], p_end[1], p_end[2]) + v.normalized() * (v.squaredNorm() / 5.0);
  EXPECT_LT((v3(s->queue_end) - want).norm(), 2e-5) << "queue end " << v3(s->queue_end).transpose() * 1e3 << ", at " << v3(s->position).transpose() * 1e3;
}

}  // namespace
}  // namespace cpm

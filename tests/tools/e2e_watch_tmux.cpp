// SPDX-License-Identifier: Apache-2.0
// `cpm watch` as an operator sees it: cpmd on its simulator (a private
// network namespace when the test may make one, support/daemon_process.hpp),
// `cpm watch` in an 80 x 24 tmux pane, the pane captured with `tmux
// capture-pane -p`: every field's label is there on the row render() puts it
// on, no line is longer than 80 columns or wrapped, and q and Ctrl-C end it
// with the terminal given back. The drive rows are checked when cpmd
// publishes drives_t (it may not yet: then the placeholders are).
#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <thread>

#include "console.hpp"
#include "cpm/daemon/client.hpp"
#include "support/daemon_process.hpp"

namespace cpm::cli::console {
namespace {

using cpm::test::g_netns;

// Runs `cmd` in sh; its standard output.
std::string run(const std::string& cmd, int* rc = nullptr) {
  std::string out;
  FILE* f = ::popen(cmd.c_str(), "r");
  if (!f) return out;
  std::array<char, 4096> buf{};
  for (std::size_t n; (n = std::fread(buf.data(), 1, buf.size(), f)) > 0;) out.append(buf.data(), n);
  const int st = ::pclose(f);
  if (rc) *rc = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return out;
}

Lines split(const std::string& text) {
  Lines l;
  std::istringstream is(text);
  for (std::string line; std::getline(is, line);) l.push_back(line);
  return l;
}

int row_of(const Lines& lines, const std::string& label) {
  for (std::size_t i = 0; i < lines.size(); ++i)
    if (lines[i].find(label) != std::string::npos) return static_cast<int>(i);
  return -1;
}

// Our own tmux server (its socket in the test's folder), killed at the end.
class Tmux {
 public:
  explicit Tmux(const std::string& dir) : sock_(dir + "/tmux.sock"), conf_(dir + "/tmux.conf") {
    // No status line: the pane is the whole 80 x 24; a terminal type every
    // ncurses knows (ncurses-base).
    std::ofstream(conf_) << "set -g status off\nset -g default-terminal screen\n";
  }
  ~Tmux() { run(base() + " kill-server 2>/dev/null"); }
  [[nodiscard]] std::string base() const { return "tmux -S " + sock_ + " -f " + conf_; }
  [[nodiscard]] std::string capture(bool join = false) const {
    return run(base() + " capture-pane -p" + (join ? " -J" : "") + " -t watch");
  }
  // Waits up to `timeout_s` for the pane to show `text`; the last capture.
  std::string wait_for(const std::string& text, double timeout_s) const {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    std::string c;
    while (std::chrono::steady_clock::now() < end) {
      c = capture();
      if (c.find(text) != std::string::npos) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    return c;
  }

 private:
  std::string sock_, conf_;
};

TEST(WatchInTmux, EveryLabelIn80x24NothingWrappedQAndCtrlCRestore) {
  int rc = 0;
  run("command -v tmux", &rc);
  if (rc != 0) GTEST_SKIP() << "tmux is not installed (tools/setup.sh installs it)";
  const cpm::test::TempDir dir("watch");
  cpm::test::OperatorsDir ops(dir / "operators.d");
  const std::string cfg_path = cpm::test::sim_config(dir.path(), "sim.yaml", ops.path());
  const auto cfg = daemon::load_config(cfg_path);
  std::printf("watch: %s, LCM %s\n", g_netns ? "private network namespace" : "host loopback, ttl=0", cfg.lcm.url.c_str());
  auto d = cpm::test::start_cpmd(cfg_path, dir / "cpmd.log");
  daemon::Client c(cfg.lcm);
  std::optional<cpm_msgs::state_t> s;
  for (int i = 0; i < 50 && !s; ++i) s = c.state(0.2);
  ASSERT_TRUE(s) << "cpmd published no state:\n" << d->log();

  // Two watches one after the other in one pane: the first ended by q, the
  // second (after Enter) by Ctrl-C (the shell ignores it; cpm catches it).
  Tmux tmux(dir.path());
  const std::string watch = std::string(CPM_EXE) + " watch --config " + cfg_path;
  std::ofstream(dir / "watch.sh") << "trap '' INT\n"
                                  << watch << "\necho \"watch ended $?\"\nread next\n"
                                  << watch << "\necho \"watch ended $?\"\nsleep 60\n";
  run(tmux.base() + " new-session -d -x 80 -y 24 -s watch 'sh " + (dir / "watch.sh") + "'", &rc);
  ASSERT_EQ(rc, 0) << "tmux did not start";
  ASSERT_EQ(run(tmux.base() + " display -p -t watch '#{pane_width}x#{pane_height}'"), "80x24\n");

  // The state, then the loop's statistics (1 Hz), then the drives (10 Hz) if cpmd sends them.
  std::string pane = tmux.wait_for("mode DISABLED", 10.0);
  ASSERT_NE(pane.find("mode DISABLED"), std::string::npos) << pane << "\ncpmd:\n" << d->log();
  pane = tmux.wait_for("loop timing", 5.0);
  ASSERT_NE(pane.find("loop timing"), std::string::npos) << pane;
  const auto drives = c.drives(3.0);
  if (drives) pane = tmux.wait_for(" sim ", 3.0);
  const auto stats = c.stats(3.0);
  s = c.state(1.0);
  ASSERT_TRUE(stats && s);
  pane = tmux.capture();

  const Lines shown = split(pane);
  Lines joined = split(tmux.capture(true));  // -J keeps the spaces at the lines' ends
  for (auto& l : joined)
    while (!l.empty() && l.back() == ' ') l.pop_back();
  EXPECT_EQ(shown.size(), 24u) << pane;
  EXPECT_EQ(joined, shown) << "a line was wrapped:\n" << pane;
  for (const auto& l : shown) EXPECT_LE(l.size(), 80u) << l;
  // The labels where render() puts them for the same messages.
  const Lines want = render(s, stats, drives, 80, 24);
  for (const char* label : {"mode ", "space ", "law ", "homed 1:", "position mm", "reference mm", "error um",
                            "velocity mm/s", "force N", "trajectory", "last segment", "homing ", "phase ", "jog ",
                            "deadman ", "loop timing", "wake-up p99", "wake-up max", "cycle max", "overruns",
                            "skipped", "act node NMT", "CiA 402", "hb ms", "EMCY", "bus ", "fault ", "keys  q quit"}) {
    EXPECT_GE(row_of(want, label), 0) << label;
    EXPECT_EQ(row_of(shown, label), row_of(want, label)) << label << "\n" << pane;
  }
  EXPECT_EQ(shown[0], want[0]);  // disabled at rest: the same mode, space, law and homing
  if (drives) {
    const int r = row_of(want, "act node NMT");
    for (int i = 1; i <= 3; ++i) EXPECT_EQ(shown[r + i].substr(0, 30), want[r + i].substr(0, 30)) << pane;
    for (const char* label : {"error frames", "rx dropped", "tx failures", "load "})
      EXPECT_EQ(row_of(shown, label), row_of(want, label)) << label << "\n" << pane;
  } else {
    std::printf("watch: no drives_t from cpmd within 3 s: the drive rows are not checked, only their placeholders\n");
    EXPECT_NE(pane.find("(no drives message)"), std::string::npos) << pane;
  }

  // q: the first watch ends with 0 and the shell's screen is back.
  run(tmux.base() + " send-keys -t watch q");
  pane = tmux.wait_for("watch ended 0", 5.0);
  EXPECT_NE(pane.find("watch ended 0"), std::string::npos) << pane;
  EXPECT_EQ(pane.find("position mm"), std::string::npos) << "the alternate screen was not left:\n" << pane;
  // The second: Ctrl-C.
  run(tmux.base() + " send-keys -t watch Enter");
  pane = tmux.wait_for("position mm", 10.0);
  ASSERT_NE(pane.find("position mm"), std::string::npos) << pane;
  run(tmux.base() + " send-keys -t watch C-c");
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  auto ended = [&] { return pane.find("watch ended 0") != pane.rfind("watch ended 0"); };
  while (!ended() && std::chrono::steady_clock::now() < end) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    pane = tmux.capture();
  }
  EXPECT_TRUE(ended()) << pane;
  EXPECT_EQ(pane.find("position mm"), std::string::npos) << pane;
  EXPECT_EQ(d->terminate(), 0) << d->log();
}

}  // namespace
}  // namespace cpm::cli::console

// SPDX-License-Identifier: Apache-2.0
// `cpm scope` on cpmd's simulator while the paper's circle runs, as a user
// meets it: the built programs in their own processes (a private network
// namespace when the test may make one, support/daemon_process.hpp), the
// page loaded by headless Chromium. Before the circle, the live plots move
// (the newest sample drawn advances between polls). The trigger armed on a segment start
// fires on the circle's first cycle (as the test's own subscriber saw it);
// the captured window exported as CSV holds, sample by sample, the values
// `cpm record` wrote of the same run; the page shows the capture, and its
// screenshot is kept in build/tests/output/scope/. Skipped, saying so,
// without chromium.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "cpm/daemon/client.hpp"
#include "support/daemon_process.hpp"
#include "tools/cpm_command.hpp"
#include "tools/cpmd_holding.hpp"
// Last: it brings <resolv.h>, whose macro _res breaks Eigen's headers.
#include <httplib.h>

namespace cpm {
namespace {

using cpm_msgs::state_t;

// A CSV's rows keyed by their t column, each row as column name -> value.
using Rows = std::map<double, std::map<std::string, double>>;
Rows read_csv(const std::string& text, std::size_t* count = nullptr) {
  std::istringstream is(text);
  std::vector<std::string> names;
  Rows rows;
  std::size_t n = 0;
  for (std::string line; std::getline(is, line);) {
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> cells;
    std::istringstream ls(line);
    for (std::string c; std::getline(ls, c, ',');) cells.push_back(c);
    if (names.empty()) {
      names = cells;
      continue;
    }
    std::map<std::string, double> row;
    for (std::size_t k = 0; k < cells.size() && k < names.size(); ++k) {
      char* end = nullptr;
      const double v = std::strtod(cells[k].c_str(), &end);
      if (end != cells[k].c_str() && *end == '\0') row[names[k]] = v;
    }
    rows[row.at("t")] = row;
    ++n;
  }
  if (count) *count = n;
  return rows;
}

std::string chromium() {
  for (const char* p : {"/usr/bin/chromium", "/usr/bin/chromium-browser"})
    if (std::filesystem::exists(p)) return p;
  return "";
}

TEST(ScopeOnCpmd, TriggerFiresOnThePaperCirclesStartAndTheCaptureMatchesTheRecordToTheSample) {
  const std::string browser = chromium();
  if (browser.empty()) GTEST_SKIP() << "chromium is not installed (apt-get install chromium): the page is not checked";
  test::EngineerOnCpmd rig("scope");
  ASSERT_TRUE(rig.holding);
  ASSERT_TRUE(rig.client.release());
  const auto& dir = rig.dir;
  const auto& cfg = rig.cfg;
  auto& c = rig.client;
  const std::string op = rig.as_engineer();

  // To the circle's start, so that the circle is the next segment to start.
  const auto mv = test::run_command(std::string(CPM_EXE) + " move 0.6,0.425,0.3" + op, dir / "move.out");
  ASSERT_EQ(mv.status, 0) << mv.out;

  const int port = test::lcm_port();  // TCP: no clash with LCM's UDP port
  test::Process scope({CPM_EXE, "scope", "--http", std::to_string(port), "--url", cfg.lcm.url, "--trigger",
                       "segment-start", "--pre", "0.25", "--post", "1.5", "--duration", "120"},
                      dir / "scope.log", true);
  httplib::Client http("127.0.0.1", port);
  nlohmann::json st;
  for (int i = 0; i < 100; ++i) {
    if (auto r = http.Get("/api/status"); r && r->status == 200) {
      st = nlohmann::json::parse(r->body);
      if (st["received"].get<long>() > 100) break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  ASSERT_GT(st.value("received", 0L), 100) << "cpm scope did not serve cpmd's state:\n" << scope.log();
  EXPECT_EQ(st["state"], "armed");

  test::Process record({CPM_EXE, "record", "--url", cfg.lcm.url, "--until-idle", "--out", dir / "record.csv"},
                       dir / "record.log", true);
  // The page while the machine holds, before the circle: live plots that
  // move (the newest sample drawn advances from one poll to the next).
  const std::string url = "http://127.0.0.1:" + std::to_string(port) + "/";
  // The page's virtual clock: 2 s (ten polls) for the live view; the capture is drawn on the first poll.
  const std::string chrome = browser + " --headless --no-sandbox --disable-gpu --hide-scrollbars --window-size=1280,1000 ";
  const std::string live_budget = "--virtual-time-budget=2000 ", capture_budget = "--virtual-time-budget=1000 ";
  {
    const auto live = test::run_command(chrome + live_budget + "--dump-dom " + url + " 2>/dev/null", dir / "live.html");
    ASSERT_EQ(live.status, 0) << live.out;
    EXPECT_NE(live.out.find("data-state=\"armed\""), std::string::npos) << live.out.substr(0, 3000);
    const auto attr = [&](const std::string& name) -> long long {
      const auto p = live.out.find(name + "=\"");
      return p == std::string::npos ? -1 : std::atoll(live.out.c_str() + p + name.size() + 2);
    };
    EXPECT_GE(attr("data-draws"), 3) << "the live page drew fewer than 3 times";
    EXPECT_GT(attr("data-newest"), attr("data-first-newest")) << "the live plots did not move";
    std::printf("[ figures  ] scope page, live: %lld draws, newest sample from cycle %lld to %lld\n", attr("data-draws"),
                attr("data-first-newest"), attr("data-newest"));
  }

  // The test's own view of the segments: the circle's first cycle. Handling
  // the state for a second also gives record the time to subscribe (a setup
  // wait, not a measurement).
  std::int64_t circle_first = -1, prev_segment = -2;
  bool saw_live_move = false;
  c.on_state([&](const state_t& s) {
    if (prev_segment != -2 && circle_first < 0 && s.segment_id >= 0 && s.segment_id != prev_segment)
      circle_first = s.cycle;
    prev_segment = s.segment_id;
  });
  for (int i = 0; i < 20; ++i) c.handle(0.05);
  ASSERT_EQ(circle_first, -1) << "a segment started before the circle";
  test::Process circle({CPM_EXE, "circle", "--paper", "--no-approach", "--url", cfg.lcm.url, "--key", rig.ops.key_path("eng"),
                        "--operator", "eng"},
                       dir / "circle.log", true);
  std::int64_t newest_live = -1;
  for (int i = 0; i < 400 && circle.running(); ++i) {
    c.handle(0.05);
    // While it runs, the live view moves: each poll's newest sample is newer.
    if (i % 20 == 10)
      if (auto r = http.Get("/api/data?window=1&points=50&signals=x"); r && r->status == 200) {
        const auto j = nlohmann::json::parse(r->body);
        const auto cyc = j["cycle"];
        if (!cyc.empty()) {
          if (newest_live >= 0 && cyc.back().get<std::int64_t>() > newest_live) saw_live_move = true;
          newest_live = cyc.back().get<std::int64_t>();
        }
      }
  }
  EXPECT_EQ(circle.wait_exit(), 0) << circle.log();
  EXPECT_TRUE(saw_live_move) << "the live window did not advance while the circle ran";
  ASSERT_TRUE(record.wait_exit_for(20).has_value()) << "cpm record did not stop after the circle";
  EXPECT_EQ(record.wait_exit(), 0) << record.log();
  ASSERT_GE(circle_first, 0) << "the test saw no segment start";

  auto r = http.Get("/api/status");
  ASSERT_TRUE(r && r->status == 200);
  st = nlohmann::json::parse(r->body);
  ASSERT_EQ(st["state"], "captured") << st.dump();
  EXPECT_EQ(st["trigger"]["cycle"].get<std::int64_t>(), circle_first) << "the trigger is not the circle's first cycle";

  // The exported window against the record, sample by sample.
  r = http.Get("/export.csv");
  ASSERT_TRUE(r && r->status == 200);
  std::size_t captured_rows = 0;
  const Rows cap = read_csv(r->body, &captured_rows);
  const Rows rec = read_csv(test::slurp(dir / "record.csv"));
  const double rate = cfg.loop.rate_hz / cfg.lcm.state_decimation;
  EXPECT_NEAR(static_cast<double>(captured_rows), 1.75 * rate, 0.01 * rate) << "the window is 0.25 s + 1.5 s";
  std::size_t matched = 0, differing = 0;
  for (const auto& [t, row] : cap) {
    const auto it = rec.find(t);
    if (it == rec.end()) continue;
    ++matched;
    for (const char* col : {"d1", "d2", "d3", "v1", "v2", "v3", "f1", "f2", "f3"})
      if (row.at(col) != it->second.at(col)) {
        if (++differing < 5) ADD_FAILURE() << "t = " << t << " s: " << col << " " << row.at(col) << " in the scope, " << it->second.at(col) << " in the record";
      }
  }
  std::printf("[ figures  ] scope: trigger at cycle %lld (the circle's first), %zu samples captured, %zu found in "
              "cpm record's CSV, %zu values differing\n",
              static_cast<long long>(circle_first), captured_rows, matched, differing);
  EXPECT_EQ(differing, 0u);
  // A state lost on the way to one of the two is missing, never different.
  EXPECT_GE(matched, captured_rows - captured_rows / 200) << "fewer than 99.5 % of the captured samples are in the record";

  // The page in headless Chromium: the capture shown, one plot per chosen signal.
  const std::filesystem::path out = std::filesystem::path(CPM_TEST_OUTPUT) / "scope";
  std::filesystem::create_directories(out);
  const auto dom = test::run_command(chrome + capture_budget + "--dump-dom " + url + " 2>/dev/null", dir / "dom.html");
  ASSERT_EQ(dom.status, 0) << dom.out;
  EXPECT_NE(dom.out.find("data-state=\"captured\""), std::string::npos) << dom.out.substr(0, 4000);
  EXPECT_NE(dom.out.find("data-cycle=\"" + std::to_string(circle_first) + "\""), std::string::npos);
  EXPECT_NE(dom.out.find("data-captured=\"yes\""), std::string::npos);
  EXPECT_NE(dom.out.find("data-points=\"" + std::to_string(captured_rows) + "\""), std::string::npos)
      << "the plots do not show the whole capture";
  std::size_t canvases = 0;
  for (std::size_t p = dom.out.find("<canvas"); p != std::string::npos; p = dom.out.find("<canvas", p + 1)) ++canvases;
  EXPECT_EQ(canvases, 5u) << "one plot per default signal (x_ref, x, err_x, f1, latency_max)";
  std::filesystem::remove(out / "scope.png");
  const auto shot = test::run_command(chrome + capture_budget + "--screenshot=" + (out / "scope.png").string() + " " + url, dir / "shot.log");
  ASSERT_EQ(shot.status, 0) << shot.out;
  ASSERT_TRUE(std::filesystem::exists(out / "scope.png")) << shot.out;
  // A PNG of the window's size (IHDR: width and height, big-endian), with
  // plots in it: a blank page of that size compresses to a few kB.
  std::ifstream png(out / "scope.png", std::ios::binary);
  unsigned char h[24] = {};
  png.read(reinterpret_cast<char*>(h), sizeof h);
  EXPECT_EQ((h[16] << 24 | h[17] << 16 | h[18] << 8 | h[19]), 1280);
  EXPECT_EQ((h[20] << 24 | h[21] << 16 | h[22] << 8 | h[23]), 1000);
  EXPECT_GT(std::filesystem::file_size(out / "scope.png"), 30000u);
  std::ofstream(out / "capture.csv") << http.Get("/export.csv")->body;
  const std::string svg = http.Get("/export.svg?signals=x_ref,x,err_x,f1")->body;
  std::ofstream(out / "capture.svg") << svg;
  std::size_t lines = 0;
  for (std::size_t p = svg.find("<polyline"); p != std::string::npos; p = svg.find("<polyline", p + 1)) ++lines;
  EXPECT_EQ(lines, 4u) << "one trace per chosen signal in the SVG export";
  std::printf("[ figures  ] scope page: %s, %ju bytes (and capture.csv, capture.svg beside it)\n",
              (out / "scope.png").c_str(), static_cast<std::uintmax_t>(std::filesystem::file_size(out / "scope.png")));

  EXPECT_EQ(scope.terminate(), 0) << scope.log();
}

}  // namespace
}  // namespace cpm

// SPDX-License-Identifier: Apache-2.0
// `cpm latency` on cpmd's simulator for 3 s (a process-level test like the
// others here, support/daemon_process.hpp): the histogram it reports is
// cpmd's own between the two statistics messages it names, which the test
// receives itself; its counts add up to the wake-ups and to the cycles run
// between them; the worst latency is the last message's. cyclictest, when
// installed, runs beside it and its counts add up to its cycles.
#include <gtest/gtest.h>

#include <map>
#include <nlohmann/json.hpp>

#include "cpm/daemon/client.hpp"
#include "cpm/daemon/loop.hpp"
#include "support/daemon_process.hpp"
#include "tools/cpm_command.hpp"

namespace cpm {
namespace {

using cpm_msgs::loop_stats_t;

TEST(LatencyOnCpmd, HistogramAddsUpToTheCyclesAndTheMaxIsCpmdsOwn) {
  const test::TempDir dir("latency");
  test::OperatorsDir ops(dir / "operators.d");
  const std::string cfg_path = test::sim_config(dir.path(), "sim.yaml", ops.path());
  const auto cfg = daemon::load_config(cfg_path);
  auto d = test::start_cpmd(cfg_path, dir / "cpmd.log");
  daemon::Client c(cfg.lcm);
  ASSERT_TRUE(c.stats(5.0)) << "no statistics from cpmd:\n" << d->log();

  test::Process latency({CPM_EXE, "latency", "--seconds", "3", "--url", cfg.lcm.url, "--json", dir / "latency.json",
                         "--svg", dir / "latency.svg", "--config", cfg_path},
                        dir / "latency.out", true);
  // Every statistics message while it runs, by its cycle count.
  std::map<std::int64_t, loop_stats_t> seen;
  for (int i = 0; i < 20 && latency.running(); ++i)
    if (auto s = c.stats(1.5)) seen[s->cycles] = *s;
  ASSERT_EQ(latency.wait_exit(), 0) << latency.log();
  const std::string out = latency.log();
  std::printf("%s", out.c_str());
  const auto j = nlohmann::json::parse(test::slurp(dir / "latency.json"));

  const auto first = seen.find(j["stats_first"]["cycles"].get<std::int64_t>());
  const auto last = seen.find(j["stats_last"]["cycles"].get<std::int64_t>());
  ASSERT_NE(first, seen.end()) << "the test did not receive the first statistics message cpm latency used";
  ASSERT_NE(last, seen.end()) << "the test did not receive the last statistics message cpm latency used";
  EXPECT_EQ(j["seconds"].get<int>(), 3);
  const loop_stats_t &a = first->second, &b = last->second;
  const int k = daemon::kSeriesLatency;
  const auto& hist = j["cpmd"]["histogram"];
  ASSERT_EQ(hist.size(), static_cast<std::size_t>(daemon::kBins));
  long long sum = 0;
  for (int bin = 0; bin < daemon::kBins; ++bin) {
    EXPECT_EQ(hist[bin].get<long long>(), static_cast<long long>(b.histogram[k][bin]) - a.histogram[k][bin]) << "bin " << bin;
    sum += hist[bin].get<long long>();
  }
  const long long cycles = b.cycles - a.cycles;
  std::printf("[ figures  ] latency: %lld wake-ups in the histogram, %lld cycles run between the two messages, "
              "max %d ns\n", sum, cycles, b.max_ns[k]);
  EXPECT_GT(cycles, 2 * cfg.loop.rate_hz) << "fewer cycles than two seconds of the loop";
  EXPECT_EQ(sum, cycles) << "one wake-up per cycle";
  EXPECT_EQ(sum, b.count[k] - a.count[k]);
  EXPECT_EQ(j["cpmd"]["histogram_total"].get<long long>(), sum);
  EXPECT_EQ(j["cpmd"]["max_ns"].get<std::int32_t>(), b.max_ns[k]);
  // The screen says the same.
  char line[200];
  std::snprintf(line, sizeof line, "cpmd: %lld wake-ups in 3 s (%lld cycles run", sum, cycles);
  EXPECT_NE(out.find(line), std::string::npos) << out;
  std::snprintf(line, sizeof line, "worst wake-up latency %.3f us", b.max_ns[k] * 1e-3);
  EXPECT_NE(out.find(line), std::string::npos) << out;
  // One maximum per second.
  EXPECT_EQ(j["max_over_time"].size(), 3u);
  EXPECT_NE(test::slurp(dir / "latency.svg").find("<polyline"), std::string::npos);

  if (j["cyclictest"].contains("not_run")) {
    std::printf("[ note     ] cyclictest: %s\n", j["cyclictest"]["not_run"].get<std::string>().c_str());
  } else {
    EXPECT_EQ(j["cyclictest"]["histogram_total"].get<long long>(), j["cyclictest"]["cycles"].get<long long>());
    EXPECT_EQ(j["cyclictest"]["period_us"].get<int>(), static_cast<int>(1e6 / cfg.loop.rate_hz));
    EXPECT_EQ(j["cyclictest"]["priority"].get<int>(), cfg.loop.priority);
    EXPECT_GT(j["cyclictest"]["cycles"].get<long long>(), 2 * cfg.loop.rate_hz);
  }
  EXPECT_EQ(d->terminate(), 0) << d->log();
}

}  // namespace
}  // namespace cpm

// SPDX-License-Identifier: Apache-2.0
// cpmd's messages: the journal's priority prefix when stderr is the journal
// ($JOURNAL_STREAM names its device and inode), "cpmd: warning: ..." otherwise;
// and the --stats-json document.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "cpm/daemon/log.hpp"
#include "cpm/daemon/stats_json.hpp"

namespace cpm::daemon {
namespace {

namespace fs = std::filesystem;
using log::Severity;
using log::Style;

TEST(Log, JournalStreamMustNameThisDeviceAndInode) {
  EXPECT_TRUE(log::is_journal_stream("8:123456", 8, 123456));
  EXPECT_FALSE(log::is_journal_stream("8:123457", 8, 123456)) << "another inode";
  EXPECT_FALSE(log::is_journal_stream("9:123456", 8, 123456)) << "another device";
  for (const char* bad : {"", "8", "8:", ":123456", "8:123456x", "x8:123456", "8 :123456", "-8:123456"})
    EXPECT_FALSE(log::is_journal_stream(bad, 8, 123456)) << "'" << bad << "'";
  EXPECT_FALSE(log::is_journal_stream(nullptr, 8, 123456)) << "JOURNAL_STREAM not set";
}

// Sets JOURNAL_STREAM for one scope, and puts back what was there.
class JournalStream {
 public:
  explicit JournalStream(const std::optional<std::string>& value) {
    if (const char* v = std::getenv("JOURNAL_STREAM")) saved_ = v;
    if (value) ::setenv("JOURNAL_STREAM", value->c_str(), 1);
    else ::unsetenv("JOURNAL_STREAM");
  }
  ~JournalStream() {
    if (saved_) ::setenv("JOURNAL_STREAM", saved_->c_str(), 1);
    else ::unsetenv("JOURNAL_STREAM");
  }
  JournalStream(const JournalStream&) = delete;
  JournalStream& operator=(const JournalStream&) = delete;

 private:
  std::optional<std::string> saved_;
};

std::string device_and_inode(int fd) {
  struct stat st {};
  EXPECT_EQ(::fstat(fd, &st), 0);
  return std::to_string(st.st_dev) + ":" + std::to_string(st.st_ino);
}

TEST(Log, StyleFollowsJournalStream) {
  const fs::path a = fs::temp_directory_path() / ("cpm_log_a_" + std::to_string(::getpid()));
  const fs::path b = fs::temp_directory_path() / ("cpm_log_b_" + std::to_string(::getpid()));
  const int fa = ::open(a.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
  const int fb = ::open(b.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
  ASSERT_GE(fa, 0);
  ASSERT_GE(fb, 0);
  {
    const JournalStream js(device_and_inode(fa));  // what systemd sets when stderr is the journal
    EXPECT_EQ(log::style_for(fa), Style::journal);
    EXPECT_EQ(log::style_for(fb), Style::plain) << "stderr redirected elsewhere by the unit";
  }
  {
    const JournalStream js(std::nullopt);  // a terminal, a test
    EXPECT_EQ(log::style_for(fa), Style::plain);
  }
  {
    const JournalStream js(std::string("garbage"));
    EXPECT_EQ(log::style_for(fa), Style::plain);
  }
  ::close(fa);
  ::close(fb);
  fs::remove(a);
  fs::remove(b);
}

TEST(Log, JournalLinesCarryTheSyslogPriority) {
  EXPECT_EQ(log::format(Style::journal, Severity::error, "cannot write x"), "<3>cannot write x\n");
  EXPECT_EQ(log::format(Style::journal, Severity::warning, "operators: none"), "<4>operators: none\n");
  EXPECT_EQ(log::format(Style::journal, Severity::notice, "SIGTERM"), "<5>SIGTERM\n");
  EXPECT_EQ(log::format(Style::journal, Severity::info, "sim backend"), "<6>sim backend\n");
  EXPECT_EQ(log::format(Style::journal, Severity::debug, "d"), "<7>d\n");
  // A journal entry is one line: each line of a message gets the priority.
  EXPECT_EQ(log::format(Style::journal, Severity::warning, "one\ntwo\n"), "<4>one\n<4>two\n");
}

TEST(Log, PlainLinesSayWhoAndHowBad) {
  EXPECT_EQ(log::format(Style::plain, Severity::error, "cannot write x"), "cpmd: error: cannot write x\n");
  EXPECT_EQ(log::format(Style::plain, Severity::warning, "operators: none"), "cpmd: warning: operators: none\n");
  EXPECT_EQ(log::format(Style::plain, Severity::notice, "SIGTERM"), "cpmd: SIGTERM\n");
  EXPECT_EQ(log::format(Style::plain, Severity::info, "sim backend"), "cpmd: sim backend\n");
  EXPECT_EQ(log::format(Style::plain, Severity::debug, "d"), "cpmd: debug: d\n");
  EXPECT_EQ(log::format(Style::plain, Severity::error, "a\nb"), "cpmd: error: a\ncpmd: error: b\n");
}

// What the daemon writes goes to stderr, formatted, in one piece.
TEST(Log, WritesToStderr) {
  const fs::path p = fs::temp_directory_path() / ("cpm_log_err_" + std::to_string(::getpid()));
  const int f = ::open(p.c_str(), O_RDWR | O_CREAT | O_TRUNC, 0600);
  ASSERT_GE(f, 0);
  const int saved = ::dup(STDERR_FILENO);
  ::dup2(f, STDERR_FILENO);
  log::warning("cannot keep the other threads off CPU %d: %s", 3, "Invalid argument");
  log::info("%s backend, %.0f Hz", "sim", 1000.0);
  ::dup2(saved, STDERR_FILENO);
  ::close(saved);
  ::close(f);
  std::ifstream in(p);
  std::stringstream text;
  text << in.rdbuf();
  fs::remove(p);
  // This test's stderr is not the journal: plain lines.
  EXPECT_EQ(text.str(), "cpmd: warning: cannot keep the other threads off CPU 3: Invalid argument\n"
                        "cpmd: sim backend, 1000 Hz\n");
}

TEST(StatsJson, SeriesAndHistogramsReadBack) {
  cpm_msgs::loop_stats_t s{};
  s.rate_hz = 1000.0;
  s.cycles = 3;
  s.overruns = 1;
  s.realtime = 1;
  s.count[kSeriesLatency] = 3;
  s.min_ns[kSeriesLatency] = 7000;
  s.max_ns[kSeriesLatency] = 260000;
  s.sum_ns[kSeriesLatency] = 7000.0 + 13000.0 + 260000.0;
  s.histogram[kSeriesLatency][7] = 1;
  s.histogram[kSeriesLatency][13] = 1;
  s.histogram[kSeriesLatency][201] = 1;  // [250, 300) us
  FineLatencyHistogram fine{};
  fine[7] = 1;
  fine[13] = 1;
  fine[260] = 1;
  const nlohmann::ordered_json j = nlohmann::ordered_json::parse(stats_json(s, fine));
  EXPECT_EQ(j["rate_hz"].get<double>(), 1000.0);
  EXPECT_EQ(j["cycles"], 3);
  EXPECT_EQ(j["overruns"], 1);
  EXPECT_EQ(j["realtime"], true);
  EXPECT_EQ(j["memory_locked"], false);
  ASSERT_EQ(j["series"].size(), static_cast<std::size_t>(kSeries));
  EXPECT_EQ(j["series"].begin().key(), "wakeup_latency");
  const auto& w = j["series"]["wakeup_latency"];
  EXPECT_EQ(w["mean_ns"].get<double>(), 280000.0 / 3.0);
  EXPECT_EQ(w["histogram_us"], nlohmann::ordered_json::parse(R"({"7": 1, "13": 1, "250": 1})"));
  EXPECT_EQ(w["histogram_1us"], nlohmann::ordered_json::parse(R"({"7": 1, "13": 1, "260": 1})"));
  EXPECT_FALSE(j["series"]["cycle"].contains("histogram_1us")) << "the 1 us bins are the wake-up latency's";
  EXPECT_EQ(j["series"]["cycle"]["mean_ns"].get<double>(), 0.0) << "no samples: 0, not NaN";
}

}  // namespace
}  // namespace cpm::daemon

// SPDX-License-Identifier: Apache-2.0
// cpmd's state stream as a motion log: lcm-logger files written here event by
// event (states with the drives on and off, a foreign channel, a damaged
// event, a non-finite value), read back strictly and leniently; and a
// simulated run with a planted effect written as an lcm-logger file, read as
// compare/diagnose/fit read it, in which the diagnosis names the effect.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <lcm/lcm-cpp.hpp>
#include <string>
#include <vector>

#include "cpm/identification/diagnose.hpp"
#include "identification/sim_data.hpp"
#include "state_log.hpp"

namespace cpm::cli {
namespace {

using cpm_msgs::state_t;

struct TempDir {
  std::filesystem::path path =
      std::filesystem::temp_directory_path() / ("cpm-state-log-" + std::to_string(getpid()));
  TempDir() { std::filesystem::create_directories(path); }
  ~TempDir() { std::filesystem::remove_all(path); }
  [[nodiscard]] std::string file(const std::string& name) const { return (path / name).string(); }
};

class LogWriter {
 public:
  explicit LogWriter(const std::string& path) : log_(path, "w") { EXPECT_TRUE(log_.good()); }
  void state(const state_t& s, const std::string& channel = "CPMD_STATE") {
    std::vector<std::uint8_t> buf(static_cast<std::size_t>(s.getEncodedSize()));
    s.encode(buf.data(), 0, static_cast<int>(buf.size()));
    raw(buf, channel);
  }
  void raw(std::vector<std::uint8_t> bytes, const std::string& channel) {
    lcm::LogEvent ev;
    ev.eventnum = next_++;
    ev.timestamp = 1000 * ev.eventnum;
    ev.channel = channel;
    ev.datalen = static_cast<std::int32_t>(bytes.size());
    ev.data = bytes.data();
    EXPECT_EQ(log_.writeEvent(&ev), 0);
  }

 private:
  lcm::LogFile log_;
  std::int64_t next_ = 0;
};

state_t state_at(std::int64_t cycle, std::int8_t mode) {
  state_t s{};
  s.cycle = cycle;
  s.t = cycle * 1e-3;
  s.mode = mode;
  for (int i = 0; i < 3; ++i) {
    s.d[i] = 0.2 + 0.01 * std::sin(0.5 * s.t + i);
    s.d_dot[i] = 0.005 * std::cos(0.5 * s.t + i);
    s.force[i] = i == 2 ? -36.0 : 0.1 * i;
  }
  return s;
}

TEST(StateLog, OnlyCyclesWithTheDrivesApplyingForceEachStretchOneRun) {
  TempDir dir;
  const std::string path = dir.file("modes.lcmlog");
  {
    LogWriter w(path);
    std::int64_t c = 0;
    for (int k = 0; k < 10; ++k) w.state(state_at(c++, state_t::MODE_DISABLED));
    for (int k = 0; k < 300; ++k) w.state(state_at(c++, k < 100 ? state_t::MODE_HOLDING : state_t::MODE_MOVING));
    w.state(state_at(c, state_t::MODE_MOVING), "CPMD_OTHER");  // another channel: not ours
    for (int k = 0; k < 5; ++k) w.state(state_at(c++, state_t::MODE_FAULT));
    for (int k = 0; k < 200; ++k) w.state(state_at(c++, k < 150 ? state_t::MODE_STOPPING : state_t::MODE_HOLDING));
  }
  ASSERT_TRUE(is_lcm_log(path));
  const io::DataSet ds = read_measurements(path);
  ASSERT_TRUE(std::holds_alternative<io::MotionData>(ds));
  const auto& m = std::get<io::MotionData>(ds);
  EXPECT_EQ(m.t.size(), 500u);
  ASSERT_EQ(m.run.size(), 500u);
  EXPECT_EQ(m.run.front(), 0);
  EXPECT_EQ(m.run[299], 0);
  EXPECT_EQ(m.run[300], 1);  // the fault split the log
  EXPECT_EQ(m.run.back(), 1);
  EXPECT_DOUBLE_EQ(m.rate, 1000.0);
  EXPECT_DOUBLE_EQ(m.t.front(), 0.010);          // the first state with the drives on
  EXPECT_DOUBLE_EQ(m.f.front().z(), -36.0);
  EXPECT_EQ(m.info.line_of_row.front(), 10);     // its event number
  bool said = false;
  for (const auto& wmsg : m.info.warnings) said |= wmsg.find("15 states left out") != std::string::npos;
  EXPECT_TRUE(said);
}

TEST(StateLog, ADamagedEventOrANonFiniteValueIsAnErrorNamingTheEventWhenStrict) {
  TempDir dir;
  const std::string damaged = dir.file("damaged.lcmlog"), nan = dir.file("nan.lcmlog");
  {
    LogWriter w(damaged);
    for (int k = 0; k < 50; ++k) w.state(state_at(k, state_t::MODE_MOVING));
    w.raw({1, 2, 3, 4, 5, 6, 7, 8, 9}, "CPMD_STATE");  // event 50: not a state_t
    for (int k = 51; k < 100; ++k) w.state(state_at(k, state_t::MODE_MOVING));
  }
  {
    LogWriter w(nan);
    for (int k = 0; k < 100; ++k) {
      state_t s = state_at(k, state_t::MODE_MOVING);
      if (k == 42) s.force[1] = NAN;
      w.state(s);
    }
  }
  auto refused_saying = [](const std::string& path, std::initializer_list<const char*> words) {
    try {
      (void)read_measurements(path);
      ADD_FAILURE() << path << " was accepted";
    } catch (const Error& e) {
      for (const char* w : words) EXPECT_NE(std::string(e.what()).find(w), std::string::npos) << e.what();
    }
  };
  refused_saying(damaged, {"event 50", "does not decode"});
  refused_saying(nan, {"event 42", "f2"});
  // Converting (lcm-log-to-csv) skips them and says how many.
  const StateLogRead lenient = read_state_log(damaged, "CPMD_STATE", false);
  EXPECT_EQ(lenient.undecodable, 1);
  EXPECT_EQ(lenient.data.t.size(), 99u);
  // A log with no state on the channel says so.
  EXPECT_THROW((void)read_state_log(damaged, "CPMD_NOTHING", true), Error);
}

TEST(StateLog, ACsvIsStillACsv) {
  TempDir dir;
  const std::string path = dir.file("log.csv");
  io::MotionData m;
  for (int k = 0; k < 20; ++k) {
    m.t.push_back(k * 1e-3);
    m.d.emplace_back(0.2, 0.2, 0.2);
    m.v.emplace_back(0, 0, 0);
    m.f.emplace_back(0, 0, -36);
  }
  io::write_motion(path, m);
  EXPECT_FALSE(is_lcm_log(path));
  EXPECT_TRUE(std::holds_alternative<io::MotionData>(read_measurements(path)));
}

// What `cpm diagnose --data run.lcmlog` does: a simulated run of the true
// machine (Coulomb friction of 1.5 N on axis 2) stored as cpmd would publish
// it, with the drives off before and after, read and diagnosed.
TEST(StateLog, ADiagnosisReadsTheDaemonsLogDirectly) {
  TempDir dir;
  const std::string path = dir.file("run.lcmlog");
  test::SimSpec spec;
  spec.duration = 12.0;
  spec.seed = 31;
  spec.effects = {{"coulomb_friction", 1, {1.5}}};
  const io::MotionData sim = test::simulate(spec);
  {
    LogWriter w(path);
    std::int64_t c = 0;
    for (int k = 0; k < 200; ++k) w.state(state_at(c++, state_t::MODE_DISABLED));
    for (std::size_t k = 0; k < sim.t.size(); ++k) {
      state_t s{};
      s.cycle = c++;
      s.t = sim.t[k];
      s.mode = state_t::MODE_MOVING;
      for (int i = 0; i < 3; ++i) {
        s.d[i] = sim.d[k][i];
        s.d_dot[i] = sim.v[k][i];
        s.force[i] = sim.f[k][i];
      }
      w.state(s);
    }
    for (int k = 0; k < 200; ++k) w.state(state_at(c++, state_t::MODE_DISABLED));
  }
  const io::DataSet ds = read_measurements(path);
  const auto& m = std::get<io::MotionData>(ds);
  ASSERT_EQ(m.t.size(), sim.t.size());
  const ident::Diagnosis D = ident::diagnose_motion(m, ctl::Machine(ctl::MachineModel::elkady()));
  ASSERT_GE(D.verdict, 0) << D.verdict_text;
  const auto& v = D.candidates[static_cast<std::size_t>(D.verdict)];
  EXPECT_EQ(v.label(), "coulomb_friction[axis 2]") << D.verdict_text;
  EXPECT_LE(std::fabs(v.params[0].value - 1.5), 3.0 * v.params[0].std_error) << v.params[0].value;
}

}  // namespace
}  // namespace cpm::cli

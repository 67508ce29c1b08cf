// SPDX-License-Identifier: Apache-2.0
// The operator's console without a terminal (tools/cpm/console.hpp): the
// watch screen at 80 x 24 and 120 x 40 in every mode, with a drive in fault
// and a long fault sentence (every field's label there, no line wider than
// the window, the sentence whole across its lines); the drive table and the
// JSON of `cpm drives` and `cpm get`; `cpm set`'s units; `cpm home`'s
// actuators; and what `cpm jog`'s keys send, on a clock the test gives.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <regex>
#include <sstream>

#include "console.hpp"
#include "cpm/daemon/client.hpp"
#include "cpm/daemon/fault_report.hpp"
#include "cpm/daemon/loop.hpp"

namespace cpm::cli::console {
namespace {

using cpm_msgs::control_command_t;
using cpm_msgs::drives_t;
using cpm_msgs::loop_stats_t;
using cpm_msgs::params_t;
using cpm_msgs::state_t;

std::vector<std::string> words(const std::string& s) {
  std::istringstream is(s);
  std::vector<std::string> w;
  for (std::string x; is >> x;) w.push_back(x);
  return w;
}

// The row `label` is on (-1: none).
int row_of(const Lines& lines, const std::string& label) {
  for (std::size_t i = 0; i < lines.size(); ++i)
    if (lines[i].find(label) != std::string::npos) return static_cast<int>(i);
  return -1;
}

// Whether `text` has a match of `re` (figures with the spaces of their columns).
bool has(const std::string& text, const std::string& re) { return std::regex_search(text, std::regex(re)); }

std::string joined(const Lines& lines) {
  std::string r;
  for (const auto& l : lines) r += l + "\n";
  return r;
}

state_t make_state(std::int8_t mode) {
  state_t s{};
  s.cycle = 123456;
  s.t = 123.456;
  s.mode = mode;
  s.controller = 3;
  const double p[3] = {0.600, 0.425, 0.300}, e[3] = {12.3e-6, -4.5e-6, 0.7e-6};
  for (int i = 0; i < 3; ++i) {
    s.position[i] = p[i];
    s.position_error[i] = e[i];
    s.position_ref[i] = p[i] + e[i];
    s.velocity[i] = 0.0123 * (i + 1);
    s.force[i] = 10.0 * (i + 1);
    s.d[i] = 0.1 * (i + 1);
    s.d_ref[i] = s.d[i];
    s.homed[i] = 1;
  }
  s.saturated[1] = 1;
  s.control_space = state_t::SPACE_TASK;
  s.segment_id = -1;
  s.last_segment_id = -1;
  s.homing_axis = -1;
  s.max_latency_ns = 45600;
  s.max_cycle_ns = 120300;
  s.overruns = 2;
  s.skipped = 3;
  switch (mode) {
    case state_t::MODE_MOVING:
      s.segment_id = 36028797018963968;  // a client's id: random base << 32
      s.segment_elapsed = 1.25;
      s.segment_duration = 5.0;
      s.queue_depth = 2;
      s.last_segment_id = 36028797018963967;
      s.last_segment_rmse = 12.3e-6;
      s.last_segment_max = 45.6e-6;
      break;
    case state_t::MODE_HOMING:
      s.homing_axis = 2;
      s.homing_phase = state_t::HOMING_BACK_OFF;
      s.homed[2] = 0;
      s.control_space = state_t::SPACE_ACTUATOR;
      break;
    case state_t::MODE_JOGGING:
      s.jog_frame = control_command_t::JOG_MACHINE;
      s.jog_velocity[0] = -0.050;
      s.jog_velocity[2] = 0.020;
      s.jog_keepalive_left = 0.150;
      break;
    case state_t::MODE_FAULT: {
      s.faults = int{state_t::FAULT_DRIVE} | int{state_t::FAULT_FOLLOWING_ERROR};
      s.first_fault = state_t::FAULT_DRIVE;
      s.fault_axis = 1;
      s.fault_value = 0x0218;
      // The backend's words, as long as fault_text holds (95 characters and its NUL).
      const std::string why = "drive 2 (y, node 2): EMCY 0x8611 register 0x11: following error of the drive's own loop";
      std::memcpy(s.fault_text, why.data(), std::min(why.size(), sizeof s.fault_text - 1));
      break;
    }
    default: break;
  }
  return s;
}

loop_stats_t make_stats() {
  loop_stats_t st{};
  st.rate_hz = 1000;
  st.cycles = 100000;
  st.overruns = 2;
  st.skipped = 3;
  // Wake-up latency: 1000 samples, 990 in [10, 11) us and 10 in [150, 151) us.
  st.count[daemon::kSeriesLatency] = 1000;
  st.histogram[daemon::kSeriesLatency][10] = 990;
  st.histogram[daemon::kSeriesLatency][150] = 10;
  st.max_ns[daemon::kSeriesLatency] = 150700;
  st.count[daemon::kSeriesCycle] = 1000;
  st.histogram[daemon::kSeriesCycle][40] = 1000;
  st.max_ns[daemon::kSeriesCycle] = 40900;
  return st;
}

// CANopen drives, drive 2 in fault after an EMCY, the bus error-passive.
drives_t make_drives() {
  drives_t d{};
  d.backend = drives_t::BACKEND_CANOPEN;
  for (int i = 0; i < 3; ++i) {
    d.node_id[i] = static_cast<std::int16_t>(i + 1);
    d.nmt_state[i] = drives_t::NMT_OPERATIONAL;
    d.cia402_state[i] = drives_t::CIA402_OPERATION_ENABLED;
    d.mode_display[i] = 10;
    d.enabled[i] = 1;
    d.homed[i] = 1;
    d.heartbeat_age_ms[i] = 40 + i;
    d.statusword[i] = 0x1237;
    d.controlword[i] = 0x000F;
  }
  d.cia402_state[1] = drives_t::CIA402_FAULT;
  d.fault[1] = 1;
  d.enabled[1] = 0;
  d.statusword[1] = 0x0218;
  d.emcy_count[1] = 3;
  d.last_emcy_code[1] = 0x8611;
  d.last_emcy_register[1] = 0x11;
  d.master_faults[1] = 0x4;
  d.bus_state = drives_t::BUS_ERROR_PASSIVE;
  d.error_frames = 1234567;
  d.tx_error_counter = 128;
  d.rx_error_counter = 7;
  d.rx_dropped = 5;
  d.tx_failures = 1;
  d.bus_load = 0.69;
  d.home_switch[2] = 1;
  return d;
}

// Every field's label, as the screen names it.
const std::vector<std::string> kLabels = {
    "mode ", "space ", "law ", "homed 1:", "position mm", "reference mm", "error um", "velocity mm/s", "force N",
    "trajectory", "segment ", "queue ", "last segment", "RMS ", " max ", "homing ", "actuator ", "phase ",
    "jog ", "frame ", " v ", "deadman ", "loop timing", "wake-up p99", "wake-up max", "cycle max", "overruns",
    "skipped", "node", "NMT", "CiA 402", "enabled", "fault", "hb ms", "EMCY", "reg", "count", "bus ",
    "error frames", "TEC ", "REC ", "rx dropped", "tx failures", "load "};

void expect_fits(const Lines& lines, int w, int h) {
  EXPECT_LE(static_cast<int>(lines.size()), h);
  for (const auto& l : lines) EXPECT_LE(static_cast<int>(l.size()), w) << "'" << l << "'";
}

TEST(ConsoleWatch, EveryFieldInEveryModeAt80x24And120x40) {
  const auto st = make_stats();
  const auto d = make_drives();
  for (std::int8_t mode = state_t::MODE_INIT; mode <= state_t::MODE_JOGGING; ++mode)
    for (const auto& [w, h] : {std::pair{80, 24}, std::pair{120, 40}}) {
      SCOPED_TRACE(std::string(daemon::mode_text(mode)) + " at " + std::to_string(w) + " x " + std::to_string(h));
      const state_t s = make_state(mode);
      const Lines lines = render(s, st, d, w, h);
      expect_fits(lines, w, h);
      const std::string text = joined(lines);
      for (const auto& label : kLabels) EXPECT_NE(text.find(label), std::string::npos) << label << " missing:\n" << text;
      // The mode, in words.
      static const char* names[] = {"INIT", "DISABLED", "ENABLING", "HOLDING", "MOVING",
                                    "STOPPING", "FAULT", "HOMING", "JOGGING"};
      EXPECT_EQ(lines[0].rfind(std::string("mode ") + names[mode] + " ", 0), 0u) << lines[0];
    }
}

TEST(ConsoleWatch, FiguresInScreenUnits) {
  const Lines lines = render(make_state(state_t::MODE_MOVING), make_stats(), make_drives(), 80, 24);
  const std::string text = joined(lines);
  // Position in mm to the um, the error in um to 0.1 um, velocity in mm/s.
  EXPECT_NE(lines[row_of(lines, "position mm")].find("600.000     425.000     300.000"), std::string::npos) << text;
  EXPECT_NE(lines[row_of(lines, "error um")].find("12.3        -4.5         0.7"), std::string::npos) << text;
  EXPECT_NE(lines[row_of(lines, "velocity mm/s")].find("12.3        24.6        36.9"), std::string::npos) << text;
  // Actuator 2 at its force limit, and only it.
  const std::string force = lines[row_of(lines, "force N")];
  EXPECT_NE(force.find("10.0 SAT    20.0        30.0"), std::string::npos) << force;
  EXPECT_EQ(force.find("SAT"), force.rfind("SAT")) << force;
  // 1.25 s of 5 s: a quarter of the bar, 25 %, the whole id.
  EXPECT_NE(text.find("segment 36028797018963968"), std::string::npos) << text;
  EXPECT_TRUE(has(text, R"( 1\.25 / +5\.00 s)")) << text;
  EXPECT_TRUE(has(text, R"(\[#{5}\.{17}\]  25%)")) << text;  // 22 columns at 80
  EXPECT_TRUE(has(text, R"(RMS +12\.3 um  max +45\.6 um)")) << text;
  // 99 % of the wake-ups within [10, 11) us: p99 is the bin's top; the worst is 150.7 us.
  EXPECT_TRUE(has(text, R"(wake-up p99 +11\.0 us)")) << text;
  EXPECT_TRUE(has(text, R"(wake-up max +150\.7 us)")) << text;
  EXPECT_TRUE(has(text, R"(cycle max +40\.9 us)")) << text;
  EXPECT_TRUE(has(text, R"(overruns +2\n)")) << text;
  // The bus: error-passive, a count past 5 digits to 3 figures, TEC 128.
  EXPECT_NE(text.find("error-passive"), std::string::npos) << text;
  EXPECT_NE(text.find("error frames 1.23M "), std::string::npos) << text;
  EXPECT_NE(text.find("TEC 128"), std::string::npos) << text;
  EXPECT_NE(text.find("load  69%"), std::string::npos) << text;
}

TEST(ConsoleWatch, HomingAndJogInWords) {
  const Lines homing = render(make_state(state_t::MODE_HOMING), std::nullopt, std::nullopt, 80, 24);
  EXPECT_NE(homing[row_of(homing, "homing ")].find("actuator 3  phase back_off"), std::string::npos) << joined(homing);
  EXPECT_NE(homing[0].find("space actuator"), std::string::npos) << homing[0];
  EXPECT_NE(homing[0].find("homed 1:yes 2:yes 3:no"), std::string::npos) << homing[0];
  const Lines jog = render(make_state(state_t::MODE_JOGGING), std::nullopt, std::nullopt, 80, 24);
  EXPECT_NE(jog[row_of(jog, "jog ")].find("frame machine   v -50.0, 0.0, 20.0 mm/s  deadman 0.150 s left"),
            std::string::npos)
      << joined(jog);
}

// A drive in fault after an EMCY: its row says so, with the code and register.
TEST(ConsoleWatch, DriveInFaultWithItsEmcy) {
  const drives_t d = make_drives();
  for (int w : {80, 120, 200}) {
    SCOPED_TRACE(w);
    const Lines t = drive_table(&d, w);
    ASSERT_EQ(t.size(), 4u);
    for (const auto& l : t) EXPECT_LE(static_cast<int>(l.size()), w) << l;
    const std::string& row2 = t[2];
    EXPECT_EQ(row2.rfind("2 ", 0), 0u) << row2;
    EXPECT_NE(row2.find("FAULT"), std::string::npos) << row2;
    EXPECT_NE(row2.find("0x8611 0x11"), std::string::npos) << row2;
    EXPECT_EQ(t[1].find("FAULT"), std::string::npos) << t[1];
    EXPECT_EQ(t[1].find("0x8611"), std::string::npos) << t[1];
  }
  // Wider: the CiA 402 states in full, then the status and control words, the master's bits, d and F.
  const Lines wide = drive_table(&d, 200);
  for (const char* h : {"status", "control", "master", "d mm", "force N"})
    EXPECT_NE(wide[0].find(h), std::string::npos) << h;
  EXPECT_NE(wide[1].find("operation enabled"), std::string::npos) << wide[1];
  EXPECT_NE(wide[2].find("0x0218"), std::string::npos) << wide[2];
  EXPECT_EQ(drive_table(&d, 80)[0].find("status"), std::string::npos);
}

// The sentence of fault_report, complete across its lines, the rest still there.
TEST(ConsoleWatch, LongFaultSentenceIsWrappedWhole) {
  const state_t s = make_state(state_t::MODE_FAULT);
  const std::string sentence = daemon::fault_report(s);
  ASSERT_GT(sentence.size(), 240u) << sentence;  // three lines and more at 80 columns
  for (const auto& [w, h] : {std::pair{80, 24}, std::pair{120, 40}, std::pair{80, 14}}) {
    SCOPED_TRACE(std::to_string(w) + " x " + std::to_string(h));
    const Lines lines = render(s, make_stats(), make_drives(), w, h);
    expect_fits(lines, w, h);
    const int first = row_of(lines, "fault  ");
    ASSERT_GE(first, 0) << joined(lines);
    std::string shown;
    for (std::size_t i = static_cast<std::size_t>(first); i < lines.size() && (i == static_cast<std::size_t>(first) || lines[i].rfind("       ", 0) == 0); ++i)
      shown += lines[i] + " ";
    std::vector<std::string> want = words("fault " + sentence + " [also active: following_error]");
    EXPECT_EQ(words(shown), want) << joined(lines);
    if (h >= 24) {
      const std::string text = joined(lines);
      for (const auto& label : kLabels) EXPECT_NE(text.find(label), std::string::npos) << label;
    }
  }
}

// Without drives or statistics the rows stay where they are, with placeholders.
TEST(ConsoleWatch, MissingMessagesKeepTheLayout) {
  const state_t s = make_state(state_t::MODE_HOLDING);
  const Lines full = render(s, make_stats(), make_drives(), 80, 24);
  const Lines bare = render(s, std::nullopt, std::nullopt, 80, 24);
  const Lines none = render(std::nullopt, std::nullopt, std::nullopt, 80, 24);
  EXPECT_EQ(full.size(), bare.size());
  EXPECT_EQ(full.size(), none.size());
  for (const char* label : {"position mm", "force N", "trajectory", "homing ", "jog ", "overruns", "CiA 402", "fault "})
    EXPECT_EQ(row_of(full, label), row_of(bare, label)) << label;
  EXPECT_NE(joined(bare).find("(no drives message)"), std::string::npos);
  EXPECT_NE(joined(bare).find("loop (no stats yet)"), std::string::npos);
  EXPECT_NE(joined(none).find("mode (no state message)"), std::string::npos);
  expect_fits(none, 80, 24);
}

// A taller window shows more rows; a wider one more decimals and columns.
TEST(ConsoleWatch, BiggerWindowsShowMore) {
  const state_t s = make_state(state_t::MODE_HOLDING);
  const Lines small = render(s, make_stats(), make_drives(), 80, 24);
  const Lines big = render(s, make_stats(), make_drives(), 160, 50);
  EXPECT_EQ(row_of(small, "actuator d mm"), -1);
  EXPECT_GE(row_of(big, "actuator d mm"), 0);
  EXPECT_GE(row_of(big, "limit high"), 0);
  EXPECT_GE(row_of(big, "home switch  act 1 off   act 2 off   act 3 ON"), 0) << joined(big);
  EXPECT_NE(big[row_of(big, "position mm")].find("600.0000"), std::string::npos);
  EXPECT_NE(big[0].find("cycle 123456"), std::string::npos) << big[0];
  EXPECT_GE(row_of(big, "status"), 0);
}

TEST(ConsoleWatch, PercentileFromTheHistogram) {
  loop_stats_t st{};
  // One sample in each 1 us bin from 1 to 100 us: the 99th is in [99, 100).
  for (int b = 1; b <= 100; ++b) st.histogram[0][b] = 1;
  st.count[0] = 100;
  EXPECT_DOUBLE_EQ(percentile_us(st, 0, 0.99), 100.0);
  EXPECT_DOUBLE_EQ(percentile_us(st, 0, 0.50), 51.0);
  // Beyond 200 us, 50 us bins.
  loop_stats_t slow{};
  slow.histogram[0][202] = 10;  // [300, 350) us
  slow.count[0] = 10;
  EXPECT_DOUBLE_EQ(percentile_us(slow, 0, 0.99), 350.0);
}

TEST(ConsoleWatch, WrapLosesNothing) {
  const std::string text = "a short start, then " + std::string(200, 'x') + " and a tail of words to wrap";
  const Lines l = wrap(text, 40, "fault  ", 7);
  std::string back;
  for (const auto& x : l) {
    EXPECT_LE(x.size(), 40u) << x;
    back += x;
  }
  back.erase(std::remove(back.begin(), back.end(), ' '), back.end());
  std::string want = "fault" + text;
  want.erase(std::remove(want.begin(), want.end(), ' '), want.end());
  EXPECT_EQ(back, want);
}

TEST(ConsoleDrives, JsonHasEveryField) {
  const Json j = Json::parse(json_text(drives_json(make_drives()), -1));
  for (const char* k : {"utime", "cycle", "backend", "drives", "bus", "inputs"}) EXPECT_TRUE(j.contains(k)) << k;
  ASSERT_EQ(j["drives"].size(), 3u);
  for (const auto& d : j["drives"])
    for (const char* k : {"actuator", "node_id", "nmt_state", "cia402_state", "statusword", "controlword",
                          "mode_display", "enabled", "fault", "homed", "heartbeat_age_ms", "master_faults", "emcy_count",
                          "last_emcy_code", "last_emcy_register", "position", "force"})
      EXPECT_TRUE(d.contains(k)) << k;
  for (const char* k : {"state", "error_frames", "tx_error_counter", "rx_error_counter", "rx_dropped", "tx_failures", "load"})
    EXPECT_TRUE(j["bus"].contains(k)) << k;
  for (const char* k : {"estop", "limit_low", "limit_high", "home_switch"}) EXPECT_TRUE(j["inputs"].contains(k)) << k;
  EXPECT_EQ(j["backend"], "canopen");
  EXPECT_EQ(j["drives"][1]["actuator"], 2);
  EXPECT_EQ(j["drives"][1]["cia402_state"], "fault");
  EXPECT_EQ(j["drives"][0]["cia402_state"], "operation_enabled");
  EXPECT_EQ(j["drives"][0]["nmt_state"], "operational");
  EXPECT_EQ(j["drives"][1]["last_emcy_code"], 0x8611);
  EXPECT_EQ(j["drives"][1]["fault"], true);
  EXPECT_EQ(j["bus"]["state"], "error_passive");
  EXPECT_EQ(j["bus"]["load"], 0.69);
  EXPECT_EQ(j["inputs"]["home_switch"], Json::array({false, false, true}));
}

params_t make_params() {
  params_t p{};
  p.count = 3;
  p.name = {"limits.following_error", "jog.max_velocity", "controller.kp.z"};
  p.value = {0.005, 0.05, 12691.0};
  p.unit = {"m", "m/s", "N/m"};
  p.minimum = {0.0001, 0.001, 0.0};
  p.maximum = {0.05, 0.25, 1e6};
  p.while_moving = {0, 1, 0};
  p.description = {"the largest distance between the platform and its reference", "the fastest jog",
                   "proportional gain along z"};
  return p;
}

TEST(ConsoleParams, GetTextAndJson) {
  const params_t p = make_params();
  const Lines all = params_table(p, select_params(p, {}), false);
  ASSERT_EQ(all.size(), 4u);
  EXPECT_NE(all[0].find("while moving"), std::string::npos);
  EXPECT_NE(all[1].find("0.005 m (5.000 mm)"), std::string::npos) << all[1];
  EXPECT_NE(all[1].find("0.0001 .. 0.05 m"), std::string::npos) << all[1];
  EXPECT_EQ(all[1].substr(all[1].size() - 2), "no");
  EXPECT_NE(all[2].find("0.05 m/s (50.0 mm/s)"), std::string::npos) << all[2];
  EXPECT_EQ(all[2].substr(all[2].size() - 3), "yes");
  EXPECT_NE(all[3].find("12691 N/m"), std::string::npos) << all[3];
  EXPECT_NE(all[3].find("0 .. 1e+06 N/m"), std::string::npos) << all[3];
  EXPECT_EQ(all[3].find("mm"), std::string::npos) << all[3];  // no mm rendering for N/m

  const auto which = select_params(p, {"controller.kp.z", "limits.following_error"});
  ASSERT_EQ(which, (std::vector<int>{2, 0}));
  const Lines named = params_table(p, which, true);
  EXPECT_NE(joined(named).find("proportional gain along z"), std::string::npos);
  const Json j = Json::parse(json_text(params_json(p, which), -1));
  ASSERT_EQ(j.size(), 2u);
  const Json& fe = j["limits.following_error"];
  for (const char* k : {"value", "unit", "minimum", "maximum", "while_moving", "description"}) EXPECT_TRUE(fe.contains(k)) << k;
  EXPECT_EQ(fe["value"], 0.005);
  EXPECT_EQ(fe["unit"], "m");
  EXPECT_EQ(fe["minimum"], 0.0001);
  EXPECT_EQ(fe["maximum"], 0.05);
  EXPECT_EQ(fe["while_moving"], false);

  try {
    select_params(p, {"limits.nosuch"});
    FAIL() << "an unknown parameter was taken";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("'limits.nosuch'"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("jog.max_velocity"), std::string::npos) << e.what();
  }
  EXPECT_EQ(screen_value(5e-6, "m"), "5.0 um");
  EXPECT_EQ(screen_value(0.5, "m/s^2"), "500.0 mm/s^2");
}

TEST(ConsoleParams, SetValueUnits) {
  struct Case {
    const char* text;
    double si;
    const char* unit;
  };
  for (const Case& c : {Case{"0.006", 0.006, ""}, Case{"6mm", 0.006, "m"}, Case{"6 mm", 0.006, "m"},
                        Case{"6000um", 0.006, "m"}, Case{"0.006m", 0.006, "m"}, Case{"-2mm", -0.002, "m"},
                        Case{"+1e-3m", 0.001, "m"}, Case{"20mm/s", 0.020, "m/s"}, Case{"0.02m/s", 0.020, "m/s"},
                        Case{"500mm/s^2", 0.5, "m/s^2"}, Case{"500mm/s2", 0.5, "m/s^2"}, Case{"12691", 12691.0, ""}}) {
    SCOPED_TRACE(c.text);
    const Quantity q = parse_quantity(c.text);
    EXPECT_NEAR(q.value, c.si, 1e-15);
    EXPECT_EQ(q.unit, c.unit);
  }
  for (const char* bad : {"", "abc", "5 furlongs", "5mm/h", "nan", "inf", "-inf", "1e999", "mm"})
    EXPECT_THROW(parse_quantity(bad), UsageError) << bad;
  // The suffix must be the parameter's unit; without one, the value is the parameter's SI.
  EXPECT_DOUBLE_EQ(value_for(parse_quantity("5mm"), "limits.following_error", "m"), 0.005);
  EXPECT_DOUBLE_EQ(value_for(parse_quantity("500mm/s^2"), "jog.acceleration", "m/s2"), 0.5);
  EXPECT_DOUBLE_EQ(value_for(parse_quantity("12000"), "controller.kp.z", "N/m"), 12000.0);
  EXPECT_THROW(value_for(parse_quantity("5mm/s"), "limits.following_error", "m"), UsageError);
  EXPECT_THROW(value_for(parse_quantity("5mm"), "controller.kp.z", "N/m"), UsageError);
}

TEST(ConsoleHome, Actuators) {
  EXPECT_EQ(parse_home_axes({}), 0);
  EXPECT_EQ(parse_home_axes({"x"}), 1);
  EXPECT_EQ(parse_home_axes({"2"}), 2);
  EXPECT_EQ(parse_home_axes({"z", "1"}), 5);
  EXPECT_EQ(parse_home_axes({"y,z"}), 6);
  EXPECT_EQ(parse_home_axes({"x", "y", "z", "1"}), 7);
  EXPECT_THROW(parse_home_axes({"w"}), UsageError);
  EXPECT_THROW(parse_home_axes({"4"}), UsageError);
}

using Key = JogPad::Key;

TEST(ConsoleJog, AHeldKeyJogsWhileItsRepeatComes) {
  JogPad pad;
  pad.press(Key::cartesian, 0.0);
  ASSERT_EQ(pad.frame(), control_command_t::JOG_MACHINE);
  EXPECT_FALSE(pad.command(0.0));
  // Pressed at 1 s: held through the terminal's repeat delay.
  pad.press(Key::right, 1.0);
  for (double t : {1.0, 1.3, 1.0 + JogPad::kFirstRepeat - 0.01}) {
    const auto v = pad.command(t);
    ASSERT_TRUE(v) << t;
    EXPECT_EQ(*v, (std::array<double, 3>{0.005, 0, 0})) << t;
  }
  // The repeat: every 33 ms until 2.5 s; held until kRepeat after the last.
  for (double t = 1.5; t <= 2.5; t += 0.033) {
    pad.press(Key::right, t);
    ASSERT_TRUE(pad.command(t + 0.02));
  }
  const double last = 1.5 + 0.033 * 30;
  EXPECT_TRUE(pad.command(last + JogPad::kRepeat - 0.01));
  EXPECT_FALSE(pad.command(last + JogPad::kRepeat + 0.01));  // nothing sent: the deadman stops it
  EXPECT_FALSE(pad.command(last + 1.0));
  // A single press, never repeated, lets go after the repeat delay.
  pad.press(Key::page_down, 10.0);
  EXPECT_EQ(*pad.command(10.1), (std::array<double, 3>{0, 0, 0.005}));  // z is down: page down goes down
  EXPECT_FALSE(pad.command(10.0 + JogPad::kFirstRepeat + 0.01));
  pad.press(Key::page_up, 20.0);
  EXPECT_EQ(*pad.command(20.1), (std::array<double, 3>{0, 0, -0.005}));
  pad.press(Key::up, 20.2);  // another key takes over at once
  EXPECT_EQ(*pad.command(20.2), (std::array<double, 3>{0, 0.005, 0}));
  pad.press(Key::down, 20.25);
  EXPECT_EQ(*pad.command(20.25), (std::array<double, 3>{0, -0.005, 0}));
  pad.press(Key::left, 20.3);
  EXPECT_EQ(*pad.command(20.3), (std::array<double, 3>{-0.005, 0, 0}));
}

TEST(ConsoleJog, StopFrameChangeAndQuitSendZerosOnce) {
  JogPad pad;
  pad.press(Key::right, 0.0);  // actuator 1 selected: its keys jog d1
  EXPECT_EQ(*pad.command(0.0), (std::array<double, 3>{0.005, 0, 0}));
  pad.press(Key::stop, 0.1);
  EXPECT_EQ(*pad.command(0.1), (std::array<double, 3>{0, 0, 0}));
  EXPECT_FALSE(pad.command(0.15));
  pad.press(Key::right, 1.0);
  pad.press(Key::cartesian, 1.1);
  EXPECT_EQ(*pad.command(1.1), (std::array<double, 3>{0, 0, 0}));
  EXPECT_FALSE(pad.command(1.2));
  pad.press(Key::up, 2.0);
  pad.press(Key::quit, 2.1);
  EXPECT_TRUE(pad.quit());
  EXPECT_EQ(*pad.command(2.1), (std::array<double, 3>{0, 0, 0}));
  EXPECT_FALSE(pad.command(2.2));
}

TEST(ConsoleJog, ActuatorFrameMovesOnlyTheSelectedActuator) {
  JogPad pad;
  EXPECT_EQ(pad.frame(), control_command_t::JOG_ACTUATOR);
  EXPECT_EQ(pad.selected(), 0);
  const std::string m = pad.press(Key::up, 0.0);  // actuator 2's keys while 1 is selected
  EXPECT_NE(m.find("press 2"), std::string::npos) << m;
  EXPECT_FALSE(pad.command(0.0));
  EXPECT_EQ(pad.press(Key::select2, 0.1), "");
  pad.press(Key::up, 0.2);
  EXPECT_EQ(*pad.command(0.2), (std::array<double, 3>{0, 0.005, 0}));
  pad.press(Key::select3, 0.3);  // another actuator: the one moving stops
  EXPECT_EQ(*pad.command(0.3), (std::array<double, 3>{0, 0, 0}));
  pad.press(Key::page_up, 0.4);
  EXPECT_EQ(*pad.command(0.4), (std::array<double, 3>{0, 0, -0.005}));
}

TEST(ConsoleJog, SpeedStepsCappedByTheDaemonsMaximum) {
  JogPad pad;
  EXPECT_DOUBLE_EQ(pad.speed(), 0.005);
  pad.press(Key::slower, 0);
  pad.press(Key::slower, 0);
  EXPECT_DOUBLE_EQ(pad.speed(), 0.001);
  EXPECT_NE(pad.press(Key::slower, 0), "");
  pad.set_max_speed(0.015);  // jog.max_velocity 15 mm/s: 10 is the fastest step
  for (int i = 0; i < 10; ++i) pad.press(Key::faster, 0);
  EXPECT_DOUBLE_EQ(pad.speed(), 0.010);
  EXPECT_NE(pad.press(Key::faster, 0), "");
  pad.set_max_speed(0.0005);  // below every step: the maximum itself
  EXPECT_DOUBLE_EQ(pad.speed(), 0.0005);
  JogPad fast;
  for (int i = 0; i < 10; ++i) fast.press(Key::faster, 0);
  EXPECT_DOUBLE_EQ(fast.speed(), 0.050);
}

TEST(ConsoleJog, ScreenSaysWhichWayAndWhy) {
  JogPad pad;
  pad.press(Key::cartesian, 0);
  pad.set_max_speed(0.05);
  cpm_msgs::ack_t refused{};
  refused.accepted = false;
  refused.message = "jog in the machine frame refused: actuators 1 and 3 are not homed; home them first (cpm home) "
                    "or jog the actuators one at a time (keys 1 2 3)";
  state_t s = make_state(state_t::MODE_HOLDING);
  s.homed[0] = 0;
  for (const auto& [w, h] : {std::pair{80, 24}, std::pair{120, 40}}) {
    const Lines l = render_jog(s, pad, refused, std::array<double, 3>{0, 0, 0.005}, "", w, h);
    expect_fits(l, w, h);
    const std::string text = joined(l);
    for (const char* want : {"z- (up)", "z+ (down", "space stop", "q quit", "position mm", "velocity mm/s", "deadman",
                             "no key-up", "jog.max_velocity 50 mm/s", "homed 1:no ", "frame   machine",
                             "sending 0.0, 0.0, 5.0 mm/s (x, y, z)"})
      EXPECT_NE(text.find(want), std::string::npos) << want << "\n" << text;
    std::string shown;
    for (std::size_t i = static_cast<std::size_t>(row_of(l, "last jog")); i < l.size() && (shown.empty() || l[i].rfind("          ", 0) == 0); ++i)
      shown += l[i] + " ";
    EXPECT_EQ(words(shown), words("last jog REFUSED: " + refused.message)) << text;
  }
}

}  // namespace
}  // namespace cpm::cli::console

// ---- the rough edges a newcomer met (issue 29)

namespace cpm::cli::console {
namespace {

TEST(ConsoleRoughEdges, WorstLatencyIsNoneYetOrSaturatedNeverTheIntegersMaximum) {
  EXPECT_EQ(worst_us_text(0, false), "none yet");
  EXPECT_EQ(worst_us_text(45600, true), "45.6 us");
  const std::string sat = worst_us_text(INT32_MAX, true);
  EXPECT_EQ(sat.find("2147483.6"), std::string::npos) << sat;
  EXPECT_NE(sat.find("> 2147483 us"), std::string::npos) << sat;
  EXPECT_NE(sat.find("stall"), std::string::npos) << sat;

  state_t s = make_state(state_t::MODE_HOLDING);
  s.cycles = 0;
  EXPECT_NE(status_lines(s)[0].find("worst wake-up latency none yet"), std::string::npos) << status_lines(s)[0];
  s.cycles = 5000;
  s.max_latency_ns = INT32_MAX;
  EXPECT_NE(status_lines(s)[0].find("worst wake-up latency > 2147483 us"), std::string::npos) << status_lines(s)[0];
  // The watch's loop panel from the state alone, and from the statistics.
  const std::string w = joined(render(s, std::nullopt, std::nullopt, 80, 24));
  EXPECT_EQ(w.find("2147ms"), std::string::npos) << w;
  EXPECT_TRUE(has(w, "wake-up max +>2\\.1s")) << w;
  loop_stats_t st{};
  EXPECT_TRUE(has(joined(render(s, st, std::nullopt, 80, 24)), "wake-up max +none")) << joined(render(s, st, std::nullopt, 80, 24));
}

TEST(ConsoleRoughEdges, StatusMarksAPositionBeforeHomingAndNamesNoIdNobodySent) {
  state_t s = make_state(state_t::MODE_MOVING);
  EXPECT_EQ(not_homed_mark(s), "");
  s.homed[1] = 0;
  s.homed[2] = 0;
  EXPECT_EQ(not_homed_mark(s).rfind("NOT HOMED (actuators 2 3)", 0), 0u) << not_homed_mark(s);
  s.homed[2] = 1;
  EXPECT_EQ(not_homed_mark(s).rfind("NOT HOMED (actuator 2)", 0), 0u) << not_homed_mark(s);
  s.cycles = 1000;
  const std::string all = joined(status_lines(s));
  EXPECT_EQ(all.find(std::to_string(s.last_segment_id)), std::string::npos) << all;
  EXPECT_NE(all.find("last finished segment: tracking error RMS 12.3 um, max 45.6 um"), std::string::npos) << all;
  s.last_segment_id = -1;  // none finished yet: no line
  EXPECT_EQ(status_lines(s).size(), 1u);
}

TEST(ConsoleRoughEdges, GetPrintsEveryDigitNotTwoSignificant) {
  params_t p{};
  p.count = 3;
  p.name = {"limits.force", "limits.following_error", "controller.kp.z"};
  p.unit = {"N", "m", "N/m"};
  p.value = {120.0, 0.005, 2550.25};
  p.minimum = {0.0, 0.0001, 0.0};
  p.maximum = {1000.0, 0.05, 1e6};
  p.while_moving = {0, 0, 0};
  p.description = {"", "", ""};
  const std::string t = joined(params_table(p, select_params(p, {}), false));
  EXPECT_EQ(t.find("e+02"), std::string::npos) << t;
  EXPECT_NE(t.find("limits.force  "), std::string::npos) << t;
  EXPECT_TRUE(has(t, "limits\\.force +120 N ")) << t;
  EXPECT_TRUE(has(t, "0 \\.\\. 1000 N")) << t;
  EXPECT_TRUE(has(t, "2550\\.25 N/m")) << t;
  EXPECT_TRUE(has(t, "0 \\.\\. 1e\\+06 N/m")) << t;  // the exponent from 1e6 up
  EXPECT_TRUE(has(t, "0\\.0001 \\.\\. 0\\.05 m")) << t;
}

TEST(ConsoleRoughEdges, OnceAndPipedBlocksHaveNoKeysLine) {
  const state_t s = make_state(state_t::MODE_HOLDING);
  EXPECT_GE(row_of(render(s, std::nullopt, std::nullopt, 80, 100), "keys  q quit"), 0);
  EXPECT_LT(row_of(render(s, std::nullopt, std::nullopt, 80, 100, "", /*keys=*/false), "keys"), 0);
  EXPECT_LT(row_of(render(s, std::nullopt, std::nullopt, 80, 100, "", false), "q quit"), 0);
}

TEST(ConsoleRoughEdges, ScriptedJogSaysWhatCameAfterTheLastCommand) {
  // 10 mm/s for 2 s on actuator 1: 20 mm while sent, then 0.4 mm of stop ramp.
  const std::array<double, 3> start{0.100, 0.200, 0.300}, sent{0.120, 0.200, 0.300}, rest{0.1204, 0.200, 0.300};
  const std::string t = jog_distance_text(start, sent, rest, 2.0, false);
  EXPECT_NE(t.find("moved 20.400 mm (d1 +20.400, d2 +0.000, d3 +0.000 mm)"), std::string::npos) << t;
  EXPECT_NE(t.find("20.000 mm in the 2.00 s of jog, then 0.400 mm while stopping"), std::string::npos) << t;
  EXPECT_NE(jog_distance_text(start, sent, rest, 2.0, true).find("x +20.400"), std::string::npos);
}

}  // namespace
}  // namespace cpm::cli::console

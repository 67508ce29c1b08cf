// SPDX-License-Identifier: Apache-2.0
// The operator's console: what `cpm watch`, `drives`, `get`, `set`, `home`
// and `jog` show and how they read their input, as pure functions of the
// messages (state_t, loop_stats_t, drives_t, params_t), so that tests check
// every screen without a terminal. The terminal itself (ncurses) is
// console_screen.hpp; the subcommands are cmd_console*.cpp.
//
// Screens are ASCII (a column is a byte): "um" for micrometres, as `cpm
// status` writes them. Figures are in mm, um, mm/s and N on screen, labelled;
// everything else (JSON, values sent) is SI.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <cpm_msgs/ack_t.hpp>
#include <cpm_msgs/drives_t.hpp>
#include <cpm_msgs/loop_stats_t.hpp>
#include <cpm_msgs/params_t.hpp>
#include <cpm_msgs/state_t.hpp>

#include "cpm/daemon/text.hpp"

#include "cli.hpp"

namespace cpm::cli::console {

using Lines = std::vector<std::string>;

// ---- cpm watch

// The watch screen for a terminal of `width` x `height`: at most `height`
// lines, none longer than `width` (for width >= 80). A missing message shows
// placeholders ("(no drives message)") in the same rows, so the layout
// depends only on the size and on how many lines the fault sentence takes.
// At 80 x 24 every field is there; wider windows get wider figures and more
// columns (statusword, controlword, the master's fault bits, the actuators'
// positions and forces), taller ones more rows (actuator displacements and
// their references, the transfer force, one line per GPIO input). The active
// fault's sentence (daemon::fault_report) is wrapped and never cut off: rows
// of less weight give way to it. `note` (e.g. "no state from cpmd for 3 s")
// is shown on the last line. `keys`: the full screen's "keys  q quit" line
// (a plain block, --once or to a pipe, reads no key and has none).
Lines render(const std::optional<cpm_msgs::state_t>& state, const std::optional<cpm_msgs::loop_stats_t>& stats,
             const std::optional<cpm_msgs::drives_t>& drives, int width, int height, const std::string& note = "",
             bool keys = true);

// The drive table (the same rows in watch and `cpm drives`): a header and one
// row per drive, as wide as `width` allows; placeholders without a message.
Lines drive_table(const cpm_msgs::drives_t* drives, int width);
// The bus (state, error frames, TEC/REC, rx dropped, tx failures, load): one
// line when it fits in `width`, else two.
Lines bus_lines(const cpm_msgs::drives_t* drives, int width);
// The GPIO inputs: one line per input (e-stop, limit low, limit high, home
// switch) when `per_input`, else one line.
Lines input_lines(const cpm_msgs::drives_t* drives, int width, bool per_input);

// The `q`-th quantile (0..1) of loop_stats_t series `k` (0 wake-up latency,
// 9 the whole cycle) in us, to the histogram's bins (1 us below 200 us).
double percentile_us(const cpm_msgs::loop_stats_t& s, int k, double q);

// `text` wrapped at spaces into lines of at most `width` columns, the first
// starting with `first`, the others with `indent` spaces; a word longer than
// a line is cut across lines. Nothing is lost.
Lines wrap(const std::string& text, int width, const std::string& first, int indent);

// Names of the drives_t codes: for JSON (snake_case) and for screens.
const char* nmt_name(std::int8_t nmt) noexcept;         // "operational", "pre_operational", ...
const char* cia402_name(std::int8_t state) noexcept;    // "operation_enabled", "switch_on_disabled", ...
const char* bus_state_name(std::int8_t state) noexcept; // "error_active", ..., "none" (simulator)
const char* homing_phase_name(std::int8_t phase) noexcept;  // "idle", "search", "back_off", ...

// ---- cpm status, stats

// A worst-case time from cpmd's statistics: daemon/text.hpp.
using daemon::worst_us_text;
// The homed mark after a position: "" when every actuator is homed, else
// "NOT HOMED (actuators 1 3): the position is not referenced".
std::string not_homed_mark(const cpm_msgs::state_t& s);
// `cpm status`'s lines after the state's: controller, cycles, overruns and
// the worst wake-up latency; the last finished segment's tracking (named by
// what it was, not by the client's internal command id).
Lines status_lines(const cpm_msgs::state_t& s);

// ---- cpm drives --json

// Every drives_t field by its name; the codes also by name (nmt_state,
// cia402_state, bus.state, backend), per drive an object with "actuator" 1-3.
Json drives_json(const cpm_msgs::drives_t& d);

// ---- cpm get, cpm set

// The indices of `names` in `p` (all, in the message's order, when empty);
// Error naming the unknown one and listing those cpmd has.
std::vector<int> select_params(const cpm_msgs::params_t& p, const std::vector<std::string>& names);
// The value as an operator reads it where the unit is m, m/s or m/s^2
// ("5.000 mm", "12.0 um", "50.0 mm/s"); "" for other units.
std::string screen_value(double value, const std::string& unit);
// `cpm get`: name, value and unit (and the mm/um rendering), range, whether
// it may change while the platform moves; with the description when
// `describe`.
Lines params_table(const cpm_msgs::params_t& p, const std::vector<int>& which, bool describe);
// `cpm get --json`: {"NAME": {"value", "unit", "minimum", "maximum",
// "while_moving", "description"}, ...} in the message's order.
Json params_json(const cpm_msgs::params_t& p, const std::vector<int>& which);

// `cpm set`'s VALUE: a number in SI, or with a unit suffix converted to SI:
// m, mm, um (to m), m/s, mm/s (to m/s), m/s^2, mm/s^2 (to m/s^2); "5mm" and
// "5 mm" alike. `unit` is the SI unit the suffix names ("" without one).
// UsageError for anything else (a non-finite number, an unknown suffix).
struct Quantity {
  double value = 0;
  std::string unit;
};
Quantity parse_quantity(const std::string& text);
// The SI value to send for parameter `name` of unit `param_unit` (as
// params_t gives it; "" when unknown): UsageError when the suffix's unit is
// not the parameter's.
double value_for(const Quantity& q, const std::string& name, const std::string& param_unit);

// ---- cpm home

// x|y|z|1|2|3 ... -> control_command_t.home_axes (bit i = actuator i + 1);
// none -> 0 (every actuator, in the configured order). UsageError otherwise.
std::uint8_t parse_home_axes(const std::vector<std::string>& words);

// ---- cpm jog

// The keys of `cpm jog` and what they send. Terminals send no key-up, only a
// held key's auto-repeat: a direction key keeps its velocity alive while its
// repeat keeps coming (the first repeat comes after the terminal's delay,
// `kFirstRepeat`; then every few tens of ms, `kRepeat`), and nothing is sent
// once it stops: cpmd's deadman (jog.keepalive) then stops the platform.
// Times are the caller's clock in s, so that tests give them.
class JogPad {
 public:
  enum class Key { none, left, right, up, down, page_up, page_down, select1, select2, select3, cartesian, faster,
                   slower, stop, quit };
  // How long a key press holds without a repeat: the first one (a terminal's
  // auto-repeat delay is 250-660 ms), then between repeats (25-30 Hz).
  static constexpr double kFirstRepeat = 0.7, kRepeat = 0.15;
  // The speed steps (m/s).
  static constexpr std::array<double, 6> kSteps = {0.001, 0.002, 0.005, 0.010, 0.020, 0.050};

  JogPad();
  // jog.max_velocity from params_t (m/s): the steps above it are left out.
  void set_max_speed(double v);
  // A key at `now`. Returns a sentence for the screen when the key did
  // nothing ("actuator 1 is selected: press 2 to jog actuator 2"), else "".
  std::string press(Key k, double now);
  // The velocity to send at `now` (m/s, in frame()): the held key's while
  // its repeat keeps coming, zeros once after a stop (space, a frame change),
  // nullopt when nothing is to be sent.
  std::optional<std::array<double, 3>> command(double now);

  [[nodiscard]] std::int8_t frame() const noexcept { return frame_; }  // control_command_t::JOG_*
  [[nodiscard]] int selected() const noexcept { return selected_; }    // actuator 0..2 (actuator frame)
  [[nodiscard]] double speed() const noexcept;                         // m/s
  [[nodiscard]] double max_speed() const noexcept { return max_speed_; }
  [[nodiscard]] bool quit() const noexcept { return quit_; }
  // Whether a key's velocity is being held at `now`.
  [[nodiscard]] bool holding(double now) const noexcept;

 private:
  std::int8_t frame_;
  int selected_ = 0;
  int step_ = 2;  // 5 mm/s
  double max_speed_ = 0;  // 0: unknown (no cap but the steps')
  int axis_ = -1;         // the held key's axis, its sign
  double sign_ = 0;
  double last_key_ = -1e9;  // when the held key last came
  bool repeating_ = false, stop_pending_ = false, quit_ = false;
};

// `cpm jog --for`'s account of the distance (mm; in the jog's frame:
// actuator displacements or the platform's position): `start` when the first
// jog was sent, `sent_end` when the last one was, `rest` where the platform
// stopped. The part after the last jog (the stop ramp, or the deadman's
// coast) is given apart, so that the distance is not read as v * S.
std::string jog_distance_text(const std::array<double, 3>& start, const std::array<double, 3>& sent_end,
                              const std::array<double, 3>& rest, double seconds, bool machine_frame);

// The jog screen: mode, space, homed, frame and selection, speed, the keys
// (which way is which: z is down), position and velocity, what is being
// sent (`sending`, m/s in the pad's frame; nullopt: nothing), the deadman's
// time left, the last jog's refusal (cpmd's sentence), and why releasing a
// key stops the platform.
Lines render_jog(const std::optional<cpm_msgs::state_t>& state, const JogPad& pad,
                 const std::optional<cpm_msgs::ack_t>& last_ack, const std::optional<std::array<double, 3>>& sending,
                 const std::string& note, int width, int height);

}  // namespace cpm::cli::console

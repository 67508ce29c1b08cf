// SPDX-License-Identifier: Apache-2.0
// The screens of the operator's console (console.hpp): cpm watch, the drive
// table, the bus and inputs, and cpm jog's screen.
#include "console.hpp"

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdint>
#include <cstdio>
#include <cstring>

#include <cpm_msgs/control_command_t.hpp>

#include "cpm/control/controller.hpp"
#include "cpm/daemon/client.hpp"
#include "cpm/daemon/fault_report.hpp"
#include "cpm/daemon/text.hpp"
#include "cpm/daemon/loop.hpp"
#include "cpm/hal/canopen.hpp"
#include "cpm/hal/cia402.hpp"

namespace cpm::cli::console {

using cpm_msgs::control_command_t;
using cpm_msgs::drives_t;
using cpm_msgs::loop_stats_t;
using cpm_msgs::state_t;

namespace {


// `s` left-aligned in `w` columns (cut when longer).
std::string left(const std::string& s, int w) {
  if (static_cast<int>(s.size()) >= w) return s.substr(0, static_cast<std::size_t>(std::max(w, 0)));
  return s + std::string(static_cast<std::size_t>(w) - s.size(), ' ');
}
// `s` right-aligned in `w` columns (never cut: callers size the figures).
std::string right(const std::string& s, int w) {
  if (static_cast<int>(s.size()) >= w) return s;
  return std::string(static_cast<std::size_t>(w) - s.size(), ' ') + s;
}

// A figure with `prec` decimals in at most `w` columns: fewer decimals, then
// an exponent, when it does not fit (a runaway value stays readable and the
// columns stay where they are).
std::string fixed(double v, int w, int prec) {
  if (!std::isfinite(v)) return right(std::isnan(v) ? "nan" : (v > 0 ? "inf" : "-inf"), w);
  for (int p = prec; p >= 0; --p) {
    std::string s = daemon::printf_text("%.*f", p, v);
    if (static_cast<int>(s.size()) <= w) return right(s, w);
  }
  for (int p = 2; p >= 0; --p) {
    std::string s = daemon::printf_text("%.*e", p, v);
    if (static_cast<int>(s.size()) <= w) return right(s, w);
  }
  return std::string(static_cast<std::size_t>(w), '#');
}

// A count in at most 6 columns, 3 significant digits past 99999: 12345,
// 123k, 1.23M, 12.3G.
std::string count(double n) {
  if (std::fabs(n) < 1e5) return daemon::printf_text("%.0f", n);
  static const char units[] = {'k', 'M', 'G', 'T', 'P', 'E'};
  double m = n / 1e3;
  std::size_t u = 0;
  while (std::fabs(m) >= 999.5 && u + 1 < sizeof units) m /= 1e3, ++u;
  const int decimals = std::fabs(m) < 9.995 ? 2 : std::fabs(m) < 99.95 ? 1 : 0;
  return daemon::printf_text("%.*f%c", decimals, m, units[u]);
}

// A time in us in at most 7 columns.
std::string micros(double us) { return us < 1e5 ? daemon::printf_text("%.1f", us) : daemon::printf_text("%.0fms", us / 1e3); }

// A worst-case time (int32 ns) in at most 7 columns: "none" before the first
// sample, ">2.1s" where it saturated (the true figure is unknown).
std::string worst_micros(std::int32_t ns, bool any) {
  if (!any) return "none";
  if (ns >= INT32_MAX) return ">2.1s";
  return micros(ns * 1e-3);
}

std::string upper(std::string s) {
  for (auto& c : s) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return s;
}

bool wide(int width) { return width >= 110; }

// The screens are laid out for 80 columns and more: a narrower window cuts
// the lines (a wider one never has to). At most `height` lines, none ending
// in spaces.
Lines fit(Lines lines, int width, int height) {
  if (static_cast<int>(lines.size()) > height) lines.resize(static_cast<std::size_t>(std::max(height, 0)));
  for (auto& l : lines) {
    if (width < 80 && static_cast<int>(l.size()) > width) l.resize(static_cast<std::size_t>(std::max(width, 0)));
    while (!l.empty() && l.back() == ' ') l.pop_back();
  }
  return lines;
}

// ---- the state's figures

// The columns of the platform table: a label of 15 columns, then x, y, z
// (platform, machine frame) = actuators 1, 2, 3 (one along each axis).
constexpr int kLabel = 15;
int column(int width) { return wide(width) ? 14 : 12; }

std::string table_header(int width) {
  const int cw = column(width);
  return left("", kLabel) + right("x / act 1", cw) + right("y / act 2", cw) + right("z / act 3", cw);
}

// One row: `label`, then v[0..2] * scale with `prec` decimals (+1 when wide);
// `mark[i]` appends a 4-column mark (" SAT") after the figure.
std::string table_row(const std::string& label, const double* v, double scale, int prec, int width,
                      const std::int8_t* mark = nullptr, const char* mark_text = " SAT") {
  const int cw = column(width), p = prec + (wide(width) ? 1 : 0);
  std::string r = left(label, kLabel);
  for (int i = 0; i < 3; ++i) {
    if (mark)  // the mark before the figure: the figures stay aligned with the rows above
      r += (mark[i] ? mark_text : "    ") + fixed(v[i] * scale, cw - 4, p);
    else
      r += fixed(v[i] * scale, cw, p);
  }
  return r;
}

std::string table_row_none(const std::string& label, int width) {
  const int cw = column(width);
  return left(label, kLabel) + right("-", cw) + right("-", cw) + right("-", cw);
}

// The loop's timing beside the table: a header and five rows.
Lines loop_panel(const std::optional<state_t>& s, const std::optional<loop_stats_t>& st) {
  auto row = [](const char* label, const std::string& v, const char* unit) {
    return left(label, 12) + right(v, 9) + unit;
  };
  std::string p99 = "-", lat = "-", cyc = "-", over = "-", skip = "-";
  if (st) {
    if (st->count[daemon::kSeriesLatency] > 0) p99 = micros(percentile_us(*st, daemon::kSeriesLatency, 0.99));
    lat = worst_micros(st->max_ns[daemon::kSeriesLatency], st->count[daemon::kSeriesLatency] > 0);
    cyc = worst_micros(st->max_ns[daemon::kSeriesCycle], st->count[daemon::kSeriesCycle] > 0);
    over = count(static_cast<double>(st->overruns));
    skip = count(static_cast<double>(st->skipped));
  } else if (s) {  // the state carries the worst figures and the counts
    lat = worst_micros(s->max_latency_ns, s->cycles > 0);
    cyc = worst_micros(s->max_cycle_ns, s->cycles > 0);
  }
  if (s) {  // 1 kHz: fresher than the statistics' 1 Hz
    over = count(static_cast<double>(s->overruns));
    skip = count(static_cast<double>(s->skipped));
  }
  return {st ? std::string("loop timing") : std::string("loop (no stats yet)"), row("wake-up p99", p99, " us"),
          row("wake-up max", lat, " us"), row("cycle max", cyc, " us"), row("overruns", over, ""),
          row("skipped", skip, "")};
}

const char* law_text(std::int8_t law) {
  if (law < 0 || law > 3) return "unknown";
  return ctl::law_name(static_cast<ctl::ControlLaw>(law));
}

std::string homed_text(const std::int8_t* homed) {
  return daemon::printf_text("homed 1:%s 2:%s 3:%s", homed[0] ? "yes" : "no ", homed[1] ? "yes" : "no ", homed[2] ? "yes" : "no ");
}

std::string title(const std::optional<state_t>& s, int width) {
  if (!s) return "mode (no state message)   space -   law -   homed -";
  std::string t = "mode " + left(upper(daemon::mode_text(s->mode)), 8) + "  space " +
                  left(s->control_space == state_t::SPACE_TASK ? "task" : "actuator", 8) + "  law " +
                  left(law_text(s->controller), 15) + "  " + homed_text(s->homed);
  if (wide(width)) t += daemon::printf_text("  t %.3f s  cycle %lld", s->t, static_cast<long long>(s->cycle));
  return t;
}

// The platform table with the loop's timing on its right: 6 rows.
Lines table(const std::optional<state_t>& s, const std::optional<loop_stats_t>& st, int width) {
  Lines rows;
  rows.push_back(table_header(width));
  if (s) {
    rows.push_back(table_row("position mm", s->position, 1e3, 3, width));
    rows.push_back(table_row("reference mm", s->position_ref, 1e3, 3, width));
    rows.push_back(table_row("error um", s->position_error, 1e6, 1, width));
    rows.push_back(table_row("velocity mm/s", s->velocity, 1e3, 1, width));
    rows.push_back(table_row("force N", s->force, 1.0, 1, width, s->saturated));
  } else {
    for (const char* l : {"position mm", "reference mm", "error um", "velocity mm/s", "force N"})
      rows.push_back(table_row_none(l, width));
  }
  const Lines panel = loop_panel(s, st);
  const std::size_t at = static_cast<std::size_t>(kLabel + 3 * column(width)) + (wide(width) ? 4 : 1);
  for (std::size_t i = 0; i < rows.size(); ++i) rows[i] = left(rows[i], static_cast<int>(at)) + panel[i];
  return rows;
}

// The rows a taller window adds to the table: the actuators' side.
Lines table_more(const std::optional<state_t>& s, int width) {
  if (!s)
    return {table_row_none("actuator d mm", width), table_row_none("act. ref mm", width),
            table_row_none("transfer N", width)};
  return {table_row("actuator d mm", s->d, 1e3, 3, width), table_row("act. ref mm", s->d_ref, 1e3, 3, width),
          table_row("transfer N", s->transfer_force, 1.0, 1, width)};
}

std::string bar(double f, int w) {
  f = std::clamp(std::isfinite(f) ? f : 0.0, 0.0, 1.0);
  const int fill = static_cast<int>(f * w + 1e-9);
  return "[" + std::string(static_cast<std::size_t>(fill), '#') + std::string(static_cast<std::size_t>(w - fill), '.') + "]";
}

Lines trajectory(const std::optional<state_t>& s, int width) {
  const bool playing = s && s->segment_id >= 0;
  std::string l1 = "trajectory  segment " +
                   left(playing ? std::to_string(s->segment_id) : std::string("none"), 19) + "  ";
  l1 += playing ? fixed(s->segment_elapsed, 8, 2) + " / " + fixed(s->segment_duration, 8, 2) + " s"
                : right("-", 8) + " / " + right("-", 8) + "  ";
  l1 += "  queue " + (s ? std::to_string(s->queue_depth) : std::string("-"));
  const double f = playing && s->segment_duration > 0 ? s->segment_elapsed / s->segment_duration : 0.0;
  const int bw = std::clamp(width - 58, 10, 60);
  std::string l2 = "  " + bar(f, bw) + (playing ? daemon::printf_text(" %3.0f%%", 100 * std::clamp(f, 0.0, 1.0)) : std::string("    "));
  const bool last = s && s->last_segment_id >= 0;
  l2 += "   last segment  RMS " + (last ? fixed(s->last_segment_rmse * 1e6, 8, 1) : right("-", 8)) + " um  max " +
        (last ? fixed(s->last_segment_max * 1e6, 8, 1) : right("-", 8)) + " um";
  return {l1, l2};
}

std::string homing_row(const std::optional<state_t>& s) {
  std::string r = "homing      actuator ";
  const bool on = s && (s->mode == state_t::MODE_HOMING || s->homing_phase != state_t::HOMING_IDLE) &&
                  s->homing_axis >= 0 && s->homing_axis <= 2;
  r += on ? std::to_string(s->homing_axis + 1) : std::string("-");
  r += "  phase " + std::string(s ? homing_phase_name(s->homing_phase) : "-");
  return r;
}

std::string jog_row(const std::optional<state_t>& s) {
  const bool on = s && s->mode == state_t::MODE_JOGGING;
  std::string r = "jog         frame ";
  r += left(on ? (s->jog_frame == control_command_t::JOG_MACHINE ? "machine" : "actuator") : "-", 8);
  r += "  v ";
  r += on ? daemon::printf_text("%.1f, %.1f, %.1f", s->jog_velocity[0] * 1e3, s->jog_velocity[1] * 1e3, s->jog_velocity[2] * 1e3)
          : std::string("-");
  r += " mm/s  deadman ";
  r += on ? daemon::printf_text("%.3f s left", s->jog_keepalive_left) : std::string("-");
  return r;
}

// The fault in words, or "none".
std::string fault_sentence(const state_t& s) {
  if (s.faults == 0 && s.first_fault == 0) return "none";
  std::string r = daemon::fault_report(s);
  if (r.empty()) r = daemon::fault_text(s.faults);
  const auto others = static_cast<std::uint32_t>(s.faults) & ~static_cast<std::uint32_t>(s.first_fault);
  if (others != 0) r += " [also active: " + daemon::fault_text(static_cast<std::int32_t>(others)) + "]";
  return r;
}

// ---- drives

struct Column {
  const char* header;
  int width;
  bool left_aligned;
};

// The drives' codes off the bus (drives_t.NMT_*, CIA402_*, equal to hal's
// enums: canopen_backend.cpp asserts it) to hal's one table of names.
const hal::canopen::NmtNames& nmt_names(std::int8_t n) {
  return hal::canopen::names(static_cast<hal::canopen::NmtState>(static_cast<std::uint8_t>(n)));
}
const hal::cia402::StateNames& cia402_names(std::int8_t c) {
  return hal::cia402::names(static_cast<hal::cia402::State>(static_cast<std::uint8_t>(c)));
}
// The drives screen: a fault in capitals, to be seen at a glance.
const char* cia402_shown(std::int8_t c, bool long_names) {
  if (c == drives_t::CIA402_FAULT) return "FAULT";
  return long_names ? cia402_names(c).full : cia402_names(c).brief;
}
// 0x6061, modes of operation display: "-" before a mode is set, the number
// of a manufacturer's mode.
std::string op_mode(std::int8_t m) {
  if (m == 0) return "-";
  const hal::cia402::OperationMode* mode = hal::cia402::operation_mode(m);
  return mode ? mode->brief : std::to_string(m);
}

}  // namespace

const char* nmt_name(std::int8_t n) noexcept { return nmt_names(n).key; }

const char* cia402_name(std::int8_t c) noexcept { return cia402_names(c).key; }

const char* bus_state_name(std::int8_t b) noexcept {
  switch (b) {
    case drives_t::BUS_ERROR_ACTIVE: return "error_active";
    case drives_t::BUS_ERROR_WARNING: return "error_warning";
    case drives_t::BUS_ERROR_PASSIVE: return "error_passive";
    case drives_t::BUS_OFF: return "bus_off";
    case drives_t::BUS_NONE: return "none";
    default: return "unknown";
  }
}

const char* homing_phase_name(std::int8_t p) noexcept {
  switch (p) {
    case state_t::HOMING_IDLE: return "idle";
    case state_t::HOMING_SEARCH: return "search";
    case state_t::HOMING_BACK_OFF: return "back_off";
    case state_t::HOMING_LATCH: return "latch";
    case state_t::HOMING_INDEX: return "index";
    case state_t::HOMING_DRIVE: return "drive";
    case state_t::HOMING_FINAL: return "final";
    default: return "unknown";
  }
}

double percentile_us(const loop_stats_t& s, int k, double q) {
  const double target = q * static_cast<double>(s.count[k]);
  double acc = 0;
  for (int b = 0; b < daemon::kBins; ++b) {
    acc += s.histogram[k][b];
    if (acc >= target) return static_cast<double>(daemon::histogram_bin_floor(b + 1 < daemon::kBins ? b + 1 : b)) * 1e-3;
  }
  return s.max_ns[k] * 1e-3;
}

Lines wrap(const std::string& text, int width, const std::string& first, int indent) {
  Lines out;
  std::string cur = first;
  bool empty = true;  // no word on `cur` yet
  const std::string pad(static_cast<std::size_t>(std::max(indent, 0)), ' ');
  std::size_t i = 0;
  while (i < text.size()) {
    while (i < text.size() && text[i] == ' ') ++i;
    if (i >= text.size()) break;
    std::size_t j = text.find(' ', i);
    if (j == std::string::npos) j = text.size();
    std::string word = text.substr(i, j - i);
    i = j;
    const std::size_t need = word.size() + (empty ? 0 : 1);
    if (cur.size() + need <= static_cast<std::size_t>(width)) {
      cur += (empty ? "" : " ") + word;
      empty = false;
      continue;
    }
    if (!empty) {
      out.push_back(cur);
      cur = pad;
      empty = true;
    }
    // A word longer than what is left of a fresh line: cut across lines.
    while (cur.size() + word.size() > static_cast<std::size_t>(width)) {
      const std::size_t room = static_cast<std::size_t>(width) > cur.size() ? width - cur.size() : 1;
      out.push_back(cur + word.substr(0, room));
      word.erase(0, room);
      cur = pad;
    }
    cur += word;
    empty = word.empty();
  }
  out.push_back(cur);
  return out;
}

Lines drive_table(const drives_t* d, int width) {
  // The 80-column set, then what a wider window adds, in this order.
  std::vector<Column> cols = {{"act", 3, true},    {"node", 4, false},    {"NMT", 7, true},   {"CiA 402", 14, true},
                              {"mode", 4, true},   {"homed", 5, true},    {"enabled", 7, true}, {"fault", 5, true},
                              {"hb ms", 5, false}, {"EMCY", 6, true},     {"reg", 4, true},   {"count", 5, false}};
  auto total = [&] {
    int w = -1;
    for (const auto& c : cols) w += c.width + 1;
    return w;
  };
  bool long_names = false;
  if (total() + 15 <= width) {
    long_names = true;
    cols[2].width = 15;
    cols[3].width = 21;
  }
  const Column extra[] = {{"status", 6, true}, {"control", 7, true}, {"master", 6, true}, {"d mm", 10, false},
                          {"force N", 8, false}};
  for (const auto& c : extra)
    if (total() + c.width + 1 <= width) cols.push_back(c);
    else break;

  auto line = [&](const std::vector<std::string>& cells) {
    std::string r;
    for (std::size_t k = 0; k < cols.size() && k < cells.size(); ++k) {
      if (k) r += ' ';
      r += cols[k].left_aligned ? left(cells[k], cols[k].width) : right(cells[k], cols[k].width);
    }
    while (!r.empty() && r.back() == ' ') r.pop_back();
    return r;
  };
  Lines out;
  std::vector<std::string> head;
  for (const auto& c : cols) head.push_back(c.header);
  out.push_back(line(head));
  for (int i = 0; i < 3; ++i) {
    if (!d) {
      out.push_back(daemon::printf_text("%-3d %s", i + 1, "(no drives message)"));
      continue;
    }
    const bool emcy = d->last_emcy_code[i] != 0;
    const int hb = d->heartbeat_age_ms[i];
    std::vector<std::string> cells = {
        std::to_string(i + 1),
        d->node_id[i] == 0 ? std::string("sim") : std::to_string(d->node_id[i]),
        long_names ? nmt_names(d->nmt_state[i]).full : nmt_names(d->nmt_state[i]).brief,
        cia402_shown(d->cia402_state[i], long_names),
        op_mode(d->mode_display[i]),
        d->homed[i] ? "yes" : "no",
        d->enabled[i] ? "yes" : "no",
        d->fault[i] ? "FAULT" : "no",
        hb < 0 ? std::string("-") : hb > 99999 ? std::string(">99k") : std::to_string(hb),
        emcy ? daemon::printf_text("0x%04X", static_cast<unsigned>(d->last_emcy_code[i]) & 0xFFFFu) : std::string("-"),
        emcy ? daemon::printf_text("0x%02X", static_cast<unsigned>(d->last_emcy_register[i]) & 0xFFu) : std::string("-"),
        count(d->emcy_count[i]),
        daemon::printf_text("0x%04X", static_cast<unsigned>(d->statusword[i]) & 0xFFFFu),
        daemon::printf_text("0x%04X", static_cast<unsigned>(d->controlword[i]) & 0xFFFFu),
        d->master_faults[i] > 0xFFFF ? daemon::printf_text("%X", static_cast<unsigned>(d->master_faults[i]))
                                     : daemon::printf_text("0x%04X", static_cast<unsigned>(d->master_faults[i])),
        fixed(d->position[i] * 1e3, 10, 3),
        fixed(d->force[i], 8, 1)};
    out.push_back(line(cells));
  }
  return out;
}

Lines bus_lines(const drives_t* d, int width) {
  if (!d) return {"bus  (no drives message)", ""};
  std::string state = bus_state_name(d->bus_state);
  std::replace(state.begin(), state.end(), '_', '-');
  const std::string s = left(state, 13);
  const std::string load = daemon::printf_text("%3.0f%%", 100 * d->bus_load);
  auto ec = [](std::int32_t v) { return v < 0 ? std::string("-") : std::to_string(v); };
  const std::string frames = left(count(static_cast<double>(d->error_frames)), 6);
  const std::string tec = left(ec(d->tx_error_counter), 3), rec = left(ec(d->rx_error_counter), 3);
  const std::string drop = left(count(static_cast<double>(d->rx_dropped)), 6);
  const std::string fail = left(count(static_cast<double>(d->tx_failures)), 6);
  const std::string one = "bus  " + s + "  error frames " + frames + "  TEC " + tec + "  REC " + rec + "  rx dropped " +
                          drop + "  tx failures " + fail + "  load " + load;
  Lines out;
  if (static_cast<int>(one.size()) <= width)
    out = {one};
  else
    out = {"bus  " + s + "  load " + load + "  error frames " + frames + "  TEC " + tec + "  REC " + rec,
           "     rx dropped " + drop + "  tx failures " + fail};
  for (auto& l : out)
    while (!l.empty() && l.back() == ' ') l.pop_back();
  return out;
}

Lines input_lines(const drives_t* d, int /*width*/, bool per_input) {
  if (!d)
    return per_input ? Lines{left("e-stop", 13) + "(no drives message)", left("limit low", 13) + "-",
                             left("limit high", 13) + "-", left("home switch", 13) + "-"}
                     : Lines{"inputs  (no drives message)"};
  auto list = [](const std::int8_t* v) {
    std::string r;
    for (int i = 0; i < 3; ++i) r += (i ? " " : "") + (v[i] ? std::to_string(i + 1) : std::string("-"));
    return r;
  };
  auto each = [](const std::int8_t* v) {
    std::string r;
    for (int i = 0; i < 3; ++i) r += daemon::printf_text("%sact %d %s", i ? "   " : "", i + 1, v[i] ? "ON " : "off");
    return r;
  };
  const char* estop = d->estop ? "PRESSED (chain open)" : "released";
  if (!per_input)
    return {"inputs  e-stop " + std::string(d->estop ? "PRESSED" : "released") + "  limit low " + list(d->limit_low) +
            "  limit high " + list(d->limit_high) + "  home switch " + list(d->home_switch)};
  return {left("e-stop", 13) + estop, left("limit low", 13) + each(d->limit_low),
          left("limit high", 13) + each(d->limit_high), left("home switch", 13) + each(d->home_switch)};
}

Lines render(const std::optional<state_t>& s, const std::optional<loop_stats_t>& st,
             const std::optional<drives_t>& d, int width, int height, const std::string& note, bool keys) {
  // Blocks in display order; weight 0 is always shown, a higher weight gives
  // way first when the window is short (the fault sentence has weight 0).
  struct Block {
    Lines lines;
    int weight;
  };
  std::vector<Block> blocks;
  const drives_t* dp = d ? &*d : nullptr;
  const Lines fault = wrap(s ? fault_sentence(*s) : std::string("-"), width, "fault  ", 7);
  blocks.push_back({{title(s, width)}, 0});                       // 0
  blocks.push_back({table(s, st, width), 1});                     // 1
  blocks.push_back({{}, 0});                                      // 2: table_more
  Lines traj = trajectory(s, width);
  blocks.push_back({{traj[0]}, 4});                               // 3
  blocks.push_back({{traj[1]}, 6});                               // 4
  blocks.push_back({{homing_row(s)}, 5});                         // 5
  blocks.push_back({{jog_row(s)}, 5});                            // 6
  blocks.push_back({{}, 0});                                      // 7: blank before the drives
  blocks.push_back({drive_table(dp, width), 2});                  // 8
  blocks.push_back({bus_lines(dp, width), 3});                    // 9
  blocks.push_back({{}, 0});                                      // 10: inputs
  blocks.push_back({{}, 0});                                      // 11: blank before the fault
  blocks.push_back({fault, 0});                                   // 12
  blocks.push_back({note.empty() ? Lines{} : Lines{"note  " + note}, 7});  // 13
  blocks.push_back({{}, 0});                                      // 14: keys

  auto used = [&] {
    int n = 0;
    for (const auto& b : blocks) n += static_cast<int>(b.lines.size());
    return n;
  };
  // Too short for what must be there: drop the heaviest first.
  while (used() > height) {
    int worst = -1;
    for (int i = 0; i < static_cast<int>(blocks.size()); ++i)
      if (blocks[i].weight > 0 && !blocks[i].lines.empty() && (worst < 0 || blocks[i].weight >= blocks[worst].weight))
        worst = i;
    if (worst < 0) break;
    blocks[worst].lines.clear();
  }
  // Room left: what a taller window shows, in this order.
  auto add = [&](int at, Lines l) {
    if (used() + static_cast<int>(l.size()) > height) return false;
    blocks[at].lines = std::move(l);
    return true;
  };
  if (keys) add(14, {"keys  q quit"});  // a plain block (--once, a pipe) reads no key
  if (!add(10, input_lines(dp, width, true))) add(10, input_lines(dp, width, false));
  add(2, table_more(s, width));
  add(7, {""});
  add(11, {""});

  Lines out;
  for (const auto& b : blocks) out.insert(out.end(), b.lines.begin(), b.lines.end());
  return fit(std::move(out), width, height);
}

// ---- cpm status, stats

std::string not_homed_mark(const state_t& s) {
  std::string which;
  for (int i = 0; i < 3; ++i)
    if (!s.homed[i]) which += " " + std::to_string(i + 1);
  if (which.empty()) return "";
  return "NOT HOMED (actuator" + std::string(which.size() > 2 ? "s" : "") + which +
         "): the position is not referenced to the machine";
}

Lines status_lines(const state_t& s) {
  Lines out;
  out.push_back(daemon::printf_text("controller %s, cycle %lld, overruns %lld, worst wake-up latency %s",
                                    law_text(s.controller), static_cast<long long>(s.cycles),
                                    static_cast<long long>(s.overruns), worst_us_text(s.max_latency_ns, s.cycles > 0).c_str()));
  if (s.last_segment_id >= 0)
    out.push_back(daemon::printf_text("last finished segment: tracking error RMS %.1f um, max %.1f um (%d cycles)",
                                      s.last_segment_rmse * 1e6, s.last_segment_max * 1e6, s.last_segment_cycles));
  return out;
}

// ---- cpm jog

std::string jog_distance_text(const std::array<double, 3>& start, const std::array<double, 3>& sent_end,
                              const std::array<double, 3>& rest, double seconds, bool machine_frame) {
  auto dist = [](const std::array<double, 3>& a, const std::array<double, 3>& b) {
    return std::sqrt((b[0] - a[0]) * (b[0] - a[0]) + (b[1] - a[1]) * (b[1] - a[1]) + (b[2] - a[2]) * (b[2] - a[2]));
  };
  std::string each;
  for (int i = 0; i < 3; ++i)
    each += daemon::printf_text("%s%s %+.3f", i ? ", " : "", machine_frame ? (i == 0 ? "x" : i == 1 ? "y" : "z")
                                                                           : (i == 0 ? "d1" : i == 1 ? "d2" : "d3"),
                                (rest[i] - start[i]) * 1e3);
  return daemon::printf_text("moved %.3f mm (%s mm): %.3f mm in the %.2f s of jog, then %.3f mm while stopping",
                             dist(start, rest) * 1e3, each.c_str(), dist(start, sent_end) * 1e3, seconds,
                             dist(sent_end, rest) * 1e3);
}

JogPad::JogPad() : frame_(control_command_t::JOG_ACTUATOR) {}

void JogPad::set_max_speed(double v) {
  max_speed_ = std::isfinite(v) && v > 0 ? v : 0;
  if (max_speed_ > 0)
    while (step_ > 0 && kSteps[static_cast<std::size_t>(step_)] > max_speed_ * (1 + 1e-9)) --step_;
}

double JogPad::speed() const noexcept {
  const double s = kSteps[static_cast<std::size_t>(step_)];
  return max_speed_ > 0 ? std::min(s, max_speed_) : s;
}

bool JogPad::holding(double now) const noexcept {
  return axis_ >= 0 && now - last_key_ <= (repeating_ ? kRepeat : kFirstRepeat);
}

std::string JogPad::press(Key k, double now) {
  auto let_go = [&] {
    if (axis_ >= 0) stop_pending_ = true;
    axis_ = -1;
  };
  int axis = -1;
  double sign = 0;
  switch (k) {
    case Key::none: return "";
    case Key::quit: let_go(); quit_ = true; return "";
    case Key::stop: axis_ = -1; stop_pending_ = true; return "";
    case Key::faster:
      if (step_ + 1 < static_cast<int>(kSteps.size()) &&
          (max_speed_ <= 0 || kSteps[static_cast<std::size_t>(step_) + 1] <= max_speed_ * (1 + 1e-9))) {
        ++step_;
        return "";
      }
      return max_speed_ > 0 ? "the fastest step within cpmd's jog.max_velocity" : "the fastest step";
    case Key::slower:
      if (step_ > 0) {
        --step_;
        return "";
      }
      return "the slowest step";
    case Key::select1:
    case Key::select2:
    case Key::select3: {
      const int n = k == Key::select1 ? 0 : k == Key::select2 ? 1 : 2;
      if (frame_ != control_command_t::JOG_ACTUATOR || selected_ != n) let_go();
      frame_ = control_command_t::JOG_ACTUATOR;
      selected_ = n;
      return "";
    }
    case Key::cartesian:
      if (frame_ != control_command_t::JOG_MACHINE) let_go();
      frame_ = control_command_t::JOG_MACHINE;
      return "";
    case Key::left: axis = 0, sign = -1; break;
    case Key::right: axis = 0, sign = 1; break;
    case Key::down: axis = 1, sign = -1; break;
    case Key::up: axis = 1, sign = 1; break;
    case Key::page_up: axis = 2, sign = -1; break;   // z is down: page up lifts
    case Key::page_down: axis = 2, sign = 1; break;
  }
  if (frame_ == control_command_t::JOG_ACTUATOR && axis != selected_) {
    static const char* keys[] = {"Left/Right", "Down/Up", "PgUp/PgDn"};
    return daemon::printf_text("actuator %d is selected (%s): press %d to jog actuator %d", selected_ + 1, keys[selected_], axis + 1,
               axis + 1);
  }
  if (axis == axis_ && sign == sign_ && holding(now)) {
    repeating_ = true;  // the terminal's auto-repeat: the key is held
  } else {
    axis_ = axis;
    sign_ = sign;
    repeating_ = false;
  }
  last_key_ = now;
  stop_pending_ = false;
  return "";
}

std::optional<std::array<double, 3>> JogPad::command(double now) {
  if (holding(now)) {
    std::array<double, 3> v{0, 0, 0};
    v[static_cast<std::size_t>(axis_)] = sign_ * speed();
    return v;
  }
  axis_ = -1;  // the repeat stopped: send nothing, cpmd's deadman stops the platform
  if (stop_pending_) {
    stop_pending_ = false;
    return std::array<double, 3>{0, 0, 0};
  }
  return std::nullopt;
}

Lines render_jog(const std::optional<state_t>& s, const JogPad& pad, const std::optional<cpm_msgs::ack_t>& ack,
                 const std::optional<std::array<double, 3>>& sending, const std::string& note, int width, int height) {
  Lines out;
  if (s)
    out.push_back("cpm jog   mode " + left(upper(daemon::mode_text(s->mode)), 8) + "  space " +
                  left(s->control_space == state_t::SPACE_TASK ? "task" : "actuator", 8) + "  " + homed_text(s->homed));
  else
    out.push_back("cpm jog   mode (no state message)");
  const bool machine = pad.frame() == control_command_t::JOG_MACHINE;
  if (machine)
    out.push_back("frame   machine (Cartesian; needs every actuator homed)   1 2 3: an actuator");
  else
    out.push_back(daemon::printf_text("frame   actuator %d  (1 2 3 select an actuator; c: Cartesian, the machine frame)",
                      pad.selected() + 1));
  std::string steps;
  for (double v : JogPad::kSteps)
    if (pad.max_speed() <= 0 || v <= pad.max_speed() * (1 + 1e-9)) steps += daemon::printf_text("%s%g", steps.empty() ? "" : " ", v * 1e3);
  out.push_back(daemon::printf_text("speed   %g mm/s   (+/-: %s mm/s; ", pad.speed() * 1e3, steps.c_str()) +
                (pad.max_speed() > 0 ? daemon::printf_text("jog.max_velocity %g mm/s)", pad.max_speed() * 1e3)
                                     : std::string("jog.max_velocity unknown)")));
  if (machine) {
    out.push_back("keys    Left/Right x-/x+   Down/Up y-/y+   PgUp z- (up)   PgDn z+ (down)");
  } else {
    static const char* keys[] = {"Left/Right: d1- / d1+ (along x)", "Down/Up: d2- / d2+ (along y)",
                                 "PgUp/PgDn: d3- (up) / d3+ (down: z is down)"};
    out.push_back(std::string("keys    ") + keys[pad.selected()]);
  }
  out.push_back("        space stop   q quit   (z is down in the machine frame)");
  out.push_back(table_header(width));
  if (s) {
    out.push_back(table_row("position mm", s->position, 1e3, 3, width));
    out.push_back(table_row("velocity mm/s", s->velocity, 1e3, 1, width));
    out.push_back(table_row("actuator d mm", s->d, 1e3, 3, width));
  } else {
    for (const char* l : {"position mm", "velocity mm/s", "actuator d mm"}) out.push_back(table_row_none(l, width));
  }
  if (sending)
    out.push_back(daemon::printf_text("sending %.1f, %.1f, %.1f mm/s (%s), 20 times a second while the key repeats", (*sending)[0] * 1e3,
                      (*sending)[1] * 1e3, (*sending)[2] * 1e3, machine ? "x, y, z" : "d1, d2, d3"));
  else
    out.push_back("sending nothing (no key held)");
  const bool jogging = s && s->mode == state_t::MODE_JOGGING;
  out.push_back(jogging ? daemon::printf_text("deadman %.3f s left", s->jog_keepalive_left) : std::string("deadman -"));
  if (ack) {
    const Lines a = wrap(ack->accepted ? std::string("accepted") : "REFUSED: " + ack->message, width, "last jog  ", 10);
    out.insert(out.end(), a.begin(), a.end());
  } else {
    out.push_back("last jog  -");
  }
  if (s && (s->faults || s->first_fault)) {
    const Lines f = wrap(fault_sentence(*s), width, "fault  ", 7);
    out.insert(out.end(), f.begin(), f.end());
  }
  if (!note.empty()) {
    const Lines n = wrap(note, width, "note  ", 6);
    out.insert(out.end(), n.begin(), n.end());
  }
  const Lines why = wrap(
      "Terminals send no key-up: cpm sends the jog while the key's auto-repeat keeps coming and stops sending when it "
      "stops; cpmd's deadman (jog.keepalive) then stops the platform within jog.stop_distance.",
      width, "", 0);
  out.insert(out.end(), why.begin(), why.end());
  return fit(std::move(out), width, height);
}

}  // namespace cpm::cli::console

// SPDX-License-Identifier: Apache-2.0
// The operator's console, looking: `cpm watch` (the full-screen view of a
// running cpmd: the loop, the platform, the drives and the bus) and `cpm
// drives` (the drive table once, or its JSON). What they show is
// console.hpp's; the terminal is console_screen.hpp's.
#include <sys/ioctl.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>

#include "cmd_console_common.hpp"
#include "console.hpp"
#include "console_screen.hpp"

namespace cpm::cli::client {
namespace {

using cpm_msgs::state_t;
using Clock = std::chrono::steady_clock;

double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// The terminal's width (TIOCGWINSZ) when stdout is one, else 80.
int output_width() {
  winsize ws{};
  if (::isatty(STDOUT_FILENO) && ::ioctl(STDOUT_FILENO, TIOCGWINSZ, &ws) == 0 && ws.ws_col > 0) return ws.ws_col;
  return 80;
}

// "no state from cpmd for 3.2 s" once the state stops changing.
class Freshness {
 public:
  std::string note(const std::optional<state_t>& s) {
    if (!s) return since(start_) > 2.0 ? "no state from cpmd (is it running? LCM " + url_ + ")" : "";
    if (s->cycle != cycle_) {
      cycle_ = s->cycle;
      changed_ = Clock::now();
    }
    const double age = since(changed_);
    char b[96];
    std::snprintf(b, sizeof b, "no state from cpmd for %.0f s (is it running?)", age);
    return age > 1.0 ? b : "";
  }
  explicit Freshness(std::string url) : url_(std::move(url)) {}

 private:
  std::string url_;
  Clock::time_point start_ = Clock::now(), changed_ = Clock::now();
  std::int64_t cycle_ = -1;
};

struct WatchOptions {
  double duration = -1;
  bool once = false;
  Connection connection;
};

// Not a terminal (a pipe, a log) or --once: one plain block a second.
int watch_plain(daemon::Client& c, const WatchOptions& o, const std::string& url) {
  console::catch_interrupts();
  Freshness fresh(url);
  const auto start = Clock::now();
  for (bool first = true; !console::interrupted(); first = false) {
    // The first block waits for the state, the statistics (1 Hz) and the
    // drives (10 Hz), or 1.5 s; the next ones come a second apart.
    const auto t0 = Clock::now();
    while (!console::interrupted() && since(t0) < (first ? 1.5 : 1.0)) {
      c.handle(0.05);
      if (first && c.latest_state() && c.latest_stats() && c.latest_drives()) break;
    }
    if (o.once) received(c.latest_state(), "state", 1.5, c.config(), c.config().state_channel);
    for (const auto& l : console::render(c.latest_state(), c.latest_stats(), c.latest_drives(), 80, 100,
                                         fresh.note(c.latest_state()), /*keys=*/false))
      std::printf("%s\n", l.c_str());
    if (o.once) break;
    std::printf("\n");
    std::fflush(stdout);
    if (o.duration >= 0 && since(start) >= o.duration) break;
  }
  return 0;
}

int watch(const WatchOptions& o) {
  const auto l = lcm_options(o.connection);
  daemon::Client c(l);
  auto screen = o.once ? nullptr : console::Screen::open();
  if (!screen) return watch_plain(c, o, l.url);
  Freshness fresh(l.url);
  // Refusals of forged or unverifiable messages go into the note, not over the screen.
  c.on_refused([](daemon::Trust, const char*) {});
  const auto start = Clock::now();
  while (!console::interrupted()) {
    if (o.duration >= 0 && since(start) > o.duration) break;
    c.handle(0.1);  // ~10 redraws a second; the messages in between are taken as they come
    std::string note = fresh.note(c.latest_state());
    if (const std::string t = c.trust_note(); !t.empty()) note += (note.empty() ? "" : "; ") + t;
    screen->draw(console::render(c.latest_state(), c.latest_stats(), c.latest_drives(), screen->width(),
                                 screen->height(), note));
    bool quit = false;
    for (int k; (k = screen->key(0)) >= 0;) quit = quit || console::Screen::is_quit(k);
    if (quit) break;
  }
  return 0;
}

struct DrivesOptions {
  bool json = false;
  Connection connection;
};

int drives(const DrivesOptions& o) {
  const auto l = lcm_options(o.connection);
  daemon::Client c(l);
  const auto d = received(c.drives(2.0), "drives message", 2.0, l, l.drives_channel);
  if (o.json) {
    std::printf("%s\n", json_text(console::drives_json(d), -1).c_str());
    return 0;
  }
  const int w = output_width();
  for (const auto& part : {console::drive_table(&d, w), console::bus_lines(&d, w), console::input_lines(&d, w, false)})
    for (const auto& line : part)
      if (!line.empty()) std::printf("%s\n", line.c_str());
  return 0;
}

const Command r1{"watch",
                 "full-screen view of a running cpmd: mode, platform, forces, trajectory, homing, jog, loop timing, "
                 "drives, bus, fault (q quits)",
                 [](CLI::App& app) -> Run {
                   auto o = std::make_shared<WatchOptions>();
                   add_number(app, "--duration", o->duration, "S", "stop after S seconds; < 0: until q or Ctrl-C");
                   app.add_flag("--once", o->once,
                                "print one plain block and exit (as when stdout is no terminal, which gets one a "
                                "second)");
                   add_connection(app, o->connection);
                   return [o] { return watch(*o); };
                 }};
const Command r2{"drives", "print the drives (NMT and CiA 402 states, faults, EMCY) and the CAN bus of a running cpmd",
                 [](CLI::App& app) -> Run {
                   auto o = std::make_shared<DrivesOptions>();
                   app.add_flag("--json", o->json, "one line of JSON: every drives_t field by name (SI units)");
                   add_connection(app, o->connection);
                   return [o] { return drives(*o); };
                 }};

}  // namespace
}  // namespace cpm::cli::client

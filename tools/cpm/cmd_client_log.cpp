// SPDX-License-Identifier: Apache-2.0
// Client subcommands that record the state stream: record (state -> motion
// CSV of docs/data-formats.md), lcm-log-to-csv (the same from an lcm-logger
// file). The live view, cpm watch, is the console's (cmd_console.cpp).
#include <signal.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <lcm/lcm-cpp.hpp>
#include <sstream>
#include <vector>

#include "cmd_client_common.hpp"
#include "state_log.hpp"

namespace cpm::cli::client {
namespace {

using cpm_msgs::state_t;

std::atomic<bool> g_interrupted{false};
void on_sigint(int) { g_interrupted.store(true); }

struct Options {
  double duration = -1;
  bool until_idle = false;
  Connection connection;
  std::string out, channel = "CPMD_STATE", log;
};

int record(const Options& o) {
  const std::string& out = o.out;
  const double duration = o.duration;
  const bool until_idle = o.until_idle;
  const auto l = lcm_options(o.connection);
  if (duration < 0 && !until_idle) throw UsageError("give --duration S or --until-idle");
  daemon::Client c(l);
  StateToMotion rows;
  // Counted against the loop's cycle counter (state_t.cycles), not the slot
  // index (state_t.cycle): a late cycle skips slots that never ran, which are
  // no lost message.
  std::int64_t first = -1, first_run = -1, last_run = -1, skipped0 = 0, skipped = 0;
  bool moved = false, idle = false;
  c.on_state([&](const state_t& s) {
    if (first < 0) first = s.cycle, first_run = s.cycles, skipped0 = s.skipped;
    last_run = s.cycles;
    skipped = s.skipped - skipped0;
    rows.add(s);
    if (s.mode == state_t::MODE_MOVING || s.mode == state_t::MODE_STOPPING) moved = true;
    if (moved && s.mode != state_t::MODE_MOVING && s.mode != state_t::MODE_STOPPING) idle = true;
  });
  signal(SIGINT, on_sigint);
  const auto start = std::chrono::steady_clock::now();
  while (!g_interrupted.load() && !(until_idle && idle)) {
    if (duration >= 0 && std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >= duration) break;
    c.handle(0.05);
  }
  if (first < 0) throw Error("no state received from cpmd (channel " + l.state_channel + ")");
  if (rows.rows() == 0)
    throw Error("no state of cpmd with the drives applying force (" + std::to_string(rows.inactive()) +
                " states with the drives off or faulted): enable the machine and move it");
  const long expected = static_cast<long>(last_run - first_run + 1);
  char note[240];
  std::snprintf(note, sizeof note, "cpm record from %s: %zu states of %ld cycles run (%lld slots skipped by late cycles)",
                l.state_channel.c_str(), rows.rows() + static_cast<std::size_t>(rows.inactive()), expected,
                static_cast<long long>(skipped));
  const io::MotionData m = rows.finish(out, note);
  io::write_motion(out, m);
  std::printf("record: %zu rows over %.3f s to %s (%ld cycles run, %ld missing; %lld slots skipped by late cycles; "
              "%ld states with the drives off left out)\n",
              m.t.size(), m.t.back() - m.t.front(), out.c_str(), expected,
              expected - static_cast<long>(rows.rows()) - rows.inactive(), static_cast<long long>(skipped), rows.inactive());
  return 0;
}

int log_to_csv(const Options& o) {
  const std::string& out = o.out;
  const std::string& channel = o.channel;
  const StateLogRead r = read_state_log(o.log, channel, false);
  io::MotionData m = r.data;
  m.info.path = out;
  m.info.metadata["source"] = "cpm lcm-log-to-csv from " + o.log + ", channel " + channel;
  io::write_motion(out, m);
  std::printf("lcm-log-to-csv: %zu rows to %s", m.t.size(), out.c_str());
  if (r.undecodable) std::printf(" (%ld undecodable or non-finite events skipped)", r.undecodable);
  if (r.inactive) std::printf(" (%ld states with the drives off left out)", r.inactive);
  std::printf("\n");
  return 0;
}

const Command r2{"record", "record cpmd's state to a motion CSV (data-formats.md, kind = motion)", [](CLI::App& app) -> Run {
                   auto o = std::make_shared<Options>();
                   app.add_option("--out", o->out, "the motion log to write")->type_name("FILE.csv")->required();
                   add_number(app, "--duration", o->duration, "S", "record S seconds (or give --until-idle)");
                   app.add_flag("--until-idle", o->until_idle, "record until the machine has moved and stopped");
                   add_connection(app, o->connection);
                   return [o] { return record(*o); };
                 }};
const Command r3{"lcm-log-to-csv", "convert an lcm-logger file of cpmd's state channel to a motion CSV",
                 [](CLI::App& app) -> Run {
                   auto o = std::make_shared<Options>();
                   app.add_option("LOGFILE", o->log, "the lcm-logger file")->type_name("LOGFILE")->required();
                   app.add_option("--out", o->out, "the motion log to write")->type_name("FILE.csv")->required();
                   app.add_option("--channel", o->channel, "the channel of cpmd's state")->type_name("CHANNEL");
                   return [o] { return log_to_csv(*o); };
                 }};

}  // namespace
}  // namespace cpm::cli::client

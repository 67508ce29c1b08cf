// SPDX-License-Identifier: Apache-2.0
// cpmd: the motion controller daemon. See docs/daemon.md and docs/security.md.
//   cpmd --config FILE [--check] [--duration S] [--stats-json FILE] [--loop-cpu N] [--operators DIR] [--version]
#include <fcntl.h>
#include <sched.h>
#include <malloc.h>
#include <signal.h>
#include <unistd.h>
#include <time.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <thread>

#include "cpm/daemon/canopen_backend.hpp"
#include "cpm/daemon/log.hpp"
#include "cpm/daemon/preflight.hpp"
#include "cpm/daemon/rt.hpp"
#include "cpm/daemon/server.hpp"
#include "cpm/daemon/sim_backend.hpp"
#include "cpm/daemon/stats_json.hpp"
#include "cpm/daemon/text.hpp"
#include "cpm/program_cli.hpp"

namespace {

using namespace cpm;
using namespace cpm::daemon;

// Temporary file, fsync, rename: a crash leaves the old file or the new one
// (cpmd does not link cpm_io's write_file_atomically).
void write_atomically(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  bool ok = fd >= 0;
  for (std::size_t off = 0; ok && off < text.size();) {
    const ssize_t n = ::write(fd, text.data() + off, text.size() - off);
    if (n < 0 && errno == EINTR) continue;
    ok = n > 0;
    if (ok) off += static_cast<std::size_t>(n);
  }
  ok = ok && ::fsync(fd) == 0;
  if (fd >= 0) ::close(fd);
  if (ok && std::rename(tmp.c_str(), path.c_str()) == 0) return;
  ::unlink(tmp.c_str());
  log::error("cannot write %s: %s", path.c_str(), std::strerror(errno));
}

// With the loop pinned, every other thread of cpmd (this one and all it
// starts: LCM's receive thread, the server, the housekeeping) stays off the
// loop's CPU, so a flood of datagrams is received and refused elsewhere.
// The loop's thread pins itself to its CPU (RtThread).
void keep_off_the_loops_cpu(int loop_cpu) {
  if (loop_cpu < 0) return;
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof set, &set) != 0 || !CPU_ISSET(loop_cpu, &set) || CPU_COUNT(&set) < 2) return;
  CPU_CLR(loop_cpu, &set);
  if (sched_setaffinity(0, sizeof set, &set) != 0)
    log::warning("cannot keep the other threads off CPU %d: %s", loop_cpu, std::strerror(errno));
}

// The command line (CLI11): the exit status when cpmd is to stop at once
// (--help, --version, a bad command line), else -1. The same text is the man
// page cpmd(8) (help2man at build time, tools/man/).
struct Options {
  std::string config_path, stats_path;
  double duration = -1;
  std::optional<int> loop_cpu;
  std::optional<std::string> operators_dir;
  bool check = false;
};

int parse(int argc, char** argv, Options& o) {
  CLI::App app{"cpmd: the real-time motion controller daemon of a 3-PRRR Cartesian parallel manipulator. It runs\n"
               "the control loop (a simulated plant or CiA 402 drives over CANopen), and takes trajectories and\n"
               "commands from its operators over LCM (cpm is the client).",
               "cpmd"};
  program::setup(app);
  app.add_option("--config", o.config_path, "the daemon's YAML configuration (cpmd.yaml(5); e.g. /etc/cpmd/cpmd.yaml)")
      ->type_name("FILE")
      ->required();
  app.add_flag("--check,--check-config", o.check,
               "validate the configuration and its model files, say how many operators may command, and exit");
  app.add_option("--duration", o.duration, "run S seconds, then shut down (latency runs); < 0: until SIGTERM")
      ->type_name("S")
      ->check(program::finite());
  app.add_option("--stats-json", o.stats_path,
                 "at exit, write the loop statistics as JSON to FILE (times in ns, and the wake-up latency in 1 us "
                 "bins as histogram_1us)")
      ->type_name("FILE");
  const long cpus = ::sysconf(_SC_NPROCESSORS_CONF);
  app.add_option("--loop-cpu", o.loop_cpu, "pin the real-time loop to CPU N for this run, instead of loop.cpu (-1: any)")
      ->type_name("N")
      ->check(CLI::Range(-1L, cpus > 0 ? cpus - 1 : 1023L).description(""));
  app.add_option("--operators", o.operators_dir,
                 "the operators' keys and roles (docs/security.md), instead of security.operators_dir; re-read on "
                 "SIGHUP and when it changes")
      ->type_name("DIR");
  app.footer("Signals: SIGTERM and SIGINT disable the drives and stop; SIGHUP re-reads the operators' keys.\n"
             "Exit status: 0 stopped as asked, 1 an error (bad configuration, backend failure), 2 a bad command line.");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return program::parse_exit(app, e, "cpmd");
  }
  return -1;
}

// The configuration file with the command line's overrides.
DaemonConfig load_daemon_config(const Options& o) {
  DaemonConfig c = load_config(o.config_path);
  if (o.loop_cpu) c.loop.cpu = *o.loop_cpu;
  if (o.operators_dir) c.security.operators_dir = *o.operators_dir;
  return c;
}

// The model the loop starts with, its force limit within the configured one.
std::unique_ptr<ModelStore> load_models(const DaemonConfig& cfg) {
  ctl::MachineModel model = load_model(cfg.model_file);
  model.force_limit = std::min(model.force_limit, cfg.limits.force);
  return std::make_unique<ModelStore>(std::make_unique<ctl::Machine>(model));
}

std::unique_ptr<Backend> make_backend(const DaemonConfig& cfg) {
  if (cfg.backend == "sim")
    return std::make_unique<SimBackend>(std::make_unique<ctl::Machine>(load_model(cfg.sim.truth_model_file)),
                                        sim_backend_options(cfg.sim));
  log::info("CAN %s: %s", cfg.canopen.interface.c_str(), cfg.canopen.load.describe().c_str());
  return std::make_unique<CanopenBackend>(cfg.canopen);
}

// --check: the configuration, model and backend passed; say who may command.
int report_check(const DaemonConfig& cfg, const std::string& config_path) {
  try {
    const auto t = load_operators(cfg.security.operators_dir);
    for (const auto& p : t->problems) std::printf("warning: operators: %s\n", p.c_str());
    std::printf("%s: %s\n", cfg.security.operators_dir.c_str(), t->who_may_command().c_str());
  } catch (const Error& e) {
    std::printf("warning: operators: %s: nobody could command this cpmd but stop\n", e.what());
  }
  if (cfg.security.signing_key.empty()) {
    std::printf("warning: security.signing_key is not set: clients cannot verify what cpmd publishes\n");
  } else {
    try {
      (void)read_key_file(cfg.security.signing_key);  // a missing or loose key: the file and why
    } catch (const Error& e) {
      // cpmd would not start: fail. The owner rule is the reader's, so say whose check this was.
      throw Error(std::string(e.what()) + " (cpmd would not start; check as the user the unit runs cpmd as: " +
                  "runuser -u cpmd -- cpmd --config " + config_path + " --check)");
    }
    std::printf("%s: cpmd seals what it publishes with this key\n", cfg.security.signing_key.c_str());
  }
  std::printf("%s: configuration and model files are valid\n", config_path.c_str());
  return 0;
}

// One daemon per bus: a second would take the same commands and publish a
// second state (docs/security.md). Heard before anything is powered.
void refuse_a_second_daemon(const DaemonConfig& cfg) {
  if (bus_has_another_daemon(cfg.lcm, cfg.loop.rate_hz))
    throw Error("another cpmd is already publishing on " + cfg.lcm.state_channel + " at " + cfg.lcm.url +
                ": two daemons on one bus would both take the same commands; stop the other one, or give this one "
                "its own LCM URL or channels");
}

// Block the termination signals in every thread (those started after this
// inherit the mask); the main thread waits for them. SIGHUP: re-read the
// operators directory.
sigset_t block_signals() {
  sigset_t sigs;
  sigemptyset(&sigs);
  sigaddset(&sigs, SIGINT);
  sigaddset(&sigs, SIGTERM);
  sigaddset(&sigs, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &sigs, nullptr);
  return sigs;
}

// Keys and roles: loaded at start and on every change, outside the loop and
// outside the LCM thread, and handed to the server whole.
class OperatorsReload {
 public:
  OperatorsReload(const DaemonConfig& cfg, Server& server)
      : cfg_(cfg), server_(server), watch_(cfg.security.operators_dir) {}
  void operator()(const char* why) {
    try {
      const auto t = load_operators(cfg_.security.operators_dir);
      for (const auto& p : t->problems) log::warning("operators: %s", p.c_str());
      server_.set_operators(t);
      log::info("operators: %s (%s, %s)", t->who_may_command().c_str(), cfg_.security.operators_dir.c_str(), why);
    } catch (const Error& e) {
      server_.note_reload_failure();
      log::warning("operators: %s; %s", e.what(),
                   server_.operators() ? "the operators loaded before stay"
                                       : "nobody can command this cpmd but stop (docs/security.md)");
    }
    watch_.rearm();
  }
  [[nodiscard]] bool changed() { return watch_.changed(); }

 private:
  const DaemonConfig& cfg_;
  Server& server_;
  OperatorsWatch watch_;
};

// The main thread while the loop runs: systemd's READY once it runs, the
// watchdog fed only while it advances, the mode as STATUS, the operators
// re-read on SIGHUP or a change; returns on SIGINT, SIGTERM or after
// `duration` s (< 0: never).
void housekeep(const sigset_t& sigs, const ControlLoop& loop, const RtThread& rt, OperatorsReload& reload,
               double duration) {
  sd_notify("READY=1\nSTATUS=running");
  const double wd = sd_watchdog_interval();
  const double tick = wd > 0 ? std::min(0.25, wd / 4) : 0.25;
  const auto started = std::chrono::steady_clock::now();
  std::int64_t last_cycles = -1;
  Mode last_mode = Mode::init;
  for (;;) {
    timespec ts{};
    ts.tv_sec = static_cast<time_t>(tick);
    ts.tv_nsec = static_cast<long>((tick - static_cast<double>(ts.tv_sec)) * 1e9);
    const int sig = sigtimedwait(&sigs, nullptr, &ts);
    if (sig == SIGINT || sig == SIGTERM) {
      log::notice("%s: disabling the drives and stopping", strsignal(sig));
      return;
    }
    if (sig == SIGHUP) reload("SIGHUP");
    else if (reload.changed()) reload("the directory changed");
    const std::int64_t cycles = loop.cycles_done();
    if (cycles != last_cycles && rt.running()) sd_notify("WATCHDOG=1");
    last_cycles = cycles;
    if (loop.mode() != last_mode) {
      last_mode = loop.mode();
      sd_notify(std::string("STATUS=") + mode_name(last_mode));
    }
    if (duration >= 0 && std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count() >= duration)
      return;
  }
}

// The loop disables the drives (a few cycles), then the loop's thread ends.
void stop_the_loop(ControlLoop& loop, RtThread& rt) {
  loop.request_shutdown();
  const std::int64_t c0 = loop.cycles_done();
  while (rt.running() && loop.cycles_done() < c0 + 5) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  rt.request_stop();
  rt.join();
}

void report_statistics(const ControlLoop& loop, const std::string& stats_path) {
  const cpm_msgs::loop_stats_t& st = loop.current_stats();
  if (!stats_path.empty()) write_atomically(stats_path, stats_json(st, loop.fine_latency_histogram()));
  log::info("stopped after %lld cycles, %lld overruns, worst wake-up latency %s", static_cast<long long>(st.cycles),
            static_cast<long long>(st.overruns), worst_us_text(st.max_ns[kSeriesLatency], st.cycles > 0).c_str());
}

// cpmd's life, step by step: the configuration, the model and the backend,
// checked together; then the loop, the server (LCM) and their threads; the
// housekeeping until a signal; the shutdown in the reverse order.
int run(int argc, char** argv) {
  Options o;
  if (const int rc = parse(argc, argv, o); rc >= 0) return rc;
  const DaemonConfig cfg = load_daemon_config(o);
  keep_off_the_loops_cpu(cfg.loop.cpu);  // before any thread exists: they inherit it
  const std::unique_ptr<ModelStore> models = load_models(cfg);
  const ctl::Controller controller(models->current(), cfg.controller.law, cfg.controller.gains);
  const std::unique_ptr<Backend> backend = make_backend(cfg);
  // The configuration, the model and the backend fit together (gains, homing).
  preflight(cfg, models->current(), *backend);
  if (o.check) return report_check(cfg, o.config_path);
  refuse_a_second_daemon(cfg);
  backend->start(1.0 / cfg.loop.rate_hz);
  const sigset_t sigs = block_signals();

  auto loop = std::make_unique<ControlLoop>(cfg, *backend, models->current(), controller);
  Server server(cfg, *loop, *models);  // LCM up before the loop runs
  OperatorsReload reload(cfg, server);
  reload("at start");
  RtThread rt(*loop, cfg.loop);
  rt.start();
  for (const auto& w : rt.setup().warnings) log::warning("%s", w.c_str());
  log::info("%s backend, %.0f Hz, %s, model %s, LCM %s", backend->name(), cfg.loop.rate_hz,
            rt.setup().realtime ? "SCHED_FIFO" : "normal scheduling", cfg.model_file.c_str(), cfg.lcm.url.c_str());
  std::atomic<bool> stop_server{false};
  std::thread lcm_thread([&] {
    try {
      server.run(stop_server);
    } catch (const std::exception& e) {
      log::error("LCM thread: %s", e.what());
    }
  });

  housekeep(sigs, *loop, rt, reload, o.duration);

  sd_notify("STOPPING=1");
  stop_the_loop(*loop, rt);
  stop_server.store(true);
  lcm_thread.join();
  backend->stop();
  report_statistics(*loop, o.stats_path);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  // Big blocks (a stranger's oversized LCM message, reassembled by LCM's
  // thread) are mapped and unmapped on their own, never kept in the heap:
  // glibc would otherwise raise this threshold after the first one and keep
  // every later one resident (docs/security.md). The loop allocates nothing.
  mallopt(M_MMAP_THRESHOLD, 256 * 1024);
  // One malloc arena for every thread: glibc reserves 64 MiB of address
  // space for each thread's own arena, and with mlockall(MCL_FUTURE) all of
  // it counts as locked (VmLck rose 72 MiB at the first model load, its
  // loader's arena and stack). The loop allocates nothing, so the one
  // arena's lock is never taken by it.
  mallopt(M_ARENA_MAX, 1);
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    cpm::daemon::log::error("%s", e.what());
    return 1;
  }
}

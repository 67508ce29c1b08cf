// SPDX-License-Identifier: Apache-2.0
// virtual-drives: three CiA 402 drives on a SocketCAN interface, stepping
// the true machine's plant by one control period per SYNC. See
// docs/canopen-backend.md.
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "cpm/hal/socketcan.hpp"
#include "cpm/io/model_file.hpp"
#include "cpm/sim/control_socket.hpp"
#include "cpm/sim/drive_command_line.hpp"
#include "cpm/sim/virtual_drives_control.hpp"

namespace {

using namespace cpm;

volatile sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

int run(int argc, char** argv) {
  sim::DriveCommandLine d;
  std::string ready_file, timing = sim::timing_name(d.cfg.timing);
  bool use_stdin = false;
  std::vector<double> initial;
  std::vector<std::string> faults;
  CLI::App app{"virtual-drives: three CiA 402 drives on a SocketCAN interface, stepping the true machine's plant by\n"
               "one control period per SYNC (docs/canopen-backend.md).",
               "virtual-drives"};
  program::setup(app);
  sim::add_drive_options(app, d);
  app.add_option("--initial", initial, "platform centre at power-on in m")
      ->type_name("X,Y,Z")
      ->delimiter(',')
      ->expected(3)
      ->check(program::finite())
      ->default_str("0.600,0.425,0.300");
  app.add_option("--substeps", d.cfg.plant.substeps, "RK4 steps of the plant per period")->type_name("N");
  // Homing (docs/sil.md): what the drives' own inputs see, and how the encoders count.
  app.add_flag("--incremental", d.cfg.incremental,
               "incremental encoders: each drive counts from 0 where its carriage stands at power-on (and at each "
               "reappear), so the daemon must home before it knows where the platform is");
  std::vector<double> home_switch;
  app.add_option("--home-switch", home_switch,
                 "home switches: actuator i's is actuated while its displacement d_i is below D_i, in m (a value "
                 "at or below the stroke's low end: no switch)")
      ->type_name("D1,D2,D3")
      ->delimiter(',')
      ->expected(3)
      ->check(program::finite())
      ->default_str("0.010,0.010,0.010");
  app.add_option("--limit-margin", d.cfg.limit_margin,
                 "limit switches wired to the drives, actuated within M m of each stroke end (0: none)")
      ->type_name("M")
      ->check(program::finite() & CLI::Range(0.0, 0.1).description(""))
      ->default_str(CLI::detail::to_string(d.cfg.limit_margin));
  app.add_option("--index-pitch", d.cfg.index_pitch,
                 "an encoder index pulse at every whole multiple of P m of d (e.g. a screw's lead; 0: none)")
      ->type_name("P")
      ->check(program::finite() & CLI::Range(0.0, 1.0).description(""))
      ->default_str("0");
  app.add_option("--timing", timing,
                 "synchronous: a torque received before SYNC k acts from SYNC k, after the positions of SYNC k were "
                 "sampled (CiA 402 CST: one period of dead time); lockstep: it acts at once, as the in-process loop")
      ->check(CLI::IsMember({"synchronous", "lockstep"}).description(""))
      ->type_name("synchronous|lockstep");
  app.add_flag("--stdin", use_stdin, "read fault-injection commands from the standard input too");
  app.add_option("--fault", faults, "run the command CMD when the SYNC counter reaches SYNC (repeatable)")
      ->type_name("SYNC:CMD")
      ->allow_extra_args(false);
  app.add_option("--ready-file", ready_file, "written (with the process id) once the drives have powered on")
      ->type_name("PATH");
  app.footer("Commands: heartbeat AXIS off|on, emcy AXIS CODE [REG], fault AXIS CODE [persistent], clear AXIS,\n"
             "refuse AXIS CMD on|off, late AXIS MS, silent AXIS on|off, home-switch AXIS dead|ok, disappear,\n"
             "reappear, status, quit (docs/canopen-backend.md).\n"
             "Homing: the drives run CiA 402 homing mode (methods 1-6, 17-22, 33, 34, 35, 37) on these home\n"
             "switches, limit switches and index pulses (docs/sil.md).");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return program::parse_exit(app, e, "virtual-drives");
  }
  if (initial.size() == 3) d.cfg.initial_position = Vec3(initial[0], initial[1], initial[2]);
  if (home_switch.size() == 3) d.cfg.home_switch = Vec3(home_switch[0], home_switch[1], home_switch[2]);
  d.cfg.timing = *sim::timing_from_name(timing);
  std::multimap<std::uint64_t, std::string> scheduled;
  for (const std::string& f : faults) {
    const auto colon = f.find(':');
    std::uint64_t sync = 0;
    if (colon == std::string::npos || !CLI::detail::lexical_cast(f.substr(0, colon), sync))
      throw Error("--fault: expected SYNC:COMMAND, got '" + f + "'");
    scheduled.emplace(sync, f.substr(colon + 1));
  }
  const sim::VirtualMachineConfig cfg = d.config();
  const ctl::Machine truth(d.true_machine());
  hal::SocketCanBus bus(d.interface);
  bus.set_filters({}, false);
  hal::SteadyClock clock;
  sim::VirtualMachine vm(bus, truth, cfg);

  std::unique_ptr<sim::ControlSocket> control_socket;
  if (!d.control.empty()) control_socket = std::make_unique<sim::ControlSocket>(d.control);
  if (use_stdin) fcntl(0, F_SETFL, fcntl(0, F_GETFL) | O_NONBLOCK);
  signal(SIGINT, on_signal);
  signal(SIGTERM, on_signal);
  signal(SIGPIPE, SIG_IGN);

  vm.power_on(clock.now_ns());
  if (!ready_file.empty()) std::ofstream(ready_file) << getpid() << "\n";
  std::fprintf(stderr, "virtual-drives: nodes %d %d %d on %s, %.0f Hz per SYNC, %s timing, model %s, %s encoders\n",
               cfg.axes[0].node_id, cfg.axes[1].node_id, cfg.axes[2].node_id, d.interface.c_str(), d.rate,
               sim::timing_name(cfg.timing), d.model.c_str(), cfg.incremental ? "incremental" : "absolute");

  std::string stdin_buf;
  bool quit = false;
  auto execute = [&](const std::string& line) {
    const std::string reply = sim::execute_control(vm, line, clock.now_ns(), quit);
    std::fprintf(stderr, "virtual-drives: [sync %llu] %s -> %s\n", static_cast<unsigned long long>(vm.syncs()),
                 line.c_str(), reply.c_str());
    return reply;
  };

  hal::CanFrame f;
  while (!g_stop && !quit) {
    bus.wait_receivable(2'000'000);
    const std::int64_t now = clock.now_ns();
    for (int n = 0; n < 4096 && bus.receive(f).ok(); ++n) {
      const std::uint64_t before = vm.syncs();
      vm.on_frame(f, now);
      // Scheduled faults at exact SYNC counts: deterministic whatever the host's speed.
      if (vm.syncs() != before)
        for (auto it = scheduled.begin(); it != scheduled.end() && it->first <= vm.syncs();) {
          execute(it->second);
          it = scheduled.erase(it);
        }
    }
    vm.poll(now);
    if (control_socket) control_socket->poll(execute);
    if (use_stdin && !sim::serve_lines(0, stdin_buf, false, execute)) use_stdin = false;
  }
  control_socket.reset();
  std::fprintf(stderr, "virtual-drives: stopped after %llu SYNCs, %llu plant steps\n",
               static_cast<unsigned long long>(vm.syncs()), static_cast<unsigned long long>(vm.steps()));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "virtual-drives: error: %s\n", e.what());
    return 1;
  }
}

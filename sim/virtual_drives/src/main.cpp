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
#include "cpm/sim/virtual_drives_control.hpp"

namespace {

using namespace cpm;

volatile sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

void usage() {
  std::fprintf(stderr,
               "usage: virtual-drives --interface IF [options]\n"
               "  --interface IF       SocketCAN interface (vcan0)\n"
               "  --model FILE         the true machine (model file; builtin:elkady = docs/model.md) [builtin:elkady]\n"
               "  --rate HZ            control rate: the plant advances 1/HZ s per SYNC [1000]\n"
               "  --initial X,Y,Z      platform centre at power-on (m) [0.600,0.425,0.300]\n"
               "  --nodes A,B,C        node ids of the drives of actuators 1, 2, 3 [1,2,3]\n"
               "  --counts-per-m N     0x6064 counts per metre (velocity in counts/s) [1e7]\n"
               "  --rated-force N      force of 1000 per mille of 0x6071 (N) [40]\n"
               "  --substeps N         RK4 steps per period [10]\n"
               "  --timing T           synchronous: a torque received before SYNC k acts from SYNC k, after\n"
               "                       the positions of SYNC k were sampled (CiA 402 CST: one period of dead\n"
               "                       time); lockstep: it acts at once, as the in-process loop [synchronous]\n"
               "  --control PATH       UNIX stream socket for fault-injection commands\n"
               "  --stdin              read fault-injection commands from stdin too\n"
               "  --fault SYNC:CMD     run CMD when the SYNC counter reaches SYNC (repeatable)\n"
               "  --ready-file PATH    written once the drives have powered on\n"
               "Commands: heartbeat AXIS off|on, emcy AXIS CODE [REG], fault AXIS CODE [persistent],\n"
               "clear AXIS, refuse AXIS CMD on|off, late AXIS MS, silent AXIS on|off, disappear,\n"
               "reappear, status, quit (docs/canopen-backend.md).\n");
}

std::vector<double> numbers(const std::string& s, std::size_t n, const std::string& opt) {
  std::vector<double> v;
  std::stringstream ss(s);
  for (std::string t; std::getline(ss, t, ',');) {
    std::size_t used = 0;
    double x = 0;
    try {
      x = std::stod(t, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != t.size() || t.empty()) throw Error(opt + ": '" + t + "' is not a number");
    v.push_back(x);
  }
  if (v.size() != n) throw Error(opt + ": expected " + std::to_string(n) + " comma-separated numbers, got '" + s + "'");
  return v;
}

int run(int argc, char** argv) {
  std::string interface, model = "builtin:elkady", control, ready_file;
  bool use_stdin = false;
  double rate = 1000;
  sim::VirtualMachineConfig cfg = sim::VirtualMachineConfig::defaults();
  std::multimap<std::uint64_t, std::string> scheduled;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw Error("option " + a + " needs a value");
      return argv[++i];
    };
    if (a == "--interface") interface = value();
    else if (a == "--model") model = value();
    else if (a == "--rate") rate = numbers(value(), 1, a)[0];
    else if (a == "--initial") {
      const auto v = numbers(value(), 3, a);
      cfg.initial_position = Vec3(v[0], v[1], v[2]);
    } else if (a == "--nodes") {
      const auto v = numbers(value(), 3, a);
      for (int k = 0; k < 3; ++k) cfg.axes[static_cast<std::size_t>(k)].node_id = static_cast<int>(v[static_cast<std::size_t>(k)]);
    } else if (a == "--counts-per-m") {
      const double v = numbers(value(), 1, a)[0];
      for (auto& ax : cfg.axes) ax.scaling.counts_per_m = v;
    } else if (a == "--rated-force") {
      const double v = numbers(value(), 1, a)[0];
      for (auto& ax : cfg.axes) ax.scaling.rated_force_n = v;
    } else if (a == "--substeps") cfg.plant.substeps = static_cast<int>(numbers(value(), 1, a)[0]);
    else if (a == "--timing") {
      const std::string t = value();
      const auto timing = sim::timing_from_name(t);
      if (!timing) throw Error("--timing: expected synchronous or lockstep, got '" + t + "'");
      cfg.timing = *timing;
    }
    else if (a == "--control") control = value();
    else if (a == "--stdin") use_stdin = true;
    else if (a == "--ready-file") ready_file = value();
    else if (a == "--fault") {
      const std::string f = value();
      const auto colon = f.find(':');
      if (colon == std::string::npos) throw Error("--fault: expected SYNC:COMMAND, got '" + f + "'");
      scheduled.emplace(static_cast<std::uint64_t>(numbers(f.substr(0, colon), 1, a)[0]), f.substr(colon + 1));
    } else if (a == "--help" || a == "-h") {
      usage();
      return 0;
    } else {
      usage();
      throw Error("unknown option '" + a + "'");
    }
  }
  if (interface.empty()) {
    usage();
    return 2;
  }
  if (!(rate > 0 && rate <= 10000)) throw Error("--rate must be in (0, 10000] Hz");
  cfg.period = 1.0 / rate;

  const ctl::MachineModel mm = model == "builtin:elkady" ? ctl::MachineModel::elkady() : io::load_model_file(model).model;
  const ctl::Machine truth(mm);
  hal::SocketCanBus bus(interface);
  bus.set_filters({}, false);
  hal::SteadyClock clock;
  sim::VirtualMachine vm(bus, truth, cfg);

  std::unique_ptr<sim::ControlSocket> control_socket;
  if (!control.empty()) control_socket = std::make_unique<sim::ControlSocket>(control);
  if (use_stdin) fcntl(0, F_SETFL, fcntl(0, F_GETFL) | O_NONBLOCK);
  signal(SIGINT, on_signal);
  signal(SIGTERM, on_signal);
  signal(SIGPIPE, SIG_IGN);

  vm.power_on(clock.now_ns());
  if (!ready_file.empty()) std::ofstream(ready_file) << getpid() << "\n";
  std::fprintf(stderr, "virtual-drives: nodes %d %d %d on %s, %.0f Hz per SYNC, %s timing, model %s\n",
               cfg.axes[0].node_id, cfg.axes[1].node_id, cfg.axes[2].node_id, interface.c_str(), rate,
               sim::timing_name(cfg.timing), model.c_str());

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

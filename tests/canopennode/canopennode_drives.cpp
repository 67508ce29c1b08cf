// SPDX-License-Identifier: Apache-2.0
// canopennode-drives: three CiA 402 drive nodes built on CANopenNode and its
// Linux driver (CANopenLinux), an implementation of CiA 301 this project did
// not write, around the same plant as build/bin/virtual-drives
// (sim::SyncedPlant: one period per SYNC, synchronous timing, brakes). The
// CiA 301 side (NMT, SDO server, PDO mapping and transfer, SYNC consumer,
// heartbeat producer and consumer, EMCY producer) is CANopenNode's own; the
// CiA 402 state machine on top (cia402_state.hpp) and the coupling to the
// plant are ours. Used by the SIL tests as the cheapest real drive: a
// misreading of CiA 301 shared by cpmd's master and our virtual drives fails
// here.
//
// Options and control commands are those of virtual-drives that the SIL test
// uses (--interface --model --rate --nodes --counts-per-m --rated-force
// --control; heartbeat AXIS off|on, emcy AXIS CODE [REG], status, quit), and
// --pdos N: the RPDOs and TPDOs each node has (default 2).
#include <net/if.h>
#include <signal.h>
#include <sys/epoll.h>
#include <syslog.h>
#include <unistd.h>

#include <array>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "cia402_state.hpp"
#include "cpm/io/model_file.hpp"
#include "cpm/sim/control_socket.hpp"
#include "cpm/sim/drive_command_line.hpp"
#include "cpm/sim/virtual_machine.hpp"
#include "drive_od.hpp"

extern "C" {
// CANopenLinux's driver logs through this; its own definition lives in its
// main program, which these nodes replace.
void log_printf(int priority, const char* format, ...) {
  if (priority > LOG_NOTICE) return;
  va_list ap;
  va_start(ap, format);
  std::fprintf(stderr, "canopennode-drives: CANopenLinux: ");
  std::vfprintf(stderr, format, ap);
  std::fprintf(stderr, "\n");
  va_end(ap);
}
}

namespace {

using namespace cpm;
using canopennode::DriveState;

volatile sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

std::uint64_t now_us() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::uint64_t>(ts.tv_sec) * 1'000'000u + static_cast<std::uint64_t>(ts.tv_nsec) / 1000u;
}

// A drive that the master has lost (its heartbeat consumer timed out) or
// that was told to quick-stop stays in quick stop active this many SYNCs
// before it reports switch on disabled (quick stop options 1-4), as
// hal::VirtualDrive does.
constexpr int kQuickStopSyncs = 5;

struct Node {
  std::uint8_t id = 0;
  std::unique_ptr<canopennode::DriveOd> od;
  CO_t* co = nullptr;
  CO_CANptrSocketCan_t can{};
  std::uint64_t last_us = 0;
  DriveState state = DriveState::switch_on_disabled;
  std::uint16_t last_controlword = 0;
  std::int16_t applied_permille = 0;   // the torque acting over the current period
  int quick_stop_left = 0;
  bool sync_pending = false;           // took a SYNC whose TPDOs wait for the plant
  bool heartbeat_stopped = false;
  bool master_lost = false;            // the heartbeat consumer timed out (acted on once)
};

void communication_reset(Node& n) {
  CO_t* co = n.co;
  co->CANmodule->CANnormal = false;
  CO_CANsetConfigurationMode(&n.can);
  CO_CANmodule_disable(co->CANmodule);
  if (CO_CANinit(co, &n.can, 0) != CO_ERROR_NO) throw Error("CO_CANinit failed for node " + std::to_string(n.id));
  std::uint32_t info = 0;
  // Boots pre-operational, as a drive does; heartbeat consumer timeouts and
  // bus-off take it to pre-operational (CiA 301's default error behaviour).
  const std::uint16_t control = CO_NMT_ERR_ON_BUSOFF_HB;
  const CO_ReturnError_t e = CO_CANopenInit(co, nullptr, nullptr, n.od->od(), nullptr, control, 500 /*first HB ms*/,
                                            1000 /*SDO server timeout ms*/, 0, false, n.id, &info);
  if (e != CO_ERROR_NO)
    throw Error("CO_CANopenInit failed for node " + std::to_string(n.id) + ": error " + std::to_string(e) +
                ", OD index 0x" + [&] { char b[16]; std::snprintf(b, sizeof b, "%X", info); return std::string(b); }());
  if (CO_CANopenInitPDO(co, co->em, n.od->od(), n.id, &info) != CO_ERROR_NO)
    throw Error("CO_CANopenInitPDO failed for node " + std::to_string(n.id) + " at OD entry " + std::to_string(info));
  CO_CANsetNormalMode(co->CANmodule);
  n.master_lost = false;
  n.heartbeat_stopped = false;
}

std::uint16_t statusword(const Node& n) {
  std::uint16_t sw = canopennode::state_bits(n.state) | (1u << 9);  // remote
  if (n.state == DriveState::operation_enabled) sw |= 1u << 12;       // CST: follows the command value
  return sw;
}

// The controlword of the RPDO taken at this SYNC, and the torque that acts
// from it.
void take_rpdo(Node& n) {
  auto& d = n.od->drive;
  const std::uint16_t cw = d.x6040_controlword;
  const DriveState before = n.state;
  n.state = canopennode::next_state(n.state, cw, n.last_controlword);
  if (before == DriveState::fault && n.state != DriveState::fault) d.x603F_error_code = 0;
  if (n.state == DriveState::quick_stop_active && before != DriveState::quick_stop_active) n.quick_stop_left = kQuickStopSyncs;
  n.last_controlword = cw;
  if (n.state == DriveState::quick_stop_active && n.quick_stop_left > 0 && --n.quick_stop_left == 0 &&
      d.x605A_quick_stop_option >= 1 && d.x605A_quick_stop_option <= 4)
    n.state = DriveState::switch_on_disabled;
  const int max = d.x6072_max_torque;
  n.applied_permille = 0;
  if (n.state == DriveState::operation_enabled && d.x6061_mode_display == 10)
    n.applied_permille = static_cast<std::int16_t>(std::clamp<int>(d.x6071_target_torque, -max, max));
}

// The master's heartbeat (0x1016) timed out in CANopenNode's consumer: what
// 0x6007 says, once.
void on_master_lost(Node& n) {
  if (n.master_lost) return;
  n.master_lost = true;
  switch (n.od->drive.x6007_abort_connection) {
    case 1:
      n.state = DriveState::fault;
      n.od->drive.x603F_error_code = 0x8130;
      break;
    case 2: n.state = DriveState::switch_on_disabled; break;
    case 3:
      if (n.state == DriveState::operation_enabled) {
        n.state = DriveState::quick_stop_active;
        n.quick_stop_left = kQuickStopSyncs;
      } else {
        n.state = DriveState::switch_on_disabled;
      }
      break;
    default: break;
  }
  n.applied_permille = 0;
  std::fprintf(stderr, "canopennode-drives: node %d: master heartbeat lost, 0x6007 = %d -> %s\n", n.id,
               n.od->drive.x6007_abort_connection, canopennode::name(n.state));
}

int run(int argc, char** argv) {
  sim::DriveCommandLine d;
  // Two RPDOs and two TPDOs, as many drives have: CiA 301 makes the others
  // optional, and the master must not depend on them (it did; docs/canopen-backend.md).
  int pdos = 2;
  CLI::App app{"canopennode-drives: three CiA 402 drive nodes on CANopenNode (CiA 301 by another project), around\n"
               "the plant of virtual-drives: the SIL tests' independent peer.",
               "canopennode-drives"};
  program::setup(app);
  sim::add_drive_options(app, d);
  app.add_option("--pdos", pdos, "the RPDOs and the TPDOs each node has")->type_name("N")->check(CLI::Range(1, 4).description(""));
  app.footer("Commands (--control): heartbeat AXIS off|on, emcy AXIS CODE [REG], status, quit.");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return program::parse_exit(app, e, "canopennode-drives");
  }
  const sim::VirtualMachineConfig cfg = d.config();
  const ctl::Machine truth(d.true_machine());
  sim::SyncedPlant plant(truth, cfg);

  const int ifindex = static_cast<int>(if_nametoindex(d.interface.c_str()));
  if (ifindex == 0) throw Error("no CAN interface " + d.interface);
  const int epfd = epoll_create1(EPOLL_CLOEXEC);
  std::array<Node, 3> nodes;
  for (std::size_t i = 0; i < 3; ++i) {
    Node& n = nodes[i];
    n.id = static_cast<std::uint8_t>(cfg.axes[i].node_id);
    n.od = std::make_unique<canopennode::DriveOd>(pdos);
    n.od->drive.x6076_rated_torque = static_cast<std::uint32_t>(std::lround(plant.scaling(static_cast<int>(i)).rated_force_n * 1000));
    n.od->drive.x6064_position = plant.position_units(static_cast<int>(i));
    n.od->comm.x1018.serial = n.id;
    std::uint32_t heap = 0;
    n.co = CO_new(&n.od->config(), &heap);
    if (!n.co) throw Error("CO_new failed");
    n.can = {ifindex, epfd};
    communication_reset(n);
    n.last_us = now_us();
  }

  std::unique_ptr<sim::ControlSocket> control_socket;
  if (!d.control.empty()) control_socket = std::make_unique<sim::ControlSocket>(d.control);
  signal(SIGINT, on_signal);
  signal(SIGTERM, on_signal);
  signal(SIGPIPE, SIG_IGN);
  std::fprintf(stderr, "canopennode-drives: CANopenNode nodes %d %d %d on %s, %.0f Hz per SYNC, model %s\n", nodes[0].id,
               nodes[1].id, nodes[2].id, d.interface.c_str(), d.rate, d.model.c_str());

  std::uint64_t syncs = 0;
  bool quit = false;
  auto axis_of = [&](const std::string& w) -> Node& {
    if (w == "1" || w == "x") return nodes[0];
    if (w == "2" || w == "y") return nodes[1];
    if (w == "3" || w == "z") return nodes[2];
    throw Error("AXIS must be 1, 2, 3 or x, y, z, got '" + w + "'");
  };
  auto execute = [&](const std::string& line) -> std::string {
    std::istringstream ss(line);
    std::vector<std::string> w;
    for (std::string t; ss >> t;) w.push_back(t);
    try {
      if (w.size() == 3 && w[0] == "heartbeat") {
        // CANopenNode's own producer stops and starts (the OD's 0x1017 is kept).
        Node& n = axis_of(w[1]);
        n.heartbeat_stopped = w[2] == "off";
        n.co->NMT->HBproducerTime_us = n.heartbeat_stopped ? 0u : n.od->comm.x1017_producer_ms * 1000u;
        return "ok";
      }
      if ((w.size() == 3 || w.size() == 4) && w[0] == "emcy") {
        // CANopenNode's emergency producer: the error set, then cleared
        // (EMCY with the code, then the "error reset" EMCY 0x0000).
        Node& n = axis_of(w[1]);
        const auto code = static_cast<std::uint16_t>(std::stoul(w[2], nullptr, 0));
        CO_errorReport(n.co->em, CO_EM_MANUFACTURER_START, code, 0);
        CO_errorReset(n.co->em, CO_EM_MANUFACTURER_START, 0);
        return "ok";
      }
      if (w.size() == 1 && w[0] == "status") {
        const Vec3 p = plant.plant().position();
        char b[256];
        std::snprintf(b, sizeof b, "ok syncs %llu steps %llu position %.9f %.9f %.9f states %s %s %s",
                      static_cast<unsigned long long>(syncs), static_cast<unsigned long long>(plant.steps()), p.x(), p.y(),
                      p.z(), canopennode::name(nodes[0].state), canopennode::name(nodes[1].state),
                      canopennode::name(nodes[2].state));
        return b;
      }
      if (w.size() == 1 && w[0] == "quit") {
        quit = true;
        return "ok";
      }
      return "error: unknown command (heartbeat AXIS off|on, emcy AXIS CODE, status, quit)";
    } catch (const std::exception& e) {
      return std::string("error: ") + e.what();
    }
  };

  // One frame at a time (CANopenLinux reads one per event), then every
  // node's processing; a node that took a SYNC holds its TPDOs until the
  // plant has run through the period that the SYNC ends.
  while (!g_stop && !quit) {
    epoll_event ev{};
    const int ready = epoll_wait(epfd, &ev, 1, 1);
    const std::uint64_t now = now_us();
    if (ready == 1)
      for (Node& n : nodes)
        if (CO_CANrxFromEpoll(n.co->CANmodule, &ev, nullptr, nullptr)) break;
    for (Node& n : nodes) {
      const auto dt = static_cast<std::uint32_t>(now - n.last_us);
      n.last_us = now;
      const CO_NMT_reset_cmd_t reset = CO_process(n.co, false, dt, nullptr);
      if (reset == CO_RESET_COMM || reset == CO_RESET_APP) {
        // NMT reset: the communication area back to its power-on values (and
        // the profile area too for reset node), then CANopenNode starts again
        // and sends its boot-up.
        n.od->comm = canopennode::CommObjects{};
        n.od->comm.x1018.serial = n.id;
        if (reset == CO_RESET_APP) {
          const auto rated = n.od->drive.x6076_rated_torque;
          n.od->drive = canopennode::DriveObjects{};
          n.od->drive.x6076_rated_torque = rated;
          n.state = DriveState::switch_on_disabled;
        }
        n.sync_pending = false;
        communication_reset(n);
        continue;
      }
      const bool sync = CO_process_SYNC(n.co, dt, nullptr);
      CO_process_RPDO(n.co, sync, dt, nullptr);
      if (sync) n.sync_pending = true;
      else CO_process_TPDO(n.co, false, dt, nullptr);
      // The mode takes effect when written (the master reads 0x6061 back).
      n.od->drive.x6061_mode_display = n.od->drive.x6060_mode == 10 ? 10 : n.od->drive.x6061_mode_display;
      if (n.co->HBcons) {
        const std::int8_t k = CO_HBconsumer_getIdxByNodeId(n.co->HBcons, static_cast<std::uint8_t>(n.od->comm.x1016_consumer[0] >> 16));
        if (k >= 0 && CO_HBconsumer_getState(n.co->HBcons, static_cast<std::uint8_t>(k)) == CO_HBconsumer_TIMEOUT)
          on_master_lost(n);
      }
    }
    // The SYNC reaches the three sockets as one frame, but each socket's copy
    // is read by its own event: the plant steps once, when every node that
    // consumes SYNCs (pre-operational or operational) has taken it.
    bool any_pending = false, all_taken = true;
    for (Node& n : nodes) {
      const CO_NMT_internalState_t st = CO_NMT_getInternalState(n.co->NMT);
      any_pending = any_pending || n.sync_pending;
      if (!n.sync_pending && (st == CO_NMT_PRE_OPERATIONAL || st == CO_NMT_OPERATIONAL)) all_taken = false;
    }
    if (any_pending && all_taken) {
      ++syncs;
      std::array<bool, 3> holding{};
      Vec3 activated = Vec3::Zero();
      for (std::size_t i = 0; i < 3; ++i) {
        Node& n = nodes[i];
        if (!n.sync_pending) continue;
        take_rpdo(n);
        holding[i] = n.state == DriveState::operation_enabled;
        activated[static_cast<int>(i)] = hal::pdo::force_n(n.applied_permille, plant.scaling(static_cast<int>(i)));
      }
      plant.on_sync(holding, activated);
      for (std::size_t i = 0; i < 3; ++i) {
        Node& n = nodes[i];
        auto& d = n.od->drive;
        d.x6064_position = plant.position_units(static_cast<int>(i));
        d.x606C_velocity = plant.velocity_units(static_cast<int>(i));
        d.x6077_torque = n.applied_permille;
        d.x6041_statusword = statusword(n);
        if (n.sync_pending) CO_process_TPDO(n.co, true, 0, nullptr);
        n.sync_pending = false;
      }
    } else if (!any_pending) {
      for (Node& n : nodes) n.od->drive.x6041_statusword = statusword(n);
    }
    if (control_socket)
      control_socket->poll([&](const std::string& line) {
        const std::string reply = execute(line);
        std::fprintf(stderr, "canopennode-drives: [sync %llu] %s -> %s\n", static_cast<unsigned long long>(syncs),
                     line.c_str(), reply.c_str());
        return reply;
      });
  }
  control_socket.reset();
  for (Node& n : nodes) {
    CO_CANsetConfigurationMode(&n.can);
    CO_delete(n.co);
  }
  close(epfd);
  std::fprintf(stderr, "canopennode-drives: stopped after %llu SYNCs, %llu plant steps\n",
               static_cast<unsigned long long>(syncs), static_cast<unsigned long long>(plant.steps()));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "canopennode-drives: error: %s\n", e.what());
    return 1;
  }
}

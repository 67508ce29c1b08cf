// SPDX-License-Identifier: Apache-2.0
// A whole command session against a running loop: the bytes are a script of
// LCM messages (control and trajectory, raw bytes as a commander would send
// them) interleaved with control cycles of the loop on the simulator
// backend, e-stop presses and drive faults. The messages go through
// Server::receive (decode + validation, as the LCM thread does), then the
// loop's command queue. Oracle, after every cycle: the cycle counter
// advanced by one, the loop took at most kCommandsPerCycle commands, the
// commanded forces are finite and within the force limit, nothing but zero
// force is commanded outside enabling/holding/moving/stopping, and no
// exception escapes the server.
//
// Script (little endian): op byte, then
//   op % 4 == 0: control_command_t bytes (u16 length, bytes)
//   op % 4 == 1: trajectory_command_t bytes (u16 length, bytes)
//   op % 4 == 2: run (next byte % 64) + 1 cycles
//   op % 4 == 3: next byte: bit 0 e-stop open, bit 1 drive fault on axis 1
// CMD_LOAD_MODEL paths are replaced by "builtin:elkady" or a missing file
// in a missing model directory: a fuzzer must not read the host's files.
// The target acquires the session first (as operator alice, an engineer)
// and, unless bit 2 of the op is set, writes it into the message (bytes
// 24..31); unless bit 3 is set, it writes the next seq too (bytes 32..39);
// unless bit 4 is set, it signs the message as alice (the MAC, the last 32
// bytes, over the rest). So the fuzzer gets past authentication and the
// session check and still reaches every refusal (no or a wrong MAC, another
// operator, wrong session, stale seq). The session clock is the loop's cycle
// count and the wall clock is 0 + that, so expiry and an acquire's freshness
// (its seq in us) are deterministic.
#include <cmath>
#include <memory>
#include <lcm/lcm-cpp.hpp>

#include "cpm/daemon/server.hpp"
#include "cpm/daemon/sim_backend.hpp"
#include "fuzz_common.hpp"
#include "support/test_operators.hpp"

using namespace cpm;
using namespace cpm::daemon;
using cpm_msgs::control_command_t;

namespace {

DaemonConfig config() {
  DaemonConfig c;
  c.model_file = "builtin:elkady";
  c.loop.rate_hz = 250;  // a legal rate; 4x fewer samples per validated segment than 1 kHz
  c.loop.max_consecutive_overruns = 3;
  c.lcm.url = "memq://";  // in-process: nothing leaves the fuzzer
  c.security.model_dir = "/nonexistent-fuzz-models";
  return c;
}

// Decode a control message the way a careful reader would; when it is a
// load_model, put a harmless path in and encode it again.
std::vector<std::uint8_t> tame_control(const std::uint8_t* d, std::size_t n) {
  std::vector<std::uint8_t> out(d, d + n);
  control_command_t m;
  try {
    if (n < kControlModelPathOffset + 4) return out;
    const std::uint8_t* p = d + kControlModelPathOffset;  // model_path's length prefix
    const std::int32_t len = static_cast<std::int32_t>((std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) |
                                                       (std::uint32_t{p[2]} << 8) | p[3]);
    if (len < 1) return out;  // the server must drop this one itself
    if (m.decode(d, 0, static_cast<int>(n)) < 0) return out;
  } catch (const std::exception&) {
    return out;
  }
  if (m.command != control_command_t::CMD_LOAD_MODEL) return out;
  m.model_path = (m.model_path.size() % 2) ? "builtin:elkady" : "nonexistent-fuzz-model.yaml";
  out.assign(static_cast<std::size_t>(m.getEncodedSize()), 0);
  m.encode(out.data(), 0, static_cast<int>(out.size()));
  return out;
}

struct AckTap {
  std::int64_t session = 0;
  void on(const lcm::ReceiveBuffer*, const std::string&, const cpm_msgs::ack_t* a) {
    if (a->accepted && a->session != 0) session = a->session;
  }
};

void put64(std::vector<std::uint8_t>& b, std::size_t at, std::int64_t v) {
  for (int i = 0; i < 8; ++i) b[at + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(static_cast<std::uint64_t>(v) >> (56 - 8 * i));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 64 * 1024) return 0;
  const DaemonConfig cfg = config();
  SimBackendOptions so;
  so.plant.substeps = 1;  // the plant's accuracy is not under test; speed is coverage
  auto sim_owned = std::make_unique<SimBackend>(std::make_unique<ctl::Machine>(ctl::MachineModel::elkady()), so);
  SimBackend& sim = *sim_owned;
  sim.start(1.0 / cfg.loop.rate_hz);
  ModelStore models(std::make_unique<ctl::Machine>(ctl::MachineModel::elkady()));
  ControlLoop loop(cfg, sim, models.current(), ctl::Controller(models.current(), cfg.controller.law, cfg.controller.gains));
  Server server(cfg, loop, models);
  std::int64_t k = 0;
  server.set_clock([&k, &cfg] { return static_cast<double>(k) / cfg.loop.rate_hz; });
  server.set_wall_clock([&k, &cfg] { return static_cast<double>(k) / cfg.loop.rate_hz; });
  server.set_operators(test::operator_table());
  server.set_boot_id(test::kTestBoot);
  const Credentials alice = test::credentials("alice");
  AckTap tap;
  server.bus().subscribe(cfg.lcm.ack_channel, &AckTap::on, &tap);
  {
    control_command_t acq{};
    acq.command = control_command_t::CMD_ACQUIRE;
    acq.session = 1;  // nonce
    acq.seq = 1;      // the wall clock in us, at 0 s
    const std::vector<std::uint8_t> b = test::encode_signed(acq, alice);
    server.receive(cfg.lcm.control_channel, b.data(), b.size());
    while (server.bus().handleTimeout(0) > 0) {
    }
    FUZZ_CHECK(tap.session != 0, "the first acquire was refused");
  }
  std::int64_t seq = 0;
  auto stamp = [&](std::vector<std::uint8_t>& b, std::uint8_t op) {
    if (b.size() < 40 + kMacBytes) return;
    if (!(op & 4)) put64(b, 24, tap.session);
    if (!(op & 8)) put64(b, 32, ++seq);
    if (!(op & 16)) sign_encoded(b.data(), b.size(), alice.key, alice.boot);
  };

  const double force_limit = std::min(cfg.limits.force, models.current().model().force_limit);
  // At most 500 cycles (2 s of machine time) per input: a slow input is
  // less coverage per second, not more.
  auto run = [&](int n) {
    for (int i = 0; i < n && k < 500; ++i) {
      const std::int64_t before = loop.cycles_done();
      const std::size_t queued = loop.commands().size();
      loop.cycle(k++, 0);
      FUZZ_CHECK(loop.cycles_done() == before + 1, "a cycle did not complete");
      const std::size_t taken = queued - loop.commands().size();
      FUZZ_CHECK(taken <= static_cast<std::size_t>(ControlLoop::kCommandsPerCycle),
                 "the loop took " + std::to_string(taken) + " commands in one cycle");
      const auto& s = loop.last_state();
      const Mode m = loop.mode();
      const bool powered = m == Mode::enabling || m == Mode::holding || m == Mode::moving || m == Mode::stopping;
      for (int a = 0; a < 3; ++a) {
        FUZZ_CHECK(std::isfinite(s.force[a]), "a non-finite force was commanded");
        FUZZ_CHECK(std::abs(s.force[a]) <= force_limit * (1 + 1e-12), "a force beyond the limit was commanded");
        if (!powered) FUZZ_CHECK(s.force[a] == 0.0, std::string("force commanded in mode ") + mode_name(m));
      }
      server.drain();
    }
  };

  fuzz::Bytes in(data, size);
  run(2);
  int ops = 0;
  while (!in.empty() && ops++ < 256) {
    const std::uint8_t op = in.u8();
    switch (op % 4) {
      case 0:
      case 1: {
        const std::size_t len = std::min<std::size_t>(in.u16(), in.left());
        const std::uint8_t* p = in.here();
        in.skip(len);
        try {
          if (op % 4 == 0) {
            auto tamed = tame_control(p, len);
            stamp(tamed, op);
            server.receive(cfg.lcm.control_channel, tamed.data(), tamed.size());
          } else {
            std::vector<std::uint8_t> b(p, p + len);
            stamp(b, op);
            server.receive(cfg.lcm.trajectory_channel, b.data(), b.size());
          }
        } catch (const std::exception& e) {
          fuzz::fail(__FILE__, __LINE__, std::string("Server::receive let an exception out: ") + e.what());
        }
        break;
      }
      case 2: run(in.u8() % 64 + 1); break;
      default: {
        const std::uint8_t f = in.u8();
        sim.set_estop(f & 1);
        sim.inject_drive_fault((f & 2) ? 1 : -1);
        break;
      }
    }
  }
  run(5);
  return 0;
}

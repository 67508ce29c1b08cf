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
// CMD_LOAD_MODEL paths are replaced by "builtin:elkady" or a missing file:
// a fuzzer must not read the host's files.
#include <cmath>
#include <memory>

#include "cpm/daemon/server.hpp"
#include "cpm/daemon/sim_backend.hpp"
#include "fuzz_common.hpp"

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
  return c;
}

// Decode a control message the way a careful reader would; when it is a
// load_model, put a harmless path in and encode it again.
std::vector<std::uint8_t> tame_control(const std::uint8_t* d, std::size_t n) {
  std::vector<std::uint8_t> out(d, d + n);
  control_command_t m;
  try {
    if (n < 79) return out;
    const std::uint8_t* p = d + 75;
    const std::int32_t len = static_cast<std::int32_t>((std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) |
                                                       (std::uint32_t{p[2]} << 8) | p[3]);
    if (len < 1) return out;  // the server must drop this one itself
    if (m.decode(d, 0, static_cast<int>(n)) < 0) return out;
  } catch (const std::exception&) {
    return out;
  }
  if (m.command != control_command_t::CMD_LOAD_MODEL) return out;
  m.model_path = (m.model_path.size() % 2) ? "builtin:elkady" : "/nonexistent-fuzz/model.yaml";
  out.assign(static_cast<std::size_t>(m.getEncodedSize()), 0);
  m.encode(out.data(), 0, static_cast<int>(out.size()));
  return out;
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

  const double force_limit = std::min(cfg.limits.force, models.current().model().force_limit);
  std::int64_t k = 0;
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
            const auto tamed = tame_control(p, len);
            server.receive(cfg.lcm.control_channel, tamed.data(), tamed.size());
          } else {
            server.receive(cfg.lcm.trajectory_channel, p, len);
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

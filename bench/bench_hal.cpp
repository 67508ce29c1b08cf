// SPDX-License-Identifier: Apache-2.0
// One master cycle (read + write for three drives in operation enabled) on
// the fake bus. The virtual drives answer between cycles, outside the timing.
#include <benchmark/benchmark.h>

#include <memory>
#include <vector>

#include "cpm/hal/fake_can.hpp"
#include "cpm/hal/master.hpp"
#include "cpm/hal/virtual_drive.hpp"

namespace {

using namespace cpm::hal;

void master_cycle(benchmark::State& state) {
  const bool velocity = state.range(0) != 0;
  FakeClock clock(0, 100'000);
  FakeCanNetwork net(clock);
  auto& mport = net.add_port("master");
  std::vector<std::unique_ptr<VirtualDrive>> drives;
  MasterConfig cfg;
  cfg.rate_hz = velocity ? 500 : 1000;
  cfg.velocity_from_drive = velocity;
  const char* names[] = {"x", "y", "z"};
  for (int i = 1; i <= 3; ++i) {
    cfg.drives.push_back(DriveConfig{names[i - 1], i, 1e6, 0, 400, 2000, 1, 0, {}});
    VirtualDriveConfig vc;
    vc.node_id = static_cast<std::uint8_t>(i);
    drives.push_back(std::make_unique<VirtualDrive>(net.add_port("drive"), vc));
  }
  clock.set_hook([&](std::int64_t now) {
    for (auto& d : drives) d->poll(now);
  });
  for (auto& d : drives) d->power_on(0);
  Master master(mport, clock, cfg);
  master.start();
  Commands cmd;
  Feedback fb;
  for (int i = 0; i < 3; ++i) cmd.drive[static_cast<std::size_t>(i)].target = cia402::Target::enabled;
  const auto period = static_cast<std::int64_t>(1e9 / cfg.rate_hz);
  for (int k = 0; k < 10; ++k) {
    master.read(fb);
    master.write(cmd);
    clock.wait(period);
  }
  for (int i = 0; i < 3; ++i) cmd.drive[static_cast<std::size_t>(i)].force_n = 10.0 * (i + 1);
  for (auto _ : state) {
    benchmark::DoNotOptimize(master.read(fb));
    benchmark::DoNotOptimize(master.write(cmd));
    state.PauseTiming();
    clock.wait(period);
    state.ResumeTiming();
  }
  if (fb.drive[0].state != cia402::State::operation_enabled) state.SkipWithError("drives not enabled");
}
BENCHMARK(master_cycle)->Arg(1)->Arg(0)->ArgName("velocity_pdo");

}  // namespace

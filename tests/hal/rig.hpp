// SPDX-License-Identifier: Apache-2.0
// A master and three virtual drives on the fake bus, with a fake clock: the
// whole CANopen stack runs deterministically in one thread.
#pragma once

#include <cmath>
#include <memory>
#include <vector>

#include "cpm/hal/fake_can.hpp"
#include "cpm/hal/master.hpp"
#include "cpm/hal/virtual_drive.hpp"

namespace cpm::hal::test {

inline MasterConfig three_drives(double rate_hz = 500, bool velocity = true) {
  MasterConfig c;
  c.rate_hz = rate_hz;
  c.velocity_from_drive = velocity;
  const char* names[] = {"x", "y", "z"};
  for (int i = 0; i < 3; ++i) {
    DriveConfig d;
    d.name = names[i];
    d.node_id = i + 1;
    d.counts_per_m = 1e6;         // 1 um per count
    d.rated_force_n = 400;        // 1000 per mille = 400 N
    d.max_torque_permille = 2000; // 800 N peak
    c.drives.push_back(d);
  }
  return c;
}

// What the drives' own inputs read on an axis of the rig, by the axis's
// position (m; the drive counts counts_per_m per metre upward).
struct AxisSensors {
  double home_below = std::nan("");   // home switch actuated while pos < this (a negative home switch)
  double home_above = std::nan("");   // or while pos > this (a positive one)
  double limit_low = -1e9;            // negative limit switch actuated while pos < this
  double limit_high = 1e9;            // positive limit switch while pos > this
  double index_pitch = 0;             // an index pulse at every whole multiple of this (m); 0: none
  bool home_dead = false;             // the home switch never actuates (broken)
};

struct Rig {
  FakeClock clock{0, 100'000};
  FakeCanNetwork net{clock};
  FakeCanPort& master_port = net.add_port("master");
  std::vector<FakeCanPort*> drive_ports;
  std::vector<std::unique_ptr<VirtualDrive>> drives;
  std::unique_ptr<Master> master;
  Feedback fb;
  Commands cmd;
  // A unit-mass axis per drive: a = F / m, integrated once per SYNC.
  double mass_kg = 10;
  std::vector<double> pos_m, vel_mps;
  std::vector<double> load_n;          // force on each axis besides the drive's (N), e.g. a weight
  std::vector<AxisSensors> sensors;

  // `pdos`: the RPDOs and TPDOs each drive has (VirtualDriveConfig::pdos).
  explicit Rig(MasterConfig cfg = three_drives(), int pdos = 4) {
    const double dt = 1.0 / cfg.rate_hz;
    pos_m.assign(cfg.drives.size(), 0.0);
    vel_mps.assign(cfg.drives.size(), 0.0);
    load_n.assign(cfg.drives.size(), 0.0);
    sensors.assign(cfg.drives.size(), AxisSensors{});
    for (std::size_t i = 0; i < cfg.drives.size(); ++i) {
      drive_ports.push_back(&net.add_port("drive" + std::to_string(i + 1)));
      const double counts = cfg.drives[i].counts_per_m, rated = cfg.drives[i].rated_force_n;
      VirtualDriveConfig vc;
      vc.node_id = static_cast<std::uint8_t>(cfg.drives[i].node_id);
      vc.pdos = pdos;
      vc.tune_loops(mass_kg, rated, counts, dt);  // velocity in counts per second
      drives.push_back(std::make_unique<VirtualDrive>(*drive_ports.back(), vc));
      drives.back()->on_sync = [this, i, dt, counts, rated](VirtualDrive& d) {
        const double before = pos_m[i];
        const double f = d.applied_torque() * rated / 1000.0 + load_n[i];
        vel_mps[i] += f / mass_kg * dt;
        pos_m[i] += vel_mps[i] * dt;
        d.set_actual(static_cast<std::int32_t>(std::lround(pos_m[i] * counts)),
                     static_cast<std::int32_t>(std::lround(vel_mps[i] * counts)), d.applied_torque());
        d.set_inputs(inputs(sensors[i], before, pos_m[i], counts));
      };
    }
    clock.set_hook([this](std::int64_t now) {
      for (auto& d : drives) d->poll(now);
    });
    for (auto& d : drives) d->power_on(clock.now_ns());
    master = std::make_unique<Master>(master_port, clock, cfg);
  }

  static DriveInputs inputs(const AxisSensors& s, double before, double now, double counts) {
    DriveInputs in;
    in.home_switch = !s.home_dead && (now < s.home_below || now > s.home_above);
    in.negative_limit = now < s.limit_low;
    in.positive_limit = now > s.limit_high;
    if (s.index_pitch > 0) {
      const double k0 = std::floor(before / s.index_pitch), k1 = std::floor(now / s.index_pitch);
      if (k0 != k1) {  // the mark crossed (the drive's capture is exact)
        in.index_pulse = true;
        in.index_position = static_cast<std::int32_t>(std::lround(std::max(k0, k1) * s.index_pitch * counts));
      }
    }
    return in;
  }

  std::int64_t period_ns() const { return static_cast<std::int64_t>(1e9 / master->config().rate_hz); }

  // One control cycle: read, write, then a period passes (drives answer).
  Status cycle() {
    const Status r = master->read(fb);
    const Status w = master->write(cmd);
    clock.wait(period_ns());
    return r.ok() ? w : r;
  }
  void cycles(int n) {
    for (int i = 0; i < n; ++i) cycle();
  }
  void target_all(cia402::Target t) {
    for (std::size_t i = 0; i < 3; ++i) cmd.drive[i].target = t;
  }
  // Cycles until every drive reports `s` (at most `limit`); returns the count or -1.
  int until_all(cia402::State s, int limit = 50) {
    for (int n = 0; n < limit; ++n) {
      bool all = true;
      for (std::size_t i = 0; i < fb.count; ++i) all = all && fb.drive[i].state == s;
      if (all && fb.count > 0) return n;
      cycle();
    }
    return -1;
  }
};

}  // namespace cpm::hal::test

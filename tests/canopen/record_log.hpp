// SPDX-License-Identifier: Apache-2.0
// A motion log recorded through cpmd's CANopen path, for the diagnosis: the
// daemon's loop, the canopen backend and the hal master on the fake bus,
// three virtual drives with real (synchronous) timing around the true plant
// (the nominal machine of docs/model.md), encoders with noise. What comes back is what the
// daemon publishes on its state channel, turned into rows by the converter
// of `cpm record` and `cpm lcm-log-to-csv` (cli::StateToMotion): per period
// t, the encoders' d and v as the daemon read them, and the force it
// commanded at that t. Since the drives apply a torque from the SYNC after
// the one it was computed from, row k's force acts over [t_k + T, t_k+1 + T):
// the log carries an actuation_delay of one period T.
#pragma once

#include <cmath>
#include <cstdint>
#include <numbers>

#include "canopen/rig.hpp"
#include "cpm/daemon/stream_trajectory.hpp"
#include "state_log.hpp"

namespace cpm::daemon::test {

// A 3-D Lissajous that moves every axis both ways at varied speeds (up to
// 0.27 m/s, 0.9 m/s^2), its amplitude raised from zero over the first second
// (quintic: the start is at rest) around (0.425, 0.425, 0.36) m.
struct LogPath {
  Vec3 centre = Vec3(0.425, 0.425, 0.36);
  Vec3 amplitude = Vec3(0.13, 0.11, 0.08);                       // m
  Vec3 omega = 2.0 * std::numbers::pi * Vec3(0.29, 0.41, 0.53);  // rad/s
  void at(double t, Vec3& p, Vec3& v) const {
    const double u = std::clamp(t, 0.0, 1.0);
    const double s = u * u * u * (10 - 15 * u + 6 * u * u), s_dot = t < 1.0 ? 30 * u * u * (1 - u) * (1 - u) : 0.0;
    for (int i = 0; i < 3; ++i) {
      const double w = omega[i] * t;
      p[i] = centre[i] + s * amplitude[i] * std::sin(w);
      v[i] = s_dot * amplitude[i] * std::sin(w) + s * amplitude[i] * omega[i] * std::cos(w);
    }
  }
};

// The path from t0 as one stream chunk of the daemon (cubic Hermite through
// setpoints every `step` s).
inline Command log_path_chunk(const LogPath& path, double t0, double step) {
  constexpr int n = StreamTrajectory::kMaxPoints;
  double t[n], p[n][3], v[n][3];
  for (int i = 0; i < n; ++i) {
    Vec3 pi, vi;
    path.at(t0 + i * step, pi, vi);
    t[i] = i * step;
    for (int j = 0; j < 3; ++j) p[i][j] = pi[j], v[i][j] = vi[j];
  }
  Command c;
  c.kind = CommandKind::segment;
  c.segment.traj.emplace<StreamTrajectory>(n, t, p, v);
  c.segment.start = Vec3(p[0][0], p[0][1], p[0][2]);
  c.segment.end = Vec3(p[n - 1][0], p[n - 1][1], p[n - 1][2]);
  return c;
}

// `seconds` of the Lissajous (after the move from power-on to its centre),
// through the bus at 500 Hz with the drives' velocity TPDO (the mapping that
// carries the encoder velocity; 1 kHz with it would overload the bus), encoder
// noise 1 um and 0.2 mm/s (seeded), computed torque with Table 3 gains.
// `model_has_delay`: the daemon's model carries actuation_delay = T and
// predicts across it. Fails the calling test (and returns what it has) when
// the machine faults.
inline io::MotionData record_canopen_motion_log(double seconds, std::uint64_t seed, bool model_has_delay,
                                                const DaemonConfig& cfg = config_500hz_with_velocity()) {
  ctl::MachineModel believed = ctl::MachineModel::elkady();
  if (model_has_delay) ctl::add_effect(believed, "actuation_delay", -1, {1.0 / cfg.loop.rate_hz});
  sim::EncoderModel encoder;
  encoder.position_noise = 1e-6;
  encoder.velocity_noise = 2e-4;
  encoder.seed = seed;
  Rig r(cfg, true, sim::DriveTiming::synchronous, believed, encoder);
  cli::StateToMotion rows;
  r.on_state = [&](const cpm_msgs::state_t& s) { rows.add(s); };
  r.to_holding();
  const LogPath path;
  Vec3 centre, v0;
  path.at(0.0, centre, v0);
  EXPECT_TRUE(r.command(r.move_to(centre, 0.2)).accepted);
  EXPECT_GE(r.run_until([&] { return r.mode() == Mode::holding; }, 20 * static_cast<int>(cfg.loop.rate_hz)), 0)
      << r.fault_text();
  // Chunks of 99 intervals of 10 ms, kept a few ahead of the playing one.
  constexpr double kStep = 0.01;
  const double chunk = (StreamTrajectory::kMaxPoints - 1) * kStep;
  double queued = 0.0;
  const auto cycles = static_cast<long>(std::lround(seconds * cfg.loop.rate_hz));
  for (long n = 0; n < cycles && r.mode() != Mode::fault; ++n) {
    while (queued < seconds + chunk && r.state().queue_depth < 3) {
      Command c = log_path_chunk(path, queued, kStep);
      c.segment.start = r.queue_end();  // equal to the chunk's start within rounding
      // The Lissajous starts at speed from the centre at rest: a bench's grant
      // (the loop refuses a velocity step otherwise); the chunks after join
      // with the velocity they end with.
      c.segment.allow_step = queued == 0.0;
      if (!r.command(c).accepted) break;
      queued += chunk;
    }
    r.step();
  }
  EXPECT_NE(r.mode(), Mode::fault) << r.fault_text();
  char source[160];
  std::snprintf(source, sizeof source,
                "record_canopen_motion_log: %.0f s Lissajous through the fake CANopen bus, synchronous drives, seed %llu, "
                "model %s actuation_delay",
                seconds, static_cast<unsigned long long>(seed), model_has_delay ? "with" : "without");
  return rows.finish("", source);
}

}  // namespace cpm::daemon::test

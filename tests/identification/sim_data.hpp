// SPDX-License-Identifier: Apache-2.0
// Motion logs from the simulator for the identification tests: a true
// machine (Kim-sized plane errors, planted effects) driven by the nominal
// computed-torque controller along a 3-D Lissajous path that moves every
// axis both ways at varied speeds, encoders with noise.
#pragma once

#include <cmath>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "cpm/control/controller.hpp"
#include "cpm/io/data_files.hpp"
#include "cpm/sim/closed_loop.hpp"

namespace cpm::test {

class Lissajous final : public ctl::Trajectory {
 public:
  Lissajous(double duration, Vec3 amplitude = Vec3(0.12, 0.12, 0.08), Vec3 hz = Vec3(0.31, 0.37, 0.43))
      : T_(duration), A_(std::move(amplitude)), w_(2.0 * std::numbers::pi * hz) {}
  [[nodiscard]] double duration() const noexcept override { return T_; }
  [[nodiscard]] ctl::TrajectorySample sample(double t) const noexcept override {
    // Amplitude ramp s(t) (quintic over 1 s) so the start is at rest.
    const double tr = 1.0;
    double s = 1.0, sd = 0.0, sdd = 0.0;
    const double tc = std::clamp(t, 0.0, T_);
    if (tc < tr) {
      const double u = tc / tr;
      s = u * u * u * (10 - 15 * u + 6 * u * u);
      sd = 30 * u * u * (1 - u) * (1 - u) / tr;
      sdd = 60 * u * (1 - u) * (1 - 2 * u) / (tr * tr);
    }
    ctl::TrajectorySample out;
    for (int i = 0; i < 3; ++i) {
      const double f = A_[i] * std::sin(w_[i] * tc), fd = A_[i] * w_[i] * std::cos(w_[i] * tc),
                   fdd = -A_[i] * w_[i] * w_[i] * std::sin(w_[i] * tc);
      out.p[i] = centre_[i] + s * f;
      out.v[i] = t > T_ ? 0.0 : sd * f + s * fd;
      out.a[i] = t > T_ ? 0.0 : sdd * f + 2 * sd * fd + s * fdd;
    }
    return out;
  }
  Vec3 centre_ = Vec3(0.425, 0.425, 0.36);

 private:
  double T_;
  Vec3 A_, w_;
};

// Kim-sized plane errors (tenths of a degree, tenths of a mm), deterministic.
inline kin::KinematicModel kim_sized_planes(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  kin::KinematicModel m = kin::KinematicModel::nominal();
  for (int i = 0; i < 3; ++i) {
    m.planes[i].normal = (Vec3::Unit(i) + 2.3e-3 * Vec3(u(rng), u(rng), u(rng))).normalized();
    m.planes[i].scale = 1.0 + 2e-5 * u(rng);
    m.planes[i].offset = 3e-4 * u(rng);
  }
  m.validate();
  return m;
}

struct SimSpec {
  double duration = 20.0;
  std::uint64_t seed = 1;
  double position_noise = 1e-6;   // m
  double velocity_noise = 2e-4;   // m/s
  double resolution = 0.0;
  bool base_errors = true;        // Kim-sized planes in the truth
  std::vector<std::tuple<std::string, int, std::vector<double>>> effects;  // planted (axis 0..2 / -1)
  std::vector<std::string> user_effects;  // planted user effects, in cpm sim's --truth-effect form
  const ctl::Trajectory* trajectory = nullptr;  // default: Lissajous(duration)
};

inline io::MotionData simulate(const SimSpec& s, sim::RunResult* run = nullptr,
                               const ctl::MachineModel& controller_model = ctl::MachineModel::elkady()) {
  ctl::MachineModel tm = ctl::MachineModel::elkady();
  if (s.base_errors) tm.kinematics = kim_sized_planes(s.seed * 7919 + 3);
  for (const auto& [name, axis, values] : s.effects) ctl::add_effect(tm, name, axis, values);
  for (const std::string& u : s.user_effects) ctl::add_user_effect(tm, u);
  const ctl::Machine truth(tm);
  const ctl::Machine model(controller_model);
  const ctl::Controller ctrl(model, ctl::ControlLaw::computed_torque,
                             ctl::table3_gains(ctl::ControlLaw::computed_torque));
  sim::PlantOptions po;
  po.encoder.position_noise = s.position_noise;
  po.encoder.velocity_noise = s.velocity_noise;
  po.encoder.resolution = s.resolution;
  po.encoder.seed = s.seed;
  po.substeps = 4;
  sim::Plant plant(truth, po);
  Lissajous lj(s.duration);
  const ctl::Trajectory& traj = s.trajectory ? *s.trajectory : lj;
  sim::LoopOptions lo;
  const sim::RunResult r = sim::run_closed_loop(ctrl, plant, traj, lo);
  if (!r.ok()) throw Error("simulation stopped: " + describe(r.fault));
  io::MotionData d;
  d.info.path = "sim";
  d.rate = 1000.0;
  for (const auto& row : r.log) {
    d.t.push_back(row.t);
    d.d.push_back(row.d);
    d.v.push_back(row.d_dot);
    d.f.push_back(row.force);
  }
  if (run) *run = r;
  return d;
}

}  // namespace cpm::test

// SPDX-License-Identifier: Apache-2.0
#include "cpm/calibration/simulate.hpp"

#include <cmath>
#include <cstdio>
#include <random>

#include "cpm/kinematics/workspace.hpp"

namespace cpm::cal {
namespace {

class NoiseSource {
 public:
  explicit NoiseSource(const Noise& n) : n_(n), rng_(n.seed) {}
  double operator()() {
    if (n_.size == 0.0) return 0.0;
    if (n_.shape == NoiseShape::gaussian) return n_.size * normal_(rng_);
    return n_.size * (2.0 * uniform_(rng_) - 1.0);
  }

 private:
  Noise n_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  std::uniform_real_distribution<double> uniform_{0.0, 1.0};
};

std::string where(std::size_t j, const Vec3& p) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "pose %zu at (%.3f, %.3f, %.3f) mm", j + 1, p.x() * 1e3,
                p.y() * 1e3, p.z() * 1e3);
  return buf;
}

}  // namespace

double Noise::sigma() const {
  return shape == NoiseShape::gaussian ? size : size / std::sqrt(3.0);
}

std::vector<SimulatedPose> simulate_poses(const ctl::MachineModel& truth,
                                          const ctl::MachineModel& controller,
                                          const std::vector<Vec3>& commanded,
                                          const std::vector<kin::KinematicInputs>& inputs) {
  truth.validate();
  controller.validate();
  if (!inputs.empty() && inputs.size() != commanded.size())
    throw Error("simulated measurement: " + std::to_string(inputs.size()) + " kinematic inputs for " +
                std::to_string(commanded.size()) + " poses");
  std::vector<SimulatedPose> out;
  out.reserve(commanded.size());
  for (std::size_t j = 0; j < commanded.size(); ++j) {
    const kin::KinematicInputs in = inputs.empty() ? kin::KinematicInputs{} : inputs[j];
    SimulatedPose s;
    s.commanded = commanded[j];
    if (Status st = kin::check_pose(controller.kinematics, controller.strokes, s.commanded, in); !st)
      throw Error("simulated measurement: " + where(j, s.commanded) +
                  " is outside the controller's workspace: " + describe(st));
    if (Status st = kin::inverse(controller.kinematics, s.commanded, in, s.d); !st)
      throw Error("simulated measurement: " + where(j, s.commanded) + ": " + describe(st));
    if (Status st = kin::check_strokes(truth.strokes, s.d); !st)
      throw Error("simulated measurement: " + where(j, s.commanded) + ": " + describe(st));
    if (Status st = kin::forward(truth.kinematics, s.d, in, s.p_true); !st)
      throw Error("simulated measurement: " + where(j, s.commanded) +
                  ": the true machine cannot be there: " + describe(st));
    out.push_back(s);
  }
  return out;
}

std::vector<kin::KinematicInputs> sequence_inputs(const ctl::MachineModel& controller,
                                                  const std::vector<Vec3>& commanded, double dwell,
                                                  double t0) {
  std::vector<kin::KinematicInputs> out;
  kin::KinematicInputs in;
  Vec3 prev = Vec3::Zero();
  for (std::size_t j = 0; j < commanded.size(); ++j) {
    Vec3 d;
    if (Status st = kin::inverse(controller.kinematics, commanded[j], in, d); !st)
      throw Error("simulated measurement: " + where(j, commanded[j]) + ": " + describe(st));
    if (j > 0)
      for (int i = 0; i < 3; ++i)
        if (d[i] != prev[i]) in.dir[i] = d[i] > prev[i] ? +1 : -1;
    in.t = t0 + dwell * static_cast<double>(j);
    out.push_back(in);
    prev = d;
  }
  return out;
}

namespace {
void add_inputs(io::CommonColumns& extra, const std::vector<kin::KinematicInputs>& inputs) {
  for (const auto& in : inputs) {
    extra.t.push_back(in.t);
    extra.dir.push_back(in.dir);
  }
}
}  // namespace

io::BallbarData simulate_ballbar(const ctl::MachineModel& truth, const ctl::MachineModel& controller,
                                 const std::vector<Vec3>& commanded, const BallbarSimulation& sim) {
  const auto poses = simulate_poses(truth, controller, commanded, sim.inputs);
  NoiseSource noise(sim.noise);
  io::BallbarData b;
  b.pivot = sim.pivot_nominal;
  b.length_offset_known = sim.length_offset_known;
  b.info.metadata["kind"] = "ballbar";
  for (const SimulatedPose& s : poses) {
    b.d.push_back(s.d);
    b.length.push_back((s.p_true - sim.pivot_true).norm() - sim.length_offset + noise());
  }
  add_inputs(b.extra, sim.inputs);
  return b;
}

io::PositionData simulate_positions(const ctl::MachineModel& truth,
                                    const ctl::MachineModel& controller,
                                    const std::vector<Vec3>& commanded, const Noise& noise,
                                    const std::vector<kin::KinematicInputs>& inputs) {
  const auto poses = simulate_poses(truth, controller, commanded, inputs);
  NoiseSource n(noise);
  io::PositionData out;
  out.sigma = noise.sigma();
  out.info.metadata["kind"] = "position";
  for (const SimulatedPose& s : poses) {
    out.d.push_back(s.d);
    const double a = n(), b = n(), c = n();
    out.p.push_back(s.p_true + Vec3(a, b, c));
  }
  add_inputs(out.extra, inputs);
  return out;
}

}  // namespace cpm::cal

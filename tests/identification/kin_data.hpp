// SPDX-License-Identifier: Apache-2.0
// Ball-bar and position data for the kinematic identification tests: a true
// machine with Kim's fitted plane errors (and the pivot error of his
// experiment) plus planted kinematic effects, commanded through the nominal
// model, poses visited in a shuffled order (so every axis arrives from both
// directions) at a steady pace (so time advances), the QC10's +-0.5 µm on
// each length or a 3-D instrument's gaussian noise.
#pragma once

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "cpm/calibration/kim.hpp"
#include "cpm/calibration/simulate.hpp"
#include "cpm/kinematics/kinematic_effects.hpp"

namespace cpm::test {

struct PlantedKinematic {
  const char* effect = nullptr;  // nullptr: nothing planted
  int axis = 0;                  // 0..2
  std::array<double, 3> params{};
};

inline ctl::MachineModel kim_truth_with(const std::vector<PlantedKinematic>& planted, bool kim_errors = true) {
  ctl::MachineModel m = kim_errors ? cal::kim_true_machine() : ctl::MachineModel::elkady();
  for (const auto& p : planted) {
    if (!p.effect) continue;
    const auto t = *kin::kinematic_effect_from_name(p.effect);
    auto v = kin::get_params(m.kinematics.effects[p.axis], t);
    for (int j = 0; j < 3; ++j) v[j] += p.params[j];
    kin::set_params(m.kinematics.effects[p.axis], t, v);
  }
  return m;
}

// Points on hemispheres about the pivot (the reachable side, z up = smaller),
// `rings` polar angles from 15 to 80 degrees, `per_ring` azimuths; shuffled.
inline std::vector<Vec3> hemisphere_poses(const std::vector<double>& radii, int rings, int per_ring,
                                          std::uint64_t seed, const Vec3& pivot = cal::kim_pivot()) {
  std::vector<Vec3> out;
  const auto nominal = ctl::MachineModel::elkady();
  for (std::size_t ri = 0; ri < radii.size(); ++ri)
    for (int k = 0; k < rings; ++k) {
      const double th = (15.0 + 65.0 * k / std::max(1, rings - 1)) * std::numbers::pi / 180.0;
      for (int a = 0; a < per_ring; ++a) {
        const double ph = 2.0 * std::numbers::pi * (a + 0.5 * (k % 2) + 0.25 * ri) / per_ring;
        const Vec3 p = pivot + radii[ri] * Vec3(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), -std::cos(th));
        try {
          cal::check_poses(nominal, {p});
          out.push_back(p);
        } catch (const Error&) {
        }
      }
    }
  std::mt19937_64 rng(seed);
  std::shuffle(out.begin(), out.end(), rng);
  return out;
}

struct KinSimOptions {
  std::uint64_t seed = 1;
  double dwell = 20.0;        // s between poses
  double noise = 0.5e-6;      // ball-bar: half-width of the uniform error; position: sigma
  bool with_dir = true;
  bool with_time = true;
  bool length_offset_known = true;
  bool one_direction = false; // every pose approached from the + side on every axis
  bool kim_errors = true;     // false: the true planes are nominal (only the planted effects and the pivot error)
};

inline io::BallbarData kim_ballbar(const std::vector<PlantedKinematic>& planted, const std::vector<Vec3>& poses,
                                   const KinSimOptions& o = {}) {
  const auto truth = kim_truth_with(planted, o.kim_errors);
  const auto nominal = ctl::MachineModel::elkady();
  cal::BallbarSimulation sim;
  sim.pivot_nominal = cal::kim_pivot();
  sim.pivot_true = cal::kim_pivot() + cal::kim_fitted_errors().dq;
  sim.noise = {cal::NoiseShape::uniform, o.noise, o.seed};
  sim.length_offset_known = o.length_offset_known;
  sim.inputs = cal::sequence_inputs(nominal, poses, o.dwell, 60.0);
  if (o.one_direction)
    for (auto& in : sim.inputs) in.dir = {+1, +1, +1};
  io::BallbarData b = cal::simulate_ballbar(truth, nominal, poses, sim);
  b.info.path = "simulated.csv";
  if (!o.with_dir) b.extra.dir.clear();
  if (!o.with_time) b.extra.t.clear();
  return b;
}

inline io::PositionData kim_positions(const std::vector<PlantedKinematic>& planted, const std::vector<Vec3>& poses,
                                      const KinSimOptions& o = {}) {
  const auto truth = kim_truth_with(planted, o.kim_errors);
  const auto nominal = ctl::MachineModel::elkady();
  auto inputs = cal::sequence_inputs(nominal, poses, o.dwell, 60.0);
  if (o.one_direction)
    for (auto& in : inputs) in.dir = {+1, +1, +1};
  io::PositionData p = cal::simulate_positions(truth, nominal, poses, {cal::NoiseShape::gaussian, o.noise, o.seed}, inputs);
  p.info.path = "simulated.csv";
  if (!o.with_dir) p.extra.dir.clear();
  if (!o.with_time) p.extra.t.clear();
  return p;
}

}  // namespace cpm::test

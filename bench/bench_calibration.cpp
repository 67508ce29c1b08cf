// SPDX-License-Identifier: Apache-2.0
// Calibration solve times: Kim's 32-point ball-bar problem (LM + the
// identifiability analysis), and a 25-pose full-position problem.
#include <benchmark/benchmark.h>

#include "cpm/calibration/ballbar.hpp"
#include "cpm/calibration/kim.hpp"
#include "cpm/calibration/position.hpp"
#include "cpm/calibration/simulate.hpp"

namespace {

using namespace cpm;
using namespace cpm::cal;

void BM_KimBallbarFit(benchmark::State& state) {
  KimOptions o;
  o.circular_test = false;
  const KimReproduction k = reproduce_kim(o);
  const kin::KinematicModel nominal = kin::KinematicModel::nominal();
  for (auto _ : state) {
    BallbarFit f = fit_ballbar(nominal, k.data.d, k.data.length, kim_pivot());
    benchmark::DoNotOptimize(f.params.theta_z);
  }
}
BENCHMARK(BM_KimBallbarFit)->Unit(benchmark::kMicrosecond);

void BM_PositionFit25(benchmark::State& state) {
  std::vector<Vec3> cmd;
  for (int k = 0; k < 25; ++k)
    cmd.emplace_back(0.28 + 0.012 * k, 0.30 + 0.25 * ((k * 7) % 25) / 25.0, 0.26 + 0.2 * ((k * 11) % 25) / 25.0);
  const io::PositionData pd = simulate_positions(kim_true_machine(), ctl::MachineModel::elkady(), cmd,
                                                 {NoiseShape::gaussian, 2e-6, 1});
  for (auto _ : state) {
    PositionFit f = fit_positions(kin::KinematicModel::nominal(), pd.d, pd.p);
    benchmark::DoNotOptimize(f.model.planes[0].scale);
  }
}
BENCHMARK(BM_PositionFit25)->Unit(benchmark::kMicrosecond);

}  // namespace

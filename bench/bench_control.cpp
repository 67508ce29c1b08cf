// SPDX-License-Identifier: Apache-2.0
// Benchmarks of the real-time core: one control step and one plant step.
// Speed is shown here, never asserted by a timed test.
#include <benchmark/benchmark.h>

#include "cpm/control/controller.hpp"
#include "cpm/control/gain_check.hpp"
#include "cpm/sim/plant.hpp"
#include "bench_models.hpp"

namespace {

using namespace cpm;

using bench::calibrated_model_with_effects;

// tau > 0: the model has an actuation delay, so each step also predicts
// across it (tau / 0.1 ms RK4 steps of the model's forward dynamics).
void control_step(benchmark::State& state, ctl::ControlLaw law, bool calibrated, double tau = 0.0) {
  ctl::MachineModel mm = calibrated ? calibrated_model_with_effects() : ctl::MachineModel::elkady();
  if (tau > 0.0) ctl::add_effect(mm, "actuation_delay", -1, {tau});
  const ctl::Machine model(std::move(mm));
  const ctl::Controller controller(model, law, ctl::table3_gains(law));
  const ctl::CircleTrajectory circle(ctl::CircleSpec{});
  ctl::ControlInput in;
  ctl::ControlOutput out;
  ctl::ControllerState history;
  double t = 0.0;
  for (auto _ : state) {
    in.ref = circle.sample(t + tau);
    in.d = circle.sample(t).p - model.kinematics().d0 + Vec3(1e-5, -2e-5, 3e-5);
    in.d_dot = in.ref.v;
    in.kin.t += 1e-3;  // the history's clock never goes back
    const Status s = controller.step(in, history, out);
    benchmark::DoNotOptimize(s);
    benchmark::DoNotOptimize(out.force);
    t = t < 3.999 ? t + 1e-3 : 0.0;
  }
}
BENCHMARK_CAPTURE(control_step, computed_torque_nominal, ctl::ControlLaw::computed_torque, false);
BENCHMARK_CAPTURE(control_step, computed_torque_calibrated_effects, ctl::ControlLaw::computed_torque, true);
BENCHMARK_CAPTURE(control_step, pd_feedforward_calibrated_effects, ctl::ControlLaw::pd_feedforward, true);
BENCHMARK_CAPTURE(control_step, pd_nominal, ctl::ControlLaw::pd, false);
BENCHMARK_CAPTURE(control_step, computed_torque_nominal_delay_1ms, ctl::ControlLaw::computed_torque, false, 1e-3);

void plant_step(benchmark::State& state, bool calibrated) {
  const ctl::Machine truth(calibrated ? calibrated_model_with_effects() : ctl::MachineModel::elkady());
  sim::Plant plant(truth, sim::PlantOptions{});
  const Vec3 start(0.6, 0.425, 0.3);
  (void)plant.reset(start);
  const Vec3 hold(0.0, 0.0, -truth.inertia().E);
  long k = 0;
  for (auto _ : state) {
    const Status s = plant.step(hold, 1e-3);
    benchmark::DoNotOptimize(s);
    if (++k % 2000 == 0) (void)plant.reset(start);
  }
  state.counters["sim_s_per_wall_s"] =
      benchmark::Counter(1e-3 * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK_CAPTURE(plant_step, nominal_1ms_rk4x10, false);
BENCHMARK_CAPTURE(plant_step, calibrated_effects_1ms_rk4x10, true);

// The gain check cpmd makes on its command thread before it takes a law or
// gains (budget: well under 10 ms). Its cost grows with the delay in periods:
// the loop's polynomial has degree ~ tau / T.
void gain_check(benchmark::State& state, ctl::ControlLaw law, double rate_hz, double tau) {
  ctl::MachineModel mm = ctl::MachineModel::elkady();
  if (tau > 0.0) ctl::add_effect(mm, "actuation_delay", -1, {tau});
  const ctl::Machine model(std::move(mm));
  const ctl::Gains gains = ctl::table3_gains(law);
  for (auto _ : state) {
    ctl::GainVerdict v = ctl::check_gains(model, law, gains, rate_hz, 0.005);
    benchmark::DoNotOptimize(v);
  }
}
BENCHMARK_CAPTURE(gain_check, pd_1kHz, ctl::ControlLaw::pd, 1000.0, 0.0)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(gain_check, pd_gravity_1kHz_delay_1_period, ctl::ControlLaw::pd_gravity, 1000.0, 1e-3)
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(gain_check, computed_torque_1kHz_delay_1_period, ctl::ControlLaw::computed_torque, 1000.0, 1e-3)
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(gain_check, pd_gravity_1kHz_delay_10_periods, ctl::ControlLaw::pd_gravity, 1000.0, 10e-3)
    ->Unit(benchmark::kMillisecond);
// The largest delay the model allows at the highest rate: 500 periods.
BENCHMARK_CAPTURE(gain_check, pd_gravity_10kHz_delay_50ms, ctl::ControlLaw::pd_gravity, 10000.0, 50e-3)
    ->Unit(benchmark::kMillisecond);

}  // namespace

// SPDX-License-Identifier: Apache-2.0
// The stages of prepare_motion (identification/src/motion_stages.hpp) on
// synthetic logs whose answer is known in closed form: sampling and segments,
// the acceleration source, the kept rows (state, acceleration, the force at
// every shift, the force-gain instrument) and the base columns.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <numbers>
#include <random>
#include <string>

#include "cpm/identification/motion.hpp"
#include "io/io_test_util.hpp"
#include "motion_stages.hpp"

namespace cpm::ident {
namespace {

using namespace motion_stages;
using test::error_of;  // the message of the Error a callable throws, "" when none

// A log of n samples at period dt with d(t), v(t) per axis and zero force;
// file "log.csv" whose data start on line 10.
io::MotionData make_log(int n, double dt, const std::function<Vec3(double)>& d,
                        const std::function<Vec3(double)>& v) {
  io::MotionData data;
  data.info.path = "log.csv";
  for (int k = 0; k < n; ++k) {
    const double t = k * dt;
    data.t.push_back(t);
    data.d.push_back(d(t));
    data.v.push_back(v(t));
    data.f.push_back(Vec3::Zero());
    data.info.line_of_row.push_back(k + 10);
  }
  return data;
}

// A log that does not move.
io::MotionData still_log(int n, double dt = 1e-3) {
  return make_log(
      n, dt, [](double) { return Vec3::Zero(); }, [](double) { return Vec3::Zero(); });
}

// Slow cubic motion around the middle of the workspace: d = c + s(t) e, with
// s(t) = 0.02 (u^3 - 1.5 u^2 + 0.5 u), u = t / T (m), so that every
// Savitzky-Golay kernel of degree >= 3 is exact on it.
struct CubicMotion {
  double T = 3.0;
  Vec3 centre = Vec3(0.425, 0.425, 0.36);
  Vec3 dir = Vec3(1.0, -0.7, 0.5);
  [[nodiscard]] double s(double t) const {
    const double u = t / T;
    return 0.02 * (u * u * u - 1.5 * u * u + 0.5 * u);
  }
  [[nodiscard]] double s_dot(double t) const {
    const double u = t / T;
    return 0.02 * (3 * u * u - 3 * u + 0.5) / T;
  }
  [[nodiscard]] double s_ddot(double t) const { return 0.02 * (6 * t / T - 3) / (T * T); }
  [[nodiscard]] io::MotionData log(double dt) const {
    return make_log(
        static_cast<int>(T / dt), dt, [&](double t) { return Vec3(centre + s(t) * dir); },
        [&](double t) { return Vec3(s_dot(t) * dir); });
  }
};

// ---- Stage 1 ----

TEST(MotionSampling, SegmentsSplitAtASamplingGapAndAtANewRun) {
  const double dt = 1e-3;
  io::MotionData data = still_log(60, dt);
  data.run.assign(60, 0);
  for (int k = 21; k < 40; ++k) data.t[k] += 4e-3;  // a 5 ms step between samples 20 and 21
  for (int k = 40; k < 60; ++k) {                   // a new run whose clock starts again
    data.run[k] = 1;
    data.t[k] = (k - 40) * dt;
  }
  const Sampling S = read_sampling(data);
  EXPECT_NEAR(S.dt, dt, 1e-12);
  EXPECT_EQ(S.segments, 3);
  for (int k = 0; k < 60; ++k) {
    const int start = k < 21 ? 0 : k < 40 ? 21 : 40;
    const int end = k < 21 ? 21 : k < 40 ? 40 : 60;
    EXPECT_EQ(S.segment_start[k], start) << k;
    EXPECT_EQ(S.segment_end[k], end) << k;
  }
  // The gap is reported at its file line; a new run is no gap.
  ASSERT_EQ(S.warnings.size(), 1u);
  EXPECT_NE(S.warnings[0].find("log.csv:31: sampling gap of 5"), std::string::npos) << S.warnings[0];
}

TEST(MotionSampling, TimeThatDoesNotIncreaseIsRefusedWithFileAndLine) {
  io::MotionData data = still_log(40);
  data.t[15] = data.t[14];
  const std::string msg = error_of([&] { (void)read_sampling(data); });
  EXPECT_NE(msg.find("log.csv:25: time does not increase"), std::string::npos) << msg;
  data.info.line_of_row.clear();  // no line numbers: the sample instead
  const std::string msg2 = error_of([&] { (void)read_sampling(data); });
  EXPECT_NE(msg2.find("log.csv (sample 16)"), std::string::npos) << msg2;
}

TEST(MotionSampling, ColumnsOfDifferentLengthsAndTooShortLogsAreRefused) {
  io::MotionData data = still_log(40);
  data.f.pop_back();
  EXPECT_EQ(error_of([&] { (void)read_sampling(data); }), "log.csv: columns of different lengths");
  const io::MotionData short_log = still_log(9);
  EXPECT_NE(error_of([&] { (void)read_sampling(short_log); }).find("log.csv: too few samples (9)"), std::string::npos);
}

TEST(MotionSampling, KernelHalfWidthIsTheHalfWindowInSamples) {
  const io::MotionData data = CubicMotion{}.log(1e-3);
  MotionOptions o;
  o.half_window = 0.012;
  EXPECT_EQ(kernel_half_width(data, 1e-3, o), 12);
  o.half_window = 0.0004;  // rounds to 0 samples: at least 2
  o.order = 4;
  EXPECT_EQ(kernel_half_width(data, 1e-3, o), 2);
  o.order = 5;             // degree 5 needs 6 samples in the window
  EXPECT_THROW((void)kernel_half_width(data, 1e-3, o), Error);
}

// ---- Stage 2 ----

// A 1 Hz sine on every axis with planted white noise on d and v.
io::MotionData noisy_sine(double sigma_d, double sigma_v, std::uint64_t seed) {
  const double w = 2.0 * std::numbers::pi;
  io::MotionData data = make_log(
      4000, 1e-3, [&](double t) { return Vec3::Constant(0.05 * std::sin(w * t)); },
      [&](double t) { return Vec3::Constant(0.05 * w * std::cos(w * t)); });
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> nd(0.0, sigma_d), nv(0.0, sigma_v);
  for (int k = 0; k < 4000; ++k)
    for (int i = 0; i < 3; ++i) {
      data.d[k][i] += nd(rng);
      data.v[k][i] += nv(rng);
    }
  return data;
}

// RMS error of the acceleration at the rows' time (t_k + dt/2) against the true one.
double acceleration_error(const io::MotionData& data, const AccelerationEstimate& A) {
  const double w = 2.0 * std::numbers::pi, dt = 1e-3;
  double s = 0.0;
  int count = 0;
  for (int k = 50; k < 3950; ++k) {
    const double truth = -0.05 * w * w * std::sin(w * (data.t[k] + 0.5 * dt));
    for (int i = 0; i < 3; ++i, ++count) s += std::pow(acceleration_at(data, A, A.half, dt, k, i) - truth, 2);
  }
  return std::sqrt(s / count);
}

TEST(MotionAcceleration, TheLessNoisySourceIsPickedForPlantedNoiseLevels) {
  struct Case {
    double sigma_d, sigma_v;
    AccelerationEstimate::Source expected;
  };
  for (const Case& c : {Case{1e-8, 2e-3, AccelerationEstimate::Source::position},
                        Case{1e-5, 1e-5, AccelerationEstimate::Source::velocity}}) {
    const io::MotionData data = noisy_sine(c.sigma_d, c.sigma_v, 7);
    MotionOptions o;
    const AccelerationEstimate A = choose_acceleration(data, 1e-3, 12, o);
    // The planted noise is what the smoother finds.
    for (int i = 0; i < 3; ++i) {
      EXPECT_NEAR(A.position_noise[i], c.sigma_d, 0.15 * c.sigma_d);
      EXPECT_NEAR(A.velocity_noise[i], c.sigma_v, 0.15 * c.sigma_v);
    }
    EXPECT_EQ(A.source, c.expected) << A.text;
    // ... and the source picked is the one with the smaller actual error.
    o.accel = MotionOptions::Accel::velocity;
    const double e_velocity = acceleration_error(data, choose_acceleration(data, 1e-3, 12, o));
    o.accel = MotionOptions::Accel::position;
    const double e_position = acceleration_error(data, choose_acceleration(data, 1e-3, 12, o));
    EXPECT_LT(acceleration_error(data, A), 1.0001 * std::min(e_velocity, e_position));
    EXPECT_EQ(A.source == AccelerationEstimate::Source::position, e_position < e_velocity);
  }
}

TEST(MotionAcceleration, MeasuredAccelerationsAreUsedAndFilteredLikeTheForce) {
  io::MotionData data = noisy_sine(1e-8, 2e-3, 3);
  data.a.assign(data.t.size(), Vec3::Constant(0.25));
  const AccelerationEstimate A = choose_acceleration(data, 1e-3, 12, MotionOptions{});
  EXPECT_EQ(A.source, AccelerationEstimate::Source::measured);
  EXPECT_NE(A.text.find("measured"), std::string::npos);
  EXPECT_EQ(A.accel_noise, Vec3::Zero());
  EXPECT_EQ(A.smooth_force.h, A.at_sample.h);
  EXPECT_NEAR(acceleration_at(data, A, A.half, 1e-3, 100, 1), 0.25, 1e-12);
}

// ---- Stage 3 ----

TEST(MotionSampleStates, TheStateOfACubicMotionIsExactAtEverySampleEndsIncluded) {
  const CubicMotion c;
  const io::MotionData data = c.log(1e-3);
  const Sampling S = read_sampling(data);
  const MotionOptions o;
  const AccelerationEstimate A = choose_acceleration(data, S.dt, 12, o);
  const SampleStates X = estimate_sample_states(data, S, A, o);
  ASSERT_EQ(X.d_hat.size(), data.t.size());
  for (std::size_t k = 0; k < data.t.size(); k += 7) {
    EXPECT_LT((X.d_hat[k] - data.d[k]).norm(), 1e-12) << k;
    EXPECT_LT((X.v_hat[k] - data.v[k]).norm(), 1e-9) << k;
  }
}

// ---- Stage 4 ----

TEST(MotionRows, KeptSamplesHaveEveryWindowInsideTheirSegment) {
  Sampling S;
  S.segment_end.assign(100, 100);
  S.segment_end.resize(250, 250);
  const int m = 5, stride = 5, past = 10;
  const std::vector<int> rows = kept_samples(S, m, stride, past);
  const int lo = std::max(2 * m, m + MotionProblem::kShiftHi) + past;      // 21
  const int hi = std::max(2 * m, m - MotionProblem::kShiftLo + 1) + past;  // 20
  std::vector<int> expected;
  for (int k = lo; k + hi < 100; k += stride) expected.push_back(k);
  for (int k = 100 + lo; k + hi < 250; k += stride) expected.push_back(k);
  EXPECT_EQ(rows, expected);
  EXPECT_EQ(rows.front(), 21);
  EXPECT_EQ(rows.back(), 226);
}

MotionProblem cubic_problem(const CubicMotion& c, MotionOptions o = {}) {
  return prepare_motion(c.log(1e-3), ctl::Machine(ctl::MachineModel::elkady()), o);
}

TEST(MotionRows, ColumnAccelerationAgreesWithTheRowsOnASlowPolynomialMotion) {
  const CubicMotion c;
  for (auto source : {MotionOptions::Accel::velocity, MotionOptions::Accel::position}) {
    MotionOptions o;
    o.accel = source;
    const MotionProblem P = cubic_problem(c, o);
    ASSERT_GT(P.rows(), 30);
    for (int r = 0; r < P.rows(); ++r) {
      const double t = P.t[r];
      EXPECT_NEAR(t, P.sample[r] * 1e-3 + 0.5e-3, 1e-12);
      const Vec3 a = c.s_ddot(t) * c.dir;
      EXPECT_LT((P.a[r] - a).norm(), 1e-6 * a.norm() + 1e-9) << r;
      EXPECT_LT((P.a_columns[r] - a).norm(), 1e-6 * a.norm() + 1e-9) << r;
      EXPECT_LT((P.d[r] - (c.centre + c.s(t) * c.dir)).norm(), 1e-12) << r;
      EXPECT_LT((P.v[r] - c.s_dot(t) * c.dir).norm(), 1e-9) << r;
    }
  }
}

TEST(MotionRows, TheForceAtShiftNIsTheFilteredForceNSamplesEarlier) {
  const CubicMotion c;
  io::MotionData data = c.log(1e-3);
  std::mt19937_64 rng(11);
  std::normal_distribution<double> n(0.0, 5.0);
  for (auto& f : data.f) f = Vec3(n(rng), n(rng), n(rng));
  ctl::MachineModel mm = ctl::MachineModel::elkady();
  ctl::add_effect(mm, "force_gain", 1, {0.1});  // a drive gain of 1.1 on axis 2
  const ctl::Machine model(mm);
  MotionOptions o;
  o.stride = 1;  // rows at consecutive samples
  const MotionProblem P = prepare_motion(data, model, o);
  ASSERT_NEAR(P.drive_gain[1], 1.1, 1e-15);
  ASSERT_EQ(P.delay, 0.0);  // the model's own alignment: f is the shift-0 force
  for (int r = 20; r + 2 < P.rows(); r += 13)
    for (int shift = MotionProblem::kShiftLo; shift <= MotionProblem::kShiftHi; ++shift) {
      ASSERT_EQ(P.sample[r - shift], P.sample[r] - shift);
      for (int i = 0; i < 3; ++i)
        EXPECT_NEAR(P.force_at_shift(3 * r + i, shift - MotionProblem::kShiftLo), P.drive_gain[i] * P.f[r - shift][i],
                    1e-12)
            << r << " " << shift << " " << i;
    }
  // A whole shift of delay is that column; half way between, the mean of two.
  const Eigen::VectorXd at1 = P.force_delayed(1.0 * P.dt), at2 = P.force_delayed(2.0 * P.dt);
  EXPECT_LT((at1 - P.force_at_shift.col(1 - MotionProblem::kShiftLo)).norm(), 1e-12);
  EXPECT_LT((P.force_delayed(1.5 * P.dt) - 0.5 * (at1 + at2)).norm(), 1e-9);
  // Beyond the range the last shift.
  EXPECT_LT((P.force_delayed(1.0) - P.force_at_shift.col(P.force_at_shift.cols() - 1)).norm(), 1e-12);
}

TEST(MotionRows, AConstantForceIsKeptAsItIsAtEveryShift) {
  const CubicMotion c;
  io::MotionData data = c.log(1e-3);
  for (auto& f : data.f) f = Vec3(2.0, -3.0, 7.0);
  const MotionProblem P = prepare_motion(data, ctl::Machine(ctl::MachineModel::elkady()));
  for (int r = 0; r < P.rows(); ++r)
    for (int q = 0; q < P.force_at_shift.cols(); ++q)
      for (int i = 0; i < 3; ++i) EXPECT_NEAR(P.force_at_shift(3 * r + i, q), data.f[0][i], 1e-12);
}

TEST(MotionRows, TheForceGainInstrumentRecoversACubicForceFromAroundTheWindow) {
  const CubicMotion c;
  io::MotionData data = c.log(1e-3);
  // f(k) = 1 + 0.02 k - 1e-5 k^2 + 2e-9 k^3 on every axis (k: sample index).
  auto f = [](double k) { return 1.0 + 0.02 * k - 1e-5 * k * k + 2e-9 * k * k * k; };
  for (std::size_t k = 0; k < data.f.size(); ++k) data.f[k] = Vec3::Constant(f(static_cast<double>(k)));
  const MotionProblem P = prepare_motion(data, ctl::Machine(ctl::MachineModel::elkady()));
  const ForceInstrument I = force_instrument(P.half_width);
  EXPECT_EQ(P.past_samples, I.samples);
  EXPECT_EQ(I.around.front(), -(P.past_gap + P.past_samples - 1));
  EXPECT_EQ(I.around.back(), P.future_gap + P.past_samples - 1);
  for (int r = 0; r < P.rows(); r += 5) {
    const double k = P.sample[r];
    // The same cubic about sample k: f(k + u) = c0 + c1 u + c2 u^2 + c3 u^3.
    const double c0 = f(k), c1 = 0.02 - 2e-5 * k + 6e-9 * k * k, c2 = -1e-5 + 6e-9 * k, c3 = 2e-9;
    for (int i = 0; i < 3; ++i) {
      EXPECT_NEAR(P.f_past(3 * r + i, 0), c0, 1e-9 * std::fabs(c0));
      EXPECT_NEAR(P.f_past(3 * r + i, 1), c1, 1e-8 * std::fabs(c1) + 1e-12);
      EXPECT_NEAR(P.f_past(3 * r + i, 2), c2, 1e-8 * std::fabs(c2) + 1e-12);
      EXPECT_NEAR(P.f_past(3 * r + i, 3), c3, 1e-6 * c3);
      // At the model's alignment (0) the force acting over the row's interval
      // was commanded half a sample after t_k.
      EXPECT_NEAR(P.f_predicted[r][i], f(k + 0.5), 1e-9 * std::fabs(c0));
    }
  }
}

TEST(MotionRows, TooFewRowsAreRefusedSayingHowLongALogWouldDo) {
  CubicMotion c;
  c.T = 0.12;
  const std::string msg = error_of([&] { (void)cubic_problem(c); });
  EXPECT_NE(msg.find("log.csv: too few samples: "), std::string::npos) << msg;
  EXPECT_NE(msg.find("s of motion in one piece"), std::string::npos) << msg;
}

// ---- Stage 5 ----

TEST(MotionBase, TheColumnsOfAAndEAreJTransposeTimesTheirShareOfThePlatformForce) {
  // M = 2A I + ..., K = -(0, 0, E) + ...: per unit of A the platform force
  // gains 2 p_dd, per unit of E it loses (0, 0, 1); the nominal kinematics
  // make p_dd = J a exactly.
  const ctl::Machine model(ctl::MachineModel::elkady());
  const MotionProblem P = cubic_problem(CubicMotion{});
  ASSERT_EQ(P.base_params[0].name, "A");
  ASSERT_EQ(P.base_params[3].name, "E");
  const std::vector<kin::KinematicInputs> in = row_kinematic_inputs(P);
  for (int r = 0; r < P.rows(); ++r) {
    ctl::TaskState ts;
    ASSERT_TRUE(model.task_state(P.d[r], P.v[r], in[r], ts));
    const Vec3 p_dd = ts.J * P.a_columns[r];
    const Vec3 col_a = ts.J.transpose() * (2.0 * p_dd);
    const Vec3 col_e = ts.J.transpose() * Vec3(0.0, 0.0, -1.0);
    EXPECT_LT((P.base.block<3, 1>(3 * r, 0) - col_a).norm(), 1e-9 + 1e-7 * col_a.norm()) << r;
    EXPECT_LT((P.base.block<3, 1>(3 * r, 3) - col_e).norm(), 1e-9) << r;
  }
}

TEST(MotionBase, ParametersAreTheConstantsTheModelsEffectsAndThePlaneNuisance) {
  ctl::MachineModel mm = ctl::MachineModel::elkady();
  ctl::add_effect(mm, "viscous_friction", 0, {2.0});
  const ctl::Machine model(mm);
  const std::vector<BaseParameter> base = model_base_parameters(model);
  ASSERT_EQ(base.size(), 5u);
  EXPECT_EQ(base[0].value, model.inertia().A);
  EXPECT_EQ(base[4].effect, 0);
  EXPECT_EQ(base[4].value, 2.0);
  std::vector<BaseParameter> tilt = base, coupling = base;
  const std::vector<Perturbation> pt = nuisance_parameters(mm, MotionOptions::Nuisance::tilt, tilt);
  EXPECT_EQ(pt.size(), 9u);  // two tilts and the offset of each plane
  EXPECT_EQ(tilt.size(), base.size() + 9);
  EXPECT_TRUE(nuisance_parameters(mm, MotionOptions::Nuisance::coupling, coupling).empty());
  EXPECT_EQ(coupling.size(), base.size() + 6);  // i <- j, i != j
  EXPECT_EQ(coupling.back().name, "coupling[3<-2]");
}

TEST(MotionBase, ARowTheModelCannotFollowIsNamedByFileAndLine) {
  const CubicMotion c;
  const io::MotionData data = c.log(1e-3);
  const ctl::Machine model(ctl::MachineModel::elkady());
  MotionProblem P = prepare_motion(data, model);
  P.d[3] = Vec3(5.0, 5.0, 5.0);  // far outside the workspace
  const std::string msg = error_of([&] { (void)rigid_body_force(model, data, P, row_kinematic_inputs(P), P.a); });
  const std::string where_expected = "log.csv:" + std::to_string(P.sample[3] + 10) + ": the model cannot follow";
  EXPECT_NE(msg.find(where_expected), std::string::npos) << msg;
}

}  // namespace
}  // namespace cpm::ident

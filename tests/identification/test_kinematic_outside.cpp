// SPDX-License-Identifier: Apache-2.0
// Kinematic data in the open world (issue 26): a lead screw whose pitch error
// grows smoothly along one axis' stroke, which no library effect describes.
//
// The generator is written apart from the estimator: the true machine is
// Kim's (calibration's kim_true_machine, its pivot error), the drives settle
// where the nominal model sends them (cal::simulate_poses gives the encoder
// readings d), and the pitch error is planted here by hand: the carriage of
// axis i really stands at d_i + e(d_i), so the platform is at
// forward(truth, d + e) and the bar reads its distance to the true pivot plus
// the bar's noise (uniform +-0.5 µm: sigma 0.289 µm), the position instrument
// the point plus gaussian noise (sigma 2 µm). Nothing of the diagnosis'
// columns, sensitivities or effect models is used.
//
// e(d) = A u^2 (quadratic), A u^3 (cubic) or A (exp(2u) - 1) / (e^2 - 1)
// (exponential: no polynomial), u = (d - lo) / (hi - lo) over the
// stroke the poses cover: zero at one end, A at the other. Its size is set by
// its curved part (what no offset or scale of the axis takes, which is what
// the data can show): the peak to peak of e less its best straight line over
// the stroke is `multiple` x the noise sigma.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>

#include <Eigen/Dense>
#include <nlohmann/json.hpp>

#include "cpm/calibration/kim.hpp"
#include "cpm/calibration/simulate.hpp"
#include "cpm/identification/kinematic.hpp"
#include "cpm/identification/kinematic_stages.hpp"
#include "cpm/identification/model_loop.hpp"
#include "cpm/io/model_file.hpp"
#include "cpm/identification/report.hpp"
#include "identification/kin_data.hpp"

namespace cpm::test {
namespace {

constexpr double kBarHalfWidth = 0.5e-6;                       // uniform +-0.5 µm
const double kBarSigma = kBarHalfWidth / std::sqrt(3.0);         // 0.289 µm
constexpr double kPosSigma = 2e-6;

struct PitchSet {
  bool position = false;
  std::vector<double> radii{0.150};
  int axis = 0;          // 0..2, the axis with the pitch error
  int shape = 0;         // e = A u^2, A u^3, A (exp(2u) - 1) / (e^2 - 1)
  double multiple = 0.0; // curved part, peak to peak, in noise sigmas (0: a null set)
  std::uint64_t seed = 1;
  bool noise = true;     // false: the exact readings (a test adds its own noise)
  std::vector<PlantedKinematic> library{};  // library effects planted beside it (kin_data.hpp)
  double bar_half_width = 0.5e-6;           // m, the bar's uniform noise
};

// Where the kink shape stops growing, as a fraction of the stroke.
constexpr double kKnee = 0.6;

// Peak to peak of u^n less its least-squares line over u in [0, 1] (fine grid).
double shape_of(int shape, double u) {
  if (shape == 2) return std::expm1(2.0 * u) / std::expm1(2.0);
  if (shape == 3) return std::min(u, kKnee) / kKnee;  // a kink: grows to the knee, flat beyond
  return std::pow(u, shape == 1 ? 3 : 2);
}
const char* shape_name(int shape) {
  return shape == 0 ? "quadratic" : shape == 1 ? "cubic" : shape == 2 ? "exponential" : "kink";
}

double curved_part_ptp(int shape) {
  const int n = 1001;
  double su = 0, sv = 0, suu = 0, suv = 0;
  for (int k = 0; k < n; ++k) {
    const double u = static_cast<double>(k) / (n - 1), v = shape_of(shape, u);
    su += u; sv += v; suu += u * u; suv += u * v;
  }
  const double b = (n * suv - su * sv) / (n * suu - su * su), a = (sv - b * su) / n;
  double lo = 1e300, hi = -1e300;
  for (int k = 0; k < n; ++k) {
    const double u = static_cast<double>(k) / (n - 1), r = shape_of(shape, u) - a - b * u;
    lo = std::min(lo, r);
    hi = std::max(hi, r);
  }
  return hi - lo;
}

io::DataSet pitch_data(const PitchSet& s) {
  const std::vector<Vec3> poses =
      s.position ? hemisphere_poses(s.radii, 5, 12, s.seed) : hemisphere_poses(s.radii, 6, 16, s.seed);
  const auto truth = kim_truth_with(s.library);
  const auto nominal = ctl::MachineModel::elkady();
  const auto inputs = cal::sequence_inputs(nominal, poses, 20.0, 60.0);
  const std::vector<cal::SimulatedPose> sim = cal::simulate_poses(truth, nominal, poses, inputs);
  double lo = 1e300, hi = -1e300;
  for (const auto& q : sim) {
    lo = std::min(lo, q.d[s.axis]);
    hi = std::max(hi, q.d[s.axis]);
  }
  const double sigma = s.position ? kPosSigma : s.bar_half_width / std::sqrt(3.0);
  const double on = s.noise ? 1.0 : 0.0;
  const double A = s.multiple * sigma / curved_part_ptp(s.shape);
  std::mt19937_64 rng(s.seed * 7919 + 13);
  std::uniform_real_distribution<double> bar(-s.bar_half_width, s.bar_half_width);
  std::normal_distribution<double> gauss(0.0, kPosSigma);
  const Vec3 pivot_true = cal::kim_pivot() + cal::kim_fitted_errors().dq;
  io::BallbarData b;
  io::PositionData p;
  for (std::size_t j = 0; j < sim.size(); ++j) {
    Vec3 actual = sim[j].d;
    const double u = (sim[j].d[s.axis] - lo) / (hi - lo);
    actual[s.axis] += A * shape_of(s.shape, u);
    Vec3 pt;
    if (!kin::forward(truth.kinematics, actual, inputs[j], pt)) throw Error("pitch_data: forward kinematics failed");
    if (s.position) {
      p.d.push_back(sim[j].d);
      p.p.push_back(pt + on * Vec3(gauss(rng), gauss(rng), gauss(rng)));
    } else {
      b.d.push_back(sim[j].d);
      b.length.push_back((pt - pivot_true).norm() + on * bar(rng));
    }
  }
  auto fill = [&](io::CommonColumns& c) {
    for (const auto& in : inputs) {
      c.t.push_back(in.t);
      c.dir.push_back(in.dir);
    }
  };
  if (s.position) {
    p.info.path = "pitch.csv";
    fill(p.extra);
    return p;
  }
  b.info.path = "pitch.csv";
  b.pivot = cal::kim_pivot();
  b.length_offset_known = true;
  fill(b.extra);
  return b;
}

ident::Diagnosis diagnose(const io::DataSet& ds) {
  return ident::diagnose_kinematic(std::make_shared<const ident::KinematicProblem>(
      ident::prepare_kinematic(ds, ctl::MachineModel::elkady().kinematics)));
}

bool outside_on(const ident::Diagnosis& D, int axis) {
  return !D.outside_library.empty() && D.outside_library.front().axis == axis;
}

std::string named_text(const ident::Diagnosis& D) {
  std::string s;
  if (!D.outside_library.empty()) s += "outside_library[axis " + std::to_string(D.outside_library.front().axis + 1) + "] ";
  for (int j : D.found()) s += D.candidates[static_cast<std::size_t>(j)].label() + " ";
  return s.empty() ? "none" : s;
}

struct Condition {
  const char* name;
  bool position;
  std::vector<double> radii;
};
const std::vector<Condition>& conditions() {
  static const std::vector<Condition> c = {
      {"ball-bar 150 mm", false, {0.150}},
      {"ball-bar 100 + 150 mm", false, {0.100, 0.150}},
      {"positions 100 + 150 mm", true, {0.100, 0.150}},
  };
  return c;
}

constexpr int kSets = 12;  // per condition and multiple: 4 per axis, quadratic and cubic alternately

const ident::Diagnosis::SmoothDetectability* bound_on(const ident::Diagnosis& D, int axis) {
  for (const auto& b : D.smooth_detectability)
    if (b.axis == axis) return &b;
  return nullptr;
}

bool said_alike(const ident::Diagnosis& D, int axis) {
  const std::string alt = "outside_library[axis " + std::to_string(axis + 1) + "]";
  for (int j : D.found())
    for (const auto& a : D.candidates[static_cast<std::size_t>(j)].alternatives)
      if (a == alt) return true;
  return false;
}

// Cells below what the data can show, measured on these seeds (the data's own
// bound, OneRadiusDetectabilityBoundAgainstPlantedSizes): the >= 90 % assertion
// stays for every other cell, and every cell asserts it on the sets above the bound.
std::string known_limit(const Condition& c, double mult) {
  if (c.position || c.radii.size() > 1) return "";
  if (mult < 5.0)
    return "not applicable, one bar radius: 3 sigma is below the size these data find in 90 % on every set "
           "(smooth_detectability: 4.2-5.8 sigma on axes 1-2, 28 sigma on axis 3 at six heights); nothing is named, "
           "and the note says the bound and to measure a second radius, which finds it in 12 of 12";
  return "not applicable, one bar radius: 10 sigma is below the size at which these data tell a pitch error from a "
         "guide error on another axis (12.5-17 sigma, axes 1-2) or from a cyclic error on axis 3 (160-2400 sigma): "
         "nothing is named, or the guide error with the pitch error said to fit alike and a second radius to tell them";
}

// The pitch error at 3x and 10x the noise: outside_library on its axis, no
// library effect named, in >= 90 % of sets; the figures printed.
TEST(KinematicOutside, SmoothPitchErrorIsOutsideTheLibraryOnItsAxis) {
  for (const Condition& c : conditions())
    for (double mult : {3.0, 10.0}) {
      int right = 0, no_library = 0, alike = 0, applicable = 0, right_applicable = 0;
      std::string misses;
      for (int k = 0; k < kSets; ++k) {
        PitchSet s{c.position, c.radii, k % 3, (k / 3) % 3, mult, static_cast<std::uint64_t>(100 + k)};
        const ident::Diagnosis D = diagnose(pitch_data(s));
        const bool ok = outside_on(D, s.axis);
        right += ok;
        // Applicable: the planted size is above what these data find in 90 % (their own bound).
        const double size = mult * (c.position ? kPosSigma : kBarSigma);
        if (const auto* b = bound_on(D, s.axis); b && size >= b->told_above) {
          ++applicable;
          right_applicable += ok;
        }
        no_library += D.found().empty();
        alike += !ok && said_alike(D, s.axis);
        if (!ok || !D.found().empty())
          misses += "\n  seed " + std::to_string(s.seed) + " axis " + std::to_string(s.axis + 1) + " " +
                    shape_name(s.shape) + ": " + named_text(D) + (said_alike(D, s.axis) ? "(pitch error said to fit alike)" : "");
      }
      const std::string limit = known_limit(c, mult);
      std::printf("%s, pitch error %.0fx: outside_library on its axis %d/%d (+%d said to fit alike), no library "
                  "effect named %d/%d; above the data's own bound (applicable) %d, of them outside on its axis %d%s%s\n",
                  c.name, mult, right, kSets, alike, no_library, kSets, applicable, right_applicable, misses.c_str(),
                  limit.empty() ? "" : ("\n  not met: " + limit).c_str());
      if (limit.empty()) {
        EXPECT_GE(right, 0.9 * kSets) << c.name << " " << mult << "x" << misses;
      }
      EXPECT_GE(right_applicable, 0.9 * applicable) << c.name << " " << mult << "x" << misses;
      // A library effect named without saying the pitch error fits alike is a wrong answer everywhere.
      EXPECT_GE(no_library + alike, 0.9 * kSets) << c.name << " " << mult << "x" << misses;
    }
}

// One bar radius: the data's own detectability bound (JSON
// smooth_detectability) against planted sizes. For each set the bound is read
// from the diagnosis of the same poses without the error; a pitch error at
// half the lower figure is not found, one at 1.5x the size above which it is
// told from the base and every library effect is found on its axis, in >= 11
// of 12 sets each; and the verdict without a finding says the bound.
TEST(KinematicOutside, OneRadiusDetectabilityBoundAgainstPlantedSizes) {
  int missed = 0, found = 0, told = 0;
  for (int k = 0; k < kSets; ++k) {
    PitchSet s{false, {0.150}, k % 3, (k / 3) % 3, 0.0, static_cast<std::uint64_t>(100 + k)};
    const ident::Diagnosis N = diagnose(pitch_data(s));
    const auto* b = bound_on(N, s.axis);
    ASSERT_NE(b, nullptr) << "seed " << s.seed;
    ASSERT_GT(b->found_above, b->missed_below);
    ASSERT_GE(b->told_above, b->found_above);
    bool said = false;
    for (const auto& n : N.notes) said = said || n.find("measure a second bar radius") != std::string::npos;
    EXPECT_TRUE(said) << "seed " << s.seed;
    s.multiple = 0.5 * b->missed_below / kBarSigma;
    const ident::Diagnosis Dl = diagnose(pitch_data(s));
    missed += Dl.outside_library.empty() && Dl.found().empty();
    std::string high = "never told";
    if (std::isfinite(b->told_above)) {
      ++told;
      s.multiple = 1.5 * b->told_above / kBarSigma;
      const ident::Diagnosis Dh = diagnose(pitch_data(s));
      found += outside_on(Dh, s.axis);
      high = named_text(Dh);
    }
    std::printf("  seed %d axis %d %s: missed below %.2f, found above %.2f, told above %.2f sigma (from %s); at half "
                "the first: %s; at 1.5x the third: %s\n",
                static_cast<int>(s.seed), s.axis + 1, shape_name(s.shape), b->missed_below / kBarSigma,
                b->found_above / kBarSigma, b->told_above / kBarSigma,
                b->confused_with.empty() ? "the base" : b->confused_with.c_str(), named_text(Dl).c_str(), high.c_str());
  }
  std::printf("ball-bar 150 mm: below half the lower bound nothing named %d/%d; above 1.5x the told bound outside on "
              "its axis %d/%d\n", missed, kSets, found, told);
  EXPECT_GE(missed, kSets - 1);
  EXPECT_GE(found, told - 1);
  EXPECT_GE(told, kSets / 2);
}

// The suggested pitch_table follows the planted error: its values against
// the planted e at the nodes, both less their straight line (the part the
// calibration holds), and the residual with it near the noise.
TEST(KinematicOutside, SuggestedPitchTableFollowsThePlantedError) {
  for (const Condition& c : conditions()) {
    PitchSet s{c.position, c.radii, 1, 2, 10.0, 61};
    const io::DataSet ds = pitch_data(s);
    const ident::Diagnosis D = diagnose(ds);
    ASSERT_TRUE(outside_on(D, 1)) << c.name << ": " << D.verdict_text;
    ASSERT_EQ(D.suggested_user_effects.size(), 1u);
    const ident::SuggestedUserEffect& T = D.suggested_user_effects.front();
    EXPECT_EQ(T.kind, "pitch_table");
    EXPECT_EQ(T.axis, 1);
    const std::size_t n = T.nodes.size();
    ASSERT_GE(n, 4u);
    const double lo = T.nodes.front(), hi = T.nodes.back();
    const double sigma = c.position ? kPosSigma : kBarSigma, A = s.multiple * sigma / curved_part_ptp(s.shape);
    // planted at the nodes, less the straight line through the values' own fit
    Eigen::MatrixXd L(n, 2);
    Eigen::VectorXd e(n), v(n);
    for (std::size_t k = 0; k < n; ++k) {
      L.row(k) << 1.0, T.nodes[k] - lo;
      e(k) = A * shape_of(s.shape, (T.nodes[k] - lo) / (hi - lo));
      v(k) = T.values[k];
    }
    e -= L * L.colPivHouseholderQr().solve(e);
    v -= L * L.colPivHouseholderQr().solve(v);
    const double ptp = e.maxCoeff() - e.minCoeff(), diff = std::sqrt((v - e).squaredNorm() / n);
    std::printf("%s, exponential pitch error 10x on axis 2: table %zu nodes, RMS off the planted %.3f µm of %.3f µm "
                "peak to peak; residual with it %.3f µm (floor %.3f µm)\n",
                c.name, n, diff * 1e6, ptp * 1e6, T.rms_after * 1e6, D.noise_floor * 1e6);
    EXPECT_LT(diff, 0.25 * ptp) << c.name;
    EXPECT_LT(T.rms_after, 1.3 * sigma) << c.name;
  }
}

// The report: JSON verdict.missing = "outside_library" on the axis, the
// floor's source, the table ready for the model file; the text says it.
TEST(KinematicOutside, ReportCarriesTheFindingTheFloorSourceAndTheTable) {
  const ident::Diagnosis D = diagnose(pitch_data({false, {0.100, 0.150}, 2, 0, 10.0, 62}));
  const auto j = nlohmann::json::parse(ident::diagnosis_json(D));
  EXPECT_EQ(j["verdict"]["missing"], "outside_library");
  EXPECT_EQ(j["verdict"]["axis"], 3);
  EXPECT_EQ(j["verdict"]["outside_library"][0]["kind"], "smooth");
  EXPECT_EQ(j["verdict"]["outside_library"][0]["coordinate"], "d3");
  EXPECT_TRUE(j["verdict"]["effects"].empty());
  EXPECT_EQ(j["noise_floor_source"], "bar length high band");
  EXPECT_EQ(j["noise_floor_upper_bound"], false);
  ASSERT_EQ(j["smooth_detectability"].size(), 3u);
  for (const auto& b : j["smooth_detectability"])
    EXPECT_GT(b["found_above"].get<double>(), b["missed_below"].get<double>());
  const auto& t = j["verdict"]["suggested_user_effects"][0];
  EXPECT_EQ(t["kind"], "pitch_table");
  EXPECT_EQ(t["axis"], 3);
  EXPECT_EQ(t["nodes"].size(), t["values"].size());
  const std::string text = ident::diagnosis_text(D);
  EXPECT_NE(text.find("smooth, not periodic"), std::string::npos) << text;
  EXPECT_NE(text.find("pitch_table on axis 3"), std::string::npos) << text;
  std::printf("%s\n", D.verdict_text.c_str());
}

// A library effect beside the pitch error stays named: backlash (5 µm) or a
// cyclic error (2.6 µm, 16 mm) on axis 1, the pitch error (10x) on axis 2,
// ball-bar with two radii and positions.
TEST(KinematicOutside, ALibraryEffectBesideThePitchErrorIsStillNamed) {
  const std::vector<std::vector<PlantedKinematic>> beside = {{{"backlash", 0, {5e-6, 0, 0}}},
                                                             {{"cyclic_error", 0, {2.6e-6, 0.016, 0.3}}}};
  for (const Condition& c : conditions()) {
    if (c.radii.size() < 2) continue;
    for (const auto& lib : beside) {
      int both = 0;
      const int n = 6;
      std::string misses;
      for (int k = 0; k < n; ++k) {
        PitchSet s{c.position, c.radii, 1, k % 3, 10.0, static_cast<std::uint64_t>(700 + k)};
        s.library = lib;
        if (c.position) s.library[0].params[0] *= 3.0;  // 2 µm noise: the cells' 10x on positions
        const ident::Diagnosis D = diagnose(pitch_data(s));
        const std::string want = std::string(lib[0].effect) + "[axis 1]";
        bool named = false;
        for (int j : D.found()) named = named || D.candidates[static_cast<std::size_t>(j)].label() == want;
        const bool ok = outside_on(D, 1) && named && D.found().size() == 1;
        both += ok;
        if (!ok) misses += "\n  seed " + std::to_string(s.seed) + ": " + named_text(D);
      }
      std::printf("%s, %s on axis 1 beside a pitch error 10x on axis 2: both found, nothing else, %d/%d%s\n", c.name,
                  lib[0].effect, both, n, misses.c_str());
      EXPECT_GE(both, n - 1) << c.name << " " << lib[0].effect << misses;
    }
  }
}

// Null sets (Kim's machine, nothing planted beyond its calibrated planes):
// nothing named, nothing outside, in >= 95 %.
TEST(KinematicOutside, NullSetsStayClean) {
  for (const Condition& c : conditions()) {
    const int n = 20;
    int clean = 0;
    std::string misses;
    for (int k = 0; k < n; ++k) {
      PitchSet s{c.position, c.radii, 0, 0, 0.0, static_cast<std::uint64_t>(500 + k)};
      const ident::Diagnosis D = diagnose(pitch_data(s));
      const bool ok = D.found().empty() && D.outside_library.empty();
      clean += ok;
      if (!ok) misses += "\n  seed " + std::to_string(s.seed) + ": " + named_text(D);
    }
    std::printf("%s, null: clean %d/%d%s\n", c.name, clean, n, misses.c_str());
    EXPECT_GE(clean, 0.95 * n) << c.name << misses;
  }
}

// The ball-bar noise floor from the bar's own high band: within 30 % of the
// planted sigma (0.289 µm) with and without a pitch error, one and two radii.
TEST(KinematicOutside, BallbarNoiseFloorWithin30PercentOfThePlantedNoise) {
  for (const Condition& c : conditions()) {
    if (c.position) continue;
    for (double mult : {0.0, 10.0, 30.0}) {
      double worst = 0.0, sum = 0.0;
      const int n = 6;
      for (int k = 0; k < n; ++k) {
        PitchSet s{false, c.radii, k % 3, k % 3, mult, static_cast<std::uint64_t>(300 + k)};
        const ident::Diagnosis D = diagnose(pitch_data(s));
        EXPECT_EQ(D.noise_floor_source, "bar length high band");
        EXPECT_FALSE(D.noise_floor_upper_bound);
        const double ratio = D.noise_floor / kBarSigma;
        sum += ratio;
        worst = std::max(worst, std::fabs(ratio - 1.0));
        EXPECT_NEAR(ratio, 1.0, 0.3) << c.name << " pitch " << mult << "x seed " << s.seed;
      }
      std::printf("%s, pitch error %.0fx: floor / planted sigma mean %.3f, worst |ratio - 1| %.3f\n", c.name, mult,
                  sum / n, worst);
    }
  }
}

// A planted library effect keeps the ball-bar floor near the bar's noise:
// each effect of the library alone on axis 2 at the kinematic cells' 10x for
// two radii (docs/identification.md), 3 seeds each. Where the effect is not
// smooth in the readings (backlash, a 16 mm cyclic error on poses ~30 mm
// apart, a drift in time) the high band holds it and the floor is what the
// best description leaves, labelled an upper bound; within 30 % either way.
TEST(KinematicOutside, BallbarNoiseFloorBesideALibraryEffect) {
  const std::vector<PlantedKinematic> effects = {{"backlash", 1, {5e-6, 0, 0}},
                                                 {"cyclic_error", 1, {2.6e-6, 0.016, 0.3}},
                                                 {"guide_angular_error", 1, {4.7e-4, 0, 0}},
                                                 {"limb_twist", 1, {4.9e-4, 0, 0}},
                                                 {"thermal_drift", 1, {3.3e-5, 1500.0, 0}}};
  for (const auto& e : effects) {
    std::string line;
    for (std::uint64_t seed : {41u, 42u, 43u}) {
      KinSimOptions o;
      o.seed = seed;
      const ident::Diagnosis D = diagnose(kim_ballbar({e}, hemisphere_poses({0.100, 0.150}, 6, 16, seed), o));
      const double ratio = D.noise_floor / kBarSigma;
      line += " " + std::to_string(ratio).substr(0, 5) + (D.noise_floor_upper_bound ? " (upper bound)" : " (high band)");
      EXPECT_NEAR(ratio, 1.0, 0.3) << e.effect << " seed " << seed;
      EXPECT_TRUE(D.outside_library.empty()) << e.effect << " seed " << seed << ": " << D.verdict_text;
    }
    std::printf("ball-bar 100 + 150 mm, %s on axis 2: floor / planted sigma%s\n", e.effect, line.c_str());
  }
}

// Repeated poses give the floor when present: 20 of the 120 poses measured
// again (fresh instrument noise on both readings), a pitch error planted.
TEST(KinematicOutside, RepeatedPosesGiveTheFloor) {
  PitchSet s{true, {0.100, 0.150}, 1, 0, 10.0, 77};
  s.noise = false;
  io::PositionData p = std::get<io::PositionData>(pitch_data(s));
  std::mt19937_64 rng(5);
  std::normal_distribution<double> gauss(0.0, kPosSigma);
  auto noisy = [&](const Vec3& x) { return Vec3(x + Vec3(gauss(rng), gauss(rng), gauss(rng))); };
  for (std::size_t j = 0; j < 20; ++j) {
    p.d.push_back(p.d[j]);
    p.p.push_back(noisy(p.p[j]));
    p.extra.t.push_back(p.extra.t.back() + 20.0);
    p.extra.dir.push_back(p.extra.dir[j]);
  }
  for (std::size_t j = 0; j + 20 < p.p.size(); ++j) p.p[j] = noisy(p.p[j]);
  const ident::Diagnosis D = diagnose(p);
  std::printf("positions with 20 poses repeated: floor %.3f µm (%s; planted 2 µm), verdict %s\n",
              D.noise_floor * 1e6, D.noise_floor_source.c_str(), named_text(D).c_str());
  EXPECT_EQ(D.noise_floor_source, "repeated poses");
  EXPECT_NEAR(D.noise_floor / kPosSigma, 1.0, 0.3);
  EXPECT_TRUE(outside_on(D, 1));
}

// Without repeats, position data say the floor is only an upper bound and how to measure it.
TEST(KinematicOutside, NoRepeatsOnPositionsIsAnUpperBoundWithAdvice) {
  const ident::Diagnosis D = diagnose(pitch_data({true, {0.100, 0.150}, 0, 0, 0.0, 9}));
  EXPECT_TRUE(D.noise_floor_upper_bound);
  EXPECT_EQ(D.noise_floor_source, "residual (upper bound)");
  EXPECT_NE(D.noise_floor_text.find("repeat 20 poses"), std::string::npos) << D.noise_floor_text;
}

// The user's loop on ball-bar data with two radii (issue 26): backlash on axis 2
// (the library) and a pitch error growing along axis 1's stroke at 10x the bar's
// noise (no library effect). Allowed, the loop adds backlash, then the
// diagnosis' pitch_table with the planes recalibrated beside it, down to within
// 20 % of the floor, and the model file reads back equal; not allowed, it stops
// at the pitch error above 1.2x the floor.
TEST(KinematicOutside, LoopAddsThePitchTableDownToTheFloor) {
  PitchSet s;
  s.radii = {0.100, 0.150};
  s.axis = 0;
  s.shape = 2;
  s.multiple = 10.0;
  s.seed = 3;
  s.library = {{"backlash", 1, {6e-6, 0, 0}}};
  const io::DataSet ds = pitch_data(s);
  const ctl::MachineModel nominal = ctl::MachineModel::elkady();

  const ident::LoopResult R = ident::run_loop(ds, nominal, {}, 6, {"pitch_table"});
  std::fputs(ident::loop_text(R).c_str(), stdout);
  const bool backlash = std::any_of(R.added.begin(), R.added.end(),
                                    [](const ident::FitRequest& r) { return r.effect == "backlash" && r.axis == 1; });
  EXPECT_TRUE(backlash);
  ASSERT_EQ(R.user_added.size(), 1u);
  EXPECT_EQ(R.user_added.front().kind, "pitch_table");
  EXPECT_EQ(R.user_added.front().axis, 0);
  EXPECT_FALSE(R.model.kinematics.effects[0].pitch_table.empty());
  EXPECT_FALSE(R.outside_library);
  EXPECT_LE(R.steps.back().rms, 1.2 * R.steps.back().noise_floor);
  io::ModelFile mf;
  mf.model = R.model;
  const io::ModelFile back = io::parse_model_file(io::render_model_file(mf), "out.yaml");
  const kin::PitchTable& a = R.model.kinematics.effects[0].pitch_table;
  const kin::PitchTable& b = back.model.kinematics.effects[0].pitch_table;
  ASSERT_EQ(b.size, a.size);
  for (int k = 0; k < a.size; ++k) {
    EXPECT_EQ(b.node[static_cast<std::size_t>(k)], a.node[static_cast<std::size_t>(k)]);
    EXPECT_EQ(b.error[static_cast<std::size_t>(k)], a.error[static_cast<std::size_t>(k)]);
  }

  const ident::LoopResult N = ident::run_loop(ds, nominal);
  std::fputs(ident::loop_text(N).c_str(), stdout);
  EXPECT_TRUE(N.outside_library);
  EXPECT_EQ(N.suggestion.kind, "pitch_table");
  EXPECT_EQ(N.suggestion.axis, 0);
  EXPECT_GT(N.steps.back().rms, 1.2 * N.steps.back().noise_floor);
}

// Position data (a laser tracker, 2 µm): the same pitch error at 10x its noise.
TEST(KinematicOutside, LoopAddsThePitchTableOnPositionData) {
  PitchSet s;
  s.position = true;
  s.axis = 0;
  s.shape = 2;
  s.multiple = 10.0;
  s.seed = 3;
  const io::DataSet ds = pitch_data(s);
  const ident::LoopResult R = ident::run_loop(ds, ctl::MachineModel::elkady(), {}, 6, {"pitch_table"});
  std::fputs(ident::loop_text(R).c_str(), stdout);
  ASSERT_EQ(R.user_added.size(), 1u);
  EXPECT_EQ(R.user_added.front().kind, "pitch_table");
  EXPECT_EQ(R.user_added.front().axis, 0);
  EXPECT_LE(R.steps.back().rms, 1.2 * R.steps.back().noise_floor);
  // No library effect was added: the model it leaves has its planes calibrated
  // beside the table, so the model as it is reaches the floor too.
  const ident::Diagnosis D = ident::diagnose_kinematic(
      std::make_shared<const ident::KinematicProblem>(ident::prepare_kinematic(ds, R.model.kinematics)), {});
  EXPECT_LE(D.baseline_rms, 1.2 * D.noise_floor);
}

// A pitch error that stops growing inside the stroke (linear to 60 % of it,
// flat beyond: a table's last node before the end of travel). The smooth
// P2, P3 form does not follow the kink, and a long cyclic error fitted it
// better: a 1 mm cyclic_error[axis 2] on 120 optimal position poses, and
// here cyclic_error[axis 3] in 2 of these 6 sets before. The pitch-table
// form, weighed by BIC with its effective parameters, must win: outside on its
// axis with no library effect named.
TEST(KinematicOutside, PitchErrorWithAKinkIsNotACyclicError) {
  int right = 0, no_library = 0, sets = 0;
  std::string misses;
  for (int axis = 0; axis < 3; ++axis)
    for (std::uint64_t seed : {3u, 4u}) {
      PitchSet s{true, {0.100, 0.150}, axis, 3, 10.0, seed};
      const ident::Diagnosis D = diagnose(pitch_data(s));
      ++sets;
      right += outside_on(D, axis);
      no_library += D.found().empty();
      if (!outside_on(D, axis) || !D.found().empty())
        misses += "\n  seed " + std::to_string(seed) + " axis " + std::to_string(axis + 1) + ": " + named_text(D);
    }
  std::printf("positions, kink 10x: outside on its axis %d/%d, no library effect named %d/%d%s\n", right, sets,
              no_library, sets, misses.c_str());
  EXPECT_EQ(right, sets) << misses;
  EXPECT_EQ(no_library, sets) << misses;
}


// CPM_IDENT_SEEDS=N runs N sets per axis in the sweeps below (CI: the default).
int sets_per_axis(int ci_default) {
  const char* e = std::getenv("CPM_IDENT_SEEDS");
  return e ? std::max(1, std::atoi(e)) : ci_default;
}

// The kink (linear to 60 % of the stroke, flat beyond) on ball-bar data, one
// and two radii, at 3x and 10x the bar's noise on each axis: with two radii
// outside_library on its axis and no library effect named (no cyclic error,
// guide error or twist standing in for it) in >= 90 %; with one radius a
// library effect is named only with the pitch error said to fit alike, and
// every set above the data's own bound is outside on its axis.
TEST(KinematicOutside, PitchErrorWithAKinkOnTheBallbar) {
  const int per_axis = sets_per_axis(2);
  for (const Condition& c : conditions()) {
    if (c.position) continue;
    for (double mult : {3.0, 10.0}) {
      int right = 0, no_library = 0, alike = 0, applicable = 0, right_applicable = 0, sets = 0;
      int detectable = 0, right_detectable = 0;
      std::string misses;
      for (int axis = 0; axis < 3; ++axis)
        for (int k = 0; k < per_axis; ++k) {
          PitchSet s{false, c.radii, axis, 3, mult, static_cast<std::uint64_t>(900 + 10 * k + axis)};
          const ident::Diagnosis D = diagnose(pitch_data(s));
          const bool ok = outside_on(D, axis);
          ++sets;
          right += ok;
          no_library += D.found().empty();
          alike += !ok && said_alike(D, axis);
          if (const auto* b = bound_on(D, axis); b && mult * kBarSigma >= b->told_above) {
            ++applicable;
            right_applicable += ok;
          }
          if (const auto* b = bound_on(D, axis); b && mult * kBarSigma >= b->found_above) {
            ++detectable;
            right_detectable += ok;
          }
          if (!ok || !D.found().empty()) {
            const auto* b = bound_on(D, axis);
            misses += "\n  seed " + std::to_string(s.seed) + " axis " + std::to_string(axis + 1) + ": " +
                      named_text(D) + (said_alike(D, axis) ? "(pitch error said to fit alike)" : "") +
                      (b ? "(a smooth error found above " + std::to_string(b->found_above / kBarSigma).substr(0, 5) +
                               " sigma here)"
                         : "");
          }
        }
      std::printf("%s, kink %.0fx: outside_library on its axis %d/%d (+%d said to fit alike), no library effect "
                  "named %d/%d; above the size found in 90 %% %d, of them outside on its axis %d; above the size "
                  "told from the library %d, of them outside on its axis %d%s\n",
                  c.name, mult, right, sets, alike, no_library, sets, detectable, right_detectable, applicable,
                  right_applicable, misses.c_str());
      // Two radii at 10x: every set; at 3x the kink is at the data's limit
      // (a smooth error is found above 3.3-5.0 sigma on these poses): judged on
      // the sets above that bound, and no library effect named on any.
      if (c.radii.size() > 1) {
        if (mult >= 10.0) {
          EXPECT_GE(right, 0.9 * sets) << c.name << " " << mult << "x" << misses;
        }
        EXPECT_GE(no_library, 0.9 * sets) << c.name << " " << mult << "x" << misses;
      }
      EXPECT_GE(right_detectable, 0.9 * detectable) << c.name << " " << mult << "x" << misses;
      EXPECT_GE(right_applicable, 0.9 * applicable) << c.name << " " << mult << "x" << misses;
      EXPECT_GE(no_library + alike, 0.9 * sets) << c.name << " " << mult << "x" << misses;
    }
  }
}

// A library effect and a kinked pitch error at once (10x the noise), two-radius
// ball-bar and positions: the library effect named with its value within 5 %,
// outside_library on the kinked axis, and `cpm fit` (the library effect named,
// then --add pitch_table:AXIS on that model) down to within 20 % of the
// instrument's noise. The guide error is the effect a pitch error is most
// often taken for (it tilts the platform as the carriage moves).
TEST(KinematicOutside, ALibraryEffectBesideAKinkIsNamedAndTheTableReachesTheFloor) {
  struct Beside {
    PlantedKinematic effect;
    int kink_axis;
  };
  const std::vector<Beside> cases = {{{"guide_angular_error", 0, {4.7e-4, 0, 0}}, 1},
                                     {{"backlash", 2, {5e-6, 0, 0}}, 0},
                                     {{"cyclic_error", 0, {2.6e-6, 0.016, 0.3}}, 2}};
  const ctl::MachineModel nominal = ctl::MachineModel::elkady();
  for (const Condition& c : conditions()) {
    if (c.radii.size() < 2) continue;
    const double sigma = c.position ? kPosSigma : kBarSigma;
    int sets = 0, right = 0, value = 0;
    std::string misses;
    for (const Beside& b : cases)
      for (int k = 0; k < sets_per_axis(2); ++k) {
        const auto seed = static_cast<std::uint64_t>(31 + k);
        PitchSet s{c.position, c.radii, b.kink_axis, 3, 10.0, seed};
        s.library = {b.effect};
        if (c.position) s.library[0].params[0] *= 3.0;  // 2 µm noise: the cells' 10x on positions
        const io::DataSet ds = pitch_data(s);
        const ident::Diagnosis D = diagnose(ds);
        const std::string want = std::string(b.effect.effect) + "[axis " + std::to_string(b.effect.axis + 1) + "]";
        const ident::CandidateResult* named = nullptr;
        for (int j : D.found())
          if (D.candidates[static_cast<std::size_t>(j)].label() == want) named = &D.candidates[static_cast<std::size_t>(j)];
        const double planted = s.library[0].params[0];
        const double off = named ? named->params[0].value / planted - 1.0 : 1.0;
        // cpm fit --add EFFECT:AXIS, then cpm fit --add pitch_table:AXIS on its model.
        ctl::MachineModel with = nominal;
        with.kinematics = ident::fit_kinematic(ds, nominal.kinematics, {{b.effect.effect, b.effect.axis}}, {}).model;
        const ident::PitchTableFit T = ident::fit_pitch_table(ds, with, b.kink_axis);
        std::printf("%s, %s beside a kink 10x on axis %d, seed %d: %s; %s %s (planted %.4g), the table's fit %.3f -> "
                    "%.3f µm RMS = %.3f x the planted sigma (floor %.3f µm, %s)\n",
                    c.name, want.c_str(), b.kink_axis + 1, static_cast<int>(seed), named_text(D).c_str(), want.c_str(),
                    named ? (std::to_string(100.0 * off).substr(0, 5) + " % off").c_str() : "not named", planted,
                    T.base_only * 1e6, T.after * 1e6, T.after / sigma, D.noise_floor * 1e6, D.noise_floor_source.c_str());
        ++sets;
        const bool ok = outside_on(D, b.kink_axis) && named && D.found().size() == 1;
        right += ok;
        // Within 5 %, or 3 of its standard errors where those are wider (a cyclic error at 10x on positions: 2.5 %).
        value += named && std::fabs(off) < std::max(0.05, 3.0 * named->params[0].std_error / planted);
        if (!ok) misses += "\n  " + want + " seed " + std::to_string(seed) + ": " + named_text(D);
        EXPECT_LE(T.after, 1.2 * sigma) << c.name << " " << want << " seed " << seed;
        EXPECT_LE(T.after, 1.2 * D.noise_floor) << c.name << " " << want << " seed " << seed;
      }
    std::printf("%s, a library effect beside a kink: outside on the kinked axis with the effect named and nothing "
                "else %d/%d, its value within 5 %% (or 3 s.e.) %d/%d%s\n",
                c.name, right, sets, value, sets, misses.c_str());
    EXPECT_GE(right, 0.9 * sets) << c.name << misses;
    EXPECT_GE(value, 0.9 * sets) << c.name;
  }
}

// The ball-bar noise floor over the generator's settings: one and two radii,
// the bar's noise 0.25, 0.5 and 1 µm half-width, with nothing planted, a
// smooth or kinked pitch error (10x), a library effect alone at the cells'
// 10x, and a library effect beside a kink: within 30 % of the planted sigma.
TEST(KinematicOutside, BallbarNoiseFloorOverTheGeneratorsSettings) {
  struct Planted {
    const char* name;
    int shape;
    double multiple;
    std::vector<PlantedKinematic> library;
  };
  const std::vector<Planted> planted = {
      {"nothing", 0, 0.0, {}},
      {"a smooth pitch error", 1, 10.0, {}},
      {"a kink", 3, 10.0, {}},
      {"backlash", 0, 0.0, {{"backlash", 2, {5e-6, 0, 0}}}},
      {"a guide error", 0, 0.0, {{"guide_angular_error", 0, {4.7e-4, 0, 0}}}},
      {"a cyclic error", 0, 0.0, {{"cyclic_error", 0, {2.6e-6, 0.016, 0.3}}}},
      {"backlash + a kink", 3, 10.0, {{"backlash", 2, {5e-6, 0, 0}}}},
      {"a guide error + a kink", 3, 10.0, {{"guide_angular_error", 0, {4.7e-4, 0, 0}}}},
  };
  double worst_all = 0.0;
  for (const Condition& c : conditions()) {
    if (c.position) continue;
    for (const Planted& pl : planted) {
      std::string line;
      double worst = 0.0;
      for (double hw : {0.25e-6, 1.0e-6}) {
        const double scale = hw / kBarHalfWidth;
        for (std::uint64_t seed : {51u, 52u}) {
          PitchSet s{false, c.radii, static_cast<int>(seed % 3), pl.shape, pl.multiple, seed};
          s.library = pl.library;
          for (auto& e : s.library) e.params[0] *= scale;  // the same multiple of the noise
          s.bar_half_width = hw;
          const ident::Diagnosis D = diagnose(pitch_data(s));
          const double ratio = D.noise_floor / (hw / std::sqrt(3.0));
          worst = std::max(worst, std::fabs(ratio - 1.0));
          line += " " + std::to_string(ratio).substr(0, 5) + (D.noise_floor_upper_bound ? "u" : "");
          EXPECT_NEAR(ratio, 1.0, 0.3) << c.name << ", " << pl.name << ", bar +-" << hw * 1e6 << " µm, seed " << seed
                                       << ": " << D.noise_floor_text;
        }
      }
      worst_all = std::max(worst_all, worst);
      std::printf("%s, %s: floor / planted sigma (bar +-0.25, +-1 µm; u = upper bound)%s; worst |ratio - 1| %.3f\n",
                  c.name, pl.name, line.c_str(), worst);
    }
  }
  std::printf("ball-bar floor over the generator's settings: worst |ratio - 1| %.3f\n", worst_all);
}

}  // namespace
}  // namespace cpm::test

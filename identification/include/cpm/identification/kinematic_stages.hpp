// SPDX-License-Identifier: Apache-2.0
// The stages of the kinematic diagnosis (kinematic.hpp) as units:
//  1. read: the data and the model's residual (read_kinematic), the base
//     calibrated at the model's own effects (prepare_kinematic);
//  2. columns per effect: the effect table (kinematic_fitter), one entry per
//     kinematic effect type of docs/effects.md: how its columns are built from the
//     residual's sensitivity to each axis' effective displacement, how its
//     nonlinear parameter is searched (cyclic_error's wavelength,
//     thermal_drift's time constant), what separates it from the base;
//  3. base refit: the shared engine on kinematic_linear_problem;
//  4. candidates: every effect on every axis evaluated and scored alone
//     (evaluate_kinematic_candidates);
//  5. selection and verdict: the noise floor (kinematic_noise_floor), the
//     forward selection the motion side uses too, from the calibrated base,
//     each searched parameter searched again beside the effects chosen
//     (KinematicEffectFitter::search_beside), the actuator scales judged at
//     the model as given with the effects chosen;
//  6. structure: what remains (find_kinematic_structure).
// Adding a kinematic effect: its model in kinematics/ (kinematic_effects.hpp,
// plane_model.cpp) and one entry of the table (kinematic_effects.cpp).
//
// Units: encoder readings d (m), time t (s), residual rows (m); wavenumbers
// (1/m). Frames: the base's (ball-bar or machine), as in KinematicProblem.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Dense>

#include "cpm/identification/diagnose.hpp"
#include "cpm/identification/engine.hpp"
#include "cpm/identification/kinematic.hpp"
#include "cpm/kinematics/kinematic_effects.hpp"

namespace cpm::ident {

// What the samples cover: each axis' range of encoder readings (m), the time
// covered (s), and per axis how many samples were last approached forward
// (dir > 0) and backward.
struct KinematicSpan {
  Vec3 lo = Vec3::Constant(1e300), hi = Vec3::Constant(-1e300);
  double t0 = 1e300, t1 = -1e300;
  std::array<int, 3> n_plus{}, n_minus{};
};
KinematicSpan span_of(const KinematicProblem& P);

// Column of a change g(sample) of axis `axis`' effective displacement d~
// (g in m): S_axis(row) * g(sample of the row), S = P.sensitivity.
template <class G>
Eigen::VectorXd displacement_column(const KinematicProblem& P, int axis, G&& g) {
  Eigen::VectorXd c(P.rows());
  for (int r = 0; r < P.rows(); ++r) c(r) = P.sensitivity(r, axis) * g(P.sample_of_row(r));
  return c;
}

// cyclic_error's linear columns at wavenumber k (1/m): sin and cos of
// 2 pi k d_axis as displacement columns (a sin(x + phi) = a cos phi sin x +
// a sin phi cos x).
Eigen::MatrixXd cyclic_error_columns(const KinematicProblem& P, int axis, double k);
// thermal_drift's column at time constant tau (s): d_axis (1 - exp(-t / tau)).
Eigen::VectorXd thermal_drift_column(const KinematicProblem& P, int axis, double tau);

// The wavenumber (1/m) of cyclic_error on `axis` that leaves the least RSS on
// E: a grid over [kmin, kmax] at spacing dk (a quarter cycle over the stroke),
// its three lowest local minima refined by golden section. E may hold other
// effects' columns in its base (KinematicEffectFitter::search_beside).
double search_cyclic_wavenumber(const KinematicProblem& P, const Engine& E, int axis, double kmin, double kmax,
                                double dk);
// The time constant (s) of thermal_drift on `axis` in [lo, hi] that leaves
// the least RSS on E: a log grid of 16 points refined by golden section.
double search_thermal_time_constant(const KinematicProblem& P, const Engine& E, int axis, double lo, double hi);

// What a candidate's fitter works on.
struct KinematicCandidateContext {
  const KinematicProblem& P;
  const Engine& E;                      // the base refit (kinematic_linear_problem)
  int axis;                             // 0..2
  const kin::KinematicEffectInfo& info; // parameters, units, bounds
  KinematicSpan span;
};

// What an effect's signature depends on besides the poses: the advice on
// separating two candidates compares these.
struct KinematicSignature {
  bool direction = false;  // the direction each axis last moved
  bool time = false;       // the time of the sample
  bool periodic = false;   // periodic in an axis' position
};

// The measurement that separates an effect from a base parameter it is
// confounded with.
enum class BaseSeparation : std::uint8_t {
  both_directions,  // approach the poses from both directions
  is_base_scale,    // the effect is (or is confounded with) a scale of the base
  other_times,      // repeat the poses at other times
  spread_poses,     // spread the poses (and a second bar radius)
};

// One entry of the kinematic effect table.
struct KinematicEffectFitter {
  kin::KinematicEffectType type;
  // Columns, nonlinear search and fit of the effect on ctx.axis jointly with
  // the base; fills c (columns, params, rss, residual_after, confounded,
  // identifiable, note). The common refusals (data lacking dir or t, the
  // effect already in the model) are checked before.
  void (*evaluate)(const KinematicCandidateContext& ctx, CandidateResult& c);
  // Its parameter values from a joint fit of several effects: the
  // coefficients of its columns start at fit.beta(at), their covariance is
  // cov; v (in kin::get_params order) and c.params are updated. Throws Error
  // for a value it refuses (a negative backlash).
  void (*joint_values)(const JointFit& fit, int at, const Eigen::MatrixXd& cov, CandidateResult& c,
                       std::array<double, 3>& v);
  KinematicSignature signature;
  BaseSeparation separation;
  // Its nonlinear parameter (a wavelength, a time constant) searched again
  // with the effects chosen before it fitted beside it: `beside` is the base
  // refit with their columns as base columns too. Updates c.columns, the
  // searched value and the linear values (fitted with the others), and the
  // figures of the effect alone at the new value; keeps c as it is when the
  // new value fits no better. nullptr: the effect has nothing searched.
  void (*search_beside)(const KinematicCandidateContext& ctx, const Engine& beside, CandidateResult& c);
};

// The table's entry for an effect type, nullptr when it has none.
const KinematicEffectFitter* kinematic_fitter(kin::KinematicEffectType type) noexcept;

// Stage 4: every effect of the library (or of options.effects) on every axis,
// evaluated on E and scored against the base refit (actuator_scale: absorbed
// by it; judged at the model as given in the selection). In table order, axis
// by axis.
std::vector<CandidateResult> evaluate_kinematic_candidates(const KinematicProblem& P, const Engine& E,
                                                           const DiagnoseOptions& options);

// The noise floor (m) from the data's own repeatability, never from what the
// candidates leave: the pooled scatter of poses measured more than once (same
// readings within 1 µm, same directions); else the instrument's declared
// sigma; else, for ball-bar lengths, the high band of the bar's length along
// the poses (each length against a local linear fit of its nearest
// neighbours in reading space: a smooth machine error is nearly linear over
// a neighbourhood, the noise is not); else the residual sigma (dof-corrected)
// of the best description among the base refit and the identifiable
// candidates, which is only an upper bound.
struct KinematicNoiseFloor {
  double value = 0.0;        // m
  std::string source;        // "repeated poses", "declared sigma", "bar length high band", "residual (upper bound)"
  bool upper_bound = false;
  std::string text;          // how it was measured; with no repeats, how to measure them
};
KinematicNoiseFloor kinematic_noise_floor_of(const KinematicProblem& P, const Engine& E,
                                             const std::vector<CandidateResult>& candidates);
double kinematic_noise_floor(const KinematicProblem& P, const Engine& E, const std::vector<CandidateResult>& candidates);

// The pooled standard deviation (m) of the residual rows over poses measured
// more than once (readings within 1 µm, same directions when known); 0 when
// fewer than 5 degrees of freedom. `poses` receives how many poses repeat.
double repeated_pose_sigma(const KinematicProblem& P, const Eigen::VectorXd& residual, int* poses = nullptr);
// The noise (m) of a per-sample residual from its local high band: each
// sample against a polynomial fit (degree 1 or 2) of its k nearest
// neighbours in reading space, in the directions they spread in.
double local_high_band_sigma(const KinematicProblem& P, const Eigen::VectorXd& residual, int k = 8, int degree = 1);

// A smooth, non-periodic error of axis `axis`' effective displacement:
// displacement columns of the Legendre polynomials of degree 2 and 3 over the
// readings covered (degree 0 and 1, an offset and a scale, are the base's);
// degree 4 too when `degree` >= 4. No columns for an axis covering < 2 mm.
Eigen::MatrixXd smooth_displacement_columns(const KinematicProblem& P, int axis, int degree = 3);

// How large a smooth error of axis `axis`' reading must be for the search to
// find it (kinematic_outside.cpp): the F-test of those columns beside the base
// at level alpha / 3, its power from the noncentrality the error's part off the
// base span gives at noise `sigma` (m), over every shape b2 P2 + b3 P3. Sizes:
// peak to peak of the curved part over the stroke covered (m); 0 and 0 for an
// axis the data do not move. With `beside` (unweighted columns of a library
// effect), the error's part off the base and those columns: the size above
// which it is told from that effect (in found_above; infinite when the
// columns take some shape whole).
Diagnosis::SmoothDetectability smooth_detectability(const KinematicProblem& P, const Engine& E, int axis, double sigma,
                                                    double alpha, const Eigen::MatrixXd* beside = nullptr);

// The verdict's rule on kinematic data (kinematic_outside.cpp): a library
// effect is named only when the residual reaches the noise floor and no
// significant smooth structure is left; otherwise the verdict leads with
// outside_library on the axis whose reading the structure follows, the library
// effects that explain part of it are listed as partial, and a pitch_table is
// suggested. E: the base refit of P.
void kinematic_outside_library(const KinematicProblem& P, const Engine& E, const DiagnoseOptions& options,
                               Diagnosis& D);

// A pitch table on `axis` fitted to what the base refit E leaves: `nodes`
// nodes over the readings covered, values with a second-difference penalty
// chosen by generalised cross-validation, the linear part (the base's offset
// and scale) removed.
SuggestedUserEffect fit_pitch_table(const KinematicProblem& P, const Engine& E, int axis, int nodes = 11);

}  // namespace cpm::ident

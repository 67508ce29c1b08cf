// SPDX-License-Identifier: Apache-2.0
// cpm excite: an identification experiment for this machine and model.
//
// Each axis follows a periodic multi-sine about the workspace centre
//     x_i(t) = c_i + s(t) sum_k a_ik sin(2 pi k_i f0 t + phi_ik)   (m)
// on its own harmonics of f0 (axis i takes k = 3m + i + 1, m = 0..n-1, so
// that no two axes share a frequency and their columns do not correlate
// through the motion), repeated `periods` times so that periods can be
// averaged and the noise estimated from their differences; s(t) fades the
// motion in and out (quintic, `ramp` s) so that it starts and ends at rest.
// Every axis reverses at every extremum and crosses zero speed there
// (slow passages), at the speeds the sum of its harmonics makes.
//
// Beside the sines, each axis may carry constant-speed passes (Passes): the
// stroke crossed forward and back at a few speeds per period, reversing
// through zero speed with a smooth (cosine) velocity blend. A sum of sines
// makes speed and acceleration move together and Coulomb's sign column
// nearly a multiple of the speed column; passes at several speeds hold the
// speed with no acceleration and set the sign apart from the speed.
//
// The design: the amplitudes and phases that maximise the information of
// the regressor diagnosis fits (the base parameters, the plane nuisance and
// the linear columns of every library effect, motion.hpp), by the
// D-criterion (log det of X^T X), starting from a flat spectrum with
// Schroeder phases (a random local search, then a pattern search on every
// continuous variable from its best); or, with `separate`, the one that tells two named
// effects apart (least correlation of their columns beside the base).
// Every candidate is scaled to the largest amplitude within the workspace
// box, the speed, acceleration and force limits (x `margin`), and the design
// is checked with the planner's check (ctl::validate_trajectory).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "cpm/control/machine.hpp"
#include "cpm/control/trajectory.hpp"
#include "cpm/io/data_files.hpp"

namespace cpm::ident {

struct ExcitationLimits {
  Vec3 workspace_min = Vec3(0.235, 0.235, 0.2378);  // platform box (m), cpmd's soft limits
  Vec3 workspace_max = Vec3(0.615, 0.615, 0.5168);
  double velocity = 0.5;       // platform speed |p_dot| (m/s)
  double acceleration = 5.0;   // platform acceleration |p_dd| (m/s^2)
  double force = 120.0;        // actuator force (N), through the model's inverse dynamics
  double margin = 0.85;        // share of each limit the design may use
};

struct ExcitationOptions {
  double period = 5.0;         // s, one period of the multi-sine (f0 = 1 / period)
  int periods = 4;             // periods played (>= 2 to estimate noise from their differences)
  int harmonics = 6;           // harmonics per axis
  double ramp = 1.0;           // s, fade in and out
  int iterations = 400;        // candidate designs tried by the optimiser's random search
  int refine = -1;             // then designs tried by the pattern search from its best (-1: iterations / 2)
  int searches = 1;            // searches from the best start, each on its own seed with its share of both budgets
  std::uint64_t seed = 1;
  bool optimise = true;        // false: the flat spectrum with Schroeder phases
  int speeds = 4;              // pairs of constant-speed passes per axis and period (0: sines only)
  // What the optimiser maximises: the D-criterion (log det X^T X), or the
  // product of the standard errors' inverses (sum of -log sigma_j over the
  // columns: it rewards separating each column from all the others, where
  // the D-criterion also rewards columns already well determined). Criteria
  // relative to the flat Schroeder start's standard errors were measured
  // against the D-criterion and not kept (docs/identification.md, "How the
  // designs are compared").
  enum class Criterion { log_det, std_errors } criterion = Criterion::log_det;
  // Tell two effects apart ("coulomb_friction:1", "payload_mass") instead of the D-criterion.
  std::optional<std::pair<std::string, std::string>> separate;
  void validate() const;       // throws Error naming the option
};

// Constant-speed passes of one axis over one period: pair j crosses the
// stroke forward then back, each way in share[j] / 2 of the period (shares
// sum to 1), so at speed stroke / ((1 - blend) share[j] period / 2): long
// shares are slow passes. Every pass starts and ends at rest, its speed
// blended in and out (1 - cos) over `blend` of its time. The pattern starts
// at offset * period, at -stroke / 2 about the centre.
struct Passes {
  double stroke = 0.0;          // m, 0: none
  std::vector<double> share;    // per pair of passes, summing to 1
  double offset = 0.0;          // share of the period, [0, 1)
  static constexpr double blend = 0.25;
};

// A periodic multi-sine per axis, with passes, faded in and out (see the top).
class MultiSine final : public ctl::Trajectory {
 public:
  MultiSine(Vec3 centre, double period, int periods, double ramp, std::array<std::vector<int>, 3> harmonic,
            std::array<std::vector<double>, 3> amplitude, std::array<std::vector<double>, 3> phase,
            std::array<Passes, 3> passes = {});
  [[nodiscard]] double duration() const noexcept override { return 2.0 * ramp_ + periods_ * period_; }
  [[nodiscard]] ctl::TrajectorySample sample(double t) const noexcept override;
  // The periodic part alone (no fade), t in s.
  [[nodiscard]] ctl::TrajectorySample periodic(double t) const noexcept;
  [[nodiscard]] const Vec3& centre() const noexcept { return centre_; }
  [[nodiscard]] double period() const noexcept { return period_; }
  [[nodiscard]] int periods() const noexcept { return periods_; }
  [[nodiscard]] double ramp() const noexcept { return ramp_; }
  [[nodiscard]] const std::array<std::vector<int>, 3>& harmonic() const noexcept { return k_; }
  [[nodiscard]] const std::array<std::vector<double>, 3>& amplitude() const noexcept { return a_; }
  [[nodiscard]] const std::array<std::vector<double>, 3>& phase() const noexcept { return phi_; }
  [[nodiscard]] const std::array<Passes, 3>& passes() const noexcept { return passes_; }
  // Speed of pass pair j of axis i (m/s).
  [[nodiscard]] double pass_speed(int axis, std::size_t j) const;
  // Peak displacement from the centre per axis over a period (m).
  [[nodiscard]] Vec3 peak_displacement() const;
  // The same design with every amplitude times s (all axes) or s_i (per axis).
  [[nodiscard]] MultiSine scaled(const Vec3& s) const;

 private:
  Vec3 centre_;
  double period_, ramp_;
  int periods_;
  std::array<std::vector<int>, 3> k_;
  std::array<std::vector<double>, 3> a_, phi_;
  std::array<Passes, 3> passes_;
};

// How a design uses the limits and what it gives.
struct ExcitationFigures {
  Vec3 peak_displacement = Vec3::Zero();  // m, per axis
  double peak_speed = 0.0;                // m/s, platform
  double peak_acceleration = 0.0;         // m/s^2, platform
  double peak_force = 0.0;                // N, largest actuator force of the model
  double log_det = 0.0;                   // D-criterion of the normalised regressor
  double condition = 0.0;                 // its condition number (columns scaled to unit norm)
  double log_std_errors = 0.0;            // sum over the columns of -log of the standard errors below
  // Relative standard errors: sqrt(diag((X^T X)^-1)) per column at unit noise, per unit force of column.
  std::vector<std::string> columns;
  Eigen::VectorXd std_error;
  int base_columns = 0;                   // columns[0, base_columns): the base and the plane nuisance; then the effects
  double separation = 0.0;                // with `separate`: 1 - rho^2 of the two columns beside the base
};

struct ExcitationDesign {
  MultiSine trajectory;
  ExcitationFigures figures;
  ExcitationFigures start;     // the flat-spectrum, Schroeder-phase start, scaled the same way
  int evaluations = 0;
};

// The flat spectrum with Schroeder phases, scaled to the limits.
MultiSine schroeder_multisine(const ctl::Machine& model, const ExcitationLimits& limits, const ExcitationOptions& o);

// The flat spectrum with Schroeder phases whose peak displacement is `peak`
// (m, per axis), over the same duration as o's: at o.period if the limits
// allow that peak there, else on fewer, longer periods of the same total
// (its frequencies lowered), the first that reaches it, or the one that
// comes nearest. The plain reference at the optimised design's amplitude.
MultiSine schroeder_multisine_at_peak(const ctl::Machine& model, const ExcitationLimits& limits,
                                      const ExcitationOptions& o, const Vec3& peak);

// The largest multiple of `shape` (per-axis to the box, then all axes
// together) within the limits. Throws Error when none is (a centre outside the workspace).
MultiSine scale_to_limits(const MultiSine& shape, const ctl::Machine& model, const ExcitationLimits& limits);

// Figures of a design on `model` (the regressor of one period).
ExcitationFigures excitation_figures(const MultiSine& m, const ctl::Machine& model, const ExcitationOptions& o);

// Design the experiment (see the top). Throws Error for bad options or limits.
ExcitationDesign design_excitation(const ctl::Machine& model, const ExcitationLimits& limits,
                                   const ExcitationOptions& options = {});

// The design's regressor fitted on a measured log (the effect columns of
// every library effect beside the base, as the design sees them, unbounded):
// values and standard errors from the fit's covariance with the noise the
// log shows (the residual's variance over its effective rows). What the
// standard errors of two experiments are compared by.
struct RegressorFit {
  std::vector<std::string> columns;  // "viscous_friction[axis 1]", ..., "actuation_delay"
  Eigen::VectorXd value, std_error;  // per unit of each column (N s/m, N, ..., s)
  double residual_rms = 0.0;         // N, after the fit
};
RegressorFit fit_design_regressor(const io::MotionData& log, const ctl::Machine& model);

// The stream file's rows (t, x, y, z, vx, vy, vz; SI) at `rate` Hz.
std::vector<std::array<double, 7>> excitation_rows(const MultiSine& m, double rate);

}  // namespace cpm::ident

// SPDX-License-Identifier: Apache-2.0
// The kinematic side of compare / diagnose / fit: ball-bar lengths and full
// positions (kind = ballbar, position), residual in m.
//
// The base model is calibration's: for ball-bar data Kim's eta (c1, c2,
// theta_z, c3, theta_x, theta_y, dq[, dl]) in the ball-bar frame
// (cal::fit_ballbar, residual and analytic Jacobian cal::ballbar_residuals);
// for position data the 12 plane parameters (cal::fit_positions,
// cal::position_residuals). The data are first calibrated (the model's own
// kinematic effects applied to the encoder readings), then every kinematic
// effect of docs/effects.md is fitted jointly with the base by the shared engine
// (engine.hpp), linearised at the calibrated point (the effects are microns
// on a calibrated machine: second-order terms are far below the noise).
//
// Candidate columns: effects that act through the effective displacement
// d~_i (backlash, cyclic error, thermal drift, actuator scale) are
// S_i(row) * dd~_i/dtheta, with S_i = dr/dd~_i the residual's sensitivity
// to axis i (central differences through the full forward kinematics);
// effects on the normals or offsets (guide angular error, limb twist) by
// central differences of the full residual of a kin::KinematicModel with the
// effect set. Nonlinear parameters by search: lambda of cyclic_error by a
// periodogram over 1..50 mm (capped at 2/3 of the stroke covered) refined by
// golden section; tau of thermal_drift on a log grid over the time covered.
// The stages as units, and the table of effects: kinematic_stages.hpp.
#pragma once

#include <array>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "cpm/calibration/ballbar.hpp"
#include "cpm/calibration/circular_test.hpp"
#include "cpm/calibration/position.hpp"
#include "cpm/identification/diagnose.hpp"
#include "cpm/identification/fit.hpp"
#include "cpm/io/data_files.hpp"
#include "cpm/kinematics/plane_model.hpp"

namespace cpm::ident {

using KinematicEffects = std::array<kin::LimbKinematicEffects, 3>;

struct KinematicProblem {
  std::string kind;                   // "ballbar" or "position"
  std::string data_file;
  int per_sample = 1;                 // residual rows per sample: 1 (ball-bar) or 3 (position: x, y, z)
  std::vector<Vec3> d;                // encoder readings (m)
  std::vector<kin::KinematicInputs> inputs;  // dir and t of each sample (defaults when absent)
  bool has_dir = false, has_time = false;
  std::vector<int> line;              // file line of each sample
  std::vector<long> run;              // run column (empty when absent)
  // Ball-bar.
  std::vector<double> length;         // m
  Vec3 pivot = Vec3::Zero();          // nominal pivot (m)
  bool with_dl = false;               // the bar's length offset is fitted
  // Position.
  std::vector<Vec3> p;                // measured platform point (m)
  double sigma_declared = 0.0;        // metadata sigma (m), 0 when absent

  kin::KinematicModel given;          // the model's kinematics, machine frame, with its effects
  // The base at the calibrated point.
  Eigen::VectorXd base_value;
  std::vector<std::string> base_names, base_units;
  std::optional<cal::BallbarFit> ballbar_fit;
  std::optional<cal::PositionFit> position_fit;
  Eigen::VectorXd residual_given;     // model as given (m); ball-bar with dl unknown: its mean removed
  Eigen::VectorXd residual;           // at the calibrated base (m)
  Eigen::MatrixXd base;               // d residual / d base parameter (what the data determine of it)
  // A change d of the base parameters found against `base` moves them by
  // base_map * d: the identity, or for a circular test the projector onto
  // what the poses determine (cal::BallbarFit::determined).
  Eigen::MatrixXd base_map;
  Eigen::MatrixXd sensitivity;        // rows x 3: d residual / d d~_i
  std::vector<std::string> warnings, notes;

  [[nodiscard]] int samples() const noexcept { return static_cast<int>(d.size()); }
  [[nodiscard]] int rows() const noexcept { return per_sample * samples(); }
  // Residual for base parameters x with `extra` effects on top of the model's own.
  [[nodiscard]] Eigen::VectorXd residual_of(const Eigen::VectorXd& x, const KinematicEffects& extra) const;
  // The machine-frame model for base parameters x and the given effects.
  [[nodiscard]] kin::KinematicModel model_of(const Eigen::VectorXd& x, const KinematicEffects& effects) const;
  // Residual of a machine-frame model on these data, nothing refitted (m).
  [[nodiscard]] Eigen::VectorXd residual_of_model(const kin::KinematicModel& m) const;
  // Sample index of a residual row and the coordinate it measures (0 for ball-bar).
  [[nodiscard]] int sample_of_row(int r) const noexcept { return r / per_sample; }
};

// Read the data and the residual of the model as given, nothing fitted (compare).
KinematicProblem read_kinematic(const io::DataSet& data, const kin::KinematicModel& model);

// Read the data into a problem and calibrate the base. Throws Error naming
// the file and line for a reading the model cannot follow, DegeneratePoses
// for a pose set that cannot determine the base.
KinematicProblem prepare_kinematic(const io::DataSet& data, const kin::KinematicModel& model);

LinearProblem kinematic_linear_problem(const KinematicProblem& P);

CandidateResult evaluate_kinematic_candidate(const KinematicProblem& P, const Engine& E,
                                             const std::string& effect, int axis,
                                             const DiagnoseOptions& options);

Diagnosis diagnose_kinematic(std::shared_ptr<const KinematicProblem> P, const DiagnoseOptions& options = {});

// What remains after the verdict: periodic in an axis' position, a step at a
// position, a drift in time, a direction dependence.
std::vector<StructureFinding> find_kinematic_structure(const KinematicProblem& P, const Eigen::VectorXd& residual,
                                                       const DiagnoseOptions& options);

// Fit: base + effects; the new model in the machine frame (the ball-bar
// registered to the nominal pivot as calibration does). Refuses effects the
// data cannot show or determine.
struct KinematicFit {
  kin::KinematicModel model;
  std::vector<CandidateResult> effects;
  std::vector<io::FittedParameter> fitted;
  ErrorFigures on_fit;                 // model as given -> new model (m RMS)
  double base_only = 0.0;              // calibrated base without the effects (m RMS)
  std::optional<ErrorFigures> holdout; // base only -> base + effects, both fitted on the data
  std::optional<ErrorFigures> cross_validation;  // 2-fold, alternate samples
  std::vector<std::string> notes;
};
KinematicFit fit_kinematic(const io::DataSet& data, const kin::KinematicModel& model,
                           const std::vector<FitRequest>& requests, const DiagnoseOptions& options = {},
                           const io::DataSet* holdout = nullptr, bool cross_validate = true);

// cpm fit --add pitch_table:AXIS[:NODES] on ball-bar or position data: the
// table of axis `axis` (0..2; any table it had is replaced) fitted by the
// diagnosis' own fit (kinematic_stages.hpp fit_pitch_table: `nodes` nodes
// over the stroke the data cover, least squares with a second-difference
// penalty chosen by generalised cross-validation, its straight line left to
// the calibration), then the planes recalibrated beside it. Residuals in m.
struct PitchTableFit {
  ctl::MachineModel model;        // the table on `axis`, the planes recalibrated with it
  SuggestedUserEffect table;      // nodes and values (m), as the model file holds them
  double before = 0.0;            // the model as given
  double base_only = 0.0;         // planes recalibrated, no table on the axis
  double after = 0.0;             // planes recalibrated with the table
  std::vector<std::string> notes;
};
// Throws Error (saying which) for an axis outside 1..3, fewer than 4 or more
// than kin::PitchTable::kCapacity nodes, or data that barely move the axis.
PitchTableFit fit_pitch_table(const io::DataSet& data, const ctl::MachineModel& model, int axis, int nodes = 11);

// Residual summary (cpm compare) of a kinematic problem's given residual.
struct KinematicSummary {
  double rms = 0.0, max = 0.0;         // m
  Vec3 component_rms = Vec3::Zero();   // position: x, y, z; ball-bar: rms in [0]
  Vec3 rms_forward = Vec3::Zero(), rms_backward = Vec3::Zero();  // by dir_i (when present)
  Vec3 mean_forward = Vec3::Zero(), mean_backward = Vec3::Zero();
  std::optional<cal::CircularTestResult> circle;  // circle-like ball-bar data
  std::string circle_note;
};
KinematicSummary summarize_kinematic(const KinematicProblem& P, const Eigen::VectorXd& residual);

std::string kinematic_summary_text(const KinematicProblem& P, const KinematicSummary& s);
std::string kinematic_summary_json(const KinematicProblem& P, const KinematicSummary& s, const std::string& model_file);
std::string kinematic_compare_html(const KinematicProblem& P, const KinematicSummary& s, const std::string& title);

}  // namespace cpm::ident

// SPDX-License-Identifier: Apache-2.0
// Diagnosis: which effects of docs/effects.md are missing from a
// model, judged on measurements. For a motion log, a straight list of stages
// (docs/identification.md):
//  1. read: the force residual of the model as given (motion.hpp);
//  2. align: when the logged force acts, actuation_delay (align.hpp), redone
//     with the effects found until it settles;
//  3. columns: every dynamic effect the data can show, on every axis, its
//     nonlinear parameters found by search (the cogging wavelength by a
//     periodogram over 2-100 mm then golden-section refinement, the Stribeck
//     speed by a log grid then refinement), physical bounds enforced; the
//     force gain instrumented (candidate_fitters.cpp, instrumented). One
//     fitter per effect type, from the table in candidates.cpp;
//  4. confounding with the base and between candidates, and the measurement
//     that would separate them (decide.cpp);
//  5. selection: forward, by one statistic, from the model as given, the base
//     refit itself a candidate (select.cpp); each effect chosen refitted on what
//     the others leave;
//  6. outside the library: strong structure in what is left leads the verdict
//     and the selection is redone beside it (outside.cpp);
//  7. verdict and report: every effect found with its parameters (report.hpp).
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "cpm/identification/align.hpp"
#include "cpm/identification/engine.hpp"
#include "cpm/identification/motion.hpp"

namespace cpm::ident {

struct KinematicProblem;  // kinematic.hpp

struct ParamEstimate {
  std::string name, unit;
  double value = 0.0;
  double std_error = -1.0;  // < 0: not determined
  bool at_bound = false;    // held at a physical bound
};

struct Confounder {
  std::string with;         // "E" (a base parameter) or "force_gain[axis 3]"
  std::string effect;       // effect name when `with` is a candidate, empty for base parameters
  int axis = -1;
  double correlation = 0.0; // |cos| of the angle between their signatures (0..1)
  std::string separate_by;  // the measurement that would tell them apart
};

struct CandidateResult {
  std::string effect;       // name of docs/effects.md
  int axis = -1;            // 0..2, -1 for machine-wide effects
  std::vector<ParamEstimate> params;        // in the order of docs/effects.md
  std::vector<ParamEstimate> base_after;    // base parameters after the joint refit
  bool refits_base = true;
  double rss = 0.0;         // weighted
  double rms_after = 0.0;   // data units
  double explained = 0.0;   // share of the baseline mean square removed (0..1)
  double explained_beyond_base = 0.0;  // share of what the base refit leaves
  double f_stat = 0.0, p_value = 1.0, p_adjusted = 1.0;
  double delta_bic = 0.0;   // against its nested parent (< 0 favours the candidate)
  double score = 0.0;       // BIC against the model as given, for ranking (lower first)
  int n_params = 0;         // including searched ones
  int k_total = 0;          // parameters fitted in all (base included) for the test
  double trials = 1.0;      // effective number of independent search trials
  // false: another value of its searched parameter fits these data alike (a
  // wavelength on an axis seen at a few positions only: its aliases).
  bool searched_determined = true;
  double n_eff = 0.0;
  bool identifiable = true;
  bool significant = false;
  std::string note;         // why not identifiable / held at a bound / ...
  std::vector<Confounder> confounded;
  // Effects that explained these data as well when this one was chosen (BIC
  // within 6, signatures alike): the verdict names them as alternatives.
  std::vector<std::string> alternatives;
  Eigen::MatrixXd columns;  // unweighted columns at the fitted nonlinear parameters
  Eigen::VectorXd fitted;   // unweighted contribution of the candidate (data units)
  Eigen::VectorXd residual_after;
  // Beside structure outside the library its refit came out unphysical: kept
  // out of the selection (Diagnosis::partial_unphysical says it with the value).
  bool held_out = false;
  [[nodiscard]] std::string label() const;  // "coulomb_friction[axis 2]"
};

// A variable the data cannot tell from a smooth finding's own (structure.cpp):
// nearly affine in it over the log (|correlation| >= 0.9), or its own fit
// explains at least 80 % of what the finding's does (share).
struct AlikeVariable {
  std::string var;           // d1..d3, v1..v3, a1..a3, t
  double correlation = 0.0;  // of the two variables over the log's rows
  double share = 0.0;        // its fit's removed sum of squares / the finding's
};

struct StructureFinding {
  std::string kind;         // "periodic", "step", "bump", "trend", "direction", "periodic_time"
  int axis = -1;
  std::string coordinate;   // "d1" (position of axis 1), "t", ...
  double location = 0.0;    // SI: position (m), time (s) or wavelength (m)
  double size = 0.0;        // amplitude in data units
  double z = 0.0;           // significance in standard errors
  std::string text;         // one sentence for people
  double lo = 0.0, hi = 0.0;  // bump: the coordinate range it covers; smooth: the variable's range (SI)
  // kind "smooth": a force on `axis` that follows one variable of the state
  // (`coordinate`: d1..d3, v1..v3, a1..a3 or t), fitted by Legendre
  // polynomials of degree 1..kSmoothDegree over [lo, hi]; `size` is the RMS of
  // the fitted force over the log (N).
  std::vector<double> nodes{}, values{};  // the fitted force (N) at a few values of the variable (SI)
  std::string shape{};                // "linear", "odd", "even" or "mixed"
  double slope = 0.0;                 // N per SI unit of the variable (the linear part)
  // Other variables where the same structure is seen (explaining at least
  // 80 % of what `coordinate` does, or nearly affine in it over the log):
  // the data cannot tell them apart. The most alike first; `alike` says why.
  std::vector<std::string> also_in{};
  std::vector<AlikeVariable> alike{};
};

// A user effect that would describe structure no library effect describes,
// as data ready for the model file's `user_effects:` list (docs/model-file.md).
struct SuggestedUserEffect {
  // "pitch_table": an error of axis `axis`' effective displacement against its
  // reading (kinematic data); "table" or "expression": a force on axis `axis`
  // (N), the drive's force beyond the model as the library's effects are.
  std::string kind;
  int axis = -1;                      // 0..2 (the file says 1..3)
  std::string input;                  // table: the variable it follows (d1..d3, v1..v3, a1..a3, t)
  std::vector<double> nodes;          // SI values of the input (pitch_table: encoder readings, m), increasing
  std::vector<double> values;         // at each node: force (N) or, for pitch_table, error (m: d~ = d + value)
  std::string formula;                // expression: e.g. "c*v1"
  std::vector<std::pair<std::string, double>> params;  // expression: its parameters fitted (SI)
  double rms_after = 0.0;             // residual with it fitted beside the rest (data units; 0: not measured)
  std::string text;                   // one sentence for people
};

struct DiagnoseOptions {
  MotionOptions motion;
  double alpha = 0.01;              // family-wise level of "significant"
  double cogging_lambda_min = 2e-3; // m
  double cogging_lambda_max = 0.1;  // m
  std::vector<std::string> effects; // restrict to these names (empty: the whole dynamic library)
  bool structure_search = true;
  int max_forward_steps = 6;  // effects chosen at most (motion: forward selection)
};

struct Diagnosis {
  std::string kind = "motion";      // "motion", "ballbar" or "position"
  std::string units = "N";
  std::string data_file, model_file;
  int samples = 0;                  // rows of the file
  int rows = 0;                     // residual rows used (3 per kept sample)
  double baseline_rms = 0.0, baseline_max = 0.0;
  Vec3 baseline_axis_rms = Vec3::Zero();
  double base_refit_rms = 0.0;
  double noise_floor = 0.0;         // estimated from second differences (data units)
  Vec3 axis_noise = Vec3::Zero();   // per axis: the weights of the fits (N)
  // The honest floor (motion logs): per axis the white part of the final
  // residual, from its high band (second differences along time, corrected
  // for the filter), which the smooth effects and structures do not reach;
  // never the residual's RMS. Said with its source.
  Vec3 axis_floor = Vec3::Zero();   // N
  Vec3 axis_residual_rms = Vec3::Zero();  // N: the final residual per axis
  // Where the floor comes from, in a few words (motion: "residual high band";
  // kinematic: "repeated poses", "bar length high band", "declared sigma",
  // "residual (upper bound)"); noise_floor_text says it in a sentence.
  std::string noise_floor_source;
  // Library effects that explain part of an outside-the-library finding and
  // are therefore not named beside it: labels ("spring[axis 2]").
  std::vector<std::string> partial;
  // Of those, the ones whose refit beside the outside finding came out with a
  // value no missing effect has (a negative reflected inertia, a drive gain
  // beyond 30 %, a parameter pinned at its physical bound) or a parameter
  // the data do not determine (standard error above the value): never named
  // as missing, said as partial with the figure and why.
  struct UnphysicalPartial {
    std::string effect;
    int axis = -1;
    std::vector<ParamEstimate> params;
    std::string why;
    [[nodiscard]] std::string label() const { return effect + (axis >= 0 ? "[axis " + std::to_string(axis + 1) + "]" : ""); }
  };
  std::vector<UnphysicalPartial> partial_unphysical;
  std::vector<CandidateResult> candidates;  // ranked, best first
  int verdict = -1;                 // index in candidates, -1: none missing
  bool ambiguous = false;           // the verdict cannot be told apart from another candidate
  std::vector<int> also;            // further effects by forward selection
  // Every effect named, best first: the verdict, then `also` (indices in candidates).
  [[nodiscard]] std::vector<int> found() const {
    std::vector<int> f;
    if (verdict >= 0) f.push_back(verdict);
    for (int j : also) f.push_back(j);
    return f;
  }
  std::string verdict_text;
  std::vector<StructureFinding> structure;
  // Structure no library effect describes, strong enough to lead the verdict
  // (JSON verdict.missing = "outside_library"): motion logs.
  std::vector<StructureFinding> outside_library;
  std::vector<std::string> notes;
  std::vector<std::string> warnings;
  // Kinematic data: where the noise floor comes from (repeated poses, the
  // bar's high band, the instrument's declared sigma, or the residual, then
  // only an upper bound) and the sentence saying so.
  bool noise_floor_upper_bound = false;
  std::string noise_floor_text;
  // The user effect that would describe an outside_library finding.
  std::vector<SuggestedUserEffect> suggested_user_effects;
  // Kinematic data: per axis, how large a smooth error of its reading (peak
  // to peak of its curved part over the stroke covered, m) these poses and
  // this noise floor let the search find: below `missed_below` no shape is
  // found in 90 % of data sets, above `found_above` every shape is found in
  // 90 % (kinematic_outside.cpp smooth_detectability); above `told_above`
  // it is told in 90 % from the base and from `confused_with`, the library
  // effect that imitates it best (infinite: that effect takes some shape whole).
  struct SmoothDetectability {
    int axis = -1;
    double missed_below = 0.0, found_above = 0.0, told_above = 0.0;
    std::string confused_with;
  };
  std::vector<SmoothDetectability> smooth_detectability;
  Eigen::VectorXd residual_final;   // after the verdict's effects (or the base refit)
  MotionProblem motion;             // the processed data (plots, summaries), kind motion
  Alignment alignment;              // kind motion: when the logged force acts (align.hpp)
  std::shared_ptr<const KinematicProblem> kinematic;  // kinds ballbar and position
};

// Refuses (Error) an effect name that is unknown or that this data kind cannot show.
void check_effect_for_kind(const std::string& effect, const std::string& kind);

Diagnosis diagnose_motion(const io::MotionData& data, const ctl::Machine& model,
                          const DiagnoseOptions& options = {});

// The LinearProblem of a motion problem with per-axis weights 1/sigma_i,
// sigma_i the noise of axis i estimated from the base refit (returned).
LinearProblem motion_linear_problem(const MotionProblem& P, Vec3* axis_noise = nullptr);

// The same problem with only its nuisance columns in the base: fits on it keep
// the base parameters at the model's values (the selection before it chooses
// inertia_error, and cpm fit without it).
LinearProblem nuisance_only(const LinearProblem& L);
// The problem with its base columns but the nuisance.
LinearProblem without_nuisance(const LinearProblem& L);

// One candidate evaluated on an engine (used by diagnose and fit).
CandidateResult evaluate_dynamic_candidate(const MotionProblem& P, const Engine& E,
                                           const ctl::MachineModel& model, const std::string& effect,
                                           int axis, const DiagnoseOptions& options);

}  // namespace cpm::ident

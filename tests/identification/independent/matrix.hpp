// SPDX-License-Identifier: Apache-2.0
// The robustness matrix of the motion diagnosis: logs from the independent
// generator (generator.hpp) in every cell of
//   {sampled, zoh, delay1, delay1_5} x {plant, command} x {250, 1000, 4000 Hz},
// null logs and each dynamic effect of docs/effects.md planted at 3x and 10x its
// unit amplitude (4 standard errors of the amplitude on effect-free data),
// each diagnosed with `cpm::ident::diagnose_motion` and default options, and
// scored: hit (the planted effect on its axis is named), phantom (anything
// else named, except actuation_delay in the delay cells, which is their own
// convention), clean null logs, and the delay's estimate against the truth.
//
// Combination mode (MatrixOptions::combos): per seed and cell one log per
// combination size, with 2 or 3 effects planted at once (a combination motion
// data can separate in principle, see separable()), scored on all planted
// named and phantoms, and then ident::run_loop from the nominal model: the
// waterfall, and whether it ends within 20 % of the noise floor.
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "cpm/identification/diagnose.hpp"
#include "cpm/identification/engine.hpp"
#include "cpm/identification/model_loop.hpp"
#include "cpm/identification/motion.hpp"
#include "generator.hpp"

namespace cpm::indep {

// "viscous_friction[axis 2]" (axis 0-based in, 1-based out), "payload_mass" for axis < 0.
std::string effect_label(const std::string& effect, int axis);

// One effect the diagnosis named. tau (s) is set for actuation_delay.
struct NamedEffect {
  std::string effect;
  int axis = -1;
  double tau = std::numeric_limits<double>::quiet_NaN();
  // Effects the verdict names beside it as explaining these data as well
  // (an ambiguous verdict); labels as label() writes them.
  std::vector<std::string> alternatives;
  // Its parameters as the diagnosis gives them (docs/effects.md order, SI) and
  // their standard errors (< 0: not determined).
  std::vector<double> values, std_errors;
  [[nodiscard]] std::string label() const;  // "viscous_friction[axis 2]" (axis 1-based), "payload_mass"
};

// THE one place that reads what a diagnosis named: the verdict
// (D.candidates[D.verdict] when D.verdict >= 0) then D.candidates[i] for i
// in D.also. Change only this when the Diagnosis API changes.
std::vector<NamedEffect> named_effects(const ident::Diagnosis& D);
// Whether n names the planted effect (its label): as itself, or as the
// alternative of an ambiguous verdict.
bool names_planted(const NamedEffect& n, const std::string& planted);

// An effect of the dynamic library with its shape at unit amplitude.
struct EffectShape {
  std::string name;
  bool per_axis = true;
  std::vector<double> shape;  // parameters at amplitude 1 (the amplitude's entry scaled)
  int amp_index = 0;          // which parameter is the amplitude, -1: all scale together
};
// viscous, Coulomb, Stribeck (v_s 0.02 m/s), cogging (lambda 12 mm, phi 0.5),
// spring (d_ref 0.2 m), force gain, payload, inertia error (link balance).
const std::vector<EffectShape>& dynamic_library();
std::vector<double> planted_values(const EffectShape& e, double amplitude);

// Standard error of the effect's amplitude on effect-free data with its shape
// known (the approach of tests/identification/test_identification.cpp).
// P and E are the prepared null log (ident::prepare_motion) and its engine
// (ident::motion_linear_problem): prepared once, used for every effect and axis.
double amplitude_standard_error(const ident::MotionProblem& P, const ident::Engine& E, const EffectShape& e,
                                int axis);

// One effect of a combination: its index in dynamic_library() and its axis (-1: machine-wide).
struct EffectOnAxis {
  int effect = -1;
  int axis = -1;
};
// Whether motion data can separate these effects planted together in
// principle: distinct effects and no pair of the list of inseparable pairs
// (kInseparable in matrix.cpp, with the reason for each).
bool separable(const std::vector<EffectOnAxis>& set);
// Every separable combination of n effects drawn from `pool` (indices in
// dynamic_library()), per-axis ones on every axis, in a fixed order.
std::vector<std::vector<EffectOnAxis>> separable_combinations(const std::vector<int>& pool, int n);

struct MatrixOptions {
  std::vector<Timing> timings = {Timing::sampled, Timing::zoh, Timing::delay1, Timing::delay1_5};
  std::vector<NoisePlacement> noises = {NoisePlacement::plant, NoisePlacement::command};
  std::vector<double> rates = {250.0, 1000.0, 4000.0};
  std::vector<std::string> effects;        // empty: the whole dynamic library
  std::vector<double> multiples = {3.0, 10.0};
  bool nulls = true;
  // Combination sizes (2, 3). Non-empty: the matrix holds only combination
  // logs, one per seed, cell, size and multiple, drawn from `effects`.
  std::vector<int> combos;
  int seeds = 1;
  int first_seed = 1;                      // seeds first_seed .. first_seed + seeds - 1
  double duration = 20.0;                  // s per log
  int threads = 1;
  std::string write_logs;                  // directory: write every log as CSV ("" = no)
  ident::DiagnoseOptions diagnose;         // default options
};

struct LogResult {
  Timing timing = Timing::zoh;
  NoisePlacement noise = NoisePlacement::plant;
  double rate = 0.0;
  int seed = 0;                  // matrix seed (1..N)
  std::uint64_t log_seed = 0;    // generator seed
  std::string planted;           // "" for a null log
  int axis = -1;
  double multiple = 0.0;
  double amplitude = 0.0;
  std::vector<NamedEffect> named;
  bool hit = false;
  std::vector<std::string> phantoms;  // labels of named effects that were not planted
  double tau_error_periods = std::numeric_limits<double>::quiet_NaN();  // |tau - true| / T when named
  // The planted amplitude as the diagnosis estimates it, where the planted
  // effect itself was named: (estimate - planted) / its standard error. NaN
  // otherwise. (inertia_error, whose parameters scale together: its largest, dC.)
  double amplitude_z = std::numeric_limits<double>::quiet_NaN();
  std::string error;             // the generator or the diagnosis threw
  double generate_s = 0.0, diagnose_s = 0.0;
  // A combination log: every effect planted (`planted` stays ""), how many of
  // them were named (`hit`: all), and the loop from the nominal model:
  // waterfall[0] is the model as given, then one step per effect added.
  std::vector<PlantedEffect> combo;
  int planted_named = 0;
  std::vector<ident::LoopStep> waterfall;
  std::string loop_stop;
  bool loop_within = false;      // final RMS <= kLoopTolerance x the final noise floor
  double loop_s = 0.0;
  [[nodiscard]] bool is_combo() const { return !combo.empty(); }
  [[nodiscard]] double final_over_floor() const;  // NaN without a waterfall
};

// The loop "brings the residual to within 20 % of the noise floor".
constexpr double kLoopTolerance = 1.2;

struct CellSummary {
  Timing timing = Timing::zoh;
  NoisePlacement noise = NoisePlacement::plant;
  double rate = 0.0;
  int hits3 = 0, n3 = 0, hits10 = 0, n10 = 0;  // planted at 3x / 10x named
  std::vector<std::pair<double, std::pair<int, int>>> hits_by_multiple;  // multiple -> (hits, n)
  int null_clean = 0, n_null = 0;
  int phantoms = 0, named = 0;       // phantom names / all names in the cell
  int logs = 0, logs_with_phantom = 0;
  int errors = 0;
  double median_tau_error = std::numeric_limits<double>::quiet_NaN();  // periods, delay cells
  int tau_named = 0;
  std::vector<std::pair<std::string, int>> top_phantoms;  // most frequent first
  std::vector<std::string> missed;   // "coulomb_friction[axis 2] x3 seed 1"
  // Combination logs: all planted named, loop within kLoopTolerance of the floor.
  int n_combo = 0, combo_all_named = 0, loop_within = 0;
  double median_final_over_floor = std::numeric_limits<double>::quiet_NaN();
  std::vector<std::string> combo_failures;  // per log that misses either: planted, named, waterfall
};

struct MatrixResult {
  MatrixOptions options;
  std::vector<LogResult> logs;
  std::vector<CellSummary> cells;
  // Unit amplitudes: per (noise, rate) and effect/axis, as text lines for the report.
  struct Unit {
    NoisePlacement noise;
    double rate;
    std::string effect;
    int axis;
    double value;
  };
  std::vector<Unit> units;
  double wall_s = 0.0;
};

// Runs the matrix. `progress` (may be empty) is called after each log.
MatrixResult run_matrix(const MatrixOptions& o, const std::function<void(const LogResult&, int done, int total)>& progress = {});

std::vector<CellSummary> summarise(const std::vector<LogResult>& logs, const MatrixOptions& o);
std::string markdown_table(const MatrixResult& r);  // the combination table when options.combos
// One line for a combination log: planted, named, the waterfall and the floor.
std::string combo_log_text(const LogResult& r);
std::string to_json(const MatrixResult& r);
// Per noise placement and effect, over the logs where the planted effect was
// named: how many, the mean and spread of amplitude_z, and the mean's own
// standard error: an unbiased estimate with honest standard errors has mean
// z within ~2 of its standard error of 0 and spread ~1.
std::string amplitude_bias_table(const MatrixResult& r);

// The thresholds: every planted effect named, every null log clean,
// phantoms <= 1 in 50 logs; in combination cells all planted named and the
// loop within 20 % of the floor in >= 95 % of the logs, phantoms <= 1 in 50
// named. One line per cell that fails, saying how.
std::vector<std::string> threshold_failures(const MatrixResult& r, double phantom_rate = 1.0 / 50.0);

}  // namespace cpm::indep

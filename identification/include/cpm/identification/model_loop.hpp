// SPDX-License-Identifier: Apache-2.0
// The user's loop, as one command (cpm loop): diagnose, add the effect found
// first, refit every effect added so far together, diagnose again, until
// nothing is missing, something outside the library is, or the steps run out.
// Each step records the residual RMS of the model it leaves: the waterfall
// that shows the error fall to the noise floor.
#pragma once

#include <string>
#include <vector>

#include "cpm/identification/diagnose.hpp"
#include "cpm/identification/fit.hpp"
#include "cpm/io/data_files.hpp"

namespace cpm::ident {

struct LoopStep {
  std::string added;         // the effect added at this step ("" for the model as given)
  double rms = 0.0;          // residual RMS of the model after this step (N for motion, m otherwise)
  double noise_floor = 0.0;  // the diagnosis' estimate, same units
  std::string verdict;       // what the diagnosis of that model said
};

// The suggestion for a finding, or kind "" when a table or expression would
// not describe it better than a library effect (periodic, direction, trend).
SuggestedUserEffect suggest_user_effect(const StructureFinding& f);

struct LoopResult {
  std::string kind;                          // "motion", "ballbar", "position"
  std::string units;                         // "N" or "m"
  ctl::MachineModel model;                   // the model after the last step
  std::vector<FitRequest> added;             // in the order added
  std::vector<io::FittedParameter> fitted;   // of the last refit (for the model file)
  std::vector<CandidateResult> effects;      // their parameters after the last refit
  std::vector<LoopStep> steps;               // the waterfall: steps[0] is the model as given
  std::string stop;                          // why the loop stopped, for people
  bool outside_library = false;              // it stopped at something no library effect describes
  SuggestedUserEffect suggestion;            // then: that finding as a user effect (kind "" if none)
  std::vector<SuggestedUserEffect> user_added;  // user effects added (allowed kinds), as fitted, in order
  std::vector<std::string> notes;            // outside findings reported that did not stop the loop
};

// An outside finding too small to stop the loop while significant library
// effects remain: under the noise floor, or under kSmallFindingShare of what
// the effects explain (`explained`, RMS in the data's units).
inline constexpr double kSmallFindingShare = 0.02;
bool finding_too_small(const StructureFinding& f, const Diagnosis& D, double explained);

// Why the loop stops at diagnosis D after the steps of R (empty: go on and
// add one of `next`, best first). With an outside finding: the library
// effects named beside it first; when every finding is too small
// (finding_too_small), the significant library candidates not yet added;
// only then the finding stops it.
std::string loop_stop_reason(const Diagnosis& D, const LoopResult& R, std::vector<FitRequest>& next);

// The suggestion of a diagnosis' first outside finding: kinematic data, the
// pitch_table the diagnosis fitted; motion, suggest_user_effect of the finding.
SuggestedUserEffect suggestion_of(const Diagnosis& D);

// The model's user effect for a motion suggestion (table or expression), or
// throws Error saying why it cannot be one (a table over a1..a3 or t).
ctl::UserEffect user_effect_of(const SuggestedUserEffect& s);

// The model's pitch table for a pitch_table suggestion; throws Error when it is not a usable one.
kin::PitchTable pitch_table_of(const SuggestedUserEffect& s);

// The waterfall's label of a user effect: "expression[axis 2]: c*v1", "table[axis 1]: d1", "pitch_table[axis 1]".
std::string label_of(const SuggestedUserEffect& s);

// `allow`: the user effect kinds ("table", "expression", "pitch_table") the
// loop may add when it reaches an outside finding whose suggestion is of that
// kind: it adds it, fits it (motion: fit_user_effect with the library effects
// held, then those refitted beside it; kinematic: the diagnosis' pitch table,
// the planes recalibrated beside it) and goes on. Empty: it stops there.
LoopResult run_loop(const io::DataSet& data, const ctl::MachineModel& model, const DiagnoseOptions& options = {},
                    int max_steps = 6, const std::vector<std::string>& allow = {});

// The waterfall as text and as an HTML page (bars of RMS per step, the noise floor drawn over them).
std::string loop_text(const LoopResult& R);
std::string loop_html(const LoopResult& R, const std::string& data_file);
std::string loop_json(const LoopResult& R, const std::string& data_file, const std::string& out_file);

}  // namespace cpm::ident

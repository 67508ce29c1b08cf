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
};

LoopResult run_loop(const io::DataSet& data, const ctl::MachineModel& model, const DiagnoseOptions& options = {},
                    int max_steps = 6);

// The waterfall as text and as an HTML page (bars of RMS per step, the noise floor drawn over them).
std::string loop_text(const LoopResult& R);
std::string loop_html(const LoopResult& R, const std::string& data_file);
std::string loop_json(const LoopResult& R, const std::string& data_file, const std::string& out_file);

}  // namespace cpm::ident

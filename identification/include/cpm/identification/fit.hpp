// SPDX-License-Identifier: Apache-2.0
// cpm fit: add effects to a model, refit, and measure the error before and
// after on the fitted data and on data it was not fitted to.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "cpm/identification/diagnose.hpp"
#include "cpm/io/model_file.hpp"

namespace cpm::ident {

struct FitRequest {
  std::string effect;
  int axis = -1;  // 0..2, -1 for machine-wide effects
};

// "coulomb_friction:2" -> {coulomb_friction, 1}; "payload_mass" -> {payload_mass, -1}.
// Throws Error for unknown names, a missing or extra axis.
FitRequest parse_fit_request(const std::string& spec);

struct ErrorFigures {
  double before = 0.0;   // RMS force residual of the model as given (N)
  double after = 0.0;    // of the new model, nothing refitted (N)
};

struct FitResult {
  ctl::MachineModel model;                 // the new model
  std::vector<CandidateResult> effects;    // one per request (actuation_delay first when asked for)
  std::optional<CandidateResult> delay;    // actuation_delay, when asked for
  bool base_refitted = false;              // A..E changed (written as inertia_error)
  std::vector<ParamEstimate> base_change;  // dA, dB, dC, dE with standard errors
  std::vector<io::FittedParameter> fitted; // for the model file
  ErrorFigures on_fit;
  std::optional<ErrorFigures> holdout;     // --holdout FILE
  std::optional<ErrorFigures> cross_validation;  // 2-fold by halves in time, when no holdout
  std::vector<std::string> notes;
};

// Fit on a motion log. Refuses (Error) effects the data cannot show or
// determine (not excited, confounded with the base), saying why.
FitResult fit_motion(const io::MotionData& data, const ctl::MachineModel& model,
                     const std::vector<FitRequest>& requests, const DiagnoseOptions& options = {},
                     const io::MotionData* holdout = nullptr, bool cross_validate = true);

// RMS force residual of a model on a log, N: nothing of the model refitted,
// only the plane nuisance (the tilts and offsets of a model whose kinematics
// was not calibrated, motion.hpp), as the diagnosis' "model as given" has it.
// The effects are fitted beside that nuisance; measured without it, an effect
// fitted alone beside a missing one the nuisance had partly taken (a spring
// beside a payload) made the residual 4x worse, and the loop stopped there.
double motion_rms(const io::MotionData& data, const ctl::MachineModel& model, const MotionOptions& o = {});

}  // namespace cpm::ident

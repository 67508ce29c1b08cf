// SPDX-License-Identifier: Apache-2.0
// cpm fit for user effects (docs/effects.md, "Effects you add"): a table's
// values or an expression's parameters fitted on a motion log, beside the
// nuisance the model as given is fitted with (motion.hpp, plane tilts).
//
//   table:      the force is linear in the values at the nodes (the hat
//               functions of linear interpolation held beyond the ends), so
//               the values come from linear least squares with a penalty
//               lambda * sum (second difference of the values)^2; lambda
//               minimises the generalised cross-validation score
//               GCV = n RSS / (n - tr H)^2 over a log grid;
//   expression: the parameters by Levenberg-Marquardt on the residual, the
//               Jacobian by central differences, each parameter kept within
//               its bounds from the model file (the nuisance projected out
//               at every step).
// Standard errors from the weighted residual (rows decimated so that
// neighbours are nearly independent, motion.hpp).
#pragma once

#include <string>
#include <vector>

#include "cpm/control/machine.hpp"
#include "cpm/identification/motion.hpp"
#include "cpm/io/data_files.hpp"

namespace cpm::ident {

struct UserFit {
  ctl::MachineModel model;             // the model with the fitted values
  int index = -1;                      // the effect, in model.user_effects
  std::vector<std::string> names;      // "values[k]" (table) or the parameter names
  std::vector<double> value, std_error;  // table: N at each node; expression: in the parameters' units
  double lambda = 0.0;                 // table: the smoothness weight GCV chose (weighted units)
  double effective_parameters = 0.0;   // table: tr H at lambda (nuisance included)
  int iterations = 0;                  // expression: LM steps taken
  double rms_before = 0.0, rms_after = 0.0;  // N: force residual RMS without the effect and with it
  std::vector<std::string> notes;
};

// Fit user effect `index` of model.user_effects on a motion log; its values
// in the model are the starting point (expression) or ignored (table).
// Throws Error when the data do not reach the table's nodes or the
// expression's parameters are not determined (singular Jacobian), saying which.
UserFit fit_user_effect(const io::MotionData& data, const ctl::MachineModel& model, int index,
                        const MotionOptions& options = {});

// A table of `nodes` nodes over the range the log covers on the input
// (d_j or v_j, `input` as "d2"), values 0, for fitting: what
// `cpm fit --add table:AXIS:INPUT[:NODES]` adds before it fits.
ctl::UserEffect table_over_data(const io::MotionData& data, int axis, const std::string& input, int nodes);

}  // namespace cpm::ident

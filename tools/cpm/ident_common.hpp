// SPDX-License-Identifier: Apache-2.0
// Options shared by the identification subcommands (compare, diagnose, fit,
// loop): the measurements, the model judged, the motion logs' filter, and
// the new model file fit and loop write. Not a subcommand itself.
#pragma once

#include <optional>
#include <string>

#include "cli.hpp"
#include "cpm/identification/align.hpp"
#include "cpm/identification/motion.hpp"
#include "cpm/identification/report.hpp"

namespace cpm::cli {

struct MeasurementOptions {
  std::string data;
  std::optional<std::string> model;
  double window_ms = ident::MotionOptions{}.half_window * 1e3;
  [[nodiscard]] std::string model_path() const { return model_or_default(model); }
  [[nodiscard]] double half_window() const { return window_ms * 1e-3; }  // s
};

// --data FILE.csv (required), --model MODEL.yaml, --window MS.
inline void add_measurement_options(CLI::App& app, MeasurementOptions& m, const std::string& model_what) {
  app.add_option("--data", m.data,
                 "the measurements: a motion log, ball-bar or position data (data-formats.md), or an lcm-logger file "
                 "of cpmd's state")
      ->type_name("FILE.csv")
      ->required();
  add_model_option(app, m.model, model_what);
  add_number(app, "--window", m.window_ms, "MS", "half width of the motion logs' smoothing filter in ms");
}

// --out NEW_MODEL.yaml (required) of fit and loop.
inline void add_new_model_option(CLI::App& app, std::string& out) {
  app.add_option("--out", out, "the new model file (the input model is never overwritten)")
      ->type_name("NEW_MODEL.yaml")
      ->required();
}

// A model judged on a motion log as compare does it: aligned as far as the
// model may take (ident::alignment_text says how), the residual's summary
// with the fit per axis, and its correlation (MATLAB's compare and resid).
struct MotionJudgement {
  ident::MotionProblem P;
  ident::Alignment A;
  ident::ResidualSummary s;
  ident::ResidualCorrelation c;
};
inline MotionJudgement judge_motion(const io::MotionData& data, const ctl::Machine& model,
                                    const ident::MotionOptions& mo, int lags) {
  MotionJudgement m{ident::prepare_motion(data, model, mo), {}, {}, {}};
  m.A = ident::align_motion(data, model, mo);
  m.P.set_delay(m.A.reference);
  m.s = ident::summarize(m.P, m.P.residual);
  m.c = ident::residual_correlation(m.P, m.P.residual, lags);
  return m;
}

}  // namespace cpm::cli

// SPDX-License-Identifier: Apache-2.0
// cpm diagnose: which effect of the library is missing from a model, judged
// on measurements (motion logs: the force residual; identification/).
#include <cstdio>

#include "ident_common.hpp"
#include "cpm/identification/diagnose.hpp"
#include "cpm/identification/fit.hpp"
#include "cpm/identification/kinematic.hpp"
#include "cpm/identification/report.hpp"
#include "cpm/io/data_files.hpp"
#include "cpm/io/model_file.hpp"
#include "state_log.hpp"

namespace cpm::cli {
namespace {

struct Options {
  MeasurementOptions in;
  std::optional<std::string> json, report, validate;
  ident::DiagnoseOptions diagnose;
  bool quiet = false;
};

// --validate: the effects the diagnosis found, fitted on its log, judged on a
// second log neither saw: the residual before and after, the fit per axis
// and the residual's correlation of the model with them (as compare gives).
void validate(const ident::Diagnosis& D, const io::MotionData& data, const ctl::MachineModel& given,
              const ident::DiagnoseOptions& o, const std::string& path, bool quiet) {
  const io::MotionData val = io::read_motion(path);
  std::vector<ident::FitRequest> req;
  for (int j : D.found()) {
    const ident::CandidateResult& c = D.candidates[static_cast<std::size_t>(j)];
    req.push_back({c.effect, c.axis});
  }
  ctl::MachineModel model = given;
  std::string what = "the model as given (nothing found to fit)";
  if (!req.empty()) {
    const ident::FitResult R = ident::fit_motion(data, given, req, o, &val, /*cross_validate=*/false);
    model = R.model;
    what = "the model with the effects found (fitted on " + D.data_file + ")";
    if (!quiet && R.holdout)
      std::printf("\nvalidation on %s (seen by neither the diagnosis nor the fit): force residual RMS %.4g N with the "
                  "model as given, %.4g N with the effects found\n",
                  path.c_str(), R.holdout->before, R.holdout->after);
  }
  if (!D.outside_library.empty() && !quiet)
    std::printf("(the structure outside the library is not carried over: it has no fit here)\n");
  if (quiet) return;
  const MotionJudgement m = judge_motion(val, ctl::Machine(model), o.motion, 20);
  std::printf("on %s, %s:\n", path.c_str(), what.c_str());
  std::printf("  fit to the measured force (NRMSE): axis 1 %.2f %%, axis 2 %.2f %%, axis 3 %.2f %%\n",
              m.s.fit_percent[0], m.s.fit_percent[1], m.s.fit_percent[2]);
  std::fputs(ident::correlation_text(m.c).c_str(), stdout);
}

int run(const Options& opt) {
  const std::string model_path = opt.in.model_path();
  const std::string& data_path = opt.in.data;
  const auto& json_path = opt.json;
  const auto& report_path = opt.report;
  ident::DiagnoseOptions o = opt.diagnose;
  o.motion.half_window = opt.in.half_window();
  const bool quiet = opt.quiet;
  if (!(o.alpha > 0.0 && o.alpha < 1.0)) throw UsageError("--alpha must be within (0, 1)");
  const io::DataSet ds = read_measurements(data_path);
  const io::ModelFile mf = io::load_model_file(model_path);
  if (opt.validate && !std::holds_alternative<io::MotionData>(ds))
    throw UsageError("--validate: motion logs only (kinematic data: cpm fit --holdout judges on unseen data)");
  ident::Diagnosis D;
  if (!std::holds_alternative<io::MotionData>(ds)) {
    const std::string kind = io::kind_name(io::kind_of(ds));
    for (const auto& e : o.effects) ident::check_effect_for_kind(e, kind);
    D = ident::diagnose_kinematic(
        std::make_shared<const ident::KinematicProblem>(ident::prepare_kinematic(ds, mf.model.kinematics)), o);
  } else {
    const ctl::Machine model(mf.model);
    D = ident::diagnose_motion(std::get<io::MotionData>(ds), model, o);
  }
  D.model_file = model_path;
  if (!quiet) std::fputs(ident::diagnosis_text(D).c_str(), stdout);
  if (opt.validate) validate(D, std::get<io::MotionData>(ds), mf.model, o, *opt.validate, quiet);
  if (json_path) io::write_file_atomically(*json_path, ident::diagnosis_json(D));
  if (report_path) {
    io::write_file_atomically(*report_path, ident::diagnosis_html(D));
    if (!quiet) std::printf("report: %s\n", report_path->c_str());
  }
  return 0;
}

Run setup(CLI::App& app) {
  auto o = std::make_shared<Options>();
  add_measurement_options(app, o->in, "the model to diagnose");
  app.add_option("--json", o->json, "write the diagnosis as JSON")->type_name("OUT.json");
  app.add_option("--report", o->report, "write an HTML report with the plots")->type_name("OUT.html");
  app.add_option("--effect", o->diagnose.effects, "judge only these effects (repeat the option; e.g. --effect backlash)")
      ->type_name("EFFECT")
      ->check(effect_name())
      ->allow_extra_args(false);
  add_number(app, "--alpha", o->diagnose.alpha, "P", "significance level of the F-test, within (0, 1)")
;
  app.add_flag("--quiet", o->quiet, "print nothing (the files only)");
  app.add_option("--validate", o->validate,
                 "motion logs: fit the effects found on --data and judge them on this second log (residual, fit %, "
                 "residual correlation)")
      ->type_name("FILE.csv");
  app.footer("Motion logs: the force residual, every dynamic effect of the library on every axis fitted with the\n"
             "base (A, B, C, E), scored (RMS after, share explained, F-test, BIC, confounding), ranked, a verdict,\n"
             "and the structure no effect explains. Ball-bar and position data: the same with every kinematic\n"
             "effect, fitted jointly with calibration's base (beta', dq[, dl]; the 12 plane parameters).");
  return [o] { return run(*o); };
}

const Command reg{"diagnose", "name the effect missing from a model, judged on measurements", setup};

}  // namespace
}  // namespace cpm::cli

// SPDX-License-Identifier: Apache-2.0
// cpm compare: the residual of a model on a data file, broken down by axis,
// direction, position and time, with an HTML report (identification/).
// Motion logs: the force residual (N). Ball-bar and position data: the
// length or position residual (m; µm on screen), with the polar trace and
// G, H, F of ISO 230-4 when the ball-bar data are a circle about the pivot.
#include <cmath>
#include <cstdio>
#include <optional>

#include "ident_common.hpp"
#include "cpm/identification/align.hpp"
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
  int lags = 20;
};

int run(const Options& o) {
  const std::string model_path = o.in.model_path();
  const std::string& data_path = o.in.data;
  const auto& json_path = o.json;
  const auto& report_path = o.report;
  ident::MotionOptions mo;
  mo.half_window = o.in.half_window();
  const io::DataSet ds = read_measurements(data_path);
  const io::ModelFile mf = io::load_model_file(model_path);
  const std::string title = "cpm compare: " + model_path + " on " + data_path;
  if (!std::holds_alternative<io::MotionData>(ds)) {
    const ident::KinematicProblem P = ident::read_kinematic(ds, mf.model.kinematics);
    const ident::KinematicSummary s = ident::summarize_kinematic(P, P.residual_given);
    std::printf("model %s on %s (kind %s, %d samples)\n", model_path.c_str(), data_path.c_str(), P.kind.c_str(),
                P.samples());
    std::fputs(ident::kinematic_summary_text(P, s).c_str(), stdout);
    for (const auto& w : P.warnings) std::printf("warning: %s\n", w.c_str());
    if (json_path) io::write_file_atomically(*json_path, ident::kinematic_summary_json(P, s, model_path));
    if (report_path) {
      io::write_file_atomically(*report_path, ident::kinematic_compare_html(P, s, title));
      std::printf("report: %s\n", report_path->c_str());
    }
    return 0;
  }
  const io::MotionData& data = std::get<io::MotionData>(ds);
  const ctl::Machine model(mf.model);
  const MotionJudgement m = judge_motion(data, model, mo, o.lags);
  std::printf("%s\n", ident::alignment_text(m.A).c_str());
  std::printf("model %s on %s (kind motion, %zu samples)\n", model_path.c_str(), data_path.c_str(), data.t.size());
  std::fputs(ident::summary_text(m.s, m.P).c_str(), stdout);
  std::fputs(ident::correlation_text(m.c).c_str(), stdout);
  for (const auto& w : m.P.warnings) std::printf("warning: %s\n", w.c_str());
  // --validate: the same model judged on a second log (one it was not fitted on).
  std::optional<MotionJudgement> v;
  if (o.validate) {
    const io::DataSet vs = read_measurements(*o.validate);
    if (!std::holds_alternative<io::MotionData>(vs))
      throw Error(*o.validate + ": --validate needs a motion log, as --data is");
    v = judge_motion(std::get<io::MotionData>(vs), model, mo, o.lags);
    std::printf("\nvalidation: model %s on %s (kind motion, %zu samples)\n%s\n", model_path.c_str(),
                o.validate->c_str(), std::get<io::MotionData>(vs).t.size(), ident::alignment_text(v->A).c_str());
    std::fputs(ident::summary_text(v->s, v->P).c_str(), stdout);
    std::fputs(ident::correlation_text(v->c).c_str(), stdout);
    std::printf("fit (%%): on %s %.1f, %.1f, %.1f; on %s (validation) %.1f, %.1f, %.1f\n", data_path.c_str(),
                m.s.fit_percent[0], m.s.fit_percent[1], m.s.fit_percent[2], o.validate->c_str(), v->s.fit_percent[0],
                v->s.fit_percent[1], v->s.fit_percent[2]);
  }
  if (json_path)
    io::write_file_atomically(*json_path,
                              ident::summary_json(m.s, m.P, data_path, model_path, static_cast<int>(data.t.size())));
  if (report_path) {
    std::string html = ident::compare_html(m.P, m.s, title, &m.c);
    if (v) {
      // The validation's sections after the first log's, under their own heading.
      const std::string vh = ident::compare_html(v->P, v->s, "validation on " + *o.validate, &v->c);
      const auto body = vh.find("<body>"), end = html.rfind("</body>");
      html = html.substr(0, end) + "<hr>" + vh.substr(body + 6);
    }
    io::write_file_atomically(*report_path, html);
    std::printf("report: %s\n", report_path->c_str());
  }
  return 0;
}

Run setup(CLI::App& app) {
  auto o = std::make_shared<Options>();
  add_measurement_options(app, o->in, "the model to judge");
  app.add_option("--json", o->json, "write the residual summary as JSON (SI units)")->type_name("OUT.json");
  app.add_option("--report", o->report, "write an HTML report with the plots")->type_name("OUT.html");
  app.add_option("--validate", o->validate,
                 "motion logs: judge the model on this second log too (fit % and residual correlation on data it was "
                 "not fitted on)")
      ->type_name("FILE.csv");
  app.add_option("--lags", o->lags, "motion logs: the residual correlation's lags (rows)")->type_name("K")->capture_default_str();
  app.footer("Motion logs: force residual (N), the fit per axis (100 (1 - |y - yhat| / |y - mean(y)|) %, as MATLAB's\n"
             "compare) and the residual's autocorrelation and cross-correlation with position, velocity and force with\n"
             "their 99 % bands (as MATLAB's resid; docs/identification.md). Ball-bar and position data: length or position residual (m in the\n"
             "JSON, µm on screen); a ball-bar circle about the pivot gets G, H, F and its polar plot.");
  return [o] { return run(*o); };
}

const Command reg{"compare", "residuals of a model on measurements, by axis, direction, position and time", setup};

}  // namespace
}  // namespace cpm::cli

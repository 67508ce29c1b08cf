// cpm compare: the residual of a model on a data file, broken down by axis,
// direction, position and time, with an HTML report (identification/).
// Motion logs: the force residual (N). Ball-bar and position data: the
// length or position residual (m; µm on screen), with the polar trace and
// G, H, F of ISO 230-4 when the ball-bar data are a circle about the pivot.
#include <cstdio>

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
  std::optional<std::string> json, report;
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
  ident::MotionProblem P = ident::prepare_motion(data, model, mo);
  // The model as given may take the force's alignment within half a period of
  // its own actuation_delay (how the log was sampled); beyond is its error.
  const ident::Alignment A = ident::align_motion(data, model, mo);
  P.set_delay(A.reference);
  std::printf("force alignment: %.3f ms after t_k (%s); compared at %.3f ms (model's actuation_delay %.3f ms)\n",
              A.tau * 1e3, A.convention().c_str(), A.reference * 1e3, A.model_tau * 1e3);
  const ident::ResidualSummary s = ident::summarize(P, P.residual);
  std::printf("model %s on %s (kind motion, %zu samples)\n", model_path.c_str(), data_path.c_str(), data.t.size());
  std::fputs(ident::summary_text(s, P).c_str(), stdout);
  for (const auto& w : P.warnings) std::printf("warning: %s\n", w.c_str());
  if (json_path)
    io::write_file_atomically(*json_path, ident::summary_json(s, P, data_path, model_path, static_cast<int>(data.t.size())));
  if (report_path) {
    io::write_file_atomically(*report_path, ident::compare_html(P, s, title));
    std::printf("report: %s\n", report_path->c_str());
  }
  return 0;
}

Run setup(CLI::App& app) {
  auto o = std::make_shared<Options>();
  add_measurement_options(app, o->in, "the model to judge");
  app.add_option("--json", o->json, "write the residual summary as JSON (SI units)")->type_name("OUT.json");
  app.add_option("--report", o->report, "write an HTML report with the plots")->type_name("OUT.html");
  app.footer("Motion logs: force residual (N). Ball-bar and position data: length or position residual (m in the\n"
             "JSON, µm on screen); a ball-bar circle about the pivot gets G, H, F and its polar plot.");
  return [o] { return run(*o); };
}

const Command reg{"compare", "residuals of a model on measurements, by axis, direction, position and time", setup};

}  // namespace
}  // namespace cpm::cli

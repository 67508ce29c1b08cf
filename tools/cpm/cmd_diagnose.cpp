// cpm diagnose: which effect of the library is missing from a model, judged
// on measurements (motion logs: the force residual; identification/).
#include <cstdio>

#include "cli.hpp"
#include "cpm/identification/diagnose.hpp"
#include "cpm/identification/report.hpp"
#include "cpm/io/data_files.hpp"
#include "cpm/io/model_file.hpp"

namespace cpm::cli {
namespace {

int run(Args& a) {
  const std::string model_path = a.option_or("model", "config/machine.yaml");
  const auto data_path = a.option("data");
  const auto json_path = a.option("json");
  const auto report_path = a.option("report");
  ident::DiagnoseOptions o;
  o.effects = a.options("effect");
  o.alpha = a.number("alpha", o.alpha);
  o.motion.half_window = a.number("window", o.motion.half_window * 1e3) * 1e-3;
  const bool quiet = a.flag("quiet");
  a.finish();
  if (!data_path) throw UsageError("--data FILE is required");
  if (!(o.alpha > 0.0 && o.alpha < 1.0)) throw UsageError("--alpha must be within (0, 1)");
  const io::DataSet ds = io::read_data_file(*data_path);
  if (!std::holds_alternative<io::MotionData>(ds)) {
    const std::string kind = std::holds_alternative<io::BallbarData>(ds) ? "ballbar" : "position";
    for (const auto& e : o.effects) ident::check_effect_for_kind(e, kind);
    throw Error(*data_path + ": kind = " + kind +
                ": the kinematic diagnosis (ball-bar and position data) is not available yet; it needs the "
                "calibration module's base fit (see docs/identification.md)");
  }
  const io::MotionData& data = std::get<io::MotionData>(ds);
  const io::ModelFile mf = io::load_model_file(model_path);
  const ctl::Machine model(mf.model);
  ident::Diagnosis D = ident::diagnose_motion(data, model, o);
  D.model_file = model_path;
  if (!quiet) std::fputs(ident::diagnosis_text(D).c_str(), stdout);
  if (json_path) io::write_file_atomically(*json_path, ident::diagnosis_json(D));
  if (report_path) {
    io::write_file_atomically(*report_path, ident::diagnosis_html(D));
    if (!quiet) std::printf("report: %s\n", report_path->c_str());
  }
  return 0;
}

const Command reg{
    "diagnose", "name the effect missing from a model, judged on measurements", run,
    "--data FILE.csv [--model MODEL.yaml] [--json OUT.json] [--report OUT.html]\n"
    "       [--effect NAME]... (only these effects) [--alpha 0.01] [--window MS (filter half width, 12)] [--quiet]\n"
    "  Motion logs: the force residual, every dynamic effect of effects.md on every axis fitted with the\n"
    "  base (A, B, C, E), scored (RMS after, share explained, F-test, BIC, confounding), ranked, a verdict,\n"
    "  and the structure no effect explains. Default model: config/machine.yaml."};

}  // namespace
}  // namespace cpm::cli

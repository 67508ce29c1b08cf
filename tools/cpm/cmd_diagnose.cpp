// cpm diagnose: which effect of the library is missing from a model, judged
// on measurements (motion logs: the force residual; identification/).
#include <cstdio>

#include "cli.hpp"
#include "cpm/identification/diagnose.hpp"
#include "cpm/identification/kinematic.hpp"
#include "cpm/identification/report.hpp"
#include "cpm/io/data_files.hpp"
#include "cpm/io/model_file.hpp"
#include "state_log.hpp"

namespace cpm::cli {
namespace {

int run(Args& a) {
  const std::string model_path = a.option_or("model", default_model_path());
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
  const io::DataSet ds = read_measurements(*data_path);
  const io::ModelFile mf = io::load_model_file(model_path);
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
    "  Motion logs: the force residual, every dynamic effect of docs/effects.md on every axis fitted with the\n"
    "  base (A, B, C, E), scored (RMS after, share explained, F-test, BIC, confounding), ranked, a verdict,\n"
    "  and the structure no effect explains. Ball-bar and position data: the same with every kinematic\n"
    "  effect, fitted jointly with calibration's base (beta', dq[, dl]; the 12 plane parameters).\n"
    "  Default model: config/machine.yaml."};

}  // namespace
}  // namespace cpm::cli

// cpm fit: add effects to a model, refit, write the new model file (never
// the input), and show the error before and after (identification/).
#include <cstdio>
#include <sstream>

#include "cli.hpp"
#include "cpm/identification/fit.hpp"
#include "cpm/identification/kinematic.hpp"
#include "cpm/identification/report.hpp"
#include "cpm/io/data_files.hpp"
#include "cpm/io/model_file.hpp"
#include "state_log.hpp"

namespace cpm::cli {
namespace {

// Ball-bar and position data: the effects go into the kinematics, the planes
// are recalibrated with them; errors in m (µm on screen).
int run_kinematic(const io::DataSet& ds, const std::vector<ident::FitRequest>& req, const std::vector<std::string>& adds,
                  const std::string& model_path, const std::string& data_path, const std::string& out_path,
                  const std::optional<std::string>& holdout_path, const std::optional<std::string>& json_path) {
  io::ModelFile mf = io::load_model_file(model_path);
  std::optional<io::DataSet> hold;
  if (holdout_path) {
    hold = read_measurements(*holdout_path);
    if (io::kind_of(*hold) != io::kind_of(ds))
      throw Error(*holdout_path + ": kind = " + io::kind_name(io::kind_of(*hold)) + ", but the fitted data are kind = " +
                  io::kind_name(io::kind_of(ds)));
  }
  const ident::KinematicFit R = ident::fit_kinematic(ds, mf.model.kinematics, req, {}, hold ? &*hold : nullptr);
  mf.model.kinematics = R.model;
  std::ostringstream note;
  note << "added";
  for (const auto& s : adds) note << " " << s;
  note << " (planes recalibrated with them); residual RMS " << R.on_fit.before * 1e6 << " -> " << R.on_fit.after * 1e6
       << " µm";
  record_fit(mf, R.fitted, "cpm fit", data_path, note.str());
  io::save_model_file(out_path, mf, model_path);
  for (const auto& c : R.effects) {
    std::printf("%s:", c.label().c_str());
    for (const auto& p : c.params) {
      std::printf(" %s = %.6g", p.name.c_str(), p.value);
      if (p.std_error >= 0) std::printf(" ± %.2g", p.std_error);
      std::printf(" %s;", p.unit.c_str());
    }
    std::printf("\n");
  }
  std::printf("residual RMS on the fitted data: %.4g µm with the model as given, %.4g µm calibrated without the "
              "effects, %.4g µm with them\n", R.on_fit.before * 1e6, R.base_only * 1e6, R.on_fit.after * 1e6);
  if (R.holdout)
    std::printf("on the held-out data %s: %.4g µm calibrated without the effects, %.4g µm with them\n",
                holdout_path->c_str(), R.holdout->before * 1e6, R.holdout->after * 1e6);
  if (R.cross_validation)
    std::printf("2-fold cross-validation (alternate samples; fit on one half, measure on the other): %.4g µm "
                "calibrated without the effects, %.4g µm with them\n",
                R.cross_validation->before * 1e6, R.cross_validation->after * 1e6);
  for (const auto& n : R.notes) std::printf("note: %s\n", n.c_str());
  std::printf("new model: %s\n", out_path.c_str());
  if (json_path) {
    using ident::json_num;
    std::ostringstream js;
    js << "{\"model\": " << ident::json_string(model_path) << ", \"out\": " << ident::json_string(out_path)
       << ", \"data\": " << ident::json_string(data_path) << ", \"units\": \"m\",\n \"before\": {\"rms\": "
       << json_num(R.on_fit.before) << "}, \"base_only\": {\"rms\": " << json_num(R.base_only)
       << "}, \"after\": {\"rms\": " << json_num(R.on_fit.after) << "},\n";
    if (R.holdout)
      js << " \"holdout\": {\"file\": " << ident::json_string(*holdout_path) << ", \"before\": {\"rms\": "
         << json_num(R.holdout->before) << "}, \"after\": {\"rms\": " << json_num(R.holdout->after) << "}},\n";
    if (R.cross_validation)
      js << " \"cross_validation\": {\"before\": {\"rms\": " << json_num(R.cross_validation->before)
         << "}, \"after\": {\"rms\": " << json_num(R.cross_validation->after) << "}},\n";
    js << " \"effects\": [";
    for (std::size_t k = 0; k < R.effects.size(); ++k) {
      const auto& c = R.effects[k];
      js << (k ? ", " : "") << "{\"effect\": " << ident::json_string(c.effect) << ", \"axis\": " << c.axis + 1
         << ", \"params\": {";
      for (std::size_t j = 0; j < c.params.size(); ++j)
        js << (j ? ", " : "") << ident::json_string(c.params[j].name) << ": " << json_num(c.params[j].value);
      js << "}, \"std_errors\": {";
      for (std::size_t j = 0; j < c.params.size(); ++j)
        js << (j ? ", " : "") << ident::json_string(c.params[j].name) << ": "
           << (c.params[j].std_error >= 0 ? json_num(c.params[j].std_error) : "null");
      js << "}}";
    }
    js << "]}\n";
    io::write_file_atomically(*json_path, js.str());
  }
  return 0;
}

int run(Args& a) {
  const std::string model_path = a.option_or("model", default_model_path());
  const auto data_path = a.option("data");
  const auto out_path = a.option("out");
  const auto holdout_path = a.option("holdout");
  const auto json_path = a.option("json");
  const std::vector<std::string> adds = a.options("add");
  ident::DiagnoseOptions o;
  o.motion.half_window = a.number("window", o.motion.half_window * 1e3) * 1e-3;
  a.finish();
  if (!data_path) throw UsageError("--data FILE is required");
  if (!out_path) throw UsageError("--out NEW_MODEL.yaml is required (the input model is never overwritten)");
  if (adds.empty()) throw UsageError("--add EFFECT[:AXIS] is required (e.g. --add coulomb_friction:2)");
  std::vector<ident::FitRequest> req;
  for (const auto& s : adds) req.push_back(ident::parse_fit_request(s));
  const io::DataSet ds = read_measurements(*data_path);
  if (!std::holds_alternative<io::MotionData>(ds)) {
    const std::string kind = io::kind_name(io::kind_of(ds));
    for (const auto& r : req) ident::check_effect_for_kind(r.effect, kind);
    return run_kinematic(ds, req, adds, model_path, *data_path, *out_path, holdout_path, json_path);
  }
  const io::MotionData& data = std::get<io::MotionData>(ds);
  io::ModelFile mf = io::load_model_file(model_path);
  std::optional<io::MotionData> hold;
  if (holdout_path) hold = io::read_motion(*holdout_path);
  const ident::FitResult R = ident::fit_motion(data, mf.model, req, o, hold ? &*hold : nullptr);

  mf.model = R.model;
  std::ostringstream note;
  note << "added";
  for (const auto& s : adds) note << " " << s;
  note << "; force residual RMS " << R.on_fit.before << " -> " << R.on_fit.after << " N";
  record_fit(mf, R.fitted, "cpm fit", *data_path, note.str());
  io::save_model_file(*out_path, mf, model_path);

  for (const auto& c : R.effects) {
    std::printf("%s:", c.label().c_str());
    for (const auto& p : c.params) {
      std::printf(" %s = %.6g", p.name.c_str(), p.value);
      if (p.std_error >= 0) std::printf(" ± %.2g", p.std_error);
      std::printf(" %s;", p.unit.c_str());
    }
    std::printf("\n");
  }
  if (R.base_refitted) {
    std::printf("rigid-body constants refitted (inertia_error):");
    for (const auto& p : R.base_change) std::printf(" %s = %.4g ± %.2g %s;", p.name.c_str(), p.value, p.std_error, p.unit.c_str());
    std::printf("\n");
  }
  std::printf("force residual RMS on the fitted data: %.4g N before, %.4g N after\n", R.on_fit.before, R.on_fit.after);
  if (R.holdout)
    std::printf("on the held-out data %s: %.4g N before, %.4g N after\n", holdout_path->c_str(), R.holdout->before,
                R.holdout->after);
  if (R.cross_validation)
    std::printf("2-fold cross-validation (fit on one half in time, measure on the other): %.4g N before, %.4g N after\n",
                R.cross_validation->before, R.cross_validation->after);
  for (const auto& n : R.notes) std::printf("note: %s\n", n.c_str());
  std::printf("new model: %s\n", out_path->c_str());
  if (json_path) {
    std::ostringstream js;
    using ident::json_num;
    js << "{\"model\": " << ident::json_string(model_path) << ", \"out\": " << ident::json_string(*out_path)
       << ", \"data\": " << ident::json_string(*data_path) << ",\n \"before\": {\"rms\": " << json_num(R.on_fit.before)
       << "}, \"after\": {\"rms\": " << json_num(R.on_fit.after) << "},\n";
    if (R.holdout)
      js << " \"holdout\": {\"file\": " << ident::json_string(*holdout_path) << ", \"before\": {\"rms\": "
         << json_num(R.holdout->before) << "}, \"after\": {\"rms\": " << json_num(R.holdout->after) << "}},\n";
    if (R.cross_validation)
      js << " \"cross_validation\": {\"before\": {\"rms\": " << json_num(R.cross_validation->before)
         << "}, \"after\": {\"rms\": " << json_num(R.cross_validation->after) << "}},\n";
    js << " \"effects\": [";
    for (std::size_t k = 0; k < R.effects.size(); ++k) {
      const auto& c = R.effects[k];
      js << (k ? ", " : "") << "{\"effect\": " << ident::json_string(c.effect) << ", \"axis\": "
         << (c.axis >= 0 ? std::to_string(c.axis + 1) : "null") << ", \"params\": {";
      for (std::size_t j = 0; j < c.params.size(); ++j)
        js << (j ? ", " : "") << ident::json_string(c.params[j].name) << ": " << json_num(c.params[j].value);
      js << "}, \"std_errors\": {";
      for (std::size_t j = 0; j < c.params.size(); ++j)
        js << (j ? ", " : "") << ident::json_string(c.params[j].name) << ": "
           << (c.params[j].std_error >= 0 ? json_num(c.params[j].std_error) : "null");
      js << "}}";
    }
    js << "], \"base_refitted\": " << (R.base_refitted ? "true" : "false") << "}\n";
    io::write_file_atomically(*json_path, js.str());
  }
  return 0;
}

const Command reg{
    "fit", "add effects to a model, refit, write a new model file, show the error before and after", run,
    "--data FILE.csv --add EFFECT[:AXIS]... --out NEW_MODEL.yaml [--model MODEL.yaml]\n"
    "       [--holdout FILE.csv] [--json OUT.json] [--window MS]\n"
    "  Without --holdout the error on unseen data is a 2-fold cross-validation (motion: halves in time;\n"
    "  ball-bar and position data: alternate samples). Kinematic effects (backlash:2, cyclic_error:1, ...)\n"
    "  go into the kinematics and the planes are recalibrated with them."};

}  // namespace
}  // namespace cpm::cli

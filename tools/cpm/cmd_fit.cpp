// SPDX-License-Identifier: Apache-2.0
// cpm fit: add effects to a model, refit, write the new model file (never
// the input), and show the error before and after (identification/).
#include <cstdio>
#include <sstream>

#include "ident_common.hpp"
#include "cpm/identification/fit.hpp"
#include "cpm/identification/fit_user.hpp"
#include "cpm/identification/kinematic.hpp"
#include "cpm/identification/report.hpp"
#include "cpm/io/data_files.hpp"
#include "cpm/io/model_file.hpp"
#include "state_log.hpp"

namespace cpm::cli {
namespace {

// The fitted effects as the JSON has them: axis 1..3 (null for machine-wide
// ones), parameters and standard errors by name (null: unknown).
template <class Effects>
Json effects_json(const Effects& effects) {
  Json out = Json::array();
  for (const auto& c : effects) {
    Json params = Json::object(), errors = Json::object();
    for (const auto& p : c.params) {
      params[p.name] = p.value;
      errors[p.name] = p.std_error >= 0 ? Json(p.std_error) : Json(nullptr);
    }
    out.push_back({{"effect", c.effect},
                   {"axis", c.axis >= 0 ? Json(c.axis + 1) : Json(nullptr)},
                   {"params", params},
                   {"std_errors", errors}});
  }
  return out;
}

// The error on unseen data (held-out file, cross-validation) and the effects.
template <class Result>
void add_unseen_and_effects(Json& js, const Result& R, const std::optional<std::string>& holdout_path) {
  if (R.holdout)
    js["holdout"] = {{"file", *holdout_path},
                     {"before", {{"rms", R.holdout->before}}},
                     {"after", {{"rms", R.holdout->after}}}};
  if (R.cross_validation)
    js["cross_validation"] = {{"before", {{"rms", R.cross_validation->before}}},
                              {"after", {{"rms", R.cross_validation->after}}}};
  js["effects"] = effects_json(R.effects);
}

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
    Json js{{"model", model_path}, {"out", out_path}, {"data", data_path}, {"units", "m"},
            {"before", {{"rms", R.on_fit.before}}}, {"base_only", {{"rms", R.base_only}}},
            {"after", {{"rms", R.on_fit.after}}}};
    add_unseen_and_effects(js, R, holdout_path);
    write_json(*json_path, js);
  }
  return 0;
}

// A user effect (docs/effects.md, "Effects you add") added and fitted on a motion log:
//   table:AXIS:INPUT[:NODES]                 nodes evenly over the log's range of INPUT (default 20)
//   expression:AXIS:FORMULA:NAME=START,...   parameters from their start values, unbounded
// or user effect N of the model file refitted (--fit-user N, 1-based, with its bounds).
int run_user(const io::MotionData& data, const std::string& add, int refit, const std::string& model_path,
             const std::string& data_path, const std::string& out_path, const std::optional<std::string>& json_path,
             const ident::MotionOptions& mo) {
  io::ModelFile mf = io::load_model_file(model_path);
  int index = refit;
  if (!add.empty()) {
    if (add.rfind("table:", 0) == 0) {
      std::vector<std::string> f;
      std::string part;
      std::istringstream is(add);
      while (std::getline(is, part, ':')) f.push_back(part);
      if (f.size() < 3 || f.size() > 4 || f[1].size() != 1 || f[1][0] < '1' || f[1][0] > '3')
        throw UsageError("--add " + add + ": expected table:AXIS:INPUT[:NODES] (e.g. table:2:d2:20)");
      int nodes = 20;
      if (f.size() == 4 && !CLI::detail::lexical_cast(f[3], nodes))
        throw UsageError("--add " + add + ": NODES must be a whole number");
      mf.model.user_effects.push_back(ident::table_over_data(data, f[1][0] - '1', f[2], nodes));
    } else if (add.rfind("expression:", 0) == 0) {
      ctl::add_user_effect(mf.model, add);
    } else {
      throw UsageError("--add " + add + ": a pitch_table is not fitted from motion logs");
    }
    index = static_cast<int>(mf.model.user_effects.size()) - 1;
  }
  if (index < 0 || index >= static_cast<int>(mf.model.user_effects.size()))
    throw UsageError("--fit-user " + std::to_string(index + 1) + ": the model has " +
                     std::to_string(mf.model.user_effects.size()) + " user effects");
  const ident::UserFit F = ident::fit_user_effect(data, mf.model, index, mo);
  mf.model = F.model;
  const ctl::UserEffect& e = F.model.user_effects[static_cast<std::size_t>(index)];
  std::vector<io::FittedParameter> fitted;
  const std::string key = "user_effects[" + std::to_string(index) + "].";
  for (std::size_t k = 0; k < F.value.size(); ++k) {
    const std::string unit =
        e.kind == ctl::UserEffectKind::table ? "N" : e.params[k].unit;
    fitted.push_back({key + (e.kind == ctl::UserEffectKind::table ? F.names[k] : "params." + F.names[k]), unit, 0.0,
                      F.value[k], F.std_error[k]});
  }
  std::ostringstream note;
  note << (add.empty() ? "refitted user effect " + std::to_string(index + 1) : "added " + add)
       << "; force residual RMS " << F.rms_before << " -> " << F.rms_after << " N";
  record_fit(mf, fitted, "cpm fit", data_path, note.str());
  io::save_model_file(out_path, mf, model_path);
  if (e.kind == ctl::UserEffectKind::table) {
    std::printf("table on axis %d against %s (%s), smoothness chosen by GCV: lambda %.3g, %.1f effective parameters\n",
                e.axis + 1, e.input_name().c_str(), e.input == 'd' ? "mm" : "mm/s", F.lambda, F.effective_parameters);
    std::printf("%12s  %10s  %10s\n", e.input == 'd' ? "node (mm)" : "node (mm/s)", "force (N)", "std (N)");
    for (std::size_t k = 0; k < e.nodes.size(); ++k)
      std::printf("%12.3f  %10.4f  %10.4f\n", e.nodes[k] * 1e3, F.value[k], F.std_error[k]);
  } else {
    std::printf("expression on axis %d: %s\n", e.axis + 1, e.formula.c_str());
    for (std::size_t k = 0; k < F.value.size(); ++k)
      std::printf("  %s = %.6g ± %.2g %s\n", F.names[k].c_str(), F.value[k], F.std_error[k], e.params[k].unit.c_str());
  }
  std::printf("force residual RMS on the fitted data: %.4g N without the effect, %.4g N with it\n", F.rms_before,
              F.rms_after);
  for (const auto& n : F.notes) std::printf("note: %s\n", n.c_str());
  std::printf("new model: %s\n", out_path.c_str());
  if (json_path) {
    Json params = Json::object(), errors = Json::object();
    for (std::size_t k = 0; k < F.value.size(); ++k) {
      params[F.names[k]] = F.value[k];
      errors[F.names[k]] = F.std_error[k];
    }
    Json js{{"model", model_path}, {"out", out_path}, {"data", data_path},
            {"before", {{"rms", F.rms_before}}}, {"after", {{"rms", F.rms_after}}},
            {"user_effect", {{"index", index + 1}, {"kind", e.kind == ctl::UserEffectKind::table ? "table" : "expression"},
                             {"axis", e.axis + 1}, {"params", params}, {"std_errors", errors}}}};
    if (e.kind == ctl::UserEffectKind::table) js["user_effect"]["lambda"] = F.lambda;
    write_json(*json_path, js);
  }
  return 0;
}

// A pitch_table (an error of axis AXIS' effective displacement against its
// reading) fitted on ball-bar or position data: pitch_table:AXIS[:NODES],
// NODES evenly over the stroke the data cover (default 11); the planes are
// recalibrated beside it.
int run_pitch_table(const io::DataSet& ds, const std::string& add, const std::string& model_path,
                    const std::string& data_path, const std::string& out_path,
                    const std::optional<std::string>& json_path) {
  std::vector<std::string> f;
  std::string part;
  std::istringstream is(add);
  while (std::getline(is, part, ':')) f.push_back(part);
  int nodes = 11;
  if (f.size() < 2 || f.size() > 3 || f[1].size() != 1 || f[1][0] < '1' || f[1][0] > '3' ||
      (f.size() == 3 && !CLI::detail::lexical_cast(f[2], nodes)))
    throw UsageError("--add " + add + ": expected pitch_table:AXIS[:NODES] on ball-bar or position data (e.g. pitch_table:2:11)");
  const int axis = f[1][0] - '1';
  io::ModelFile mf = io::load_model_file(model_path);
  const ident::PitchTableFit F = ident::fit_pitch_table(ds, mf.model, axis, nodes);
  mf.model = F.model;
  std::vector<io::FittedParameter> fitted;
  const std::string key = "pitch_table[axis " + f[1] + "].values[";
  for (std::size_t k = 0; k < F.table.values.size(); ++k)
    fitted.push_back({key + std::to_string(k) + "]", "m", 0.0, F.table.values[k], -1.0});
  std::ostringstream note;
  note << "added " << add << " (planes recalibrated with it); residual RMS " << F.base_only * 1e6 << " -> "
       << F.after * 1e6 << " µm";
  record_fit(mf, fitted, "cpm fit", data_path, note.str());
  io::save_model_file(out_path, mf, model_path);
  std::printf("pitch_table on axis %d, smoothness chosen by cross-validation, its straight line left to the "
              "calibration:\n%12s  %10s\n", axis + 1, "node (mm)", "error (µm)");
  for (std::size_t k = 0; k < F.table.nodes.size(); ++k)
    std::printf("%12.3f  %10.4f\n", F.table.nodes[k] * 1e3, F.table.values[k] * 1e6);
  std::printf("residual RMS on the fitted data: %.4g µm with the model as given, %.4g µm calibrated without the "
              "table, %.4g µm with it\n", F.before * 1e6, F.base_only * 1e6, F.after * 1e6);
  for (const auto& n : F.notes) std::printf("note: %s\n", n.c_str());
  std::printf("new model: %s\n", out_path.c_str());
  if (json_path)
    write_json(*json_path, Json{{"model", model_path}, {"out", out_path}, {"data", data_path}, {"units", "m"},
                                {"before", {{"rms", F.before}}}, {"base_only", {{"rms", F.base_only}}},
                                {"after", {{"rms", F.after}}},
                                {"user_effect", {{"kind", "pitch_table"}, {"axis", axis + 1},
                                                 {"nodes", F.table.nodes}, {"values", F.table.values}}}});
  return 0;
}

struct Options {
  int fit_user = 0;
  MeasurementOptions in;
  std::optional<std::string> holdout, json;
  std::string out;
  std::vector<std::string> adds;
};

int run(const Options& opt) {
  const std::string model_path = opt.in.model_path();
  const std::string& data_path = opt.in.data;
  const std::string& out_path = opt.out;
  const auto& holdout_path = opt.holdout;
  const auto& json_path = opt.json;
  const std::vector<std::string>& adds = opt.adds;
  ident::DiagnoseOptions o;
  o.motion.half_window = opt.in.half_window();
  std::string user_add;
  for (const auto& s : adds)
    if (ctl::is_user_effect_spec(s)) user_add = s;
  if (!user_add.empty() || opt.fit_user > 0) {
    if (adds.size() > (user_add.empty() ? 0u : 1u))
      throw UsageError("a user effect (table, expression, --fit-user) is fitted alone: give no other --add");
    const io::DataSet ds = read_measurements(data_path);
    const bool motion = std::holds_alternative<io::MotionData>(ds);
    if (!motion && user_add.rfind("pitch_table", 0) == 0) {
      if (holdout_path) throw UsageError("--holdout: not yet for a pitch_table (its smoothness is chosen by cross-validation)");
      return run_pitch_table(ds, user_add, model_path, data_path, out_path, json_path);
    }
    if (!motion)
      throw UsageError(std::string("table and expression effects are fitted on motion logs (not on ") +
                       io::kind_name(io::kind_of(ds)) + " data; there: pitch_table:AXIS[:NODES])");
    return run_user(std::get<io::MotionData>(ds), user_add, opt.fit_user - 1, model_path, data_path, out_path,
                    json_path, o.motion);
  }
  std::vector<ident::FitRequest> req;
  for (const auto& s : adds) req.push_back(ident::parse_fit_request(s));
  const io::DataSet ds = read_measurements(data_path);
  if (!std::holds_alternative<io::MotionData>(ds)) {
    const std::string kind = io::kind_name(io::kind_of(ds));
    for (const auto& r : req) ident::check_effect_for_kind(r.effect, kind);
    return run_kinematic(ds, req, adds, model_path, data_path, out_path, holdout_path, json_path);
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
  std::printf("new model: %s\n", out_path.c_str());
  if (json_path) {
    Json js{{"model", model_path}, {"out", out_path}, {"data", data_path},
            {"before", {{"rms", R.on_fit.before}}}, {"after", {{"rms", R.on_fit.after}}}};
    add_unseen_and_effects(js, R, holdout_path);
    js["base_refitted"] = R.base_refitted;
    write_json(*json_path, js);
  }
  return 0;
}

Run setup(CLI::App& app) {
  auto o = std::make_shared<Options>();
  add_measurement_options(app, o->in, "the model to extend");
  app.add_option("--add", o->adds,
                 "an effect to add and fit, with its axis when it acts on one (repeat the option; e.g. --add "
                 "coulomb_friction:2 --add payload_mass; a user effect: table:AXIS:INPUT[:NODES] or "
                 "expression:AXIS:FORMULA:NAME=START,... (motion logs), pitch_table:AXIS[:NODES] (ball-bar, position data), "
                 "docs/effects.md \"Effects you add\")")
      ->type_name("EFFECT[:AXIS]")
      ->check(effect_name())
      ->allow_extra_args(false);
  app.add_option("--fit-user", o->fit_user,
                 "refit user effect N of the model file (1-based, in user_effects' order) on a motion log")
      ->type_name("N")
      ->default_str("none")
      ->check(CLI::Range(1, 1000));
  add_new_model_option(app, o->out);
  app.add_option("--holdout", o->holdout, "measurements of the same kind to judge the fit on, unseen by it")
      ->type_name("FILE.csv");
  app.add_option("--json", o->json, "write the fit (parameters, RMS before and after) as JSON")->type_name("OUT.json");
  app.footer("Without --holdout the error on unseen data is a 2-fold cross-validation (motion: halves in time;\n"
             "ball-bar and position data: alternate samples). Kinematic effects (backlash:2, cyclic_error:1, ...)\n"
             "go into the kinematics and the planes are recalibrated with them.");
  return [o] {
    if (o->adds.empty() && o->fit_user == 0) throw UsageError("give --add EFFECT (or --fit-user N)");
    return run(*o);
  };
}

const Command reg{"fit", "add effects to a model, refit, write a new model file, show the error before and after",
                  setup};

}  // namespace
}  // namespace cpm::cli

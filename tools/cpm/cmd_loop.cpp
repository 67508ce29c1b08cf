// SPDX-License-Identifier: Apache-2.0
// cpm loop: the identification loop as one command (identification/model_loop.hpp):
// diagnose, add the effect found, refit, diagnose again, until nothing is
// missing; prints the waterfall, writes the new model file (never the input)
// and, on request, the waterfall as JSON and as an HTML page.
#include <algorithm>
#include <cstdio>
#include <sstream>

#include "ident_common.hpp"
#include "cpm/identification/model_loop.hpp"
#include "cpm/io/data_files.hpp"
#include "cpm/io/model_file.hpp"
#include "state_log.hpp"

namespace cpm::cli {
namespace {

struct Options {
  MeasurementOptions in;
  std::optional<std::string> json, report;
  std::string out;
  int max_steps = 6;
  std::vector<std::string> allow;  // user effect kinds the loop may add
};

// The model file's `user_effects:` section for the suggestion, to paste.
std::string suggestion_yaml(const ident::SuggestedUserEffect& s) {
  ctl::MachineModel m = ctl::MachineModel::elkady();
  if (s.kind == "pitch_table") {
    m.kinematics.effects[static_cast<std::size_t>(s.axis)].pitch_table = ident::pitch_table_of(s);
  } else {
    m.user_effects.push_back(ident::user_effect_of(s));
  }
  // The file's own rendering of that model, its user_effects section only
  // (from the section's comment up to the next section's).
  io::ModelFile mf;
  mf.model = m;
  const std::string file = io::render_model_file(mf);
  const std::size_t from = file.find("\n# Effects added by the user");
  const std::size_t list = file.find("\nuser_effects:", from == std::string::npos ? 0 : from);
  if (from == std::string::npos || list == std::string::npos) return file;
  const std::size_t to = file.find("\n# ", list);
  return file.substr(from + 1, to == std::string::npos ? std::string::npos : to - from);
}

// Without --allow (or with other kinds): the suggestion as YAML and the command that adds it.
void print_suggestion(const ident::LoopResult& R, const Options& opt) {
  const ident::SuggestedUserEffect& s = R.suggestion;
  if (!R.outside_library || s.kind.empty()) return;
  std::string yaml;
  try {
    yaml = suggestion_yaml(s);
  } catch (const Error& e) {
    std::printf("(the suggestion cannot be written as a user effect: %s)\n", e.what());
    return;
  }
  std::printf("\nthe outside finding as a user effect (%s), ready to paste into the model file:\n%s",
              ident::label_of(s).c_str(), yaml.c_str());
  std::string cmd = "cpm loop --model " + opt.in.model_path() + " --data " + opt.in.data + " --allow " + s.kind;
  cmd += " --out " + opt.out;
  std::printf("or let the loop add and fit it:\n  %s\n", cmd.c_str());
}

int run(const Options& opt) {
  const std::string model_path = opt.in.model_path();
  const std::string& data_path = opt.in.data;
  const std::string& out_path = opt.out;
  const auto& json_path = opt.json;
  const auto& report_path = opt.report;
  const int max_steps = opt.max_steps;
  ident::DiagnoseOptions o;
  o.motion.half_window = opt.in.half_window();
  const io::DataSet ds = read_measurements(data_path);
  io::ModelFile mf = io::load_model_file(model_path);
  const ident::LoopResult R = ident::run_loop(ds, mf.model, o, max_steps, opt.allow);
  std::fputs(ident::loop_text(R).c_str(), stdout);
  print_suggestion(R, opt);
  mf.model = R.model;
  std::ostringstream note;
  note << "cpm loop added";
  for (std::size_t j = 1; j < R.steps.size(); ++j)
    if (R.steps[j].added != "calibrated planes") note << " " << R.steps[j].added;
  if (R.steps.size() > 1) note << "; residual RMS " << R.steps.front().rms << " -> " << R.steps.back().rms << " " << R.units;
  record_fit(mf, R.fitted, "cpm loop", data_path, note.str());
  io::save_model_file(out_path, mf, model_path);
  std::printf("new model: %s\n", out_path.c_str());
  if (json_path) io::write_file_atomically(*json_path, ident::loop_json(R, data_path, out_path));
  if (report_path) {
    io::write_file_atomically(*report_path, ident::loop_html(R, data_path));
    std::printf("report: %s\n", report_path->c_str());
  }
  return 0;
}

Run setup(CLI::App& app) {
  auto o = std::make_shared<Options>();
  add_measurement_options(app, o->in, "the model to start from");
  add_new_model_option(app, o->out);
  app.add_option("--report", o->report, "write the waterfall as an HTML page")->type_name("LOOP.html");
  app.add_option("--json", o->json, "write the waterfall as JSON")->type_name("LOOP.json");
  app.add_option("--max-steps", o->max_steps, "stop after N steps (1 .. 20)")
      ->type_name("N")
      ->check(CLI::Range(1, 20).description(""));
  app.add_option("--allow", o->allow,
                 "user effect kinds the loop may add at an outside finding: table, expression, pitch_table "
                 "(comma-separated)")
      ->type_name("KIND[,KIND...]")
      ->delimiter(',')
      ->check(CLI::IsMember({"table", "expression", "pitch_table"}).description(""));
  app.footer("Each step adds the effect the diagnosis names first and refits every effect added so far together;\n"
             "it stops when nothing is missing, when something no library effect describes remains, or after N\n"
             "steps. At something outside the library it prints the finding as a user effect (model-file YAML,\n"
             "docs/effects.md \"Effects you add\") and the command that adds it; with --allow KIND it adds a\n"
             "suggestion of that kind itself (a table or expression on motion logs, fitted with the effects added\n"
             "before refitted beside it; a pitch_table on ball-bar and position data, the planes recalibrated), and\n"
             "goes on. The waterfall is the residual RMS of the model after each step beside the noise floor.");
  return [o] { return run(*o); };
}

const Command reg{"loop", "diagnose, add what is missing, refit, diagnose again until nothing is; print the waterfall",
                  setup};

}  // namespace
}  // namespace cpm::cli

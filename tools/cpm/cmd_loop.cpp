// cpm loop: the identification loop as one command (identification/loop.hpp):
// diagnose, add the effect found, refit, diagnose again, until nothing is
// missing; prints the waterfall, writes the new model file (never the input)
// and, on request, the waterfall as JSON and as an HTML page.
#include <cstdio>
#include <sstream>

#include "cli.hpp"
#include "cpm/identification/loop.hpp"
#include "cpm/io/data_files.hpp"
#include "cpm/io/model_file.hpp"
#include "state_log.hpp"

namespace cpm::cli {
namespace {

struct Options {
  std::optional<std::string> model, json, report;
  std::string data, out;
  int max_steps = 6;
  double window_ms = ident::DiagnoseOptions{}.motion.half_window * 1e3;
};

int run(const Options& opt) {
  const std::string model_path = model_or_default(opt.model);
  const std::string& data_path = opt.data;
  const std::string& out_path = opt.out;
  const auto& json_path = opt.json;
  const auto& report_path = opt.report;
  const int max_steps = opt.max_steps;
  ident::DiagnoseOptions o;
  o.motion.half_window = opt.window_ms * 1e-3;
  const io::DataSet ds = read_measurements(data_path);
  io::ModelFile mf = io::load_model_file(model_path);
  const ident::LoopResult R = ident::run_loop(ds, mf.model, o, max_steps);
  std::fputs(ident::loop_text(R).c_str(), stdout);
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
  app.add_option("--data", o->data,
                 "the measurements: a motion log, ball-bar or position data (data-files.md), or an lcm-logger file "
                 "of cpmd's state")
      ->type_name("FILE.csv")
      ->required();
  app.add_option("--out", o->out, "the new model file (the input model is never overwritten)")
      ->type_name("NEW_MODEL.yaml")
      ->required();
  add_model_option(app, o->model, "the model to start from");
  app.add_option("--report", o->report, "write the waterfall as an HTML page")->type_name("LOOP.html");
  app.add_option("--json", o->json, "write the waterfall as JSON")->type_name("LOOP.json");
  app.add_option("--max-steps", o->max_steps, "stop after N steps (1 .. 20)")
      ->type_name("N")
      ->check(CLI::Range(1, 20).description(""));
  add_number(app, "--window", o->window_ms, "MS", "half width of the motion logs' smoothing filter in ms");
  app.footer("Each step adds the effect the diagnosis names first and refits every effect added so far together;\n"
             "it stops when nothing is missing, when something no library effect describes remains, or after N\n"
             "steps. The waterfall is the residual RMS of the model after each step beside the noise floor.");
  return [o] { return run(*o); };
}

const Command reg{"loop", "diagnose, add what is missing, refit, diagnose again until nothing is; print the waterfall",
                  setup};

}  // namespace
}  // namespace cpm::cli

// cpm loop: the identification loop as one command (identification/loop.hpp):
// diagnose, add the effect found, refit, diagnose again, until nothing is
// missing; prints the waterfall, writes the new model file (never the input)
// and, on request, the waterfall as JSON and as an HTML page.
#include <cstdio>
#include <sstream>

#include "ident_common.hpp"
#include "cpm/identification/loop.hpp"
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
};

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
  add_measurement_options(app, o->in, "the model to start from");
  add_new_model_option(app, o->out);
  app.add_option("--report", o->report, "write the waterfall as an HTML page")->type_name("LOOP.html");
  app.add_option("--json", o->json, "write the waterfall as JSON")->type_name("LOOP.json");
  app.add_option("--max-steps", o->max_steps, "stop after N steps (1 .. 20)")
      ->type_name("N")
      ->check(CLI::Range(1, 20).description(""));
  app.footer("Each step adds the effect the diagnosis names first and refits every effect added so far together;\n"
             "it stops when nothing is missing, when something no library effect describes remains, or after N\n"
             "steps. The waterfall is the residual RMS of the model after each step beside the noise floor.");
  return [o] { return run(*o); };
}

const Command reg{"loop", "diagnose, add what is missing, refit, diagnose again until nothing is; print the waterfall",
                  setup};

}  // namespace
}  // namespace cpm::cli

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

int run(Args& a) {
  const std::string model_path = a.option_or("model", default_model_path());
  const auto data_path = a.option("data");
  const auto out_path = a.option("out");
  const auto json_path = a.option("json");
  const auto report_path = a.option("report");
  const int max_steps = static_cast<int>(a.number("max-steps", 6));
  ident::DiagnoseOptions o;
  o.motion.half_window = a.number("window", o.motion.half_window * 1e3) * 1e-3;
  a.finish();
  if (!data_path) throw UsageError("--data FILE is required");
  if (!out_path) throw UsageError("--out NEW_MODEL.yaml is required (the input model is never overwritten)");
  if (max_steps < 1 || max_steps > 20) throw UsageError("--max-steps must be 1..20");
  const io::DataSet ds = read_measurements(*data_path);
  io::ModelFile mf = io::load_model_file(model_path);
  const ident::LoopResult R = ident::run_loop(ds, mf.model, o, max_steps);
  std::fputs(ident::loop_text(R).c_str(), stdout);
  mf.model = R.model;
  std::ostringstream note;
  note << "cpm loop added";
  for (std::size_t j = 1; j < R.steps.size(); ++j)
    if (R.steps[j].added != "calibrated planes") note << " " << R.steps[j].added;
  if (R.steps.size() > 1) note << "; residual RMS " << R.steps.front().rms << " -> " << R.steps.back().rms << " " << R.units;
  record_fit(mf, R.fitted, "cpm loop", *data_path, note.str());
  io::save_model_file(*out_path, mf, model_path);
  std::printf("new model: %s\n", out_path->c_str());
  if (json_path) io::write_file_atomically(*json_path, ident::loop_json(R, *data_path, *out_path));
  if (report_path) {
    io::write_file_atomically(*report_path, ident::loop_html(R, *data_path));
    std::printf("report: %s\n", report_path->c_str());
  }
  return 0;
}

const Command reg{
    "loop", "diagnose, add what is missing, refit, diagnose again until nothing is; print the waterfall", run,
    "--data FILE.csv --out NEW_MODEL.yaml [--model MODEL.yaml] [--report LOOP.html] [--json LOOP.json]\n"
    "       [--max-steps N] [--window MS]\n"
    "  Each step adds the effect the diagnosis names first and refits every effect added so far together;\n"
    "  it stops when nothing is missing, when something no library effect describes remains, or after N steps.\n"
    "  The waterfall is the residual RMS of the model after each step beside the noise floor."};

}  // namespace
}  // namespace cpm::cli

// SPDX-License-Identifier: Apache-2.0
// cpm calibrate: kinematic calibration (Kim 2005) from a ball-bar or
// full-position measurement file; writes a new model file.
#include <cstdio>

#include "calib_common.hpp"
#include "cpm/calibration/workflow.hpp"

namespace cpm::cli {
namespace {

struct Options {
  std::optional<std::string> model, json;
  std::string data, out;
  bool quiet = false;
};

int run(const Options& o) {
  const std::string model = model_or_default(o.model);
  const auto& json = o.json;
  std::string tool = "cpm calibrate --model " + model + " --data " + o.data + " --out " + o.out;
  const cal::CalibrationResult r = cal::calibrate_files(model, o.data, o.out, json, tool);
  if (!o.quiet) std::fputs(r.summary().c_str(), stdout);
  std::printf("\nwrote %s%s%s\n", o.out.c_str(), json ? " and " : "", json ? json->c_str() : "");
  return 0;
}

const Command reg{"calibrate", "kinematic calibration from ball-bar or full-position measurements (Kim 2005)",
                  [](CLI::App& app) {
                    auto o = std::make_shared<Options>();
                    add_model_option(app, o->model, "the model to calibrate (never overwritten)");
                    app.add_option("--data", o->data,
                                   "the measurements: a `kind = ballbar` or `kind = position` file (data-formats.md)")
                        ->type_name("FILE.csv")
                        ->required();
                    app.add_option("--out", o->out, "the calibrated model to write (not the input model)")
                        ->type_name("NEW.yaml")
                        ->required();
                    app.add_option("--json", o->json, "also write the fit (parameters, errors in m) as JSON to FILE")
                        ->type_name("FILE");
                    app.add_flag("--quiet", o->quiet, "print only what was written");
                    app.footer("Nothing is written when the input is bad.");
                    return [o] { return run(*o); };
                  }};

}  // namespace
}  // namespace cpm::cli

// cpm calibrate: kinematic calibration (Kim 2005) from a ball-bar or
// full-position measurement file; writes a new model file.
#include <cstdio>

#include "calib_common.hpp"
#include "cpm/calibration/workflow.hpp"

namespace cpm::cli {
namespace {

int run(Args& a) {
  const std::string model = a.option_or("model", default_model_path());
  const auto data = a.option("data");
  const auto out = a.option("out");
  const auto json = a.option("json");
  const bool quiet = a.flag("quiet");
  a.finish();
  if (!data) throw UsageError("--data FILE.csv is required (a ballbar or position file, docs/data-formats.md)");
  if (!out) throw UsageError("--out NEW.yaml is required (the input model is never overwritten)");
  std::string tool = "cpm calibrate --model " + model + " --data " + *data + " --out " + *out;
  const cal::CalibrationResult r = cal::calibrate_files(model, *data, *out, json, tool);
  if (!quiet) std::fputs(r.summary().c_str(), stdout);
  std::printf("\nwrote %s%s%s\n", out->c_str(), json ? " and " : "", json ? json->c_str() : "");
  return 0;
}

const Command reg{"calibrate",
                  "kinematic calibration from ball-bar or full-position measurements (Kim 2005)", run,
                  "[--model MODEL.yaml] --data FILE.csv --out NEW.yaml [--json FILE] [--quiet]\n"
                  "  MODEL.yaml defaults to config/machine.yaml; FILE.csv is a `kind = ballbar` or\n"
                  "  `kind = position` file (docs/data-formats.md). Nothing is written when the input is bad."};

}  // namespace
}  // namespace cpm::cli

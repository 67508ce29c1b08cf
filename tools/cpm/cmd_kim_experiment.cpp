// SPDX-License-Identifier: Apache-2.0
// cpm kim-experiment: Kim's ball-bar calibration experiment reproduced in
// simulation, with the circular test before and after beside Kim's figures.
#include <cstdio>

#include "calib_common.hpp"
#include "cpm/calibration/kim.hpp"
#include "cpm/calibration/workflow.hpp"
#include "cpm/io/model_file.hpp"

namespace cpm::cli {
namespace {

struct Options {
  cal::KimOptions kim;
  long seed = 1;
  bool kinematic = false;
  std::optional<std::string> centre, svg_before, svg_after, json, data, truth_out, model_out;
};

int run(const Options& opt) {
  cal::KimOptions o = opt.kim;
  o.seed = static_cast<std::uint64_t>(opt.seed);
  o.circle.closed_loop = !opt.kinematic;
  if (opt.centre) o.circle.centre = calib_point("--centre", *opt.centre);
  const auto& svg_before = opt.svg_before;
  const auto& svg_after = opt.svg_after;
  const auto& json = opt.json;
  const auto& data = opt.data;
  const auto& truth_out = opt.truth_out;
  const auto& model_out = opt.model_out;
  const cal::KimReproduction k = cal::reproduce_kim(o);
  std::fputs(k.report().c_str(), stdout);
  if (svg_before)
    io::write_file_atomically(*svg_before, cal::circular_test_svg(k.before, "Before calibration (nominal model), simulated Kim machine"));
  if (svg_after)
    io::write_file_atomically(*svg_after, cal::circular_test_svg(k.after, "After ball-bar calibration, simulated Kim machine"));
  if (data) io::write_ballbar(*data, k.data);
  if (truth_out) {
    io::ModelFile t;
    t.model = cal::kim_true_machine();
    io::Provenance p;
    p.tool = "cpm kim-experiment";
    p.date = io::utc_now_iso8601();
    p.note = "true machine carrying Kim's fitted errors (docs/calibration.md); the fixed ball is 1.030 mm above its declared pivot";
    t.history.push_back(p);
    io::save_model_file(*truth_out, t);
  }
  if (model_out) {
    io::ModelFile m;
    m.model.kinematics = k.fit.model;
    io::Provenance p;
    p.tool = "cpm kim-experiment";
    p.date = io::utc_now_iso8601();
    p.note = "calibrated from the simulated ball-bar data";
    m.history.push_back(p);
    io::save_model_file(*model_out, m);
  }
  if (json) io::write_file_atomically(*json, k.json());
  return k.all_within_3sigma ? 0 : 1;
}

Run setup(CLI::App& app) {
  auto o = std::make_shared<Options>();
  app.add_option("--seed", o->seed, "seed of the simulated bar's noise")->type_name("N");
  add_number(app, "--noise", o->kim.noise, "M", "half-width of the bar's uniform length error in m (QC10: 0.5e-6)");
  add_number(app, "--feed", o->kim.circle.feed, "M/S", "feed of the circular tests in m/s");
  app.add_flag("--kinematic", o->kinematic, "circular tests on the kinematics only (no servo error)");
  app.add_option("--centre", o->centre, "centre of the circular tests in m")
      ->type_name("X,Y,Z")
      ->default_str(point_text(o->kim.circle.centre));
  add_number(app, "--radius", o->kim.circle.radius, "M", "radius of the circular tests in m");
  app.add_option("--svg-before", o->svg_before, "polar plot before calibration")->type_name("FILE.svg");
  app.add_option("--svg-after", o->svg_after, "polar plot after calibration")->type_name("FILE.svg");
  app.add_option("--data", o->data, "write the simulated ball-bar data (data-formats.md)")->type_name("FILE.csv");
  app.add_option("--truth-out", o->truth_out, "write the true machine (Kim's errors) as a model file")
      ->type_name("FILE.yaml");
  app.add_option("--model-out", o->model_out, "write the calibrated model")->type_name("FILE.yaml");
  app.add_option("--json", o->json, "write the fit and the checks as JSON to FILE")->type_name("FILE");
  app.footer("Exit status 1 when some fitted parameter is outside its 3-sigma interval.");
  return [o] { return run(*o); };
}

const Command reg{"kim-experiment",
                  "Kim's ball-bar experiment in simulation: fit, 3-sigma check, circular test before/after", setup};

}  // namespace
}  // namespace cpm::cli

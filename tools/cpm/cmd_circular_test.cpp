// SPDX-License-Identifier: Apache-2.0
// cpm circular-test: ISO 230-4 circular test of a simulated true machine
// driven by a controller that believes another model.
#include <cstdio>
#include <sstream>

#include "calib_common.hpp"
#include "cpm/calibration/circular_report.hpp"
#include "cpm/calibration/circular_test.hpp"
#include "cpm/calibration/workflow.hpp"
#include "cpm/io/model_file.hpp"

namespace cpm::cli {
namespace {

std::string trace_csv(const cal::CircularTestResult& r) {
  std::ostringstream o;
  o.precision(12);
  o << "# circular test traces: commanded angle (rad) and bar reading minus radius (m)\n";
  o << "direction,angle,deviation\n";
  for (std::size_t k = 0; k < r.ccw.angle.size(); ++k) o << "ccw," << r.ccw.angle[k] << ',' << r.ccw.deviation[k] << '\n';
  for (std::size_t k = 0; k < r.cw.angle.size(); ++k) o << "cw," << r.cw.angle[k] << ',' << r.cw.deviation[k] << '\n';
  return o.str();
}

struct Options {
  std::optional<std::string> truth, model, centre, pivot, svg, json, trace, report, report_json, tolerances;
  double um_per_division = 0.0;
  cal::CircularTestSpec spec;
  std::string plane = "xy", controller = "computed_torque";
  bool kinematic = false;
};

int run(const Options& o) {
  const std::string truth_path = model_or_default(o.truth);
  const std::string model_path = model_or_default(o.model);
  cal::CircularTestSpec s = o.spec;
  if (o.centre) s.centre = calib_point("--centre", *o.centre);
  s.plane = calib_plane(o.plane);
  s.closed_loop = !o.kinematic;
  s.law = *ctl::law_from_name(o.controller);
  if (o.pivot) s.pivot = calib_point("--pivot", *o.pivot);
  const auto& svg = o.svg;
  const auto& json = o.json;
  const auto& trace = o.trace;
  const io::ModelFile truth = io::load_model_file(truth_path);
  const io::ModelFile model = io::load_model_file(model_path);
  const cal::CircularTestResult r = cal::run_circular_test(truth.model, model.model, s);
  std::printf("circular test (ISO 230-4): true machine %s, controller model %s\n", truth_path.c_str(),
              model_path.c_str());
  std::printf("  %s plane, radius %.3f mm, centre (%.3f, %.3f, %.3f) mm, feed %.0f mm/min, %s\n",
              cal::plane_name(s.plane), s.radius * 1e3, s.centre.x() * 1e3, s.centre.y() * 1e3,
              s.centre.z() * 1e3, s.feed * 6e4, s.closed_loop ? "closed loop" : "kinematic only");
  std::printf("  pivot (true position) (%.4f, %.4f, %.4f) mm\n", r.pivot.x() * 1e3, r.pivot.y() * 1e3,
              r.pivot.z() * 1e3);
  std::printf("  circular deviation G:  CCW %.2f µm, CW %.2f µm, both %.2f µm\n", r.ccw_metrics.G * 1e6,
              r.cw_metrics.G * 1e6, r.G_bidirectional * 1e6);
  std::printf("  circular hysteresis H: %.2f µm\n", r.H * 1e6);
  std::printf("  radial deviation F:    max %+.2f µm, min %+.2f µm (centre as set); max |error| %.2f µm\n",
              r.F_max * 1e6, r.F_min * 1e6, r.max_abs_error * 1e6);
  if (s.closed_loop) std::printf("  servo error (reference - estimate), RMS %.3f µm\n", r.servo_rms * 1e6);
  const std::string title = "Circular test: " + truth_path + " driven by " + model_path;
  if (svg) {
    io::write_file_atomically(*svg, cal::circular_test_svg(r, title, o.um_per_division));
    std::printf("polar plot: %s\n", svg->c_str());
  }
  if (trace) {
    io::write_file_atomically(*trace, trace_csv(r));
    std::printf("traces: %s\n", trace->c_str());
  }
  if (o.report || o.report_json) {
    const cal::BallbarTolerances tol = o.tolerances ? cal::load_ballbar_tolerances(*o.tolerances) : cal::BallbarTolerances{};
    const cal::BallbarReport b = cal::make_ballbar_report(r, tol, o.um_per_division);
    std::printf("  error sources (contribution peak-to-valley, share of their sum):\n");
    for (const auto& e : b.errors)
      std::printf("    %-40s %8.2f µm  %3.0f %%\n", e.name.c_str(), e.contribution * 1e6, e.share);
    if (!b.checks.empty()) std::printf("  against the tolerances of %s: %s\n", o.tolerances->c_str(), b.pass ? "PASS" : "FAIL");
    if (o.report) {
      io::write_file_atomically(*o.report, cal::ballbar_report_html(b, title));
      std::printf("report: %s\n", o.report->c_str());
    }
    if (o.report_json) {
      io::write_file_atomically(*o.report_json, cal::ballbar_report_json(b));
      std::printf("report data: %s\n", o.report_json->c_str());
    }
  }
  if (json)
    write_json(*json, Json{{"G", r.G_bidirectional},
                           {"G_ccw", r.ccw_metrics.G},
                           {"G_cw", r.cw_metrics.G},
                           {"H", r.H},
                           {"F_max", r.F_max},
                           {"F_min", r.F_min},
                           {"max_abs_error", r.max_abs_error},
                           {"servo_rms", r.servo_rms},
                           {"radius", s.radius},
                           {"feed", s.feed},
                           {"plane", cal::plane_name(s.plane)},
                           {"closed_loop", s.closed_loop},
                           {"pivot", {r.pivot.x(), r.pivot.y(), r.pivot.z()}}});
  return 0;
}

Run setup(CLI::App& app) {
  auto o = std::make_shared<Options>();
  add_model_option(app, o->truth, "the true machine, simulated", "--truth");
  add_model_option(app, o->model, "the model the controller believes");
  app.add_option("--centre", o->centre, "commanded centre of the circle in m (e.g. 0.430,0.430,0.400)")
      ->type_name("X,Y,Z")
      ->default_str(point_text(o->spec.centre));
  add_number(app, "--radius", o->spec.radius, "M", "circle radius in m, the bar length (e.g. 0.150)");
  add_choice(app, "--plane", o->plane, {"xy", "yz", "zx"}, "the circle's plane");
  add_number(app, "--feed", o->spec.feed, "M/S", "feed along the circle in m/s (0.020 = 1200 mm/min)");
  add_number(app, "--overshoot", o->spec.overshoot_time, "S", "speed ramp at each end in s (the overshoot arcs)");
  app.add_flag("--kinematic", o->kinematic, "kinematics only: no controller, no servo error");
  add_choice(app, "--controller", o->controller, law_names(), "the control law (Table 3 gains)");
  app.add_option("--pivot", o->pivot, "true position of the fixed ball in m, the truth's frame")
      ->type_name("X,Y,Z")
      ->default_str("the commanded centre");
  app.add_option("--svg", o->svg, "write the polar plot to FILE.svg")->type_name("FILE.svg");
  app.add_option("--trace", o->trace, "write the traces (angle in rad, deviation in m) to FILE.csv")->type_name("FILE.csv");
  app.add_option("--report", o->report, "write the one-page ball-bar report (prints on one A4 sheet) to FILE.html")
      ->type_name("FILE.html");
  app.add_option("--report-json", o->report_json, "write the report's data (error sources, checks) as JSON to FILE")
      ->type_name("FILE");
  app.add_option("--tolerances", o->tolerances, "judge the report against the tolerances in FILE.yaml (docs/calibration.md)")
      ->type_name("FILE.yaml")
      ->check(CLI::ExistingFile);
  add_number(app, "--magnification", o->um_per_division, "UM",
             "plot scale in µm per ring (division); 0 picks one from the largest deviation")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--json", o->json, "write G, H, F (m) as JSON to FILE")->type_name("FILE");
  return [o] { return run(*o); };
}

const Command reg{"circular-test",
                  "ISO 230-4 circular test (ball-bar) of a simulated machine: G, H, F and a polar plot", setup};

}  // namespace
}  // namespace cpm::cli

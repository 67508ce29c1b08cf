// cpm circular-test: ISO 230-4 circular test of a simulated true machine
// driven by a controller that believes another model.
#include <cstdio>
#include <fstream>
#include <sstream>

#include "calib_common.hpp"
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

int run(Args& a) {
  const std::string truth_path = a.option_or("truth", default_model_path());
  const std::string model_path = a.option_or("model", default_model_path());
  cal::CircularTestSpec s;
  if (auto v = a.option("centre")) s.centre = calib_point("--centre", *v);
  s.radius = a.number("radius", s.radius);
  s.plane = calib_plane(a.option_or("plane", "xy"));
  s.feed = a.number("feed", s.feed);
  s.overshoot_time = a.number("overshoot", s.overshoot_time);
  s.closed_loop = !a.flag("kinematic");
  const std::string law = a.option_or("controller", "computed_torque");
  const auto l = ctl::law_from_name(law);
  if (!l) throw UsageError("--controller must be pd, pd_gravity, pd_feedforward or computed_torque");
  s.law = *l;
  if (auto v = a.option("pivot")) s.pivot = calib_point("--pivot", *v);
  const auto svg = a.option("svg");
  const auto json = a.option("json");
  const auto trace = a.option("trace");
  a.finish();
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
  if (svg) {
    io::write_file_atomically(*svg, cal::circular_test_svg(r, "Circular test: " + truth_path + " driven by " + model_path));
    std::printf("polar plot: %s\n", svg->c_str());
  }
  if (trace) {
    io::write_file_atomically(*trace, trace_csv(r));
    std::printf("traces: %s\n", trace->c_str());
  }
  if (json) {
    std::ostringstream o;
    o << "{\"G\": " << cal::json_num(r.G_bidirectional) << ", \"G_ccw\": " << cal::json_num(r.ccw_metrics.G)
      << ", \"G_cw\": " << cal::json_num(r.cw_metrics.G) << ", \"H\": " << cal::json_num(r.H)
      << ", \"F_max\": " << cal::json_num(r.F_max) << ", \"F_min\": " << cal::json_num(r.F_min)
      << ", \"max_abs_error\": " << cal::json_num(r.max_abs_error)
      << ", \"servo_rms\": " << cal::json_num(r.servo_rms) << ", \"radius\": " << cal::json_num(s.radius)
      << ", \"feed\": " << cal::json_num(s.feed) << ", \"plane\": \"" << cal::plane_name(s.plane)
      << "\", \"closed_loop\": " << (s.closed_loop ? "true" : "false") << ", \"pivot\": ["
      << cal::json_num(r.pivot.x()) << ", " << cal::json_num(r.pivot.y()) << ", " << cal::json_num(r.pivot.z())
      << "]}\n";
    io::write_file_atomically(*json, o.str());
  }
  return 0;
}

const Command reg{"circular-test",
                  "ISO 230-4 circular test (ball-bar) of a simulated machine: G, H, F and a polar plot", run,
                  "[--truth TRUE.yaml] [--model MODEL.yaml] [--centre X,Y,Z] [--radius M] [--plane xy|yz|zx]\n"
                  "       [--feed M/S] [--overshoot S] [--kinematic] [--controller LAW] [--pivot X,Y,Z]\n"
                  "       [--svg FILE.svg] [--trace FILE.csv] [--json FILE]\n"
                  "  Both model files default to config/machine.yaml; lengths in m, feed in m/s."};

}  // namespace
}  // namespace cpm::cli

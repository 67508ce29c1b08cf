// cpm sim: run a trajectory with a chosen controller on a chosen true machine.
#include <cstdio>
#include <memory>
#include <sstream>

#include "cli.hpp"
#include "cpm/io/model_file.hpp"
#include "cpm/sim/closed_loop.hpp"

namespace cpm::cli {
namespace {

// NAME:AXIS:V1,V2,... (axis 1..3, empty for machine-wide effects).
void apply_effect(ctl::MachineModel& m, const std::string& spec) {
  const auto c1 = spec.find(':');
  const auto c2 = c1 == std::string::npos ? c1 : spec.find(':', c1 + 1);
  if (c2 == std::string::npos)
    throw UsageError("--truth-effect '" + spec + "': expected NAME:AXIS:V1,V2,...");
  const std::string name = spec.substr(0, c1);
  const std::string axis_text = spec.substr(c1 + 1, c2 - c1 - 1);
  int axis = -1;
  if (!axis_text.empty()) {
    if (axis_text != "1" && axis_text != "2" && axis_text != "3")
      throw UsageError("--truth-effect '" + spec + "': axis must be 1, 2, 3 or empty");
    axis = std::stoi(axis_text) - 1;
  }
  std::vector<double> values;
  std::istringstream is(spec.substr(c2 + 1));
  std::string part;
  while (std::getline(is, part, ',')) {
    char* end = nullptr;
    const double x = std::strtod(part.c_str(), &end);
    if (part.empty() || *end != '\0') throw UsageError("--truth-effect '" + spec + "': bad number '" + part + "'");
    values.push_back(x);
  }
  ctl::add_effect(m, name, axis, values);
}

std::unique_ptr<ctl::Trajectory> make_trajectory(Args& a) {
  const std::string kind = a.option_or("trajectory", "paper-circle");
  if (kind == "paper-circle" || kind == "circle") {
    ctl::CircleSpec c;
    if (kind == "circle") {
      c.ramp_time = 0.5;
      c.cruise_time = 4.0;
    }
    if (auto v = a.option("centre")) c.centre = parse_point("--centre", *v);
    c.radius = a.number("radius", c.radius);
    c.angular_speed = a.number("speed", c.angular_speed);
    c.cruise_time = a.number("time", c.cruise_time);
    c.ramp_time = a.number("ramp", c.ramp_time);
    c.start_angle = a.number("start-angle", c.start_angle);
    if (a.flag("cw")) c.angular_speed = -std::abs(c.angular_speed);
    const std::string plane = a.option_or("plane", "xy");
    if (plane == "xy") c.plane = ctl::CirclePlane::xy;
    else if (plane == "yz") c.plane = ctl::CirclePlane::yz;
    else if (plane == "zx") c.plane = ctl::CirclePlane::zx;
    else throw UsageError("--plane must be xy, yz or zx");
    return std::make_unique<ctl::CircleTrajectory>(c);
  }
  if (kind == "p2p") {
    const auto from = a.option("from");
    const auto to = a.option("to");
    if (!from || !to) throw UsageError("--trajectory p2p needs --from X,Y,Z and --to X,Y,Z (m)");
    ctl::MotionLimits lim;
    lim.velocity = a.number("vmax", lim.velocity);
    lim.acceleration = a.number("amax", lim.acceleration);
    lim.jerk = a.number("jmax", lim.jerk);
    return std::make_unique<ctl::PointToPoint>(parse_point("--from", *from), parse_point("--to", *to), lim);
  }
  throw UsageError("--trajectory must be paper-circle, circle or p2p, got '" + kind + "'");
}

int run(Args& a) {
  const std::string law_text = a.option_or("controller", "computed_torque");
  const auto law = ctl::law_from_name(law_text);
  if (!law) throw UsageError("--controller must be pd, pd_gravity, pd_feedforward or computed_torque");
  ctl::Gains gains = ctl::table3_gains(*law);
  const double kp = a.number("kp", gains.kp.x()), kd = a.number("kd", gains.kd.x());
  gains.kp.setConstant(kp);
  gains.kd.setConstant(kd);
  // The controller's model and the true machine: model files (docs/model-file.md),
  // the nominal machine when none is given; --truth-effect adds to the truth.
  const auto model_path = a.option("model");
  const auto truth_path = a.option("truth");
  const ctl::MachineModel controller_model =
      model_path ? io::load_model_file(*model_path).model : ctl::MachineModel::elkady();
  ctl::MachineModel truth_model =
      truth_path ? io::load_model_file(*truth_path).model : ctl::MachineModel::elkady();
  for (const std::string& spec : a.options("truth-effect")) apply_effect(truth_model, spec);
  sim::PlantOptions po;
  po.substeps = static_cast<int>(a.integer("substeps", po.substeps));
  po.encoder.resolution = a.number("encoder-resolution", 0.0);
  po.encoder.position_noise = a.number("encoder-noise", 0.0);
  po.encoder.velocity_noise = a.number("velocity-noise", 0.0);
  po.encoder.seed = static_cast<std::uint64_t>(a.integer("seed", 1));
  sim::LoopOptions lo;
  lo.rate_hz = a.number("rate", lo.rate_hz);
  lo.duration = a.number("duration", -1.0);
  const auto log_path = a.option("log");
  const auto json_path = a.option("json");
  auto traj = make_trajectory(a);
  a.finish();

  const ctl::Machine model(controller_model);
  const ctl::Machine truth(truth_model);
  ctl::validate_trajectory(*traj, model, 1e-3);
  const ctl::Controller controller(model, *law, gains);
  sim::Plant plant(truth, po);
  lo.keep_log = log_path.has_value();
  const sim::RunResult r = sim::run_closed_loop(controller, plant, *traj, lo);
  const auto& m = r.metrics;
  std::printf("controller %s (Kp %g, Kd %g), %.0f Hz, %ld samples over %.3f s\n", ctl::law_name(*law),
              kp, kd, lo.rate_hz, m.samples, m.samples / lo.rate_hz);
  std::printf("position error: RMSE %.4f mm, max %.4f mm (RMS by axis x %.4f, y %.4f, z %.4f mm)\n",
              m.position_rmse * 1e3, m.position_max * 1e3, m.position_rms_axis.x() * 1e3,
              m.position_rms_axis.y() * 1e3, m.position_rms_axis.z() * 1e3);
  std::printf("velocity error: RMSE %.3f mm/s, max %.3f mm/s\n", m.velocity_rmse * 1e3,
              m.velocity_max * 1e3);
  std::printf("force limit reached in %ld of %ld periods\n", m.saturated_samples, m.samples);
  if (!r.ok())
    std::printf("STOPPED at t = %.4f s: %s\n", r.fault_time, describe(r.fault).c_str());
  if (log_path) {
    sim::write_motion_log(*log_path, r.log, lo.rate_hz);
    std::printf("motion log: %s (%zu rows)\n", log_path->c_str(), r.log.size());
  }
  if (json_path) {
    std::ostringstream js;
    js << "{\"controller\": \"" << ctl::law_name(*law) << "\", \"ok\": " << (r.ok() ? "true" : "false")
       << ", \"fault\": \"" << fault_name(r.fault.fault) << "\", \"samples\": " << m.samples
       << ", \"position_rmse\": " << json_number(m.position_rmse)
       << ", \"position_max\": " << json_number(m.position_max)
       << ", \"velocity_rmse\": " << json_number(m.velocity_rmse)
       << ", \"velocity_max\": " << json_number(m.velocity_max)
       << ", \"saturated_samples\": " << m.saturated_samples << "}\n";
    write_file_atomically(*json_path, js.str());
  }
  return r.ok() ? 0 : 1;
}

const Command reg{
    "sim", "run a trajectory with a controller on a simulated true machine", run,
    "[--controller pd|pd_gravity|pd_feedforward|computed_torque] [--kp N] [--kd N]\n"
    "       [--trajectory paper-circle|circle|p2p] [--centre X,Y,Z] [--radius R] [--speed RAD/S]\n"
    "       [--plane xy|yz|zx] [--cw] [--time S] [--ramp S] [--from X,Y,Z --to X,Y,Z]\n"
    "       [--vmax M/S] [--amax M/S2] [--jmax M/S3] [--rate HZ] [--substeps N] [--duration S]\n"
    "       [--model MODEL.yaml] [--truth MODEL.yaml] [--truth-effect NAME:AXIS:V1,V2,...]... [--encoder-resolution M] [--encoder-noise M]\n"
    "       [--velocity-noise M/S] [--seed N] [--log FILE.csv] [--json FILE]"};

}  // namespace
}  // namespace cpm::cli

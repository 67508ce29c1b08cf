// SPDX-License-Identifier: Apache-2.0
// cpm sim: run a trajectory with a chosen controller on a chosen true machine.
#include <cstdio>
#include <memory>
#include <sstream>
#include <vector>

#include "cli.hpp"
#include "cpm/io/model_file.hpp"
#include "cpm/sim/closed_loop.hpp"

namespace cpm::cli {
namespace {

// NAME:AXIS:V1,V2,... (axis 1..3, empty for machine-wide effects).
// Or a user effect: table:..., expression:..., pitch_table:... (ctl::add_user_effect).
void apply_effect(ctl::MachineModel& m, const std::string& spec) {
  if (ctl::is_user_effect_spec(spec)) {
    try {
      ctl::add_user_effect(m, spec);
    } catch (const Error& e) {
      throw UsageError(std::string("--truth-effect ") + e.what());
    }
    return;
  }
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
    axis = axis_text[0] - '1';
  }
  std::vector<double> values;
  std::istringstream is(spec.substr(c2 + 1));
  std::string part;
  while (std::getline(is, part, ',')) {
    double x = 0;
    if (!CLI::detail::lexical_cast(part, x)) throw UsageError("--truth-effect '" + spec + "': bad number '" + part + "'");
    values.push_back(x);
  }
  ctl::add_effect(m, name, axis, values);
}

struct Options {
  std::string controller = "computed_torque";
  std::optional<double> kp, kd;
  std::string trajectory = "paper-circle";
  std::optional<std::string> centre, from, to;
  std::optional<double> radius, speed, time, ramp, start_angle;
  std::string plane = "xy";
  bool cw = false;
  ctl::MotionLimits limits;
  double rate = sim::LoopOptions{}.rate_hz;
  double duration = -1.0;
  int substeps = sim::PlantOptions{}.substeps;
  std::optional<std::string> model, truth, log, json;
  std::vector<std::string> truth_effects;
  double encoder_resolution = 0.0, encoder_noise = 0.0, velocity_noise = 0.0;
  long seed = 1;
  // Which options were given: those of one trajectory kind do not go with another.
  std::vector<const CLI::Option*> circle_only, p2p_only;
};

std::unique_ptr<ctl::Trajectory> make_trajectory(const Options& o) {
  const bool p2p = o.trajectory == "p2p";
  for (const CLI::Option* opt : p2p ? o.circle_only : o.p2p_only)
    if (opt->count() > 0)
      throw UsageError(opt->get_name() + " does not apply to --trajectory " + o.trajectory);
  if (!p2p) {
    ctl::CircleSpec c;
    if (o.trajectory == "circle") {
      c.ramp_time = 0.5;
      c.cruise_time = 4.0;
    }
    if (o.centre) c.centre = parse_point("--centre", *o.centre);
    c.radius = o.radius.value_or(c.radius);
    c.angular_speed = o.speed.value_or(c.angular_speed);
    c.cruise_time = o.time.value_or(c.cruise_time);
    c.ramp_time = o.ramp.value_or(c.ramp_time);
    c.start_angle = o.start_angle.value_or(c.start_angle);
    if (o.cw) c.angular_speed = -std::abs(c.angular_speed);
    c.plane = o.plane == "xy" ? ctl::CirclePlane::xy : o.plane == "yz" ? ctl::CirclePlane::yz : ctl::CirclePlane::zx;
    return std::make_unique<ctl::CircleTrajectory>(c);
  }
  if (!o.from || !o.to) throw UsageError("--trajectory p2p needs --from X,Y,Z and --to X,Y,Z (m)");
  return std::make_unique<ctl::PointToPoint>(parse_point("--from", *o.from), parse_point("--to", *o.to), o.limits);
}

int run(const Options& o) {
  const ctl::ControlLaw law = *ctl::law_from_name(o.controller);
  ctl::Gains gains = ctl::table3_gains(law);
  const double kp = o.kp.value_or(gains.kp.x()), kd = o.kd.value_or(gains.kd.x());
  gains.kp.setConstant(kp);
  gains.kd.setConstant(kd);
  // The controller's model and the true machine: model files (model-file.md),
  // the nominal machine when none is given; --truth-effect adds to the truth.
  const ctl::MachineModel controller_model = o.model ? io::load_model_file(*o.model).model : ctl::MachineModel::elkady();
  ctl::MachineModel truth_model = o.truth ? io::load_model_file(*o.truth).model : ctl::MachineModel::elkady();
  for (const std::string& spec : o.truth_effects) apply_effect(truth_model, spec);
  sim::PlantOptions po;
  po.substeps = o.substeps;
  po.encoder.resolution = o.encoder_resolution;
  po.encoder.position_noise = o.encoder_noise;
  po.encoder.velocity_noise = o.velocity_noise;
  po.encoder.seed = static_cast<std::uint64_t>(o.seed);
  sim::LoopOptions lo;
  lo.rate_hz = o.rate;
  lo.duration = o.duration;
  const auto& log_path = o.log;
  const auto& json_path = o.json;
  auto traj = make_trajectory(o);

  const ctl::Machine model(controller_model);
  const ctl::Machine truth(truth_model);
  ctl::validate_trajectory(*traj, model, 1e-3);
  const ctl::Controller controller(model, law, gains);
  sim::Plant plant(truth, po);
  lo.keep_log = log_path.has_value();
  const sim::RunResult r = sim::run_closed_loop(controller, plant, *traj, lo);
  const auto& m = r.metrics;
  std::printf("controller %s (Kp %g, Kd %g), %.0f Hz, %ld samples over %.3f s\n", ctl::law_name(law),
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
  if (json_path)
    write_json(*json_path, Json{{"controller", ctl::law_name(law)},
                                {"ok", r.ok()},
                                {"fault", fault_name(r.fault.fault)},
                                {"samples", m.samples},
                                {"position_rmse", m.position_rmse},
                                {"position_max", m.position_max},
                                {"velocity_rmse", m.velocity_rmse},
                                {"velocity_max", m.velocity_max},
                                {"saturated_samples", m.saturated_samples}});
  return r.ok() ? 0 : 1;
}

Run setup(CLI::App& app) {
  auto o = std::make_shared<Options>();
  add_choice(app, "--controller", o->controller, law_names(), "the control law (Elkady's four)");
  add_number(app, "--kp", o->kp, "K", "proportional gain on every axis: N/m for the PD laws, 1/s^2 for computed_torque")
      ->default_str("Table 3's gain of the law");
  add_number(app, "--kd", o->kd, "K", "derivative gain on every axis: N s/m for the PD laws, 1/s for computed_torque")
      ->default_str("Table 3's gain of the law");
  add_choice(app, "--trajectory", o->trajectory, {"paper-circle", "circle", "p2p"},
             "what to run: Elkady's circle (starts at full speed), a circle with speed ramps, or a straight "
             "point-to-point move");
  const ctl::CircleSpec c;
  o->circle_only = {
      app.add_option("--centre", o->centre, "circle centre in m (e.g. 0.425,0.425,0.300)")
          ->type_name("X,Y,Z")->default_str("0.425,0.425,0.300"),
      add_number(app, "--radius", o->radius, "M", "circle radius in m (e.g. 0.150)")->default_str(CLI::detail::to_string(c.radius)),
      add_number(app, "--speed", o->speed, "RAD/S", "angular speed in rad/s, > 0 counter-clockwise (e.g. 1.0)")
          ->default_str(CLI::detail::to_string(c.angular_speed)),
      add_choice(app, "--plane", o->plane, {"xy", "yz", "zx"}, "the circle's plane"),
      app.add_flag("--cw", o->cw, "run the circle clockwise"),
      add_number(app, "--time", o->time, "S", "time at full speed in s")->default_str(CLI::detail::to_string(c.cruise_time)),
      add_number(app, "--ramp", o->ramp, "S", "time to reach and leave full speed in s")
          ->default_str("0 for paper-circle, 0.5 for circle"),
      add_number(app, "--start-angle", o->start_angle, "RAD", "start angle in rad from the plane's first axis")
          ->default_str("0")};
  o->p2p_only = {app.add_option("--from", o->from, "start of the move in m (e.g. 0.30,0.30,0.30)")->type_name("X,Y,Z"),
                 app.add_option("--to", o->to, "end of the move in m (e.g. 0.45,0.40,0.35)")->type_name("X,Y,Z"),
                 add_number(app, "--vmax", o->limits.velocity, "M/S", "velocity limit of the move in m/s"),
                 add_number(app, "--amax", o->limits.acceleration, "M/S2", "acceleration limit in m/s^2"),
                 add_number(app, "--jmax", o->limits.jerk, "M/S3", "jerk limit in m/s^3")};
  add_number(app, "--rate", o->rate, "HZ", "control rate in Hz (zero-order hold between cycles)");
  app.add_option("--substeps", o->substeps, "RK4 steps of the plant per control period")->type_name("N");
  add_number(app, "--duration", o->duration, "S", "simulated time in s; < 0: the trajectory's duration");
  app.add_option("--model", o->model, "the model the controller believes")
      ->type_name("MODEL.yaml")
      ->default_str("the nominal machine, built in");
  app.add_option("--truth", o->truth, "the true machine the plant simulates")
      ->type_name("MODEL.yaml")
      ->default_str("the nominal machine, built in");
  app.add_option("--truth-effect", o->truth_effects,
                 "add an effect to the true machine: NAME, axis 1..3 (empty for machine-wide ones), its parameters in "
                 "SI units (e.g. coulomb_friction:2:4.5, actuation_delay::0.001); or a user effect (docs/effects.md, "
                 "\"Effects you add\"): table:AXIS:INPUT:NODES:FORCES, expression:AXIS:FORMULA:NAME=VALUE,..., "
                 "pitch_table:AXIS:NODES:ERRORS (e.g. expression:2:c*v1:c=3)")
      ->type_name("NAME:AXIS:V1,V2,...")
      ->check(effect_name())
      ->allow_extra_args(false);
  add_number(app, "--encoder-resolution", o->encoder_resolution, "M", "encoder quantum in m (e.g. 1e-6); 0: ideal");
  add_number(app, "--encoder-noise", o->encoder_noise, "M", "position noise of the encoders, standard deviation in m");
  add_number(app, "--velocity-noise", o->velocity_noise, "M/S", "velocity noise, standard deviation in m/s");
  app.add_option("--seed", o->seed, "seed of the encoder noise")->type_name("N");
  app.add_option("--log", o->log, "write the motion log (data-formats.md, kind = motion)")->type_name("FILE.csv");
  app.add_option("--json", o->json, "write the result (RMSE and maximum errors in m, m/s) as JSON to FILE")
      ->type_name("FILE");
  app.footer("Exit status 1 when the machine stopped on a fault (force, workspace, singularity).");
  return [o] { return run(*o); };
}

const Command reg{"sim", "run a trajectory with a controller on a simulated true machine", setup};

}  // namespace
}  // namespace cpm::cli

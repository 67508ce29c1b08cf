// SPDX-License-Identifier: Apache-2.0
// cpm simulate-measurement: what a ball-bar or a laser tracker would read on
// a true machine commanded through a controller's model, as a measurement
// file of docs/data-formats.md (for trying the calibration and for tests).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "calib_common.hpp"
#include "cpm/calibration/poses.hpp"
#include "cpm/calibration/simulate.hpp"
#include "cpm/io/model_file.hpp"

namespace cpm::cli {
namespace {

struct Options {
  std::optional<std::string> truth, model, pivot, pivot_error, noise_shape;
  std::string poses, out, kind = "ballbar", order = "file";
  double length_offset = 0.0, dwell = 0.0;
  bool length_offset_unknown = false;
  std::optional<double> noise;
  long seed = 1;
  std::vector<std::string> truth_effects;  // user effects added to the true machine
};

int run(const Options& o) {
  const std::string truth_path = model_or_default(o.truth);
  const std::string model_path = model_or_default(o.model);
  const std::string& poses_path = o.poses;
  const std::string& kind = o.kind;
  cal::BallbarSimulation bs;
  if (o.pivot) bs.pivot_nominal = calib_point("--pivot", *o.pivot);
  Vec3 pivot_error = Vec3::Zero();
  if (o.pivot_error) pivot_error = calib_point("--pivot-error", *o.pivot_error);
  bs.length_offset = o.length_offset;
  bs.length_offset_known = !o.length_offset_unknown;
  cal::Noise noise;
  noise.size = o.noise.value_or(kind == "ballbar" ? 0.5e-6 : 5e-6);
  const std::string shape = o.noise_shape.value_or(kind == "ballbar" ? "uniform" : "gaussian");
  noise.shape = shape == "uniform" ? cal::NoiseShape::uniform : cal::NoiseShape::gaussian;
  noise.seed = static_cast<std::uint64_t>(o.seed);
  const double dwell = o.dwell;
  const std::string& order = o.order;
  const std::string& out = o.out;
  if (!(dwell >= 0.0)) throw UsageError("--dwell must be a number of seconds >= 0");
  io::ModelFile truth = io::load_model_file(truth_path);
  for (const auto& spec : o.truth_effects) {
    if (!ctl::is_user_effect_spec(spec))
      throw UsageError("--truth-effect '" + spec + "': a user effect (pitch_table:AXIS:N1,N2,...:E1,E2,...); library "
                       "effects go in the --truth model file");
    try {
      ctl::add_user_effect(truth.model, spec);
    } catch (const Error& e) {
      throw UsageError(std::string("--truth-effect ") + e.what());
    }
  }
  const io::ModelFile model = io::load_model_file(model_path);
  std::vector<Vec3> cmd = cal::read_poses_csv(poses_path);
  // Visiting in a shuffled order brings every axis into the poses from both
  // directions (backlash needs that); a dwell gives each pose its time and
  // approach direction (the t and dir columns: thermal drift, backlash).
  if (order == "shuffled") {
    std::mt19937_64 rng(noise.seed * 2654435761u + 17u);
    std::shuffle(cmd.begin(), cmd.end(), rng);
  }
  std::vector<kin::KinematicInputs> inputs;
  if (dwell > 0.0) inputs = cal::sequence_inputs(model.model, cmd, dwell, dwell);
  if (kind == "ballbar") {
    bs.pivot_true = bs.pivot_nominal + pivot_error;
    bs.noise = noise;
    bs.inputs = inputs;
    io::BallbarData d = cal::simulate_ballbar(truth.model, model.model, cmd, bs);
    io::write_ballbar(out, d);
  } else {
    io::PositionData d = cal::simulate_positions(truth.model, model.model, cmd, noise, inputs);
    io::write_position(out, d);
  }
  std::printf("wrote %s: %zu %s rows, true machine %s, commanded through %s, noise %s %.3g µm%s\n",
              out.c_str(), cmd.size(), kind.c_str(), truth_path.c_str(), model_path.c_str(),
              shape.c_str(), noise.size * 1e6,
              dwell > 0.0 ? ", with t and dir1..dir3 (poses visited in order, one per dwell)" : "");
  return 0;
}

Run setup(CLI::App& app) {
  auto o = std::make_shared<Options>();
  app.add_option("--poses", o->poses, "the commanded poses (cpm plan-poses writes them)")->type_name("POSES.csv")->required();
  app.add_option("--out", o->out, "the measurement file to write (data-formats.md)")->type_name("FILE.csv")->required();
  add_choice(app, "--kind", o->kind, {"ballbar", "position"}, "a ball-bar (lengths) or a laser tracker (positions)");
  add_model_option(app, o->truth, "the true machine, simulated", "--truth");
  add_model_option(app, o->model, "the model the poses are commanded through");
  app.add_option("--pivot", o->pivot, "the fixed ball as declared in the file, in m")
      ->type_name("X,Y,Z")
      ->default_str(point_text(cal::BallbarSimulation{}.pivot_nominal));
  app.add_option("--pivot-error", o->pivot_error, "where the ball really is minus where it is declared, in m")
      ->type_name("DX,DY,DZ")
      ->default_str("0,0,0");
  add_number(app, "--length-offset", o->length_offset, "M", "the bar's length offset in m (reading = distance - offset)");
  app.add_flag("--length-offset-unknown", o->length_offset_unknown, "mark the length offset unknown in the file (fitted)");
  add_number(app, "--noise", o->noise, "M", "measurement noise in m: half-width (uniform) or standard deviation (gaussian)")
      ->default_str("0.5e-6 for ballbar (QC10), 5e-6 for position");
  app.add_option("--noise-shape", o->noise_shape, "the noise's distribution")
      ->check(CLI::IsMember({"uniform", "gaussian"}).description(""))
      ->type_name("uniform|gaussian")
      ->default_str("uniform for ballbar, gaussian for position");
  app.add_option("--truth-effect", o->truth_effects,
                 "a user effect added to the true machine (repeat; e.g. pitch_table:1:0.05,0.2,0.35:0,2e-6,8e-6, m)")
      ->type_name("SPEC");
  app.add_option("--seed", o->seed, "seed of the noise (and of the shuffled order)")->type_name("N");
  add_number(app, "--dwell", o->dwell, "S",
             "visit the poses S seconds apart and write t and dir1..dir3 (what backlash and thermal drift need); "
             "0: no time columns");
  add_choice(app, "--order", o->order, {"file", "shuffled"},
             "visit the poses in the file's order or in a random one (every axis from both directions)");
  return [o] { return run(*o); };
}

const Command reg{"simulate-measurement",
                  "simulated ball-bar or position measurements of a true machine (a data file)", setup};

}  // namespace
}  // namespace cpm::cli

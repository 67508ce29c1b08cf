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

int run(Args& a) {
  const std::string truth_path = a.option_or("truth", default_model_path());
  const std::string model_path = a.option_or("model", default_model_path());
  const auto poses_path = a.option("poses");
  const std::string kind = a.option_or("kind", "ballbar");
  cal::BallbarSimulation bs;
  if (auto v = a.option("pivot")) bs.pivot_nominal = calib_point("--pivot", *v);
  Vec3 pivot_error = Vec3::Zero();
  if (auto v = a.option("pivot-error")) pivot_error = calib_point("--pivot-error", *v);
  bs.length_offset = a.number("length-offset", 0.0);
  bs.length_offset_known = !a.flag("length-offset-unknown");
  cal::Noise noise;
  noise.size = a.number("noise", kind == "ballbar" ? 0.5e-6 : 5e-6);
  const std::string shape = a.option_or("noise-shape", kind == "ballbar" ? "uniform" : "gaussian");
  if (shape == "uniform") noise.shape = cal::NoiseShape::uniform;
  else if (shape == "gaussian") noise.shape = cal::NoiseShape::gaussian;
  else throw UsageError("--noise-shape must be uniform or gaussian");
  noise.seed = static_cast<std::uint64_t>(a.integer("seed", 1));
  const double dwell = a.number("dwell", 0.0);
  const std::string order = a.option_or("order", "file");
  const auto out = a.option("out");
  a.finish();
  if (!(dwell >= 0.0) || !std::isfinite(dwell)) throw UsageError("--dwell must be a number of seconds >= 0");
  if (order != "file" && order != "shuffled") throw UsageError("--order must be file or shuffled");
  if (!poses_path) throw UsageError("--poses FILE.csv is required (cpm plan-poses writes one)");
  if (!out) throw UsageError("--out FILE.csv is required");
  const io::ModelFile truth = io::load_model_file(truth_path);
  const io::ModelFile model = io::load_model_file(model_path);
  std::vector<Vec3> cmd = cal::read_poses_csv(*poses_path);
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
    io::write_ballbar(*out, d);
  } else if (kind == "position") {
    io::PositionData d = cal::simulate_positions(truth.model, model.model, cmd, noise, inputs);
    io::write_position(*out, d);
  } else {
    throw UsageError("--kind must be ballbar or position");
  }
  std::printf("wrote %s: %zu %s rows, true machine %s, commanded through %s, noise %s %.3g µm%s\n",
              out->c_str(), cmd.size(), kind.c_str(), truth_path.c_str(), model_path.c_str(),
              shape.c_str(), noise.size * 1e6,
              dwell > 0.0 ? ", with t and dir1..dir3 (poses visited in order, one per dwell)" : "");
  return 0;
}

const Command reg{"simulate-measurement",
                  "simulated ball-bar or position measurements of a true machine (a data file)", run,
                  "--poses POSES.csv --out FILE.csv [--kind ballbar|position] [--truth TRUE.yaml]\n"
                  "       [--model MODEL.yaml] [--pivot X,Y,Z] [--pivot-error DX,DY,DZ] [--length-offset M]\n"
                  "       [--length-offset-unknown] [--noise M] [--noise-shape uniform|gaussian] [--seed N]\n"
                  "       [--dwell S] [--order file|shuffled]\n"
                  "  Ball-bar noise is +-0.5 µm uniform by default (QC10), positions 5 µm gaussian.\n"
                  "  --dwell S visits the poses S seconds apart and writes t and dir1..dir3 (what backlash and\n"
                  "  thermal drift need); --order shuffled visits them in a random order (both directions)."};

}  // namespace
}  // namespace cpm::cli

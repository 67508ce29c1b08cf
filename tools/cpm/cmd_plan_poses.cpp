// SPDX-License-Identifier: Apache-2.0
// cpm plan-poses: measurement poses for a calibration, checked against the
// workspace, as a CSV of commanded positions.
#include <cstdio>

#include "calib_common.hpp"
#include "cpm/calibration/poses.hpp"
#include "cpm/io/model_file.hpp"

namespace cpm::cli {
namespace {

std::string vec_text(const Vec3& v) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "%.6f %.6f %.6f", v.x(), v.y(), v.z());
  return buf;
}

struct Options {
  std::optional<std::string> model, layout, pivot, radii, out;
  std::string kind = "ballbar";
  long count = 32;
  bool dl_unknown = false;
};

int run(const Options& o) {
  const std::string model_path = model_or_default(o.model);
  const std::string& kind = o.kind;
  const std::string layout = o.layout.value_or(kind == "ballbar" ? "kim" : "optimal");
  Vec3 pivot(0.430, 0.430, 0.530);
  if (o.pivot) pivot = calib_point("--pivot", *o.pivot);
  std::vector<double> radii{0.100, 0.150};
  if (o.radii) radii = calib_numbers("--radii", *o.radii);
  const long count = o.count;
  const bool dl_unknown = o.dl_unknown;
  const auto& out = o.out;
  if (kind == "position" && layout == "kim") throw UsageError("Kim's layout is for a ball-bar; use --layout optimal");
  const io::ModelFile mf = io::load_model_file(model_path);
  std::vector<cal::PlannedPose> poses;
  double o1 = 0.0, o1_kim = 0.0;
  std::vector<std::pair<std::string, std::string>> meta{{"kind", "poses"}, {"measurement", kind},
                                                        {"layout", layout}, {"model", model_path}};
  if (kind == "ballbar") {
    poses = layout == "kim" ? cal::kim_ballbar_poses(mf.model, pivot, radii)
                            : cal::optimal_ballbar_poses(mf.model, pivot, radii, static_cast<int>(count), !dl_unknown);
    o1 = cal::ballbar_observability(mf.model, pivot, poses, !dl_unknown);
    meta.emplace_back("pivot", vec_text(pivot));
    if (layout == "optimal") {
      try {
        o1_kim = cal::ballbar_observability(mf.model, pivot, cal::kim_ballbar_poses(mf.model, pivot, radii), !dl_unknown);
      } catch (const Error&) {
        o1_kim = 0.0;  // Kim's layout does not fit about this pivot
      }
    }
  } else {
    poses = cal::optimal_position_poses(mf.model, static_cast<int>(count));
    o1 = cal::position_observability(mf.model, poses);
  }
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.6g", o1);
  meta.emplace_back("observability_O1", buf);
  std::printf("%zu %s poses (%s layout), every one inside the workspace of %s\n", poses.size(), kind.c_str(),
              layout.c_str(), model_path.c_str());
  std::printf("observability index O1 = %.4g (geometric mean of the singular values of J per measurement)\n", o1);
  if (o1_kim > 0.0) std::printf("  Kim's 32-point layout about the same pivot: O1 = %.4g\n", o1_kim);
  if (kind == "ballbar")
    std::printf("pivot (%.3f, %.3f, %.3f) mm, bar lengths", pivot.x() * 1e3, pivot.y() * 1e3, pivot.z() * 1e3);
  if (kind == "ballbar") {
    for (double r : radii) std::printf(" %.1f", r * 1e3);
    std::printf(" mm\n");
  }
  const std::string csv = cal::poses_csv(poses, meta, kind == "ballbar");
  if (out) {
    io::write_file_atomically(*out, csv);
    std::printf("wrote %s\n", out->c_str());
  } else {
    std::fputs(csv.c_str(), stdout);
  }
  return 0;
}

Run setup(CLI::App& app) {
  auto o = std::make_shared<Options>();
  add_model_option(app, o->model, "the model whose workspace the poses must lie in");
  add_choice(app, "--kind", o->kind, {"ballbar", "position"}, "what will be measured: bar lengths or positions");
  app.add_option("--layout", o->layout,
                 "Kim's 32 points on hemispheres of 100 and 150 mm above the pivot, or a D-optimal set")
      ->check(CLI::IsMember({"kim", "optimal"}).description(""))
      ->type_name("kim|optimal")
      ->default_str("kim for ballbar, optimal for position");
  app.add_option("--pivot", o->pivot, "the ball-bar's fixed ball in m")->type_name("X,Y,Z")->default_str("0.430,0.430,0.530");
  app.add_option("--radii", o->radii, "bar lengths in m (e.g. 0.100,0.150)")
      ->type_name("R1,R2,...")
      ->default_str("0.100,0.150");
  app.add_option("--count", o->count, "number of poses of the optimal layout (1 .. 10000)")->type_name("N")->check(CLI::Range(1L, 10000L).description(""));
  app.add_flag("--length-offset-unknown", o->dl_unknown, "the bar's length offset is fitted too (no setting master)");
  app.add_option("--out", o->out, "write the poses to FILE.csv instead of the standard output")->type_name("FILE.csv");
  return [o] { return run(*o); };
}

const Command reg{"plan-poses", "measurement poses for a calibration (Kim's layout or D-optimal), as CSV", setup};

}  // namespace
}  // namespace cpm::cli

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

int run(Args& a) {
  const std::string model_path = a.option_or("model", default_model_path());
  const std::string kind = a.option_or("kind", "ballbar");
  const std::string layout = a.option_or("layout", kind == "ballbar" ? "kim" : "optimal");
  Vec3 pivot(0.430, 0.430, 0.530);
  if (auto v = a.option("pivot")) pivot = calib_point("--pivot", *v);
  std::vector<double> radii{0.100, 0.150};
  if (auto v = a.option("radii")) radii = calib_numbers("--radii", *v);
  const long count = a.integer("count", 32);
  const bool dl_unknown = a.flag("length-offset-unknown");
  const auto out = a.option("out");
  a.finish();
  if (kind != "ballbar" && kind != "position") throw UsageError("--kind must be ballbar or position");
  if (layout != "kim" && layout != "optimal") throw UsageError("--layout must be kim or optimal");
  if (kind == "position" && layout == "kim") throw UsageError("Kim's layout is for a ball-bar; use --layout optimal");
  if (count < 1 || count > 10000) throw UsageError("--count must be within 1 .. 10000");
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

const Command reg{"plan-poses", "measurement poses for a calibration (Kim's layout or D-optimal), as CSV", run,
                  "[--model MODEL.yaml] [--kind ballbar|position] [--layout kim|optimal]\n"
                  "       [--pivot X,Y,Z] [--radii R1,R2,...] [--count N] [--length-offset-unknown] [--out FILE.csv]\n"
                  "  Lengths in m. Kim's layout: 32 points on hemispheres of 100 and 150 mm above the pivot."};

}  // namespace
}  // namespace cpm::cli

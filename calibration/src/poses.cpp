// SPDX-License-Identifier: Apache-2.0
#include "cpm/calibration/poses.hpp"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <numbers>
#include <sstream>

#include "cpm/calibration/ballbar.hpp"
#include "cpm/calibration/position.hpp"
#include "cpm/kinematics/workspace.hpp"

namespace cpm::cal {
namespace {

constexpr double kPi = std::numbers::pi;

std::string mm3(const Vec3& p) {
  char buf[80];
  std::snprintf(buf, sizeof buf, "(%.3f, %.3f, %.3f) mm", p.x() * 1e3, p.y() * 1e3, p.z() * 1e3);
  return buf;
}

// The pose if the model can command it.
bool plan(const ctl::MachineModel& m, const Vec3& p, double radius, PlannedPose& out, Status* why) {
  const kin::KinematicInputs in;
  Status s = kin::check_pose(m.kinematics, m.strokes, p, in);
  if (s) s = kin::inverse(m.kinematics, p, in, out.d);
  if (why) *why = s;
  if (!s) return false;
  out.p = p;
  out.radius = radius;
  return true;
}

// Rows of the measurement Jacobian for candidate poses.
MatX ballbar_rows(const ctl::MachineModel& m, const Vec3& pivot, const std::vector<PlannedPose>& poses,
                  bool known) {
  std::vector<Vec3> d;
  std::vector<double> l;
  for (const PlannedPose& p : poses) {
    d.push_back(p.d);
    Vec3 x;
    kin::forward(m.kinematics, p.d, {}, x);
    l.push_back((x - pivot).norm());
  }
  VecX r;
  MatX J;
  ballbar_residuals(BallbarParameters{}.vector(!known), m.kinematics.d0, d, l, pivot, r, &J);
  return J;
}

MatX position_rows(const ctl::MachineModel& m, const std::vector<PlannedPose>& poses) {
  std::vector<Vec3> d, p;
  for (const PlannedPose& q : poses) {
    d.push_back(q.d);
    p.push_back(q.p);
  }
  VecX r;
  MatX J;
  position_residuals(m.kinematics.planes, m.kinematics.d0, d, p, r, &J);
  return J;
}

// Greedy then exchange D-optimal selection of `count` candidates; `rows_per`
// Jacobian rows per candidate.
std::vector<int> d_optimal(const MatX& rows, int rows_per, int count) {
  const int n_cand = static_cast<int>(rows.rows()) / rows_per;
  const Eigen::Index P = rows.cols();
  auto block = [&](int c) { return rows.middleRows(static_cast<Eigen::Index>(c) * rows_per, rows_per); };
  std::vector<int> chosen;
  std::vector<bool> used(static_cast<std::size_t>(n_cand), false);
  // A small ridge keeps the information matrix invertible while it fills up.
  const double ridge = 1e-9 * (rows.transpose() * rows).trace() / static_cast<double>(P);
  MatX M = ridge * MatX::Identity(P, P);
  auto logdet = [](const MatX& A) {
    Eigen::LDLT<MatX> l(A);
    return l.vectorD().array().max(1e-300).log().sum();
  };
  for (int k = 0; k < count; ++k) {
    const MatX Minv = M.inverse();
    int best = -1;
    double gain = -1.0;
    for (int c = 0; c < n_cand; ++c) {
      if (used[static_cast<std::size_t>(c)]) continue;
      const MatX B = block(c);
      const double g = (MatX::Identity(rows_per, rows_per) + B * Minv * B.transpose()).determinant();
      if (g > gain) {
        gain = g;
        best = c;
      }
    }
    if (best < 0) break;
    used[static_cast<std::size_t>(best)] = true;
    chosen.push_back(best);
    M += block(best).transpose() * block(best);
  }
  // Exchange passes (Fedorov): swap a chosen pose for a candidate when that
  // raises det(M), until no swap helps.
  for (int pass = 0; pass < 10; ++pass) {
    bool improved = false;
    for (std::size_t k = 0; k < chosen.size(); ++k) {
      const MatX Bk = block(chosen[k]);
      const MatX Mk = M - Bk.transpose() * Bk;
      const double base = logdet(M);
      int best = -1;
      double best_ld = base + 1e-9;
      for (int c = 0; c < n_cand; ++c) {
        if (used[static_cast<std::size_t>(c)]) continue;
        const MatX Bc = block(c);
        const double ld = logdet(Mk + Bc.transpose() * Bc);
        if (ld > best_ld) {
          best_ld = ld;
          best = c;
        }
      }
      if (best >= 0) {
        used[static_cast<std::size_t>(chosen[k])] = false;
        used[static_cast<std::size_t>(best)] = true;
        chosen[k] = best;
        M = Mk + block(best).transpose() * block(best);
        improved = true;
      }
    }
    if (!improved) break;
  }
  return chosen;
}

}  // namespace

double observability_index(const MatX& J) {
  if (J.rows() == 0) return 0.0;
  Eigen::JacobiSVD<MatX> svd(J);
  const VecX s = svd.singularValues();
  double lg = 0.0;
  for (Eigen::Index k = 0; k < s.size(); ++k) lg += std::log(std::max(s[k], 1e-300));
  return std::exp(lg / static_cast<double>(s.size())) / std::sqrt(static_cast<double>(J.rows()));
}

void check_poses(const ctl::MachineModel& model, const std::vector<Vec3>& poses) {
  for (std::size_t j = 0; j < poses.size(); ++j) {
    PlannedPose p;
    Status why;
    if (!plan(model, poses[j], 0.0, p, &why))
      throw Error("pose " + std::to_string(j + 1) + " " + mm3(poses[j]) +
                  " is outside the workspace: " + describe(why));
  }
}

std::vector<PlannedPose> kim_ballbar_poses(const ctl::MachineModel& model, const Vec3& pivot,
                                           const std::vector<double>& radii) {
  if (radii.empty()) throw Error("Kim's layout: at least one radius needed");
  std::vector<PlannedPose> out;
  std::string errors;
  int bad = 0, n = 0;
  const double rings[2] = {30.0 * kPi / 180.0, 65.0 * kPi / 180.0};
  for (std::size_t h = 0; h < radii.size(); ++h) {
    const double r = radii[h];
    if (!(r > 0.0) || !std::isfinite(r)) throw Error("Kim's layout: radii must be positive lengths (m)");
    for (int ring = 0; ring < 2; ++ring) {
      for (int k = 0; k < 8; ++k) {
        // Turn rings by 22.5 deg and hemispheres by 11.25 deg: 32 distinct azimuths.
        const double az = (k * 45.0 + ring * 22.5 + static_cast<double>(h) * 11.25) * kPi / 180.0;
        const double pol = rings[ring];
        // The pole points up: -z (z is down in the machine frame).
        const Vec3 p = pivot + r * Vec3(std::sin(pol) * std::cos(az), std::sin(pol) * std::sin(az),
                                        -std::cos(pol));
        ++n;
        PlannedPose pp;
        Status why;
        if (plan(model, p, r, pp, &why)) {
          out.push_back(pp);
        } else {
          ++bad;
          if (bad <= 4)
            errors += "\n  pose " + std::to_string(n) + " (radius " + std::to_string(r * 1e3).substr(0, 5) +
                      " mm) at " + mm3(p) + ": " + describe(why);
        }
      }
    }
  }
  if (bad > 0)
    throw Error("Kim's layout about the pivot " + mm3(pivot) + ": " + std::to_string(bad) + " of " +
                std::to_string(n) + " poses are outside the workspace" +
                (bad == n ? " (no pose can reach this pivot: move it into the workspace)" : "") +
                ":" + errors + (bad > 4 ? "\n  ..." : ""));
  return out;
}

std::vector<PlannedPose> optimal_ballbar_poses(const ctl::MachineModel& model, const Vec3& pivot,
                                               const std::vector<double>& radii, int count,
                                               bool known) {
  if (radii.empty()) throw Error("pose planning: at least one bar length needed");
  const int P = known ? 9 : 10;
  if (count < P + 1)
    throw Error("pose planning: at least " + std::to_string(P + 1) + " ball-bar poses needed for " +
                std::to_string(P) + " unknowns, asked for " + std::to_string(count));
  // Candidates: a Fibonacci lattice on each sphere, kept where reachable.
  std::vector<PlannedPose> cand;
  const int per_sphere = 500;
  const double golden = kPi * (3.0 - std::sqrt(5.0));
  for (double r : radii) {
    if (!(r > 0.0) || !std::isfinite(r)) throw Error("pose planning: radii must be positive lengths (m)");
    for (int k = 0; k < per_sphere; ++k) {
      const double z = 1.0 - 2.0 * (k + 0.5) / per_sphere;
      const double rho = std::sqrt(1.0 - z * z);
      const Vec3 p = pivot + r * Vec3(rho * std::cos(golden * k), rho * std::sin(golden * k), z);
      PlannedPose pp;
      if (plan(model, p, r, pp, nullptr)) cand.push_back(pp);
    }
  }
  if (static_cast<int>(cand.size()) < count)
    throw Error("pose planning: only " + std::to_string(cand.size()) +
                " reachable points on the spheres about the pivot " + mm3(pivot) + " (" +
                std::to_string(count) + " wanted)" +
                (cand.empty() ? ": no pose can reach this pivot; move it into the workspace" : ""));
  const MatX rows = ballbar_rows(model, pivot, cand, known);
  std::vector<PlannedPose> out;
  for (int c : d_optimal(rows, 1, count)) out.push_back(cand[static_cast<std::size_t>(c)]);
  return out;
}

std::vector<PlannedPose> optimal_position_poses(const ctl::MachineModel& model, int count) {
  if (count < 4) throw Error("pose planning: at least 4 full-position poses needed, asked for " +
                             std::to_string(count));
  std::vector<PlannedPose> cand;
  const int n = 9;
  for (int a = 0; a < n; ++a)
    for (int b = 0; b < n; ++b)
      for (int c = 0; c < n; ++c) {
        // Encoder grid 5% inside the strokes, mapped through the model.
        Vec3 d;
        const int idx[3] = {a, b, c};
        for (int i = 0; i < 3; ++i) {
          const double lo = model.strokes.min[i], hi = model.strokes.max[i];
          d[i] = lo + (hi - lo) * (0.05 + 0.9 * idx[i] / (n - 1.0));
        }
        Vec3 p;
        if (!kin::forward(model.kinematics, d, {}, p)) continue;
        PlannedPose pp;
        if (plan(model, p, 0.0, pp, nullptr)) cand.push_back(pp);
      }
  if (static_cast<int>(cand.size()) < count)
    throw Error("pose planning: only " + std::to_string(cand.size()) + " reachable grid points");
  const MatX rows = position_rows(model, cand);
  std::vector<PlannedPose> out;
  for (int c : d_optimal(rows, 3, count)) out.push_back(cand[static_cast<std::size_t>(c)]);
  return out;
}

double ballbar_observability(const ctl::MachineModel& model, const Vec3& pivot,
                             const std::vector<PlannedPose>& poses, bool known) {
  return observability_index(ballbar_rows(model, pivot, poses, known));
}

double position_observability(const ctl::MachineModel& model, const std::vector<PlannedPose>& poses) {
  return observability_index(position_rows(model, poses));
}

std::string poses_csv(const std::vector<PlannedPose>& poses,
                      const std::vector<std::pair<std::string, std::string>>& metadata,
                      bool with_radius) {
  std::ostringstream os;
  os.precision(17);
  for (const auto& [k, v] : metadata) os << "# " << k << " = " << v << '\n';
  os << "px,py,pz,d1,d2,d3" << (with_radius ? ",radius" : "") << '\n';
  for (const PlannedPose& p : poses) {
    os << p.p.x() << ',' << p.p.y() << ',' << p.p.z() << ',' << p.d.x() << ',' << p.d.y() << ','
       << p.d.z();
    if (with_radius) os << ',' << p.radius;
    os << '\n';
  }
  return os.str();
}

std::vector<Vec3> parse_poses_csv(const std::string& text, const std::string& name) {
  std::istringstream is(text);
  std::string line;
  int ln = 0;
  std::vector<std::string> header;
  int col[3] = {-1, -1, -1};
  std::vector<Vec3> out;
  auto split = [](const std::string& l) {
    std::vector<std::string> f;
    std::string cur;
    std::istringstream ls(l);
    while (std::getline(ls, cur, ',')) {
      const auto b = cur.find_first_not_of(" \t\r");
      const auto e = cur.find_last_not_of(" \t\r");
      f.push_back(b == std::string::npos ? "" : cur.substr(b, e - b + 1));
    }
    return f;
  };
  while (std::getline(is, line)) {
    ++ln;
    if (line.empty() || line[0] == '#' || line.find_first_not_of(" \t\r") == std::string::npos) continue;
    const auto f = split(line);
    if (header.empty()) {
      header = f;
      const char* want[3] = {"px", "py", "pz"};
      for (int k = 0; k < 3; ++k) {
        for (std::size_t c = 0; c < f.size(); ++c)
          if (f[c] == want[k]) col[k] = static_cast<int>(c);
        if (col[k] < 0)
          throw Error(name + ":" + std::to_string(ln) + ": missing required column '" + want[k] + "'");
      }
      continue;
    }
    Vec3 p;
    for (int k = 0; k < 3; ++k) {
      const auto c = static_cast<std::size_t>(col[k]);
      if (c >= f.size())
        throw Error(name + ":" + std::to_string(ln) + ": column '" + header[c] + "' is missing on this row");
      char* end = nullptr;
      p[k] = std::strtod(f[c].c_str(), &end);
      if (f[c].empty() || *end != '\0' || !std::isfinite(p[k]))
        throw Error(name + ":" + std::to_string(ln) + ": column '" + header[c] + "': '" + f[c] +
                    "' is not a finite number");
    }
    out.push_back(p);
  }
  if (header.empty()) throw Error(name + ": no header line (px,py,pz,...)");
  if (out.empty()) throw Error(name + ": no poses");
  return out;
}

std::vector<Vec3> read_poses_csv(const std::string& path) {
  std::ifstream f(path);
  if (!f) throw Error(path + ": cannot open");
  std::ostringstream ss;
  ss << f.rdbuf();
  return parse_poses_csv(ss.str(), path);
}

}  // namespace cpm::cal

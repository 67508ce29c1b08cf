// actuator_scale at the model as given (part of stage 4, selection).
//
// effects.md lists actuator_scale "so that a nominal-only model can name it":
// the calibrated base absorbs a scale (it is c_i), so the scales are judged
// where the model is. H0 = the model as given with only the set-up refitted
// (ball-bar: the pivot; an uncalibrated bar's offset goes with the mean),
// Hs = H0 + the three actuator scales, Hb = the full calibration (the base's
// own nonlinear fit). Scale i is named when Hb adds to Hs nothing significant,
// or less than 1 % of what it explains in all, and scale i is significant
// within Hs. H0 and Hs are fitted by Gauss-Newton on the residual of the given
// model with the scales as its own effects (their definition in effects.md):
// a pivot a millimetre off is too far for one linearisation.
#include <algorithm>
#include <cmath>

#include "kinematic_internal.hpp"

namespace cpm::ident::kinematic_detail {
namespace {

int column_rank(const Eigen::MatrixXd& A) {
  if (A.cols() == 0) return 0;
  Eigen::MatrixXd As = A;
  for (Eigen::Index j = 0; j < As.cols(); ++j) {
    const double n = As.col(j).norm();
    if (n > 0.0) As.col(j) /= n;
  }
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(As);
  qr.setThreshold(1e-7);
  return static_cast<int>(qr.rank());
}

struct GivenFit {
  Eigen::VectorXd y;        // measurement - model at the fitted point (m)
  Eigen::MatrixXd columns;  // d residual / d (set-up, free scales) there
  Vec3 s = Vec3::Zero(), dq = Vec3::Zero();
};

GivenFit fit_at_the_given_model(const KinematicProblem& P, const std::array<bool, 3>& free_scale,
                                const Eigen::VectorXd& w) {
  const int N = P.rows(), ns = P.kind == "ballbar" ? 3 : 0;
  std::vector<int> axes;
  for (int i = 0; i < 3; ++i)
    if (free_scale[static_cast<std::size_t>(i)]) axes.push_back(i);
  GivenFit g;
  auto residual_at = [&](const Vec3& s, const Vec3& dq) {
    kin::KinematicModel m = P.given;
    for (int i = 0; i < 3; ++i) m.effects[i].actuator_scale += s[i];
    Eigen::VectorXd r = frame_residual(P, m, dq, 0.0);
    if (P.kind == "ballbar" && P.with_dl && r.size()) r.array() -= r.mean();
    return r;
  };
  const double h = 1e-6;
  for (int it = 0; it < 5; ++it) {
    const Eigen::VectorXd r = residual_at(g.s, g.dq);
    Eigen::MatrixXd X(N, ns + static_cast<int>(axes.size()));
    for (int k = 0; k < ns; ++k) {
      const Vec3 e = h * Vec3::Unit(k);
      X.col(k) = (residual_at(g.s, g.dq + e) - residual_at(g.s, g.dq - e)) / (2.0 * h);
    }
    for (std::size_t a = 0; a < axes.size(); ++a) {
      const Vec3 e = h * Vec3::Unit(axes[a]);
      X.col(ns + static_cast<int>(a)) = (residual_at(g.s + e, g.dq) - residual_at(g.s - e, g.dq)) / (2.0 * h);
    }
    g.y = -r;
    g.columns = X;
    if (X.cols() == 0) break;
    const Eigen::MatrixXd Xw = w.asDiagonal() * X;
    const Eigen::VectorXd step = Xw.colPivHouseholderQr().solve(w.cwiseProduct(g.y));
    for (int k = 0; k < ns; ++k) g.dq[k] += step(k);
    for (std::size_t a = 0; a < axes.size(); ++a) g.s[axes[a]] += step(ns + static_cast<int>(a));
    if (step.cwiseAbs().maxCoeff() < 1e-12) break;
  }
  g.y = -residual_at(g.s, g.dq);
  return g;
}

// Statistics on one engine: rows, weights, series and resolution of these
// data (L), the residual y, no base.
Engine engine_without_base(const LinearProblem& L, const Eigen::VectorXd& y) {
  LinearProblem Lg = L;
  Lg.y = y;
  Lg.B = Eigen::MatrixXd(y.size(), 0);
  Lg.base_names.clear();
  Lg.base_units.clear();
  Lg.base_values.clear();
  Lg.nuisance.clear();
  return Engine(std::move(Lg));
}

// The scales fitted at the model as given (Hs) against the set-up alone (H0)
// and the full calibration (Hb).
struct ScaleTest {
  std::array<bool, 3> moving{};  // axes that move (a circle in XY leaves z's scale unseen)
  int n_moving = 0;
  GivenFit all;                  // Hs
  double rss_s = 0.0, n_eff = 0.0;
  int k_s = 0;                   // rank of Hs' columns
  NestedTest full;               // Hb against Hs
  double share_left = 1.0;       // of what Hb explains beyond H0, the share Hs leaves
  bool scales_suffice = false;
  Eigen::MatrixXd cov;           // of the moving axes' scales, when they suffice
};

// Covariance of the scales at the fitted point (set-up jointly).
Eigen::MatrixXd scale_covariance(const LinearProblem& L, const GivenFit& all, int ns, int n_moving, int k_s) {
  LinearProblem Lc = L;
  Lc.y = all.y;
  Lc.B = all.columns.leftCols(ns);
  Lc.base_names.assign(static_cast<std::size_t>(ns), "pivot");
  Lc.base_units.assign(static_cast<std::size_t>(ns), "m");
  Lc.base_values.assign(static_cast<std::size_t>(ns), 0.0);
  Lc.nuisance.assign(static_cast<std::size_t>(ns), 0);
  const Engine Ec(std::move(Lc));
  const Eigen::MatrixXd S = all.columns.rightCols(n_moving);
  return Ec.covariance(S, Ec.fit(S), k_s, true);
}

void test_scales(const KinematicProblem& P, const DiagnoseOptions& opt, const LinearProblem& L, const Engine& EA,
                 ScaleTest& T) {
  const Eigen::VectorXd& w = L.w;
  const GivenFit setup_only = fit_at_the_given_model(P, {false, false, false}, w);
  const double rss_0 = engine_without_base(L, setup_only.y).rss_given();
  T.rss_s = EA.rss_given();
  const double rss_b = w.cwiseProduct(P.residual).squaredNorm();  // the full calibration
  T.k_s = column_rank(w.asDiagonal() * T.all.columns);
  const int k_b = column_rank(w.asDiagonal() * P.base);
  T.n_eff = EA.fit(Eigen::MatrixXd(P.rows(), 0), false).n_eff;
  T.full = EA.nested(T.rss_s, std::min(T.rss_s, rss_b), std::max(1, k_b - T.k_s), k_b, T.n_eff);
  T.share_left = rss_0 > rss_b ? std::max(0.0, T.rss_s - rss_b) / (rss_0 - rss_b) : 1.0;
  const int ns = static_cast<int>(T.all.columns.cols()) - T.n_moving;  // set-up columns
  const int k_setup = column_rank(w.asDiagonal() * T.all.columns.leftCols(ns));
  T.scales_suffice = T.k_s == k_setup + T.n_moving && k_b > T.k_s && (T.full.p_value >= opt.alpha || T.share_left < 0.01);
  if (T.scales_suffice) T.cov = scale_covariance(L, T.all, ns, T.n_moving, T.k_s);
}

// Name scale i (the candidate's axis): significant within Hs.
void name_scale(const KinematicProblem& P, const LinearProblem& L, const Engine& EA, const ScaleTest& T,
                CandidateResult& c) {
  const int i = c.axis;
  std::array<bool, 3> others = T.moving;
  others[static_cast<std::size_t>(i)] = false;
  const GivenFit without = fit_at_the_given_model(P, others, L.w);
  int ci = 0;  // index of scale i among the free ones
  for (int j = 0; j < i; ++j) ci += T.moving[static_cast<std::size_t>(j)] ? 1 : 0;
  const NestedTest t = EA.nested(engine_without_base(L, without.y).rss_given(), T.rss_s, 1, T.k_s, T.n_eff);
  c.identifiable = true;
  c.refits_base = false;
  c.columns = Eigen::MatrixXd(P.rows(), 0);
  c.params.assign(1, {"s", "1", T.all.s[i], std::sqrt(std::max(0.0, T.cov(ci, ci))), false});
  c.rss = T.rss_s;
  c.n_eff = T.n_eff;
  c.residual_after = T.all.y;
  c.fitted = -P.residual_given - T.all.y;
  c.rms_after = Engine::rms(T.all.y);
  const double given_ms = std::pow(Engine::rms(P.residual_given), 2);
  c.explained = given_ms > 0.0 ? std::clamp(1.0 - c.rms_after * c.rms_after / given_ms, 0.0, 1.0) : 0.0;
  c.explained_beyond_base = 0.0;
  c.n_params = 1;
  c.k_total = T.k_s;
  c.f_stat = t.f_stat;
  c.p_value = t.p_value;
  c.delta_bic = t.delta_bic;
  c.note = "judged at the model as given: its three actuator scales (and the set-up) explain " +
           fmt(100.0 * (1.0 - T.share_left), 4) + " % of what a full calibration explains (the rest: p = " +
           fmt(T.full.p_value, 2) + "); a calibrated model holds it in c" + std::to_string(i + 1);
}

}  // namespace

void judge_scales_at_the_given_model(const KinematicProblem& P, const DiagnoseOptions& opt,
                                     std::vector<CandidateResult>& candidates) {
  const LinearProblem L = kinematic_linear_problem(P);
  // Only the scales of axes that move (a circle in XY leaves z's scale unseen).
  const KinematicSpan sp = span_of(P);
  ScaleTest T;
  for (int i = 0; i < 3; ++i) T.moving[static_cast<std::size_t>(i)] = sp.hi[i] - sp.lo[i] >= 1e-3;
  T.n_moving = static_cast<int>(std::count(T.moving.begin(), T.moving.end(), true));
  if (T.n_moving == 0) return;
  T.all = fit_at_the_given_model(P, T.moving, L.w);
  const Engine EA = engine_without_base(L, T.all.y);
  test_scales(P, opt, L, EA, T);
  for (auto& c : candidates) {
    if (c.effect != "actuator_scale" || c.axis < 0 || c.axis > 2) continue;
    if (!T.moving[static_cast<std::size_t>(c.axis)]) continue;
    if (!T.scales_suffice) {
      c.note += "; at the model as given the scales alone leave " + fmt(100.0 * T.share_left, 3) +
                " % of what a full calibration explains (p = " + fmt(T.full.p_value, 2) + ")";
      continue;
    }
    name_scale(P, L, EA, T, c);
  }
}

}  // namespace cpm::ident::kinematic_detail

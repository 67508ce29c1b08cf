// SPDX-License-Identifier: Apache-2.0
// actuator_scale at the model as given (part of stage 5, the selection:
// kinematic_select.cpp).
//
// docs/effects.md has actuator_scale so that a nominal-only model can name it:
// the calibrated base absorbs a scale (it is c_i), so the forward selection,
// which starts from the calibrated base, cannot see one; the scales are
// judged where the model is, jointly with the effects the selection chose
// (their columns Xe, linear, at the calibrated point). H0 = the model as given
// with only the set-up refitted (ball-bar: the pivot; an uncalibrated bar's
// offset goes with the mean) and the chosen effects, Hs = H0 + the three
// actuator scales, Hb = the calibrated base with the chosen effects (the
// model the selection reached). Scale i is named when Hb adds to Hs nothing
// significant, or less than 1 % of what it explains in all, and scale i is
// significant within Hs by the selection's statistic. Judged without the
// chosen effects, the scales took up part of them (beside a backlash on axis
// 3, an unplanted scale on axis 3 was significant), and the full calibration
// explained the other effect's share the scales could not, so a planted scale
// beside another effect was never named. H0 and Hs are fitted by Gauss-Newton
// on the residual of the given model with the scales as its own effects
// (their definition in docs/effects.md): a pivot a millimetre off is too far for
// one linearisation.
#include <algorithm>
#include <cmath>

#include "kinematic_internal.hpp"
#include "selection.hpp"

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
  Eigen::MatrixXd columns;  // d residual / d (set-up, chosen effects, free scales) there
  Vec3 s = Vec3::Zero(), dq = Vec3::Zero();
  Eigen::VectorXd th;       // the chosen effects' linear parameters
};

// The model as given with the set-up dq (ball-bar: the pivot), the scales s
// on top of its own, and the chosen effects' columns Xe times th: the
// residual (model - measurement, m) and its columns.
struct GivenModel {
  const KinematicProblem& P;
  std::vector<int> axes;  // the free scales
  Eigen::MatrixXd Xe;     // with an uncalibrated bar, their mean removed as the residual's is
  int ns = 0;             // set-up unknowns

  GivenModel(const KinematicProblem& p, const std::array<bool, 3>& free_scale, const Eigen::MatrixXd& X)
      : P(p), Xe(X), ns(p.kind == "ballbar" ? 3 : 0) {
    for (int i = 0; i < 3; ++i)
      if (free_scale[static_cast<std::size_t>(i)]) axes.push_back(i);
    if (uncalibrated_bar())
      for (Eigen::Index j = 0; j < Xe.cols(); ++j) Xe.col(j).array() -= Xe.col(j).mean();
  }
  [[nodiscard]] bool uncalibrated_bar() const { return P.kind == "ballbar" && P.with_dl; }
  [[nodiscard]] int unknowns() const { return ns + static_cast<int>(Xe.cols() + axes.size()); }
  [[nodiscard]] Eigen::VectorXd residual(const GivenFit& g) const {
    kin::KinematicModel m = P.given;
    for (int i = 0; i < 3; ++i) m.effects[i].actuator_scale += g.s[i];
    Eigen::VectorXd r = frame_residual(P, m, g.dq, 0.0);
    if (uncalibrated_bar() && r.size()) r.array() -= r.mean();
    if (Xe.cols()) r += Xe * g.th;
    return r;
  }
  // Columns [set-up | Xe | free scales]: central differences, Xe as it is.
  [[nodiscard]] Eigen::MatrixXd columns(const GivenFit& g) const {
    const double h = 1e-6;
    Eigen::MatrixXd X(P.rows(), unknowns());
    auto diff = [&](GivenFit up, GivenFit down) { return Eigen::VectorXd((residual(up) - residual(down)) / (2.0 * h)); };
    for (int k = 0; k < ns; ++k) {
      GivenFit up = g, down = g;
      up.dq[k] += h;
      down.dq[k] -= h;
      X.col(k) = diff(up, down);
    }
    if (Xe.cols()) X.middleCols(ns, Xe.cols()) = Xe;
    for (std::size_t a = 0; a < axes.size(); ++a) {
      GivenFit up = g, down = g;
      up.s[axes[a]] += h;
      down.s[axes[a]] -= h;
      X.col(ns + static_cast<int>(Xe.cols() + a)) = diff(up, down);
    }
    return X;
  }
  void step(GivenFit& g, const Eigen::VectorXd& d) const {
    for (int k = 0; k < ns; ++k) g.dq[k] += d(k);
    g.th += d.segment(ns, Xe.cols());
    for (std::size_t a = 0; a < axes.size(); ++a) g.s[axes[a]] += d(ns + static_cast<int>(Xe.cols() + a));
  }
};

// Gauss-Newton from the model as given (five steps at most).
GivenFit fit_at_the_given_model(const KinematicProblem& P, const std::array<bool, 3>& free_scale,
                                const Eigen::VectorXd& w, const Eigen::MatrixXd& Xe) {
  const GivenModel M(P, free_scale, Xe);
  GivenFit g;
  g.th = Eigen::VectorXd::Zero(Xe.cols());
  for (int it = 0; it < 5; ++it) {
    g.y = -M.residual(g);
    g.columns = M.columns(g);
    if (g.columns.cols() == 0) break;
    const Eigen::MatrixXd Xw = w.asDiagonal() * g.columns;
    const Eigen::VectorXd d = Xw.colPivHouseholderQr().solve(w.cwiseProduct(g.y));
    M.step(g, d);
    if (d.cwiseAbs().maxCoeff() < 1e-12) break;
  }
  g.y = -M.residual(g);
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
// and the full calibration (Hb), each with the chosen effects' columns Xe.
struct ScaleTest {
  ScaleTest(const KinematicProblem& p, const LinearProblem& l, const Eigen::MatrixXd& xe) : P(p), L(l), Xe(xe) {}
  const KinematicProblem& P;
  const LinearProblem& L;
  const Eigen::MatrixXd& Xe;   // the chosen effects' columns at the calibrated point
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

// Covariance of the scales at the fitted point (set-up and chosen effects jointly).
Eigen::MatrixXd scale_covariance(const LinearProblem& L, const GivenFit& all, int ns, int n_moving, int k_s) {
  LinearProblem Lc = L;
  Lc.y = all.y;
  Lc.B = all.columns.leftCols(ns);
  Lc.base_names.assign(static_cast<std::size_t>(ns), "set-up or effect");
  Lc.base_units.assign(static_cast<std::size_t>(ns), "m");
  Lc.base_values.assign(static_cast<std::size_t>(ns), 0.0);
  Lc.nuisance.assign(static_cast<std::size_t>(ns), 0);
  const Engine Ec(std::move(Lc));
  const Eigen::MatrixXd S = all.columns.rightCols(n_moving);
  return Ec.covariance(S, Ec.fit(S), k_s, true);
}

// Hb (RSS rss_b: the calibrated base with the chosen effects) against Hs.
void test_scales(const DiagnoseOptions& opt, const Engine& EA, double rss_b, ScaleTest& T) {
  const Eigen::VectorXd& w = T.L.w;
  const GivenFit setup_only = fit_at_the_given_model(T.P, {false, false, false}, w, T.Xe);
  const double rss_0 = engine_without_base(T.L, setup_only.y).rss_given();
  T.rss_s = EA.rss_given();
  T.k_s = column_rank(w.asDiagonal() * T.all.columns);
  const int k_b = column_rank(w.asDiagonal() * detail::hstack(T.P.base, T.Xe));
  T.n_eff = EA.fit(Eigen::MatrixXd(T.P.rows(), 0), false).n_eff;
  T.full = EA.nested(T.rss_s, std::min(T.rss_s, rss_b), std::max(1, k_b - T.k_s), k_b, T.n_eff);
  T.share_left = rss_0 > rss_b ? std::max(0.0, T.rss_s - rss_b) / (rss_0 - rss_b) : 1.0;
  const int ns = static_cast<int>(T.all.columns.cols()) - T.n_moving;  // set-up and effect columns
  const int k_setup = column_rank(w.asDiagonal() * T.all.columns.leftCols(ns));
  T.scales_suffice = T.k_s == k_setup + T.n_moving && k_b > T.k_s && (T.full.p_value >= opt.alpha || T.share_left < 0.01);
  if (T.scales_suffice) T.cov = scale_covariance(T.L, T.all, ns, T.n_moving, T.k_s);
}

// Scale i (the candidate's axis) within Hs, by the selection's statistic
// over `family` candidates; the candidate filled with its fit.
detail::StepFit judge_scale(const DiagnoseOptions& opt, const Engine& EA, const ScaleTest& T, double family,
                            CandidateResult& c) {
  const int i = c.axis;
  std::array<bool, 3> others = T.moving;
  others[static_cast<std::size_t>(i)] = false;
  const GivenFit without = fit_at_the_given_model(T.P, others, T.L.w, T.Xe);
  int ci = 0;  // index of scale i among the free ones
  for (int j = 0; j < i; ++j) ci += T.moving[static_cast<std::size_t>(j)] ? 1 : 0;
  c.identifiable = true;
  c.refits_base = false;
  c.columns = Eigen::MatrixXd(T.P.rows(), 0);
  c.params.assign(1, {"s", "1", T.all.s[i], std::sqrt(std::max(0.0, T.cov(ci, ci))), false});
  c.rss = T.rss_s;
  c.n_eff = T.n_eff;
  c.residual_after = T.all.y;
  c.fitted = -T.P.residual_given - T.all.y;
  c.rms_after = Engine::rms(T.all.y);
  const double given_ms = std::pow(Engine::rms(T.P.residual_given), 2);
  c.explained = given_ms > 0.0 ? std::clamp(1.0 - c.rms_after * c.rms_after / given_ms, 0.0, 1.0) : 0.0;
  c.explained_beyond_base = 0.0;
  c.n_params = 1;
  c.k_total = T.k_s;
  c.note = "judged at the model as given" + std::string(T.Xe.cols() ? " with the effects chosen" : "") +
           ": its three actuator scales (and the set-up) explain " + fmt(100.0 * (1.0 - T.share_left), 4) +
           " % of what a full calibration explains (the rest: p = " + fmt(T.full.p_value, 2) +
           "); a calibrated model holds it in c" + std::to_string(i + 1);
  const double rss_without = engine_without_base(T.L, without.y).rss_given();
  return detail::step_statistics(EA, opt, rss_without, T.rss_s, 1, T.k_s, T.n_eff, 1.0, family);
}

// Why the scales cannot be judged beside the effects chosen, or "": one of
// them has a searched parameter the data do not determine (a cyclic error on
// axis 3 seen at six heights: with one bar radius a sine of almost any
// wavelength fits there alike, each with its own share of a linear term, so
// the scales at the model as given follow the wavelength chosen: all three
// were named beside a cyclic error and a scale on one axis).
std::string not_judged_beside(const Diagnosis& D, const detail::Selection& sel) {
  for (int j : sel.state.chosen) {
    const CandidateResult& c = D.candidates[static_cast<std::size_t>(j)];
    if (!c.searched_determined)
      return "not judged at the model as given beside " + c.label() +
             ", whose wavelength these data do not determine: each wavelength that fits alike asks for other scales";
  }
  return "";
}

}  // namespace

void select_scales_at_the_given_model(const KinematicProblem& P, const Engine& E, const DiagnoseOptions& opt,
                                      Diagnosis& D, detail::Selection& sel) {
  if (std::none_of(D.candidates.begin(), D.candidates.end(),
                   [](const CandidateResult& c) { return c.effect == "actuator_scale"; }))
    return;
  if (const std::string why = not_judged_beside(D, sel); !why.empty()) {
    for (auto& c : D.candidates)
      if (c.effect == "actuator_scale") c.note += "; " + why;
    return;
  }
  ScaleTest T(P, E.problem(), sel.state.XS);
  // Only the scales of axes that move (a circle in XY leaves z's scale unseen).
  const KinematicSpan sp = span_of(P);
  for (int i = 0; i < 3; ++i) T.moving[static_cast<std::size_t>(i)] = sp.hi[i] - sp.lo[i] >= 1e-3;
  T.n_moving = static_cast<int>(std::count(T.moving.begin(), T.moving.end(), true));
  if (T.n_moving == 0) return;
  T.all = fit_at_the_given_model(P, T.moving, T.L.w, T.Xe);
  const Engine EA = engine_without_base(T.L, T.all.y);
  test_scales(opt, EA, sel.state.rss, T);
  for (std::size_t j = 0; j < D.candidates.size(); ++j) {
    CandidateResult& c = D.candidates[j];
    if (c.effect != "actuator_scale" || c.axis < 0 || c.axis > 2) continue;
    if (!T.moving[static_cast<std::size_t>(c.axis)]) continue;
    if (!T.scales_suffice) {
      c.note += "; at the model as given the scales alone leave " + fmt(100.0 * T.share_left, 3) +
                " % of what a full calibration explains (p = " + fmt(T.full.p_value, 2) + ")";
      continue;
    }
    const detail::StepFit s = judge_scale(opt, EA, T, detail::remaining_family(D, sel.state), c);
    (s.ok ? sel.at_choice : sel.last)[j] = s;
    if (s.ok) sel.state.take_held_by_base(static_cast<int>(j));
  }
}

}  // namespace cpm::ident::kinematic_detail

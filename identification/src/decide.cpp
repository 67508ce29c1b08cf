#include <algorithm>
#include <cmath>
#include <sstream>

#include "internal.hpp"

namespace cpm::ident::detail {
namespace {
std::string fmt(double v, int prec = 3) {
  std::ostringstream os;
  os.precision(prec);
  os << v;
  return os.str();
}
}  // namespace

std::string amount(double v, const std::string& units) {
  if (units == "m") return fmt(v * 1e6, 3) + " µm";
  return fmt(v, 3) + " " + units;
}

std::string human_value(const ParamEstimate& p) {
  // Scale to the unit a person reads this size in; the standard error in the same unit.
  double k = 1.0;
  std::string u = p.unit;
  const double a = std::fabs(p.value);
  if (p.unit == "m") { k = a < 1e-3 ? 1e6 : 1e3; u = a < 1e-3 ? "µm" : "mm"; }
  else if (p.unit == "s") { k = 1e3; u = "ms"; }
  else if (p.unit == "rad" && p.name != "phi") { k = a < 1e-3 ? 1e6 : 1e3; u = a < 1e-3 ? "µrad" : "mrad"; }
  else if (p.unit == "1") { k = a < 1e-3 ? 1e6 : 1e2; u = a < 1e-3 ? "ppm" : "%"; }
  else if (p.unit == "N") { k = a < 1.0 ? 1e3 : 1.0; u = a < 1.0 ? "mN" : "N"; }
  std::string s = fmt(p.value * k, 4);
  if (p.std_error >= 0.0) s += " ± " + fmt(p.std_error * k, 2);
  return s + " " + u;
}

void rank_and_decide(Diagnosis& D, const Engine& E, const DiagnoseOptions& opt, const SeparateAdvice& advice) {
  const int rank = E.base_rank();
  // Look-elsewhere: the family of candidates and the search trials within each.
  const double family = static_cast<double>(D.candidates.size());
  double ne_ref = 0.0;
  for (const auto& c : D.candidates) ne_ref = std::max(ne_ref, c.n_eff);
  for (auto& c : D.candidates) {
    c.p_adjusted = std::min(1.0, c.p_value * c.trials * family);
    c.significant = c.identifiable && c.p_adjusted < opt.alpha && c.delta_bic < 0.0 &&
                    !(c.params.size() && c.params[0].at_bound && c.params[0].value == 0.0);
    // BIC against the model as given: the parameters beyond it (the nuisance is
    // fitted in every model alike and does not count).
    const int k_total = c.k_total > 0 ? c.k_total : rank + c.n_params;
    const int k_added = std::max(0, k_total - E.nuisance_rank());
    const double fr = E.floor_rss();
    c.score = c.rss + fr > 0.0 && E.rss_given() + fr > 0.0
                  ? ne_ref * std::log((c.rss + fr) / (E.rss_given() + fr)) + k_added * std::log(std::max(2.0, ne_ref))
                  : 0.0;
  }
  std::stable_sort(D.candidates.begin(), D.candidates.end(), [](const auto& a, const auto& b) {
    if (a.significant != b.significant) return a.significant;
    if (a.identifiable != b.identifiable) return a.identifiable;
    return a.score < b.score;
  });

  // Confounding between candidates: how much of one's fitted signature the
  // other's columns reproduce (after the base is taken out).
  const int top = std::min<int>(static_cast<int>(D.candidates.size()), 8);
  std::vector<Eigen::MatrixXd> Xp(D.candidates.size());
  for (std::size_t j = 0; j < D.candidates.size(); ++j)
    if (D.candidates[j].identifiable && D.candidates[j].columns.cols() && D.candidates[j].refits_base)
      Xp[j] = E.project_off_base(D.candidates[j].columns);
  for (int a = 0; a < top; ++a) {
    CandidateResult& ca = D.candidates[a];
    if (Xp[a].size() == 0 || !ca.identifiable) continue;
    const Eigen::VectorXd u = E.project_off_base(ca.fitted);
    if (u.squaredNorm() <= 0.0) continue;
    for (std::size_t b = 0; b < D.candidates.size(); ++b) {
      if (static_cast<int>(b) == a || Xp[b].size() == 0) continue;
      const Eigen::VectorXd coef = Xp[b].colPivHouseholderQr().solve(u);
      const double share = std::clamp((Xp[b] * coef).squaredNorm() / u.squaredNorm(), 0.0, 1.0);
      if (share < 0.81) continue;
      const CandidateResult& cb = D.candidates[b];
      ca.confounded.push_back({cb.label(), cb.effect, cb.axis, std::sqrt(share), advice(ca, cb)});
    }
  }

  // Candidates that are base directions (payload, inertia error) are judged
  // against the model as given, where the base does not absorb the others:
  // compare there, off the nuisance only. A force-gain error on the axis that
  // carries the weight is mostly "the weight is off", what a payload is too.
  // `rival` holds, per such candidate, the others that explain the data about
  // as well there (BIC within 10): a verdict for it is then ambiguous.
  std::vector<std::vector<std::string>> rival(D.candidates.size());
  const double fr = E.floor_rss();
  for (int a = 0; a < top; ++a) {
    CandidateResult& ca = D.candidates[a];
    const bool base_direction = ca.effect == "payload_mass" || ca.effect == "inertia_error";
    if (!base_direction || !ca.identifiable || ca.fitted.size() != E.rows()) continue;
    const Eigen::VectorXd u = E.project_off_nuisance(ca.fitted);
    if (u.squaredNorm() <= 0.0) continue;
    for (std::size_t b = 0; b < D.candidates.size(); ++b) {
      const CandidateResult& cb = D.candidates[b];
      if (static_cast<int>(b) == a || cb.columns.cols() == 0 || !cb.refits_base) continue;
      const Eigen::MatrixXd Xb = E.project_off_nuisance(cb.columns);
      const Eigen::VectorXd coef = Xb.colPivHouseholderQr().solve(u);
      const double share = std::clamp((Xb * coef).squaredNorm() / u.squaredNorm(), 0.0, 1.0);
      if (share < 0.81) continue;
      bool dup = false;
      for (const auto& o : ca.confounded) dup |= o.with == cb.label();
      if (!dup) ca.confounded.push_back({cb.label(), cb.effect, cb.axis, std::sqrt(share), advice(ca, cb)});
      const double rss_b = E.rss(cb.columns, false);
      const double score_b = ne_ref * std::log((rss_b + fr) / (E.rss_given() + fr)) +
                             cb.n_params * std::log(std::max(2.0, ne_ref));
      if (score_b - ca.score < 10.0) rival[static_cast<std::size_t>(a)].push_back(cb.label());
    }
  }

  // A candidate the base absorbs completely (e.g. a constant force when the
  // axis moves one way only) still looks like others on its axis: report the
  // pair from the raw columns, so the verdict does not hide it.
  for (int a = 0; a < top; ++a) {
    CandidateResult& ca = D.candidates[a];
    if (ca.columns.cols() == 0 || ca.axis < 0) continue;
    const Eigen::VectorXd ua = E.problem().w.cwiseProduct(ca.columns.col(0));
    for (std::size_t b = 0; b < D.candidates.size(); ++b) {
      const CandidateResult& cb = D.candidates[b];
      if (static_cast<int>(b) == a || cb.identifiable || cb.columns.cols() == 0 || cb.axis != ca.axis) continue;
      const Eigen::VectorXd ub = E.problem().w.cwiseProduct(cb.columns.col(0));
      const double den = ua.norm() * ub.norm();
      const double cosab = den > 0.0 ? std::fabs(ua.dot(ub)) / den : 0.0;
      if (cosab < 0.85) continue;
      bool dup = false;
      for (const auto& o : ca.confounded) dup |= o.with == cb.label();
      if (!dup)
        ca.confounded.push_back({cb.label(), cb.effect, cb.axis, cosab,
                                 advice(ca, cb) + " (" + cb.label() + " is absorbed by the base in these data)"});
    }
  }

  // Verdict and forward selection: motion logs choose by one statistic from
  // the model as given (select_motion_effects, select.cpp); the kinematic kinds as below.
  if (D.kind == "motion") return;
  if (!D.candidates.empty() && D.candidates[0].significant) {
    D.verdict = 0;
    const CandidateResult& v = D.candidates[0];
    std::vector<std::string> alts;
    for (const auto& cf : v.confounded) {
      if (cf.effect.empty() || cf.correlation < 0.85) continue;
      const auto& riv = rival[0];
      const bool close_given = std::find(riv.begin(), riv.end(), cf.with) != riv.end();
      for (const auto& o : D.candidates)
        if (o.label() == cf.with && ((o.significant && o.score - v.score < 10.0) || !o.identifiable || close_given)) {
          D.ambiguous = true;
          alts.push_back(cf.with + " (" + cf.separate_by + ")");
        }
    }
    std::ostringstream os;
    os << "missing: " << v.label() << " — ";
    for (std::size_t j = 0; j < v.params.size(); ++j)
      os << (j ? ", " : "") << v.params[j].name << " = " << fmt(v.params[j].value, 4) << " "
         << v.params[j].unit;
    os << "; it brings the residual from " << amount(D.baseline_rms, D.units) << " to "
       << amount(v.rms_after, D.units) << " RMS (noise floor about " << amount(D.noise_floor, D.units) << ")";
    if (D.ambiguous) {
      os << ". These data cannot tell it apart from ";
      for (std::size_t j = 0; j < alts.size(); ++j) os << (j ? "; " : "") << alts[j];
    }
    D.verdict_text = os.str();
    // Forward selection of further effects on top of the verdict.
    Eigen::MatrixXd acc = v.refits_base ? v.columns : Eigen::MatrixXd(E.rows(), 0);
    JointFit cur = E.fit(acc);
    std::vector<bool> used(D.candidates.size(), false);
    used[0] = true;
    for (int step = 0; step < opt.max_forward_steps; ++step) {
      int best = -1;
      double best_bic = 0.0;
      JointFit best_fit;
      for (std::size_t j = 0; j < D.candidates.size(); ++j) {
        const CandidateResult& c = D.candidates[j];
        if (used[j] || !c.significant || !c.refits_base || c.columns.cols() == 0) continue;
        Eigen::MatrixXd X(E.rows(), acc.cols() + c.columns.cols());
        X << acc, c.columns;
        const JointFit f = E.fit(X);
        if (!f.full_rank) continue;
        const int q = c.n_params;
        const int k_total = rank + static_cast<int>(X.cols());
        const NestedTest t = E.nested(cur.rss, f.rss, q, k_total, std::max(f.n_eff, 10.0));
        const double p = std::min(1.0, t.p_value * c.trials * family);
        const double dbic = t.delta_bic;
        if (p < opt.alpha && dbic < best_bic) {
          best = static_cast<int>(j);
          best_bic = dbic;
          best_fit = f;
        }
      }
      if (best < 0) break;
      used[best] = true;
      D.also.push_back(best);
      Eigen::MatrixXd X(E.rows(), acc.cols() + D.candidates[best].columns.cols());
      X << acc, D.candidates[best].columns;
      acc = X;
      cur = best_fit;
    }
    D.residual_final = v.refits_base || !D.also.empty() ? cur.residual : v.residual_after;
    if (!D.also.empty()) {
      D.verdict_text += ". Also significant on top of it: ";
      for (std::size_t j = 0; j < D.also.size(); ++j)
        D.verdict_text += (j ? ", " : "") + D.candidates[D.also[j]].label();
    }
  } else {
    D.verdict_text = "none: no effect of the library explains a significant part of the residual "
                     "(RMS " + amount(D.baseline_rms, D.units) + ", noise floor about " +
                     amount(D.noise_floor, D.units) + ")";
    D.residual_final = E.base_fit().residual;
  }
}

}  // namespace cpm::ident::detail

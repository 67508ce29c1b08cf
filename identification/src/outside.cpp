// SPDX-License-Identifier: Apache-2.0
// Stage "outside the library" of the motion diagnosis (internal.hpp).
//
// The structure scan (structure.hpp) looks at what the chosen effects leave.
// A strong finding there (|z| >= 8 and at least half the axis' noise) is
// something no library effect describes: it leads the verdict, and the
// selection is run again with that structure fitted as nuisance, so that a
// library effect is named only for what the structure does not explain (a
// local excess of force on one axis was otherwise named a force gain, which
// explains a little of any bump).
#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>

#include "internal.hpp"
#include "cpm/identification/structure.hpp"

namespace cpm::ident::detail {
namespace {

constexpr double kStrongZ = 8.0;

// Columns that describe a finding on its axis' rows.
Eigen::MatrixXd structure_columns(const StructureFinding& f, const MotionProblem& P) {
  if (f.kind == "smooth") return smooth_columns(P, f.axis, f.coordinate, f.lo, f.hi);
  if (f.kind == "position_friction") return friction_map_columns(P, f.axis, f.lo, f.hi);
  const int R = P.rows(), i = f.axis;
  const double tp = 2.0 * std::numbers::pi;
  const int j = f.coordinate.size() == 2 && f.coordinate[0] == 'd' ? f.coordinate[1] - '1' : -1;
  const bool two = f.kind == "periodic" || f.kind == "periodic_time";
  // A bump: its local profile, sixteen sub-bins over three times the bin the
  // scan found, each the indicator of the sample's position through the rows'
  // filter as the effect columns are (six sub-bins over twice the bin, of the
  // row's position, left enough of a Gaussian tight spot for cogging and a
  // spring to be named beside it), and a constant on the axis: the bump's
  // mean over the log, which the model as given has nowhere else to put (on z
  // a spring with its rest position at the bound and a drive gain took it).
  constexpr int kBumpBins = 16;
  constexpr double kBumpSpan = 3.0;
  const bool bump = f.kind == "bump";
  if (bump) {
    // The scan's bin holds one twentieth of the rows: where the axis dwells it
    // is narrower than the bump; the profile spans a fifth of the stroke at least.
    double mn = 1e300, mx = -1e300;
    for (int r = 0; r < R; ++r) {
      mn = std::min(mn, P.d[static_cast<std::size_t>(r)][i]);
      mx = std::max(mx, P.d[static_cast<std::size_t>(r)][i]);
    }
    const double wb = std::max({f.hi - f.lo, 0.2 * (mx - mn) / kBumpSpan, 1e-6});
    const double xb = f.location - 0.5 * kBumpSpan * wb;
    Eigen::MatrixXd B = Eigen::MatrixXd::Zero(3 * R, kBumpBins + 1);
    for (int r = 0; r < R; ++r) B(3 * r + i, kBumpBins) = 1.0;
    for (int b = 0; b < kBumpBins; ++b)
      B.col(b) = P.filter_axis(i, [&](int s, int) {
        const double u = (P.d_hat[static_cast<std::size_t>(s)][i] - xb) / (kBumpSpan * wb) * kBumpBins;
        return u >= b && u < b + 1 ? 1.0 : 0.0;
      });
    return B;
  }
  Eigen::MatrixXd X = Eigen::MatrixXd::Zero(3 * R, two ? 2 : 1);
  double tm = 0.0;
  for (int r = 0; r < R; ++r) tm += P.t[r] / R;
  for (int r = 0; r < R; ++r) {
    const int row = 3 * r + i;
    if (f.kind == "step") X(row, 0) = P.d[r][i] > f.location ? 1.0 : 0.0;
    else if (f.kind == "trend") X(row, 0) = P.t[r] - tm;
    else if (f.kind == "direction") X(row, 0) = P.v[r][i] > 0.0 ? 1.0 : (P.v[r][i] < 0.0 ? -1.0 : 0.0);
    else if (f.kind == "periodic" && j >= 0) {
      X(row, 0) = std::sin(tp * P.d[r][j] / f.location);
      X(row, 1) = std::cos(tp * P.d[r][j] / f.location);
    } else if (f.kind == "periodic_time") {
      X(row, 0) = std::sin(tp * P.t[r] / f.location);
      X(row, 1) = std::cos(tp * P.t[r] / f.location);
    }
  }
  return X;
}

}  // namespace

std::vector<StructureFinding> strong_structure(const Diagnosis& D, const MotionProblem& P, const DiagnoseOptions& opt,
                                               bool bump_beside_step) {
  std::vector<StructureFinding> out;
  if (!opt.structure_search) return out;
  for (const auto& f : find_motion_structure(P, D.residual_final, D.axis_noise, bump_beside_step))
    if (std::fabs(f.z) >= kStrongZ && f.axis >= 0 && std::fabs(f.size) >= 0.5 * D.axis_noise[f.axis])
      out.push_back(f);
  return out;
}

namespace {

// A finding's columns as nuisance beside the library: a smooth one as a table
// of its variable (piecewise linear, table_nodes), which
// follows a narrow hump the scan's degree-5 polynomial only finds: a hump of
// v1 peaking at 35 mm/s over +-275 mm/s left by the polynomial was taken by a
// -4.3 kg rotor inertia, a spring and a Stribeck friction beside it.
Eigen::MatrixXd nuisance_columns(const StructureFinding& f, const MotionProblem& P) {
  if (f.kind == "smooth") {
    Eigen::MatrixXd T = table_columns(P, f.axis, f.coordinate);
    if (T.cols() > 0) return T;
  }
  return structure_columns(f, P);
}

}  // namespace

LinearProblem with_structure(const LinearProblem& L, const std::vector<StructureFinding>& S, const MotionProblem& P) {
  LinearProblem out = L;
  for (const auto& f : S) {
    const Eigen::MatrixXd c = nuisance_columns(f, P);
    const Eigen::Index nb = out.B.cols();
    out.B.conservativeResize(Eigen::NoChange, nb + c.cols());
    out.B.rightCols(c.cols()) = c;
    for (Eigen::Index j = 0; j < c.cols(); ++j) {
      out.base_names.push_back("structure: " + f.kind + " on axis " + std::to_string(f.axis + 1));
      out.base_units.push_back("N");
      out.base_values.push_back(0.0);
      out.nuisance.push_back(1);
    }
  }
  return out;
}

namespace {

// The same structure found again: same axis and kind, at the same place (a
// bump or step within its width, a period within 10 %).
bool same_finding(const StructureFinding& a, const StructureFinding& b) {
  // A smooth force found again in a variable alike (d2 first, then v1: on a circle the same curve).
  auto listed = [](const StructureFinding& f, const std::string& v) {
    return std::find(f.also_in.begin(), f.also_in.end(), v) != f.also_in.end();
  };
  if (a.kind == "smooth" && b.kind == "smooth" && a.axis == b.axis)
    return a.coordinate == b.coordinate || listed(a, b.coordinate) || listed(b, a.coordinate);
  if (a.axis != b.axis || a.kind != b.kind || a.coordinate != b.coordinate) return false;
  const double width = std::max({a.hi - a.lo, b.hi - b.lo, 1e-3});
  if (a.kind == "bump" || a.kind == "step") return std::fabs(a.location - b.location) <= width;
  if (a.kind == "smooth") return true;  // same axis and variable
  if (a.kind == "periodic" || a.kind == "periodic_time")
    return std::fabs(a.location - b.location) <= 0.1 * std::max(std::fabs(a.location), std::fabs(b.location));
  return true;
}

// The residual of the effects chosen, fitted on E (and the base refitted
// when one of them is its refit, or when `refit_base`).
Eigen::VectorXd residual_of_chosen(const Diagnosis& D, const Engine& E, bool refit_base = false, int skip_axis = -1) {
  Eigen::MatrixXd XS(E.rows(), 0);
  bool base_in = refit_base;
  for (int j : D.found()) {
    const CandidateResult& c = D.candidates[static_cast<std::size_t>(j)];
    if (is_base_refit(c.effect)) base_in = true;
    else if (!is_alignment(c.effect) && c.columns.rows() == E.rows() && (skip_axis < 0 || c.axis != skip_axis))
      XS = hstack(XS, c.columns);
  }
  return E.fit(XS, base_in).residual;
}

// The axis whose residual, of the model as given, stands furthest above its
// floor (by the excess of its mean square), or -1 when none is above it.
int lead_axis(const Diagnosis& D) {
  int lead = -1;
  double most = 0.0;
  for (int i = 0; i < 3; ++i) {
    const double f2 = D.axis_floor[i] * D.axis_floor[i];
    const double excess = f2 > 0.0 ? (D.baseline_axis_rms[i] * D.baseline_axis_rms[i] - f2) / f2 : 0.0;
    if (excess > most) {
      most = excess;
      lead = i;
    }
  }
  return lead;
}

}  // namespace

// Strongest first, those on the lead axis (the one furthest above its floor
// under the model as given) before the others: the first stands, and each
// other one must be seen again beside those kept. Judged each against all
// the others, two findings that describe one force (on a circle a force even
// in v1 is a force of d1: a smooth curve of v2 and a step across d1) each
// explained the other away, both were dropped, and library effects
// (Stribeck, viscous, cogging, a spring) were named for an asymmetric
// friction, with the same two findings left at 14 and 10 sigma.
//
// A finding on another axis than the lead's is looked for again beside the
// lead axis' findings only, with the base refitted jointly: a large
// structure on one axis pulls the base refit and the plane tilts, which puts
// part of it on the other axes, and findings there, fitted together with the
// base, then explain part of the first (a friction map on axis 1 was
// reported on axes 2 and 3 and not on axis 1).
std::vector<StructureFinding> confirmed_outside_library(const Diagnosis& D, const Engine& E, const DiagnoseOptions& opt) {
  std::vector<StructureFinding> all = D.outside_library;
  if (all.size() < 2) return all;
  const int lead = lead_axis(D);
  std::stable_sort(all.begin(), all.end(), [&](const StructureFinding& a, const StructureFinding& b) {
    if ((a.axis == lead) != (b.axis == lead)) return a.axis == lead;
    return std::fabs(a.z) > std::fabs(b.z);
  });
  std::vector<StructureFinding> kept;
  for (std::size_t k = 0; k < all.size(); ++k) {
    const bool off_lead = lead >= 0 && all[k].axis != lead;
    if (k == 0 && !off_lead) {
      kept.push_back(all[k]);
      continue;
    }
    std::vector<StructureFinding> others;
    for (const StructureFinding& o : kept)
      if (!off_lead || o.axis == lead) others.push_back(o);
    Diagnosis probe;
    probe.axis_noise = D.axis_noise;
    LinearProblem L = with_structure(E.problem(), others, D.motion);
    // Off the lead axis: the shared fit without the lead axis' rows' pull
    // (weights a millionth: whatever describes that axis or not).
    if (off_lead)
      for (Eigen::Index r = lead; r < L.w.size(); r += 3) L.w(r) *= 1e-6;
    const Engine Ek(std::move(L));
    probe.residual_final = off_lead ? residual_of_chosen(D, Ek, true, lead) : residual_of_chosen(D, Ek);
    // Looked for as itself: a bump is not hidden behind a step the scan also
    // sees there (the bump's flank on one side is a step too: a 3x bump found
    // beside a step was otherwise dropped with it, and cogging took the axis).
    const std::vector<StructureFinding> again = strong_structure(probe, D.motion, opt, true);
    if (std::any_of(again.begin(), again.end(), [&](const StructureFinding& f) { return same_finding(f, all[k]); }))
      kept.push_back(all[k]);
  }
  return kept;
}

namespace {

// How a force of variable b is told from one of variable a (d1..a3 or t):
// vary b where a holds still.
std::string separate_variables(const std::string& a, const std::string& b) {
  if (a == "t" || b == "t") return "repeat the log: a force of time does not repeat with the motion";
  const int ja = a[1] - '1', jb = b[1] - '1';
  const std::string A = std::to_string(ja + 1), B = std::to_string(jb + 1);
  auto how = [](char kind) -> std::string {
    return kind == 'd' ? "across its stroke" : kind == 'v' ? "at several speeds" : "with several accelerations";
  };
  if (ja != jb)
    return "move axis " + B + " alone " + how(b[0]) + " while axis " + A + " holds still: a force that follows " + b +
           " then shows, one that follows " + a + " does not";
  if ((a[0] == 'd' && b[0] == 'v') || (a[0] == 'v' && b[0] == 'd'))
    return "run axis " + A + " across its stroke at several constant feeds: a force of position comes back at the "
           "same place at every feed, one of speed changes with the feed";
  return "run axis " + A + " with other accelerations at the same speeds and places";
}

// The measurement that would show the finding for what it is.
std::string settle_outside(const StructureFinding& f) {
  const std::string ax = std::to_string(f.axis + 1);
  const int j = f.coordinate.size() == 2 && f.coordinate[0] != 't' ? f.coordinate[1] - '1' : -1;
  if (f.kind == "bump" || f.kind == "step")
    return "pass " + f.coordinate + " slowly in both directions and at another feed: a force of position comes back "
           "at the same place";
  if (f.coordinate == "t") return "repeat the log: a force of time does not repeat with the motion";
  if (f.kind == "position_friction")
    return "run axis " + ax + " across its stroke at two constant feeds in both directions: a friction map opposes "
           "the motion with the same level at the same place at every feed, a force of speed changes with the feed";
  if (j >= 0 && j != f.axis)
    return "move axis " + std::to_string(j + 1) + " alone while axis " + ax + " holds still: a force that follows axis " +
           std::to_string(j + 1) + " then shows on axis " + ax + " at rest";
  if (f.coordinate[0] == 'v') return "run axis " + ax + " at several constant feeds in both directions";
  if (f.coordinate[0] == 'a') return "run axis " + ax + " with other accelerations at the same speeds";
  return "cover the stroke of axis " + ax + " at several speeds in both directions: a force of position repeats at "
         "every pass";
}

}  // namespace

std::vector<StructureFinding> structure_that_beats_library(const Diagnosis& D, const Engine& E,
                                                           const DiagnoseOptions& opt) {
  std::vector<StructureFinding> out;
  if (!opt.structure_search) return out;
  Diagnosis probe;
  probe.axis_noise = D.axis_noise;
  probe.residual_final = E.fit(Eigen::MatrixXd(E.rows(), 0), false).residual;
  std::vector<StructureFinding> early;
  // Every finding of the scan (|z| > 6 for a bump or a step, p < 1e-4 after
  // the look-elsewhere for a smooth force), not only the strong ones: the
  // comparison by BIC below, against the effects it would replace, is the test.
  for (const auto& f : find_motion_structure(D.motion, probe.residual_final, D.axis_noise, true))
    if ((f.kind == "bump" || f.kind == "step" || f.kind == "smooth" || f.kind == "position_friction") && f.axis >= 0 &&
        std::fabs(f.size) >= 0.5 * D.axis_noise[f.axis])
      early.push_back(f);
  if (early.empty()) return out;
  // The fit of the effects chosen; and without those on the finding's axis, the finding in their place.
  const std::vector<int> found = D.found();
  bool base_in = false;
  for (int j : found) base_in |= is_base_refit(D.candidates[static_cast<std::size_t>(j)].effect);
  auto columns_except = [&](int axis, int& k) {
    Eigen::MatrixXd X(E.rows(), 0);
    k = 0;
    for (int j : found) {
      const CandidateResult& c = D.candidates[static_cast<std::size_t>(j)];
      if (is_base_refit(c.effect) || is_alignment(c.effect) || c.columns.rows() != E.rows()) continue;
      if (axis >= 0 && c.axis == axis) continue;
      X = hstack(X, c.columns);
      k += std::max(static_cast<int>(c.columns.cols()), c.n_params);
    }
    return X;
  };
  int kA = 0;
  const JointFit A = E.fit(columns_except(-1, kA), base_in);
  const double n = std::max(10.0, A.n_eff), fr = E.floor_rss();
  for (const StructureFinding& f : early) {
    int kB = 0;
    // A force of a speed as the table the selection fits it with beside the
    // library (nuisance_columns): the degree-5 polynomial misses a narrow hump
    // (a hump of v3 peaking at 31 mm/s over +-190 mm/s at 3x lost to a
    // Stribeck friction with v_s 81 mm/s that left 8.6 sigma of it behind).
    const Eigen::MatrixXd S = f.kind == "smooth" && f.coordinate.size() == 2 && f.coordinate[0] == 'v'
                                  ? nuisance_columns(f, D.motion)
                                  : structure_columns(f, D.motion);
    const Eigen::MatrixXd XB = hstack(columns_except(f.axis, kB), S);
    kB += static_cast<int>(S.cols());
    const JointFit B = E.fit(XB, base_in);
    if (!B.full_rank) continue;
    if (bic_change(n, B.rss, A.rss, fr, kB - kA) < 0.0) out.push_back(f);
  }
  return out;
}

void lead_with_outside_library(Diagnosis& D) {
  if (D.outside_library.empty()) return;
  // The strongest finding leads.
  std::stable_sort(D.outside_library.begin(), D.outside_library.end(),
                   [](const StructureFinding& a, const StructureFinding& b) { return std::fabs(a.z) > std::fabs(b.z); });
  std::ostringstream os;
  os << "missing: something no library effect describes: ";
  for (std::size_t k = 0; k < D.outside_library.size(); ++k)
    os << (k ? "; " : "") << D.outside_library[k].text << " (" << std::lround(std::fabs(D.outside_library[k].z)) << " σ)";
  const StructureFinding& lead = D.outside_library.front();
  if (!lead.also_in.empty()) {
    os << ". These data cannot tell " << lead.coordinate << " from ";
    for (std::size_t k = 0; k < lead.also_in.size(); ++k)
      os << (k == 0 ? "" : k + 1 < lead.also_in.size() ? ", " : " nor from ") << lead.also_in[k];
    os << " apart";
  }
  std::vector<std::string> partial;  // named before, fitted without an unphysical value
  for (const std::string& p : D.partial)
    if (std::none_of(D.partial_unphysical.begin(), D.partial_unphysical.end(),
                     [&](const Diagnosis::UnphysicalPartial& u) { return u.label() == p; }))
      partial.push_back(p);
  if (!partial.empty()) {
    os << ". Partly explained by";
    for (std::size_t k = 0; k < partial.size(); ++k) os << (k ? "," : "") << " " << partial[k];
    os << " (named before the structure was fitted, not beside it)";
  }
  if (!D.partial_unphysical.empty()) {
    os << ". Partial, with values outside the physical range or not determined (part of this force, not missing "
          "effects):";
    for (std::size_t k = 0; k < D.partial_unphysical.size(); ++k) {
      const Diagnosis::UnphysicalPartial& u = D.partial_unphysical[k];
      os << (k ? ";" : "") << " " << u.label() << " (";
      for (std::size_t q = 0; q < u.params.size(); ++q)
        os << (q ? ", " : "") << u.params[q].name << " = " << human_value(u.params[q]);
      os << ": " << u.why << ")";
    }
  }
  os << ". To settle it: " << settle_outside(lead);
  // The measurements that tell the lead variable from the first alike ones.
  for (std::size_t k = 0; k < std::min<std::size_t>(lead.also_in.size(), 3); ++k)
    os << "; to tell " << lead.coordinate << " from " << lead.also_in[k] << ", "
       << separate_variables(lead.coordinate, lead.also_in[k]);
  if (D.verdict >= 0) os << ". Beside it, " << D.verdict_text;
  else os << ". No library effect is missing beside it";
  D.verdict_text = os.str();
}

}  // namespace cpm::ident::detail

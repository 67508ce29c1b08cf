// SPDX-License-Identifier: Apache-2.0
// cpm fit on kinematic data (kinematic.hpp): the requested effects fitted
// jointly with the base, each read through its entry of the effect table;
// the new model, and its figures on the data, held-out data or a 2-fold
// cross-validation.
#include <algorithm>
#include <cmath>

#include "kinematic_internal.hpp"

namespace cpm::ident {

using namespace kinematic_detail;

namespace {

io::CommonColumns cut_common(const io::CommonColumns& c, const std::vector<int>& keep) {
  io::CommonColumns o;
  for (int j : keep) {
    const auto u = static_cast<std::size_t>(j);
    if (u < c.t.size()) o.t.push_back(c.t[u]);
    if (u < c.dir.size()) o.dir.push_back(c.dir[u]);
    if (u < c.run.size()) o.run.push_back(c.run[u]);
  }
  return o;
}

io::FileInfo cut_info(const io::FileInfo& i, const std::vector<int>& keep) {
  io::FileInfo o = i;
  o.line_of_row.clear();
  for (int j : keep)
    if (static_cast<std::size_t>(j) < i.line_of_row.size()) o.line_of_row.push_back(i.line_of_row[static_cast<std::size_t>(j)]);
  return o;
}

// The samples `keep` of a ball-bar or position data set.
io::DataSet subset(const io::DataSet& ds, const std::vector<int>& keep) {
  if (const auto* b = std::get_if<io::BallbarData>(&ds)) {
    io::BallbarData o = *b;
    o.d.clear();
    o.length.clear();
    for (int j : keep) { o.d.push_back(b->d[static_cast<std::size_t>(j)]); o.length.push_back(b->length[static_cast<std::size_t>(j)]); }
    o.extra = cut_common(b->extra, keep);
    o.info = cut_info(b->info, keep);
    return o;
  }
  const auto& p = std::get<io::PositionData>(ds);
  io::PositionData o = p;
  o.d.clear();
  o.p.clear();
  for (int j : keep) { o.d.push_back(p.d[static_cast<std::size_t>(j)]); o.p.push_back(p.p[static_cast<std::size_t>(j)]); }
  o.extra = cut_common(p.extra, keep);
  o.info = cut_info(p.info, keep);
  return o;
}

double rms_of_model(const io::DataSet& ds, const kin::KinematicModel& m) {
  const KinematicProblem P = read_problem(ds, m);
  return Engine::rms(P.residual_of_model(m));
}

struct JointResult {
  kin::KinematicModel model, base_model;
  std::vector<CandidateResult> effects;
  JointFit fit;
  Eigen::VectorXd base_value;
  KinematicEffects added{};
  Eigen::MatrixXd cov;
};

// Each requested effect evaluated alone (its nonlinear parameters searched);
// refuses one the data cannot show or determine.
std::vector<CandidateResult> requested_effects(const KinematicProblem& P, const Engine& E,
                                               const std::vector<FitRequest>& req, const DiagnoseOptions& opt) {
  std::vector<CandidateResult> out;
  for (const auto& r : req) {
    CandidateResult c = evaluate_kinematic_candidate(P, E, r.effect, r.axis, opt);
    if (!c.identifiable || c.columns.cols() == 0)
      throw Error("cannot fit " + c.label() + " on " + P.data_file + ": " + c.note);
    out.push_back(std::move(c));
  }
  return out;
}

// The effects' columns side by side.
Eigen::MatrixXd joined_columns(const std::vector<CandidateResult>& effects, int rows) {
  int ncols = 0;
  for (const auto& c : effects) ncols += static_cast<int>(c.columns.cols());
  Eigen::MatrixXd X(rows, ncols);
  int at = 0;
  for (const auto& c : effects) { X.middleCols(at, c.columns.cols()) = c.columns; at += static_cast<int>(c.columns.cols()); }
  return X;
}

// The effects' values from the joint coefficients, through the effect table,
// into R.added and the effects' parameters.
void read_joint_values(JointResult& R) {
  int at = 0;
  for (CandidateResult& c : R.effects) {
    const auto t = *kin::kinematic_effect_from_name(c.effect);
    std::array<double, 3> v = kin::get_params(R.added[c.axis], t);
    kinematic_fitter(t)->joint_values(R.fit, at, R.cov, c, v);
    kin::set_params(R.added[c.axis], t, v);
    at += static_cast<int>(c.columns.cols());
  }
}

JointResult joint_fit(const KinematicProblem& P, const std::vector<FitRequest>& req, const DiagnoseOptions& opt) {
  const Engine E(kinematic_linear_problem(P));
  JointResult R;
  R.effects = requested_effects(P, E, req, opt);
  const Eigen::MatrixXd X = joined_columns(R.effects, E.rows());
  const int ncols = static_cast<int>(X.cols());
  const int per = std::max(1, P.per_sample);
  if (P.samples() * per < E.base_rank() + ncols + 3)
    throw Error("too few samples in " + P.data_file + " to fit " + std::to_string(ncols) + " effect parameter(s) with the " +
                std::to_string(E.base_rank()) + " base parameters (" + std::to_string(P.rows()) + " readings)");
  R.fit = E.fit(X);
  if (!R.fit.full_rank) throw Error("the requested effects cannot be told apart from each other in these data");
  R.cov = E.covariance(X, R.fit, E.base_rank() + ncols, true);
  read_joint_values(R);
  R.base_value = P.base_value + P.base_map * R.fit.base_delta;
  R.model = P.model_of(R.base_value, combine(P.given.effects, R.added));
  R.base_model = P.model_of(P.base_value, P.given.effects);
  R.model.validate();
  return R;
}

// 2-fold cross-validation on alternate samples: base only -> base + effects (m RMS).
ErrorFigures cross_validation(const io::DataSet& data, const kin::KinematicModel& model, int samples,
                              const std::vector<FitRequest>& req, const DiagnoseOptions& opt) {
  double sb = 0.0, sa = 0.0;
  for (int fold = 0; fold < 2; ++fold) {
    std::vector<int> tr, te;
    for (int j = 0; j < samples; ++j) ((j % 2 == fold) ? tr : te).push_back(j);
    const io::DataSet dtr = subset(data, tr), dte = subset(data, te);
    const KinematicProblem Pt = prepare_kinematic(dtr, model);
    const JointResult Jt = joint_fit(Pt, req, opt);
    sb += std::pow(rms_of_model(dte, Jt.base_model), 2);
    sa += std::pow(rms_of_model(dte, Jt.model), 2);
  }
  return ErrorFigures{std::sqrt(sb / 2.0), std::sqrt(sa / 2.0)};
}

}  // namespace

KinematicFit fit_kinematic(const io::DataSet& data, const kin::KinematicModel& model, const std::vector<FitRequest>& req,
                           const DiagnoseOptions& opt, const io::DataSet* holdout, bool cross_validate) {
  if (req.empty()) throw Error("fit: no effect to add");
  const std::string kind = io::kind_name(io::kind_of(data));
  for (const auto& r : req) check_effect_for_kind(r.effect, kind);
  const KinematicProblem P = prepare_kinematic(data, model);
  const JointResult J = joint_fit(P, req, opt);
  KinematicFit out;
  out.model = J.model;
  out.effects = J.effects;
  out.on_fit.before = Engine::rms(P.residual_given);
  out.base_only = Engine::rms(P.residual_of_model(J.base_model));
  out.on_fit.after = Engine::rms(P.residual_of_model(J.model));
  for (const auto& c : out.effects)
    for (const auto& p : c.params)
      out.fitted.push_back({"kinematics.limb" + std::to_string(c.axis + 1) + ".effects." + c.effect + "." + p.name, p.unit,
                            0.0, p.value, p.std_error});
  out.notes.push_back("the planes were recalibrated with the effects (" + P.kind + " base: " +
                      std::to_string(P.base_value.size()) + " parameters); calibrated base alone: " +
                      fmt(out.base_only * 1e6) + " µm RMS");
  if (holdout)
    out.holdout = ErrorFigures{rms_of_model(*holdout, J.base_model), rms_of_model(*holdout, J.model)};
  else if (cross_validate && P.samples() >= 2 * (static_cast<int>(P.base_value.size()) + 6))
    out.cross_validation = cross_validation(data, model, P.samples(), req, opt);
  else if (cross_validate)
    out.notes.push_back("too few samples for a 2-fold cross-validation");
  return out;
}

}  // namespace cpm::ident

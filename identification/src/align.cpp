// SPDX-License-Identifier: Apache-2.0
#include "cpm/identification/align.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "candidates.hpp"
#include "cpm/identification/diagnose.hpp"

namespace cpm::ident {

std::string Alignment::convention() const {
  char b[128];
  const double x = tau / period;
  if (std::fabs(x) <= 0.25) return "zero-order hold (the force acts over [t_k, t_k+1))";
  if (std::fabs(x + 0.5) <= 0.25) return "force sampled at t_k (a continuous force)";
  std::snprintf(b, sizeof b, "the force acts %.2f periods (%.3g ms) after t_k", x, tau * 1e3);
  return b;
}

Alignment estimate_alignment(const MotionProblem& P, const Engine& E) {
  Alignment A;
  A.period = P.dt;
  A.model_tau = P.delay_model;
  const int ns = MotionProblem::kShiftHi - MotionProblem::kShiftLo + 1;
  // Residual at each whole shift, off the base span (weighted).
  Eigen::MatrixXd Y(P.force_at_shift.rows(), ns);
  for (int q = 0; q < ns; ++q) Y.col(q) = P.force_at_shift.col(q) - P.model_force;
  const Eigen::MatrixXd e = E.project_off_base(Y);
  // RSS in the bracket [n, n+1]: |e_n + phi (e_n+1 - e_n)|^2, a parabola in phi.
  double best = 1e300, best_tau = 0.0, curvature = 0.0;
  for (int q = 0; q + 1 < ns; ++q) {
    const Eigen::VectorXd d = e.col(q + 1) - e.col(q);
    const double dd = d.squaredNorm();
    const double phi = dd > 0.0 ? std::clamp(-e.col(q).dot(d) / dd, 0.0, 1.0) : 0.0;
    const double r = (e.col(q) + phi * d).squaredNorm();
    if (r < best) {
      best = r;
      best_tau = (MotionProblem::kShiftLo + q + phi) * P.dt;
      curvature = dd;  // d^2 RSS / d phi^2 = 2 dd
    }
  }
  A.trials = ns - 1;
  A.tau = best_tau;
  A.rss_at_tau = best;
  A.reference = A.model_tau + std::clamp(A.tau - A.model_tau, -0.5 * P.dt, 0.5 * P.dt);
  A.rss_at_reference = MotionProblem::at_delay(e, A.reference, P.dt).squaredNorm();
  // A minimum on an end of the range is no minimum: the RSS is still falling
  // there. On a clean zoh log of a one-frequency circle it ran to the end
  // (6 periods, "6 +- 1.2 ms"), a false delay; what is left then is the
  // model's own alignment.
  const double edge = 1e-6 * P.dt;
  if (best_tau <= MotionProblem::kShiftLo * P.dt + edge || best_tau >= MotionProblem::kShiftHi * P.dt - edge) {
    A.determined = false;
    A.tau = A.reference;
    A.rss_at_tau = A.rss_at_reference;
    A.std_error = -1.0;
    A.n_eff = E.effective_rows(MotionProblem::at_delay(e, A.tau, P.dt));
    return A;
  }
  // Standard error from the parabola's curvature, with the residual's variance
  // per effective row (rows of a filtered residual are not independent).
  const double n = static_cast<double>(e.rows());
  A.n_eff = E.effective_rows(MotionProblem::at_delay(e, A.tau, P.dt));
  const double k = E.base_rank() + 1;
  const double s2 = best / std::max(1.0, n - k) * (n / std::max(A.n_eff, 1.0));
  A.std_error = curvature > 0.0 ? P.dt * std::sqrt(s2 / curvature) : -1.0;
  return A;
}

MotionProblem alignment_problem(const io::MotionData& data, const ctl::Machine& model, const MotionOptions& o) {
  // Eight times the window where the log is long enough for it, shorter ones otherwise.
  for (double widen : {8.0, 4.0, 2.0}) {
    MotionOptions ao = o;
    ao.half_window = std::min(1.0, widen * o.half_window);
    try {
      return prepare_motion(data, model, ao);
    } catch (const Error&) {
      // too few rows for this window: try a shorter one
    }
  }
  return prepare_motion(data, model, o);
}

LinearProblem alignment_linear_problem(const MotionProblem& Pa) {
  LinearProblem L = motion_linear_problem(Pa);
  // Rows near a reversal of their axis do not vote: there friction changes
  // within a few milliseconds, the second-order error of any friction column
  // is largest, and the controller's answer to it is the force's steepest
  // slope, so a misfit there reads as a delay (a 4 N Stribeck moved it by a
  // quarter period).
  constexpr double kReversalSpeed = 0.03;  // m/s
  for (int r = 0; r < Pa.rows(); ++r)
    for (int i = 0; i < 3; ++i)
      if (std::fabs(Pa.v[r][i]) < kReversalSpeed) L.w(3 * r + i) = 0.0;
  // Friction on every axis is fitted with the alignment whether or not it is
  // missing: a delay's signature (the force's slope) is the motion's jerk,
  // which on a sinusoidal axis is minus its velocity times omega^2; 1 N of
  // Coulomb friction left out moved the estimate by two periods.
  // Which: the fitter table's in_alignment_columns (candidates.cpp).
  for (int i = 0; i < 3; ++i)
    for (int t = 0; t < ctl::kDynamicEffectTypes; ++t) {
      const auto type = static_cast<ctl::DynamicEffectType>(t);
      if (!detail::candidate_fitting(type).in_alignment_columns) continue;
      ctl::DynamicEffect e;
      e.type = type;
      e.axis = static_cast<std::int8_t>(i);
      e.param = {1.0, 0.0, 0.0, 0.0};
      const Eigen::Index nb = L.B.cols();
      L.B.conservativeResize(Eigen::NoChange, nb + 1);
      L.B.col(nb) = Pa.effect_column(e, 0);
      L.base_names.push_back(e.label());
      L.base_units.push_back(ctl::info(type).params[0].unit);
      L.base_values.push_back(0.0);
      L.nuisance.push_back(0);
    }
  return L;
}

Alignment align_motion(const io::MotionData& data, const ctl::Machine& model, const MotionOptions& o) {
  const MotionProblem Pa = alignment_problem(data, model, o);
  return estimate_alignment(Pa, Engine(alignment_linear_problem(Pa)));
}


}  // namespace cpm::ident

#include "cpm/identification/diagnose.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <sstream>

#include "internal.hpp"
#include "cpm/identification/align.hpp"
#include "cpm/identification/stats.hpp"
#include "cpm/identification/structure.hpp"
#include "cpm/kinematics/kinematic_effects.hpp"

namespace cpm::ident {
namespace {

using ctl::DynamicEffect;
using ctl::DynamicEffectType;
constexpr double kTwoPi = 2.0 * std::numbers::pi;
// Resolution of the force residual, as a share of each axis' commanded-force RMS.
constexpr double kMotionResolution = 2e-4;

std::string axis_label(int axis) { return axis >= 0 ? "[axis " + std::to_string(axis + 1) + "]" : ""; }

std::string fmt(double v, int prec = 3) {
  std::ostringstream os;
  os.precision(prec);
  os << v;
  return os.str();
}

DynamicEffect make(DynamicEffectType t, int axis, std::array<double, 4> p) {
  DynamicEffect e;
  e.type = t;
  e.axis = static_cast<std::int8_t>(axis);
  e.param = p;
  return e;
}

Eigen::MatrixXd hcat(std::initializer_list<Eigen::VectorXd> cols) {
  Eigen::MatrixXd X(cols.begin()->size(), static_cast<Eigen::Index>(cols.size()));
  Eigen::Index j = 0;
  for (const auto& c : cols) X.col(j++) = c;
  return X;
}

// Two-stage least squares with one column: the instrument z (free of the
// residual's noise) scaled by the first-stage fit of the noisy regressor x on
// it, off the base. Least squares on the result gives <z, y> / <z, x>: the
// instrumental-variable estimate, without the attenuation that least squares
// on z alone has where z is noisier than x.
Eigen::VectorXd instrumented(const Engine& E, const Eigen::VectorXd& z, const Eigen::VectorXd& x) {
  const Eigen::VectorXd zp = E.project_off_base(z), xp = E.project_off_base(x);
  const double zz = zp.squaredNorm();
  return zz > 0.0 ? Eigen::VectorXd(z * (zp.dot(xp) / zz)) : z;
}

// What each effect's force depends on, for advice on separating two of them.
struct Depends { bool direction, speed, position, force; };
Depends depends(const std::string& e) {
  if (e == "viscous_friction") return {true, true, false, false};
  if (e == "coulomb_friction") return {true, false, false, false};
  if (e == "stribeck_friction") return {true, true, false, false};
  if (e == "cogging" || e == "spring") return {false, false, true, false};
  return {false, false, false, true};  // force_gain, payload_mass, inertia_error
}

struct AxisExcitation {
  Vec3 vmax = Vec3::Zero(), vmin = Vec3::Zero(), span = Vec3::Zero(), fmax = Vec3::Zero();
  // The axis moved one way only: fewer than 2 % of its moving rows (|v| > 1 mm/s)
  // go the other way (start-up and settling wobble do not count as a reversal).
  std::array<bool, 3> one_way{};
};

AxisExcitation excitation(const MotionProblem& P) {
  AxisExcitation x;
  Vec3 dmin = Vec3::Constant(1e300), dmax = Vec3::Constant(-1e300);
  x.vmin.setConstant(1e300);
  x.vmax.setConstant(-1e300);
  for (int r = 0; r < P.rows(); ++r)
    for (int i = 0; i < 3; ++i) {
      dmin[i] = std::min(dmin[i], P.d[r][i]);
      dmax[i] = std::max(dmax[i], P.d[r][i]);
      x.vmin[i] = std::min(x.vmin[i], P.v[r][i]);
      x.vmax[i] = std::max(x.vmax[i], P.v[r][i]);
      x.fmax[i] = std::max(x.fmax[i], std::fabs(P.f[r][i]));
    }
  x.span = dmax - dmin;
  for (int i = 0; i < 3; ++i) {
    int plus = 0, minus = 0;
    for (int r = 0; r < P.rows(); ++r) {
      plus += P.v[r][i] > 1e-3;
      minus += P.v[r][i] < -1e-3;
    }
    x.one_way[i] = plus + minus > 0 && std::min(plus, minus) < 0.02 * (plus + minus);
  }
  return x;
}

std::string separate_advice(const CandidateResult& a, const CandidateResult& b,
                            const AxisExcitation& x) {
  const Depends da = depends(a.effect), db = depends(b.effect);
  const int ax = a.axis >= 0 ? a.axis : b.axis;
  const std::string axis_text = ax >= 0 ? "axis " + std::to_string(ax + 1) : "the axes";
  const bool one_direction = ax >= 0 && x.one_way[ax];
  const bool payload_vs_gain = (a.effect == "payload_mass" && b.effect == "force_gain") ||
                               (a.effect == "force_gain" && b.effect == "payload_mass") ||
                               (a.effect == "inertia_error" && b.effect == "force_gain") ||
                               (a.effect == "force_gain" && b.effect == "inertia_error");
  if (payload_vs_gain)
    return "accelerate the other axes harder (a payload or an inertia error acts on every axis, a drive gain "
           "only on " + axis_text + ")";
  if (da.direction != db.direction && one_direction)
    return "move " + axis_text + " in both directions";
  if ((da.direction && db.direction) || (da.speed != db.speed))
    return "run " + axis_text + " at another feed (a different speed)";
  if (da.position != db.position)
    return "cover a longer stroke or another position range on " + axis_text;
  if (da.force || db.force) return "repeat with another payload or other accelerations";
  return "measure with other speeds, both directions and another payload";
}

}  // namespace

namespace detail {
// Fill the statistics of a fitted candidate.
void score_candidate(CandidateResult& c, const Engine& E, double rss_parent, int q, int k_total,
           double baseline_ms) {
  c.k_total = k_total;
  c.rms_after = Engine::rms(c.residual_after);
  c.explained = baseline_ms > 0.0 ? std::clamp(1.0 - c.rms_after * c.rms_after / baseline_ms, 0.0, 1.0) : 0.0;
  const double base_ms = E.rows() ? Engine::rms(E.base_fit().residual) : 0.0;
  c.explained_beyond_base =
      base_ms > 0.0 ? std::clamp(1.0 - c.rms_after * c.rms_after / (base_ms * base_ms), 0.0, 1.0) : 0.0;
  if (!c.identifiable || q <= 0 || c.rss <= 0.0) {
    c.f_stat = 0.0;
    c.p_value = 1.0;
    c.delta_bic = 0.0;
    return;
  }
  const NestedTest t = E.nested(rss_parent, c.rss, q, k_total, c.n_eff);
  c.f_stat = t.f_stat;
  c.p_value = t.p_value;
  c.delta_bic = t.delta_bic;
}

}  // namespace detail

std::string CandidateResult::label() const { return effect + axis_label(axis); }

void check_effect_for_kind(const std::string& effect, const std::string& kind) {
  const bool dyn = ctl::dynamic_effect_from_name(effect).has_value();
  const bool kinem = kin::kinematic_effect_from_name(effect).has_value();
  if (!dyn && !kinem)
    throw Error("unknown effect '" + effect +
                "' (the names are those of shared/spec/effects.md, e.g. coulomb_friction, cogging, backlash)");
  if (kind == "motion" && kinem)
    throw Error(effect + " is a kinematic effect (it changes where the platform is, not the force): a motion "
                "log (kind = motion) cannot show it; measure ball-bar lengths or positions");
  if ((kind == "ballbar" || kind == "position") && dyn)
    throw Error(effect + " is a dynamic effect (a force): " + kind +
                " data cannot show it; record a motion log (kind = motion) with the commanded forces");
}

LinearProblem nuisance_only(const LinearProblem& L) {
  LinearProblem N = L;
  std::vector<int> keep;
  for (std::size_t b = 0; b < L.nuisance.size(); ++b)
    if (L.nuisance[b]) keep.push_back(static_cast<int>(b));
  N.B.resize(L.B.rows(), static_cast<Eigen::Index>(keep.size()));
  N.base_names.clear();
  N.base_units.clear();
  N.base_values.clear();
  N.nuisance.clear();
  for (std::size_t q = 0; q < keep.size(); ++q) {
    N.B.col(static_cast<Eigen::Index>(q)) = L.B.col(keep[q]);
    N.base_names.push_back(L.base_names[static_cast<std::size_t>(keep[q])]);
    N.base_units.push_back(L.base_units[static_cast<std::size_t>(keep[q])]);
    N.base_values.push_back(L.base_values[static_cast<std::size_t>(keep[q])]);
    N.nuisance.push_back(1);
  }
  return N;
}

LinearProblem motion_linear_problem(const MotionProblem& P, Vec3* axis_noise) {
  LinearProblem L;
  const int N = 3 * P.rows();
  L.y = P.residual;
  L.B = P.base;
  for (const auto& b : P.base_params) {
    L.base_names.push_back(b.name);
    L.base_units.push_back(b.unit);
    L.base_values.push_back(b.value);
    L.nuisance.push_back(b.nuisance ? 1 : 0);
  }
  L.series.resize(N);
  for (int r = 0; r < N; ++r) L.series[r] = r % 3;
  L.n_series = 3;
  L.w = Eigen::VectorXd::Ones(N);
  // Per-axis noise from the base refit's residual (second differences: slow
  // structure and isolated steps do not count as noise).
  const Engine e0(L);
  const Eigen::VectorXd& r0 = e0.base_fit().residual;
  Vec3 sigma;
  double floor = 0.0;
  for (int i = 0; i < 3; ++i) {
    std::vector<double> s;
    for (int r = 0; r < P.rows(); ++r) s.push_back(r0(3 * r + i));
    sigma[i] = noise_from_differences(s);
    floor = std::max(floor, sigma[i]);
  }
  // Second differences of white noise filtered by the acceleration kernel are
  // not those of white noise: correct by the kernel's own autocorrelation at
  // the row spacing.
  {
    const auto& h = P.accel_kernel.h;
    auto rho = [&](int lag) {
      double num = 0.0, den = 0.0;
      for (std::size_t j = 0; j < h.size(); ++j) {
        den += h[j] * h[j];
        if (j + static_cast<std::size_t>(lag) < h.size()) num += h[j] * h[j + static_cast<std::size_t>(lag)];
      }
      return den > 0.0 ? num / den : 0.0;
    };
    const double f = (6.0 - 8.0 * rho(P.stride) + 2.0 * rho(2 * P.stride)) / 6.0;
    if (f > 0.1) sigma /= std::sqrt(f);
    floor = sigma.maxCoeff();
  }
  const double rms_all = Engine::rms(r0);
  // The residual's own resolution: on noise-free logs the filtering of terms
  // nonlinear in the state and the linearised plane nuisance leave a few
  // 1e-5 to 1e-4 of the commanded force (a Kim-sized plane-error truth:
  // 4e-5 N; a 0.4 kg payload: 4e-4 N; a 4 N Stribeck breakaway: 2e-3 N),
  // and they leak from the loaded z axis into x and y: one scale for all axes.
  double f2 = 0.0;
  for (int r = 0; r < P.rows(); ++r) f2 += P.f[r].squaredNorm();
  const Vec3 resolution = Vec3::Constant(kMotionResolution * std::sqrt(f2 / std::max(1, 3 * P.rows())));
  for (int i = 0; i < 3; ++i)
    sigma[i] = std::max({sigma[i], resolution[i], 1e-3 * floor, 1e-9 * rms_all, 1e-12});
  for (int r = 0; r < N; ++r) L.w(r) = 1.0 / sigma[r % 3];
  double fv = 0.0;
  for (int i = 0; i < 3; ++i) fv += (resolution[i] / sigma[i]) * (resolution[i] / sigma[i]);
  L.floor_variance = fv / 3.0;
  if (axis_noise) *axis_noise = sigma;
  return L;
}

CandidateResult evaluate_dynamic_candidate(const MotionProblem& P, const Engine& E,
                                           const ctl::MachineModel& model, const std::string& effect,
                                           int axis, const DiagnoseOptions& opt) {
  CandidateResult c;
  c.effect = effect;
  c.axis = axis;
  const auto type = ctl::dynamic_effect_from_name(effect);
  if (!type) throw Error("unknown dynamic effect '" + effect + "'");
  const ctl::DynamicEffectInfo& in = ctl::info(*type);
  const AxisExcitation ex = excitation(P);
  const int nb = static_cast<int>(P.base_params.size());
  const int rank = E.base_rank();
  auto set_not_identifiable = [&](const std::string& why) {
    c.identifiable = false;
    c.note = why;
    c.rss = E.rss_base();
    c.residual_after = E.base_fit().residual;
    c.fitted = Eigen::VectorXd::Zero(E.rows());
    for (int j = 0; j < in.n_params; ++j) c.params.push_back({in.params[j].name, in.params[j].unit, 0.0, -1.0, false});
  };
  auto base_after = [&](const JointFit& f, bool with_base) {
    for (int b = 0; b < nb; ++b)
      c.base_after.push_back({P.base_params[b].name, P.base_params[b].unit,
                              P.base_params[b].value + (with_base ? f.base_delta(b) : 0.0), -1.0, false});
  };
  auto finish = [&](const Eigen::MatrixXd& X, const JointFit& f, const Eigen::MatrixXd& jac,
                    const std::vector<double>& values, bool with_base) {
    c.columns = X;
    c.rss = f.rss;
    c.n_eff = f.n_eff;
    c.residual_after = f.residual;
    c.fitted = X.cols() ? Eigen::VectorXd(X * f.beta) : Eigen::VectorXd::Zero(E.rows());
    const Eigen::MatrixXd cov = E.covariance(jac, f, (with_base ? rank : 0) + static_cast<int>(jac.cols()), with_base);
    for (int j = 0; j < in.n_params; ++j) {
      const double se = j < cov.rows() ? std::sqrt(std::max(0.0, cov(j, j))) : -1.0;
      c.params.push_back({in.params[j].name, in.params[j].unit, values[j], se, false});
    }
    base_after(f, with_base);
    if (X.cols()) {
      const Eigen::VectorXd share = E.base_share(X);
      const Eigen::MatrixXd cosb = E.base_cosines(X);
      if (!f.full_rank || share.minCoeff() > 1.0 - 1e-6) {
        c.identifiable = false;
        std::string with;
        for (Eigen::Index j = 0; j < X.cols(); ++j) {
          Eigen::Index bi = 0;
          cosb.row(j).cwiseAbs().maxCoeff(&bi);
          if (cosb.cols()) with = P.base_params[static_cast<std::size_t>(bi)].name;
        }
        c.note = "in these data it cannot be told apart from the base model" +
                 (with.empty() ? std::string() : " (parameter " + with + ")");
      }
      for (Eigen::Index j = 0; j < X.cols(); ++j) {
        if (share(j) < 0.81 || cosb.cols() == 0) continue;
        Eigen::Index bi = 0;
        cosb.row(j).cwiseAbs().maxCoeff(&bi);
        Confounder cf;
        cf.with = P.base_params[static_cast<std::size_t>(bi)].name;
        cf.correlation = std::sqrt(share(j));
        const Depends d = depends(effect);
        cf.separate_by = d.direction && axis >= 0 && ex.one_way[axis]
                             ? "move axis " + std::to_string(axis + 1) + " in both directions"
                             : "vary the accelerations, speeds and poses more widely";
        bool dup = false;
        for (const auto& o : c.confounded) dup |= o.with == cf.with;
        if (!dup) c.confounded.push_back(cf);
      }
    }
  };

  const bool per_axis = in.per_axis;
  if (per_axis && (axis < 0 || axis > 2)) throw Error(effect + ": needs an axis 1..3");
  if (!per_axis && axis >= 0) throw Error(effect + " acts on all axes together; give no axis");
  for (const auto& e : model.effects)
    if (per_axis && e.type == *type && e.axis == axis) {
      c.note = "already in the model: refitted with the base parameters";
      set_not_identifiable(c.note);
      return c;
    }
  const double vabs = axis >= 0 ? std::max(std::fabs(ex.vmin[axis]), std::fabs(ex.vmax[axis])) : 0.0;
  c.n_params = in.n_params;

  switch (*type) {
    case DynamicEffectType::viscous_friction:
    case DynamicEffectType::coulomb_friction:
    case DynamicEffectType::force_gain: {
      Eigen::MatrixXd X;
      if (*type == DynamicEffectType::force_gain) {
        if (ex.fmax[axis] < 1e-6) {
          set_not_identifiable("no force was commanded on axis " + std::to_string(axis + 1));
          break;
        }
        X = hcat({instrumented(E, P.force_gain_column(axis), P.force_gain_column_logged(axis))});
      } else {
        if (vabs < 5e-3) {
          set_not_identifiable("axis " + std::to_string(axis + 1) + " does not move in these data");
          break;
        }
        X = hcat({P.effect_column(make(*type, axis, {1.0, 0, 0, 0}), 0)});
      }
      JointFit f = E.fit(X);
      double b = f.beta(0);
      const double b_free = b;
      const double lo = in.params[0].lower, hi = in.params[0].upper;
      bool held = false;
      if (b < lo || b > hi) {
        b = std::clamp(b, lo, hi);
        held = true;
        f = E.fit(Eigen::MatrixXd(X.rows(), 0));
        if (b != 0.0) {  // a bound other than 0: the column at its bound is fixed, refit the base
          LinearProblem L = E.problem();
          L.y -= X.col(0) * b;
          f = Engine(L).base_fit();
        }
        f.beta = Eigen::VectorXd::Constant(1, b);
      }
      finish(X, f, X, {b}, true);
      if (held) {
        c.params[0].at_bound = true;
        c.note = "the best fit (" + fmt(b_free) + ") is outside the physical range; held at " + fmt(b);
        c.identifiable = c.identifiable && b != 0.0;
      }
      break;
    }
    case DynamicEffectType::spring: {
      if (ex.span[axis] < 1e-3) {
        set_not_identifiable("axis " + std::to_string(axis + 1) + " does not move in these data");
        break;
      }
      const DynamicEffect unit = make(*type, axis, {1.0, 0.0, 0, 0});
      const Eigen::MatrixXd X = hcat({P.effect_column(unit, 0), P.effect_column(unit, 1)});
      JointFit f = E.fit(X);
      double k = f.beta(0), dref = std::fabs(k) > 0.0 ? f.beta(1) / k : 1e300;
      bool held = false;
      Eigen::MatrixXd Xf = X;
      if (!(std::fabs(dref) <= 1.0)) {
        held = true;
        dref = std::clamp(dref, -1.0, 1.0);
        Xf = hcat({P.effect_force_column(make(*type, axis, {1.0, dref, 0, 0}))});
        f = E.fit(Xf);
        k = f.beta(0);
      }
      k = std::clamp(k, in.params[0].lower, in.params[0].upper);
      const DynamicEffect fe = make(*type, axis, {k, dref, 0, 0});
      const Eigen::MatrixXd jac = hcat({P.effect_column(fe, 0), P.effect_column(fe, 1)});
      finish(Xf, f, held ? Eigen::MatrixXd(jac.col(0)) : jac, {k, dref}, true);
      if (held) {
        c.params[1].at_bound = true;
        c.params[1].std_error = -1.0;
        c.note = "the spring's rest position is outside [-1, 1] m; held at the bound";
        // The selection fits without the base refit, where a constant force on
        // the axis is its own (on z it is the weight's E only once the base is
        // refitted): it gets the spring's whole linear pair.
        c.columns = X;
      }
      break;
    }
    case DynamicEffectType::stribeck_friction: {
      const double lo = 2.0 * ctl::kSignEpsilon, hi = std::min(in.params[1].upper, vabs);
      if (vabs < 5e-3 || hi <= lo * 1.5) {
        set_not_identifiable("axis " + std::to_string(axis + 1) + " does not move fast enough in these data");
        break;
      }
      auto cols = [&](double vs) {
        return hcat({P.effect_column(make(*type, axis, {1.0, vs, 0, 0}), 0)});
      };
      auto cost = [&](double logvs) {
        const Eigen::MatrixXd X = cols(std::exp(logvs));
        const JointFit f = E.fit(X);
        return f.beta(0) >= 0.0 ? f.rss : E.rss_base();
      };
      const int G = 16;
      double best = 1e300, bx = std::log(lo);
      const double step = (std::log(hi) - std::log(lo)) / (G - 1);
      for (int g = 0; g < G; ++g) {
        const double x = std::log(lo) + g * step;
        const double v = cost(x);
        if (v < best) { best = v; bx = x; }
      }
      double fb = 0.0;
      const double xr = detail::golden(cost, std::max(std::log(lo), bx - step), std::min(std::log(hi), bx + step), 12, fb);
      if (fb < best) bx = xr;
      const double vs = std::exp(bx);
      const Eigen::MatrixXd X = cols(vs);
      JointFit f = E.fit(X);
      double fs = f.beta(0);
      const bool held = fs < 0.0;
      if (held) {
        fs = 0.0;
        f = E.base_fit();
        f.beta = Eigen::VectorXd::Zero(1);
      }
      const DynamicEffect fe = make(*type, axis, {fs, vs, 0, 0});
      const Eigen::MatrixXd jac = hcat({P.effect_column(fe, 0), P.effect_column(fe, 1)});
      finish(X, f, held ? Eigen::MatrixXd(jac.col(0)) : jac, {fs, vs}, true);
      c.trials = std::max(1.0, std::log(hi / lo) / std::log(3.0));
      if (held) {
        c.params[0].at_bound = true;
        c.identifiable = false;
        c.note = "the best fit is a negative breakaway force (unphysical); held at 0";
      }
      break;
    }
    case DynamicEffectType::cogging: {
      const double span = ex.span[axis];
      const double lmin = std::max(opt.cogging_lambda_min, in.params[1].lower);
      const double lmax = std::min({opt.cogging_lambda_max, in.params[1].upper, span / 1.5});
      if (vabs < 5e-3 || lmax <= lmin) {
        set_not_identifiable("axis " + std::to_string(axis + 1) + " moves over " + fmt(span * 1e3) +
                             " mm only: too little to see a force periodic in position (wavelength >= " +
                             fmt(lmin * 1e3) + " mm)");
        break;
      }
      // Periodogram of the base-refit residual against this axis' position;
      // each wavenumber's column is damped by the filter's response at the
      // row's temporal frequency |v| k.
      const int R = P.rows();
      const Eigen::VectorXd& yb = E.base_fit().residual;
      const Eigen::VectorXd& w = E.problem().w;
      const double kmin = 1.0 / lmax, kmax = 1.0 / lmin, dk = 1.0 / (4.0 * span);
      const int K = static_cast<int>((kmax - kmin) / dk) + 1;
      std::vector<double> ph_c(R), ph_s(R), rot_c(R), rot_s(R), yr(R), wr(R), damp(R);
      std::vector<double> power(K);
      for (int r = 0; r < R; ++r) {
        const double x = P.d[r][axis];
        ph_c[r] = std::cos(kTwoPi * kmin * x);
        ph_s[r] = std::sin(kTwoPi * kmin * x);
        rot_c[r] = std::cos(kTwoPi * dk * x);
        rot_s[r] = std::sin(kTwoPi * dk * x);
        wr[r] = w(3 * r + axis) * w(3 * r + axis);
        yr[r] = yb(3 * r + axis);
      }
      // The filter's amplitude response, tabulated (cycles per sample, 0..0.5).
      constexpr int kTab = 1024;
      std::vector<double> resp(kTab + 1);
      for (int q = 0; q <= kTab; ++q) resp[q] = P.smooth_force.response(0.5 * q / kTab);
      std::vector<double> fper(R);
      for (int r = 0; r < R; ++r) fper[r] = std::fabs(P.v[r][axis]) * P.dt * 2.0 * kTab;
      for (int q = 0; q < K; ++q) {
        const double kq = kmin + q * dk;
        double cc = 0, cs = 0, ss = 0, cy = 0, sy = 0;
        for (int r = 0; r < R; ++r) {
          const double h = resp[std::min(kTab, static_cast<int>(fper[r] * kq + 0.5))];
          const double cv = h * ph_c[r], sv = h * ph_s[r], ww = wr[r];
          cc += ww * cv * cv; cs += ww * cv * sv; ss += ww * sv * sv;
          cy += ww * cv * yr[r]; sy += ww * sv * yr[r];
          const double nc = ph_c[r] * rot_c[r] - ph_s[r] * rot_s[r];
          ph_s[r] = ph_s[r] * rot_c[r] + ph_c[r] * rot_s[r];
          ph_c[r] = nc;
        }
        const double det = cc * ss - cs * cs;
        power[q] = det > 1e-300 ? (ss * cy * cy - 2 * cs * cy * sy + cc * sy * sy) / det : 0.0;
      }
      std::vector<int> peaks;
      for (int q = 0; q < K; ++q)
        if ((q == 0 || power[q] >= power[q - 1]) && (q == K - 1 || power[q] >= power[q + 1])) peaks.push_back(q);
      std::sort(peaks.begin(), peaks.end(), [&](int a, int b) { return power[a] > power[b]; });
      if (peaks.size() > 3) peaks.resize(3);
      auto cols = [&](double lambda) {
        return hcat({P.effect_column(make(*type, axis, {1.0, lambda, 0.0, 0}), 0),
                     P.effect_column(make(*type, axis, {1.0, lambda, 0.5 * std::numbers::pi, 0}), 0)});
      };
      double best = 1e300, blam = 1.0 / (kmin + (peaks.empty() ? 0 : peaks[0]) * dk);
      for (int q : peaks) {
        const double k0 = kmin + q * dk;
        double fb = 0.0;
        const double kk = detail::golden([&](double kx) { return E.rss(cols(1.0 / kx)); },
                                 std::max(kmin, k0 - dk), std::min(kmax, k0 + dk), 12, fb);
        if (fb < best) { best = fb; blam = 1.0 / kk; }
      }
      const Eigen::MatrixXd X = cols(blam);
      const JointFit f = E.fit(X);
      const double a = std::hypot(f.beta(0), f.beta(1));
      const double phi = std::atan2(f.beta(1), f.beta(0));
      const DynamicEffect fe = make(*type, axis, {a, blam, phi, 0});
      const Eigen::MatrixXd jac = hcat({P.effect_column(fe, 0), P.effect_column(fe, 1), P.effect_column(fe, 2)});
      finish(X, f, jac, {a, blam, phi}, true);
      c.trials = std::max(1.0, span * (kmax - kmin));
      break;
    }
    case DynamicEffectType::payload_mass: {
      c.refits_base = false;
      const Eigen::MatrixXd X = hcat({0.5 * P.base.col(0) + ctl::kGravity * P.base.col(3)});
      JointFit f = E.fit(X, false);
      double dm = f.beta(0);
      if (dm < in.params[0].lower || dm > in.params[0].upper) {
        dm = std::clamp(dm, in.params[0].lower, in.params[0].upper);
        LinearProblem L = E.problem();
        L.y -= X.col(0) * dm;
        const Engine e2(L);
        f = e2.fit(Eigen::MatrixXd(X.rows(), 0), false);
        f.beta = Eigen::VectorXd::Constant(1, dm);
        c.note = "the best fit is outside the physical range; held at " + fmt(dm) + " kg";
      }
      c.columns = X;
      c.rss = f.rss;
      c.n_eff = f.n_eff;
      c.residual_after = f.residual;
      c.fitted = X * f.beta;
      const Eigen::MatrixXd cov = E.covariance(X, f, 1, false);
      c.params.push_back({"dm", "kg", dm, std::sqrt(std::max(0.0, cov(0, 0))), false});
      base_after(f, false);
      break;
    }
    case DynamicEffectType::inertia_error: {
      c.refits_base = true;
      const JointFit& f = E.base_fit();
      c.columns = Eigen::MatrixXd(E.rows(), 0);
      c.rss = f.rss;
      c.n_eff = f.n_eff;
      c.residual_after = f.residual;
      c.fitted = E.problem().y - f.residual;
      const Eigen::MatrixXd cov = E.covariance(P.base.leftCols(4), f, rank, false);
      const auto& un = E.unidentifiable_base();
      for (int j = 0; j < 4; ++j) {
        const bool undet = std::find(un.begin(), un.end(), j) != un.end();
        c.params.push_back({in.params[j].name, in.params[j].unit, f.base_delta(j),
                            undet ? -1.0 : std::sqrt(std::max(0.0, cov(j, j))), false});
      }
      base_after(f, true);
      c.n_params = E.base_rank_beyond_nuisance();
      if (!un.empty()) {
        std::string names;
        for (int j : un) names += (names.empty() ? "" : ", ") + P.base_params[j].name;
        c.note = "these data cannot determine " + names + " (kept at the model's value)";
      }
      break;
    }
    case DynamicEffectType::actuation_delay:
      throw Error("actuation_delay is estimated with the force-to-motion alignment, not as a candidate");
  }
  return c;
}

namespace {
// The parameters of every effect chosen, fitted on what the other chosen
// effects leave (their contributions from the joint fit), with the base
// refitted only when the selection chose to refit it (inertia_error): the
// numbers then belong to the model the verdict describes.
void refine_chosen(Diagnosis& D, const Engine& E, const MotionProblem& P, const ctl::MachineModel& model,
                   const DiagnoseOptions& opt) {
  const std::vector<int> found = D.found();
  bool base_in = false;
  for (int j : found) base_in |= D.candidates[static_cast<std::size_t>(j)].effect == "inertia_error";
  LinearProblem L = base_in ? E.problem() : nuisance_only(E.problem());
  const Eigen::VectorXd y0 = L.y;
  for (int j : found) {
    CandidateResult& c = D.candidates[static_cast<std::size_t>(j)];
    if (c.effect == "inertia_error" || c.effect == "actuation_delay") continue;
    L.y = y0;
    for (int l : found)
      if (l != j && D.candidates[static_cast<std::size_t>(l)].fitted.size() == L.y.size())
        L.y -= D.candidates[static_cast<std::size_t>(l)].fitted;
    const CandidateResult r = evaluate_dynamic_candidate(P, Engine(L), model, c.effect, c.axis, opt);
    if (r.params.size() == c.params.size()) c.params = r.params;
  }
}

// The alignment as a candidate of its own: actuation_delay with tau = the
// delay the model is missing, scored against the model as given at the
// alignment it may take without it (within T/2 of its own delay). Named
// first when significant and beyond T/2: every other effect was fitted on
// the aligned residual, so the delay is the premise of the rest of the verdict.
void name_missing_delay(Diagnosis& D, const Engine& E, const DiagnoseOptions& opt) {
  const Alignment& A = D.alignment;
  CandidateResult c;
  c.effect = "actuation_delay";
  c.axis = -1;
  c.refits_base = true;
  c.n_params = 1;
  c.trials = A.trials;
  c.n_eff = A.n_eff;
  c.params.push_back({"tau", "s", A.missing(), A.std_error, false});
  const double n = A.n_eff;
  c.rss = A.rss_at_tau;
  c.rms_after = Engine::rms(E.base_fit().residual);
  c.explained_beyond_base = A.rss_at_reference > 0.0 ? std::clamp(1.0 - A.rss_at_tau / A.rss_at_reference, 0.0, 1.0) : 0.0;
  c.explained = c.explained_beyond_base;
  const NestedTest t = E.nested(A.rss_at_reference, A.rss_at_tau, 1, E.base_rank() + 1, n);
  c.f_stat = t.f_stat;
  c.p_value = t.p_value;
  c.delta_bic = t.delta_bic;
  c.p_adjusted = std::min(1.0, c.p_value * c.trials * static_cast<double>(D.candidates.size() + 1));
  // Beyond T/2 by more than 3 standard errors: a sampling convention cannot explain it.
  const bool beyond = A.beyond_sampling() && (A.std_error < 0.0 || A.missing() - 0.5 * A.period > 3.0 * A.std_error);
  c.significant = beyond && c.p_adjusted < opt.alpha && c.delta_bic < 0.0;
  c.identifiable = true;
  if (!A.beyond_sampling())
    c.note = "within half a period of the model's alignment: how the data were sampled (" + A.convention() + ")";
  c.score = c.significant ? -1e300 : 0.0;
  if (!c.significant) {
    D.candidates.push_back(std::move(c));
    return;
  }
  // First in the ranking and in the verdict.
  D.candidates.insert(D.candidates.begin(), std::move(c));
  std::vector<int> found;
  if (D.verdict >= 0) found.push_back(D.verdict + 1);
  for (int j : D.also) found.push_back(j + 1);
  D.verdict = 0;
  D.also = found;
  std::ostringstream os;
  os.precision(3);
  os << "missing: actuation_delay (tau = " << detail::human_value(D.candidates[0].params[0]) << ": the force acts "
     << A.tau / A.period << " sample periods after t_k, the model says " << A.model_tau / A.period << ")";
  const std::string rest = D.verdict_text.rfind("missing: ", 0) == 0 ? D.verdict_text.substr(9) : std::string();
  if (found.empty()) os << ". Nothing else is missing";
  D.verdict_text = os.str() + (found.empty() ? std::string() : "; " + rest);
}
}  // namespace

namespace {
// The alignment with the effects found so far fitted jointly (their columns
// join the base): an effect left out would pull the delay towards itself.
Alignment align_with(const MotionProblem& Pa, const ctl::MachineModel& model,
                     const std::vector<std::pair<std::string, int>>& effects, const DiagnoseOptions& opt) {
  LinearProblem L = alignment_linear_problem(Pa);
  if (!effects.empty()) {
    const Engine E1(motion_linear_problem(Pa));  // the candidates' own base (their names index it)
    for (const auto& [name, axis] : effects) {
      if (name == "inertia_error" || name == "actuation_delay") continue;  // inside the base / the alignment
      if (name == "viscous_friction" || name == "coulomb_friction") continue;  // always fitted with it
      const CandidateResult c = evaluate_dynamic_candidate(Pa, E1, model, name, axis, opt);
      if (c.columns.cols() == 0) continue;
      const Eigen::Index nb = L.B.cols();
      L.B.conservativeResize(Eigen::NoChange, nb + c.columns.cols());
      L.B.rightCols(c.columns.cols()) = c.columns;
      for (Eigen::Index j = 0; j < c.columns.cols(); ++j) {
        L.base_names.push_back(c.label());
        L.base_units.push_back("");
        L.base_values.push_back(0.0);
        L.nuisance.push_back(0);
      }
    }
  }
  return estimate_alignment(Pa, Engine(std::move(L)));
}

Diagnosis diagnose_aligned(const io::MotionData& data, const ctl::Machine& model, const DiagnoseOptions& opt,
                           const Alignment& alignment);
}  // namespace

Diagnosis diagnose_motion(const io::MotionData& data, const ctl::Machine& model,
                          const DiagnoseOptions& opt) {
  for (const auto& e : opt.effects) check_effect_for_kind(e, "motion");
  // Stage "align" (align.hpp): when the logged force acts, first with the
  // base alone, then again with the effects the diagnosis found; when that
  // moves it beyond its noise the diagnosis is redone there.
  const MotionProblem Pa = alignment_problem(data, model, opt.motion);
  Alignment A = align_with(Pa, model.model(), {}, opt);
  Diagnosis D = diagnose_aligned(data, model, opt, A);
  // A large effect left out pulls the alignment (a 4 N Stribeck spike moved
  // it to the end of the range); the effects found at a wrong alignment are
  // partly wrong too: iterate until the alignment settles within its noise.
  for (int pass = 0; pass < 3; ++pass) {
    std::vector<std::pair<std::string, int>> found;
    for (int j : D.found())
      found.emplace_back(D.candidates[static_cast<std::size_t>(j)].effect, D.candidates[static_cast<std::size_t>(j)].axis);
    if (found.empty()) break;
    const Alignment A2 = align_with(Pa, model.model(), found, opt);
    if (std::fabs(A2.tau - A.tau) <= std::max(0.05 * A.period, 2.0 * std::max(0.0, A2.std_error))) break;
    A = A2;
    D = diagnose_aligned(data, model, opt, A);
  }
  return D;
}

namespace {
Diagnosis diagnose_aligned(const io::MotionData& data, const ctl::Machine& model, const DiagnoseOptions& opt,
                           const Alignment& alignment) {
  Diagnosis D;
  D.data_file = data.info.path;
  D.samples = static_cast<int>(data.t.size());
  D.motion = prepare_motion(data, model, opt.motion);
  D.alignment = alignment;
  D.motion.set_delay(alignment.tau);
  const MotionProblem& P = D.motion;
  D.warnings = P.warnings;
  for (const auto& w : data.info.warnings) D.warnings.push_back(w);
  LinearProblem L = motion_linear_problem(P, &D.axis_noise);
  const Engine E(std::move(L));
  D.rows = E.rows();
  D.baseline_rms = Engine::rms(P.residual);
  D.baseline_max = P.residual.cwiseAbs().maxCoeff();
  for (int i = 0; i < 3; ++i) {
    double s = 0.0;
    for (int r = 0; r < P.rows(); ++r) s += P.residual(3 * r + i) * P.residual(3 * r + i);
    D.baseline_axis_rms[i] = std::sqrt(s / P.rows());
  }
  D.base_refit_rms = Engine::rms(E.base_fit().residual);
  D.noise_floor = std::sqrt(D.axis_noise.squaredNorm() / 3.0);
  const double baseline_ms = D.baseline_rms * D.baseline_rms;

  // The candidates: every dynamic effect (or those asked for) on every axis.
  std::vector<std::pair<std::string, int>> todo;
  for (int t = 0; t < ctl::kDynamicEffectTypes; ++t) {
    const auto& in = ctl::info(static_cast<DynamicEffectType>(t));
    if (in.type == DynamicEffectType::actuation_delay) continue;  // estimated with the alignment
    if (!opt.effects.empty() && std::find(opt.effects.begin(), opt.effects.end(), in.name) == opt.effects.end())
      continue;
    if (in.per_axis)
      for (int i = 0; i < 3; ++i) todo.emplace_back(in.name, i);
    else
      todo.emplace_back(in.name, -1);
  }
  const int rank = E.base_rank();
  for (const auto& [name, axis] : todo) {
    CandidateResult c = evaluate_dynamic_candidate(P, E, model.model(), name, axis, opt);
    if (name == "payload_mass") detail::score_candidate(c, E, E.rss_given(), 1, E.nuisance_rank() + 1, baseline_ms);
    else if (name == "inertia_error")
      detail::score_candidate(c, E, E.rss_given(), E.base_rank_beyond_nuisance(), rank, baseline_ms);
    else detail::score_candidate(c, E, E.rss_base(), c.n_params, rank + c.n_params, baseline_ms);
    D.candidates.push_back(std::move(c));
  }
  const AxisExcitation ex = excitation(P);
  detail::rank_and_decide(D, E, opt, [&](const CandidateResult& a, const CandidateResult& b) {
    return separate_advice(a, b, ex);
  });
  // Stage "selection" (select.cpp), then each effect chosen refitted on what the others leave.
  detail::select_motion_effects(D, E, opt);
  refine_chosen(D, E, P, model.model(), opt);
  detail::verdict_text_motion(D);
  // Stage "outside the library" (outside.cpp): strong structure left leads the
  // verdict, and the selection is redone with it fitted beside the library.
  // Rescanned after each reselection (a narrow bump leaves some of itself
  // beside the bin that describes it), three rounds at most.
  std::optional<Engine> Es;
  for (int round = 0; round < 3; ++round) {
    const std::vector<StructureFinding> more = detail::strong_structure(D, P, opt);
    if (more.empty()) break;
    D.outside_library.insert(D.outside_library.end(), more.begin(), more.end());
    Es.emplace(detail::with_structure(E.problem(), D.outside_library, P));
    for (auto& c : D.candidates) c.alternatives.clear();
    detail::select_motion_effects(D, *Es, opt);
    refine_chosen(D, *Es, P, model.model(), opt);
    detail::verdict_text_motion(D);
  }
  detail::lead_with_outside_library(D);
  // Coulomb friction on an axis that moved one way only is a constant force:
  // what a tilted plane puts into the weight, what a force-gain error makes
  // of a nearly steady force, what a distant spring pulls. The fit may prefer
  // one of them, but these data cannot name the cause: say so.
  if (D.verdict >= 0) {
    const CandidateResult& v = D.candidates[static_cast<std::size_t>(D.verdict)];
    if (v.axis >= 0 && ex.one_way[static_cast<std::size_t>(v.axis)] &&
        (v.effect == "coulomb_friction" || v.effect == "force_gain" || v.effect == "spring")) {
      const std::string ax = std::to_string(v.axis + 1);
      std::vector<std::string> alts;
      for (const char* e : {"coulomb_friction", "force_gain", "spring"})
        if (v.effect != e) alts.push_back(std::string(e) + "[axis " + ax + "]");
      D.ambiguous = true;
      D.verdict_text += ". Axis " + ax + " moved one way only: a steady force on it cannot be told apart between " +
                        v.label() + ", " + alts[0] + ", " + alts[1] +
                        " and a tilted plane's share of the weight; to separate, move axis " + ax + " in both directions";
      for (auto& c : D.candidates)
        if (c.axis == v.axis && (c.effect == "coulomb_friction" || c.effect == "force_gain" || c.effect == "spring") &&
            c.label() != v.label()) {
          bool dup = false;
          for (const auto& o : D.candidates[static_cast<std::size_t>(D.verdict)].confounded) dup |= o.with == c.label();
          if (!dup)
            D.candidates[static_cast<std::size_t>(D.verdict)].confounded.push_back(
                {c.label(), c.effect, c.axis, 0.0, "move axis " + ax + " in both directions"});
        }
    }
  }
  if (!E.unidentifiable_base().empty()) {
    std::string names;
    for (int j : E.unidentifiable_base()) names += (names.empty() ? "" : ", ") + P.base_params[j].name;
    D.notes.push_back("these data cannot determine the base parameter(s) " + names +
                      "; they are kept at the model's values");
  }
  name_missing_delay(D, E, opt);
  if (opt.structure_search) D.structure = find_motion_structure(P, D.residual_final, D.axis_noise);
  return D;
}
}  // namespace

}  // namespace cpm::ident

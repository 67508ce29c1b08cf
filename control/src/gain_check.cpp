// SPDX-License-Identifier: Apache-2.0
#include "cpm/control/gain_check.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <functional>
#include <tuple>

namespace cpm::ctl {

namespace {

constexpr std::array<const char*, 3> kAxis{"x", "y", "z"};
// Poses per stroke on the grid the effective masses and the holding forces
// are taken over: 9^3 = 729 poses, within 0.1 % of a 33^3 grid on the
// nominal machine (docs/model.md).
constexpr int kGridPoints = 9;
// Relative width to which the gain bounds are bisected.
constexpr double kBoundTolerance = 1e-5;

// All roots of a_0 + a_1 z + ... + a_d z^d strictly within |z| < r: the
// Schur-Cohn recursion on a(r z), each step dividing out one reflection
// coefficient (a Levinson step). O(d^2).
struct Scratch {
  std::vector<double> a, w, next;
};
bool roots_within(const std::vector<double>& a, double r, Scratch& s) {
  std::vector<double>& w = s.w;
  w.resize(a.size());
  double scale = 1.0;
  for (std::size_t j = 0; j < a.size(); ++j, scale *= r) w[j] = a[j] * scale;
  for (std::size_t k = a.size() - 1; k > 0; --k) {
    const double lead = w[k];
    if (!std::isfinite(lead) || lead == 0.0) return false;
    const double g = w[0] / lead;
    if (!(std::abs(g) < 1.0)) return false;
    // (w(z) - g z^k w(1/z)) / z, over the leading coefficient.
    const double inv = 1.0 / lead;
    s.next.resize(k);
    for (std::size_t j = 0; j < k; ++j) s.next[j] = (w[j + 1] - g * w[k - 1 - j]) * inv;
    std::swap(w, s.next);
  }
  return true;
}

double spectral_radius_of(const std::vector<double>& a, Scratch& s) {
  // Cauchy's bound holds every root; bisect on the radius.
  double hi = 0.0;
  for (std::size_t j = 0; j + 1 < a.size(); ++j) hi = std::max(hi, std::abs(a[j] / a.back()));
  hi += 1.0;
  double lo = 0.0;
  while (hi - lo > 1e-10 * hi) {
    const double mid = 0.5 * (lo + hi);
    (roots_within(a, mid, s) ? hi : lo) = mid;
  }
  return hi;
}

// Numbers in sentences: `sig` significant digits, no exponent, no trailing
// zeros; a bound is rounded towards the inside (round < 0: down, > 0: up).
std::string figure(double v, int sig = 4, int round = 0) {
  if (!std::isfinite(v)) return std::isnan(v) ? "nan" : (v > 0 ? "inf" : "-inf");
  const int before = v == 0.0 ? 1 : static_cast<int>(std::floor(std::log10(std::abs(v)))) + 1;
  const int decimals = std::max(0, sig - before);
  if (round != 0) {
    const double scale = std::pow(10.0, sig - before);
    v = (round < 0 ? std::floor(v * scale) : std::ceil(v * scale)) / scale;
  }
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
  std::string s = buf;
  if (s.find('.') != std::string::npos) {
    s.erase(s.find_last_not_of('0') + 1);
    if (s.back() == '.') s.pop_back();
  }
  return s;
}

std::string millimetres(double metres) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.3f", metres * 1e3);
  return buf;
}

struct Units {
  const char* kp;
  const char* kd;
};
Units units(ControlLaw law) {
  return law == ControlLaw::computed_torque ? Units{"1/s^2", "1/s"} : Units{"N/m", "N s/m"};
}

struct Interval {
  double lo = 0.0, hi = 0.0;  // 0, 0: none
  [[nodiscard]] bool empty() const { return !(hi > 0.0); }
};

// The interval of gains g around `given` (or, when that one fails, around the
// point nearest it on a logarithmic scan of [1e-12, 10] x scale) on which
// `ok` holds: bracketed by doubling and halving, then bisected. The set is
// one interval for these loops (the lower end is too slow a pole, the upper
// one too fast), which the scan only has to hit once.
Interval gain_interval(const std::function<bool(double)>& ok, double given, double scale) {
  double g0 = 0.0;
  if (ok(given)) {
    g0 = given;
  } else {
    double best = INFINITY;
    for (int k = -48; k <= 4; ++k) {
      const double g = scale * std::pow(10.0, k / 4.0);
      const double dist = std::abs(std::log(g / given));
      if (dist < best && ok(g)) {
        best = dist;
        g0 = g;
      }
    }
    if (g0 == 0.0) return {};
  }
  auto edge = [&](double factor) {
    double in = g0, out = g0 * factor;
    for (int i = 0; i < 200 && ok(out); ++i) in = out, out *= factor;
    if (ok(out)) return factor > 1.0 ? INFINITY : 0.0;
    while (std::abs(out - in) > kBoundTolerance * in) {
      const double mid = std::sqrt(in * out);
      (ok(mid) ? in : out) = mid;
    }
    return in;
  };
  return {edge(0.5), edge(2.0)};
}

struct AxisFigures {
  double rho = 0.0;
  bool lightest = true;  // the mass that gives rho
  Interval kp, kd;
};

}  // namespace

double max_spectral_radius(double rate_hz) noexcept { return std::exp(-1.0 / (rate_hz * kSlowestTimeConstant)); }

void loop_polynomial(const AxisLoop& loop, double kp, double kd, std::vector<double>& a) {
  const double T = loop.period, m = loop.mass;
  // tau = (n + f) T; a fraction within 1e-6 of a whole period is that period
  // (as integrate_delayed snaps its switching instants).
  const double q = loop.delay / T;
  const int n = static_cast<int>(std::floor(q + 1e-6));
  const double f = std::max(0.0, q - n) < 1e-6 ? 0.0 : q - n;
  // Over a period the older command u_k-n-1 acts for T1 = f T, then u_k-n
  // for T0: x_k+1 = Phi x_k + B1 u_k-n-1 + B0 u_k-n with Phi = [1 T; 0 1],
  // B0 = Gamma(T0), B1 = Phi(T0) Gamma(T1), Gamma(t) = (t^2 / 2m, t / m).
  const double T0 = (1.0 - f) * T, T1 = f * T;
  const double b0x = T0 * T0 / (2 * m), b0v = T0 / m;
  const double b1x = T1 * T1 / (2 * m) + T0 * T1 / m, b1v = T1 / m;
  // x = [(z - 1) b_x + T b_v] u / ((z - 1)^2 z^n), v = (z - 1) b_v u / (...),
  // b(z) = B0 z + B1 over z: S(z) = (z - 1)(b0x z + b1x) + T (b0v z + b1v).
  const std::array<double, 3> S{-b1x + T * b1v, b1x - b0x + T * b0v, b0x};
  const bool diff = loop.velocity == VelocityMeasurement::difference;
  const int shift = n + 1 + (diff ? 1 : 0);
  a.assign(static_cast<std::size_t>(shift + 3), 0.0);
  const auto at = [&](int j) -> double& { return a[static_cast<std::size_t>(j)]; };
  at(shift) += 1.0;  // z^shift (z - 1)^2
  at(shift + 1) -= 2.0;
  at(shift + 2) += 1.0;
  if (diff) {
    // u = -((kp + kd / T) z - kd / T) x / z
    const double c1 = kp + kd / T, c0 = -kd / T;
    for (int j = 0; j < 3; ++j) {
      at(j) += c0 * S[static_cast<std::size_t>(j)];
      at(j + 1) += c1 * S[static_cast<std::size_t>(j)];
    }
  } else {
    for (int j = 0; j < 3; ++j) at(j) += kp * S[static_cast<std::size_t>(j)];
    // kd (z - 1)(b0v z + b1v)
    at(0) -= kd * b1v;
    at(1) += kd * (b1v - b0v);
    at(2) += kd * b0v;
  }
}

double loop_spectral_radius(const AxisLoop& loop, double kp, double kd) {
  Scratch s;
  loop_polynomial(loop, kp, kd, s.a);
  return spectral_radius_of(s.a, s);
}

GainVerdict check_gains(const Machine& model, ControlLaw law, const Gains& gains, double rate_hz, double max_sag,
                        VelocityMeasurement velocity) {
  if (!std::isfinite(rate_hz) || !(rate_hz > 0.0))
    throw Error("gain check: the loop rate must be finite and > 0 Hz, got " + figure(rate_hz));
  if (!std::isfinite(max_sag) || !(max_sag > 0.0))
    throw Error("gain check: the largest sag allowed must be finite and > 0 m, got " + figure(max_sag));
  GainVerdict v;
  const Units u = units(law);
  const std::string law_s = law_name(law);
  const auto refuse = [&](int axis, std::string reason) {
    v.ok = false;
    v.axis = axis;
    v.reason = law_s + ": " + std::move(reason);
    return v;
  };
  for (int i = 0; i < 3; ++i) {
    for (const auto& [key, value, unit] : {std::tuple{"kp", gains.kp[i], u.kp}, std::tuple{"kd", gains.kd[i], u.kd}})
      if (!std::isfinite(value) || !(value > 0.0))
        return refuse(i, std::string(key) + "_" + kAxis[static_cast<std::size_t>(i)] + " = " + figure(value) + " " +
                             unit + ": a gain must be finite and > 0.");
  }

  // Effective masses and the force that holds the platform, over the strokes.
  Vec3 holding = Vec3::Zero();
  if (law == ControlLaw::computed_torque) {
    v.mass_min.setOnes();
    v.mass_max.setOnes();
  } else {
    v.mass_min.setConstant(INFINITY);
    v.mass_max.setConstant(0.0);
    const kin::Strokes& s = model.model().strokes;
    int poses = 0;
    for (int i = 0; i < kGridPoints; ++i)
      for (int j = 0; j < kGridPoints; ++j)
        for (int k = 0; k < kGridPoints; ++k) {
          const Vec3 d = s.min + (s.max - s.min).cwiseProduct(Vec3(i, j, k) / (kGridPoints - 1));
          Vec3 p;
          Mat3 J;
          RigidBodyTerms t;
          // Poses the model cannot reach (a calibrated model near a stroke's end) are not the machine's.
          if (!kin::forward(model.kinematics(), d, {}, p) || !model.jacobian(d, p, {}, J) ||
              !model.rigid_body(p, Vec3::Zero(), t))
            continue;
          const Vec3 mass = (J.transpose() * t.M * J).diagonal();
          v.mass_min = v.mass_min.cwiseMin(mass);
          v.mass_max = v.mass_max.cwiseMax(mass);
          Vec3 hold;
          if (law == ControlLaw::pd && model.holding_command(p, {}, hold)) holding = holding.cwiseMax(hold.cwiseAbs());
          ++poses;
        }
    if (poses == 0) throw Error("gain check: no pose on the model's strokes is in its workspace");
  }

  const double T = 1.0 / rate_hz, r = max_spectral_radius(rate_hz);
  Scratch sc;
  std::vector<double>& a = sc.a;
  std::array<AxisFigures, 3> fig;
  for (int i = 0; i < 3; ++i) {
    const AxisLoop light{v.mass_min[i], T, model.actuation_delay(), velocity};
    AxisLoop heavy = light;
    heavy.mass = v.mass_max[i];
    const auto settles = [&](double kp, double kd) {
      for (const AxisLoop* l : std::array<const AxisLoop*, 2>{&light, &heavy}) {
        loop_polynomial(*l, kp, kd, a);
        if (!roots_within(a, r, sc)) return false;
      }
      return true;
    };
    AxisFigures& f = fig[static_cast<std::size_t>(i)];
    const double kp = gains.kp[i], kd = gains.kd[i];
    loop_polynomial(light, kp, kd, a);
    const double rho_light = spectral_radius_of(a, sc);
    loop_polynomial(heavy, kp, kd, a);
    const double rho_heavy = spectral_radius_of(a, sc);
    f.lightest = rho_light >= rho_heavy;
    f.rho = std::max(rho_light, rho_heavy);
    f.kp = gain_interval([&](double g) { return settles(g, kd); }, kp, light.mass / (T * T));
    f.kd = gain_interval([&](double g) { return settles(kp, g); }, kd, light.mass / T);
    v.kp_min[i] = f.kp.lo;
    v.kp_max[i] = f.kp.hi;
    v.kd_min[i] = f.kd.lo;
    v.kd_max[i] = f.kd.hi;
    v.spectral_radius = std::max(v.spectral_radius, f.rho);
  }
  int sag_axis = -1;
  if (law == ControlLaw::pd)
    for (int i = 0; i < 3; ++i)
      if (holding[i] / gains.kp[i] > v.sag) {
        v.sag = holding[i] / gains.kp[i];
        sag_axis = i;
      }

  // A pole outside the unit circle first, then the sag, then a pole too slow.
  const auto pole = [&](int i) {
    const AxisFigures& f = fig[static_cast<std::size_t>(i)];
    const std::string ax = kAxis[static_cast<std::size_t>(i)];
    const double kp = gains.kp[i], kd = gains.kd[i];
    std::string s = "kp_" + ax + " = " + figure(kp) + " " + u.kp + " and kd_" + ax + " = " + figure(kd) + " " + u.kd;
    if (law != ControlLaw::computed_torque)
      s += " with the " + ax + " actuator's " + (f.lightest ? "lightest" : "heaviest") + " effective mass " +
           figure(f.lightest ? v.mass_min[i] : v.mass_max[i], 3) + " kg";
    s += " at " + figure(rate_hz) + " Hz put a closed-loop pole at |z| = " + figure(f.rho, 5);
    if (f.rho < 1.0)
      s += ", which decays with a time constant of " + figure(-T / std::log(f.rho), 2) + " s, more than " +
           figure(kSlowestTimeConstant, 1) + " s";
    // Advise on the gain that needs the smaller change.
    const auto change = [](double g, const Interval& in) {
      return in.empty() ? INFINITY : std::abs(std::log(std::clamp(g, in.lo, in.hi) / g));
    };
    const double ckp = change(kp, f.kp), ckd = change(kd, f.kd);
    if (!std::isfinite(ckp) && !std::isfinite(ckd)) {
      s += ": no kd keeps every pole within |z| < " + figure(r, 5) + " with this kp, nor any kp with this kd.";
    } else if (ckd <= ckp) {
      s += std::string(": ") + (kd > f.kd.hi ? "at most " + figure(f.kd.hi, 4, -1) : "at least " + figure(f.kd.lo, 4, +1)) + " " +
           u.kd + " keeps every pole within |z| < " + figure(r, 5) + " with this kp.";
    } else {
      s += std::string(": ") + (kp > f.kp.hi ? "at most " + figure(f.kp.hi, 4, -1) : "at least " + figure(f.kp.lo, 4, +1)) + " " +
           u.kp + " keeps every pole within |z| < " + figure(r, 5) + " with this kd.";
    }
    return refuse(i, s);
  };
  int worst = 0;
  for (int i = 1; i < 3; ++i)
    if (fig[static_cast<std::size_t>(i)].rho > fig[static_cast<std::size_t>(worst)].rho) worst = i;
  if (!(fig[static_cast<std::size_t>(worst)].rho < 1.0)) return pole(worst);
  if (v.sag > max_sag) {
    const std::string ax = kAxis[static_cast<std::size_t>(sag_axis)];
    return refuse(sag_axis, "kp_" + ax + " = " + figure(gains.kp[sag_axis]) + " N/m would let " + ax + " sag " +
                                figure(v.sag * 1e3, 3) + " mm under the weight it holds (" +
                                figure(holding[sag_axis], 3) + " N), more than the " + millimetres(max_sag) +
                                " mm the following-error limit allows: at least " +
                                figure(holding[sag_axis] / max_sag, 4, +1) + " N/m holds it, or a law with gravity.");
  }
  if (!(fig[static_cast<std::size_t>(worst)].rho < r)) return pole(worst);
  return v;
}

}  // namespace cpm::ctl

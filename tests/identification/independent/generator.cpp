// SPDX-License-Identifier: Apache-2.0
#include "generator.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <sstream>

namespace cpm::indep {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

// Per axis three sines; the frequencies (Hz) are pairwise incommensurate
// (no small integer ratios) so the path never repeats within a log.
constexpr double kFreq[3][3] = {{0.2317, 0.6143, 1.1321}, {0.2861, 0.7079, 1.3687}, {0.1931, 0.5273, 1.0119}};
constexpr double kAmp[3][3] = {{0.070, 0.035, 0.012}, {0.070, 0.035, 0.012}, {0.045, 0.025, 0.010}};
constexpr double kCentre[3] = {0.425, 0.425, 0.36};
constexpr double kRamp = 2.0;  // s: the excitation grows from rest over this time

// C3 smoothstep s(u) = 35u^4 - 84u^5 + 70u^6 - 20u^7 and its derivatives in t.
void ramp(double t, double& s, double& sd, double& sdd) noexcept {
  if (t >= kRamp) {
    s = 1.0;
    sd = sdd = 0.0;
    return;
  }
  const double u = std::max(t, 0.0) / kRamp;
  const double u2 = u * u, w = 1.0 - u;
  s = u2 * u2 * (35.0 - 84.0 * u + 70.0 * u2 - 20.0 * u2 * u);
  sd = 140.0 * u2 * u * w * w * w / kRamp;
  sdd = 420.0 * u2 * w * w * (1.0 - 2.0 * u) / (kRamp * kRamp);
}

struct Clock {
  double T = 0.0;   // sample period
  int n = 0;        // internal steps per period (even)
  double h = 0.0;   // internal step
};

Clock make_clock(const GeneratorSpec& s) {
  if (!(s.rate > 0.0) || !std::isfinite(s.rate)) throw Error("generator: rate must be > 0 Hz");
  if (!(s.max_step > 0.0)) throw Error("generator: max_step must be > 0 s");
  Clock c;
  c.T = 1.0 / s.rate;
  c.n = static_cast<int>(std::ceil(c.T / s.max_step - 1e-9));
  c.n = std::max(2, c.n + (c.n % 2));  // even: the 1.5 T switch falls on a step boundary
  c.h = c.T / c.n;
  return c;
}

void check(const Status& s, const char* what, double t) {
  if (!s) {
    std::ostringstream os;
    os << "generator: " << what << " failed at t = " << t << " s: " << fault_name(s.fault);
    throw Error(os.str());
  }
}

}  // namespace

const char* timing_name(Timing t) noexcept {
  switch (t) {
    case Timing::sampled: return "sampled";
    case Timing::zoh: return "zoh";
    case Timing::delay1: return "delay1";
    case Timing::delay1_5: return "delay1_5";
  }
  return "?";
}

const char* noise_name(NoisePlacement n) noexcept { return n == NoisePlacement::plant ? "plant" : "command"; }

Timing timing_from_name(const std::string& s) {
  for (Timing t : {Timing::sampled, Timing::zoh, Timing::delay1, Timing::delay1_5})
    if (s == timing_name(t)) return t;
  throw Error("unknown timing '" + s + "' (sampled, zoh, delay1, delay1_5)");
}

NoisePlacement noise_from_name(const std::string& s) {
  if (s == "plant") return NoisePlacement::plant;
  if (s == "command") return NoisePlacement::command;
  throw Error("unknown noise placement '" + s + "' (plant, command)");
}

double delay_periods(Timing t) noexcept {
  return t == Timing::delay1 ? 1.0 : t == Timing::delay1_5 ? 1.5 : 0.0;
}

Excitation::Excitation(std::uint64_t seed) {
  // Phases from the seed: every seed a different path through the same band.
  std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ULL + 17);
  std::uniform_real_distribution<double> ph(0.0, kTwoPi);
  for (auto& axis : phase_)
    for (double& p : axis) p = ph(rng);
}

Excitation::Excitation(double radius, double omega) : radius_(radius), omega_(omega) {}

Reference excitation(double t, std::uint64_t seed) { return Excitation(seed)(t); }

Reference Excitation::operator()(double t) const noexcept {
  double s, sd, sdd;
  ramp(t, s, sd, sdd);
  Reference r;
  for (int i = 0; i < 3; ++i) {
    double f = 0.0, fd = 0.0, fdd = 0.0;
    if (radius_ > 0.0 && i < 2) {
      const double x = omega_ * t, w = omega_;
      f = radius_ * (i == 0 ? std::sin(x) : std::cos(x));
      fd = radius_ * w * (i == 0 ? std::cos(x) : -std::sin(x));
      fdd = -w * w * f;
    }
    for (int j = 0; j < 3 && radius_ <= 0.0; ++j) {
      const double w = kTwoPi * kFreq[i][j], phi = phase_[i][j];
      // No offset: the ramp (s(0) = 0) starts the path at the centre at rest,
      // and the excursion stays within the centre +- the sum of the amplitudes.
      const double x = w * t + phi;
      f += kAmp[i][j] * std::sin(x);
      fd += kAmp[i][j] * w * std::cos(x);
      fdd += -kAmp[i][j] * w * w * std::sin(x);
    }
    r.p[i] = kCentre[i] + s * f;
    r.v[i] = sd * f + s * fd;
    r.a[i] = sdd * f + 2.0 * sd * fd + s * fdd;
  }
  return r;
}

const char* outside_kind_name(OutsideForce::Kind k) noexcept {
  switch (k) {
    case OutsideForce::Kind::cross_velocity: return "cross_velocity";
    case OutsideForce::Kind::bump: return "bump";
    case OutsideForce::Kind::velocity_hump: return "velocity_hump";
    case OutsideForce::Kind::cross_velocity_hump: return "cross_velocity_hump";
    case OutsideForce::Kind::position_friction: return "position_friction";
    default: return "cubic";
  }
}

int outside_velocity_axis(const OutsideForce& f) noexcept {
  switch (f.kind) {
    case OutsideForce::Kind::cross_velocity:
    case OutsideForce::Kind::cross_velocity_hump: return f.from_axis;
    case OutsideForce::Kind::velocity_hump: return f.axis;
    default: return -1;
  }
}

Vec3 outside_forces(const std::vector<OutsideForce>& forces, const Vec3& d, const Vec3& v) {
  Vec3 f = Vec3::Zero();
  for (const OutsideForce& o : forces) {
    const double u = (d[o.axis] - o.centre) / o.width;
    switch (o.kind) {
      case OutsideForce::Kind::cross_velocity: f[o.axis] += o.size * v[o.from_axis]; break;
      case OutsideForce::Kind::bump: f[o.axis] += o.size * std::exp(-0.5 * u * u); break;
      case OutsideForce::Kind::cubic: f[o.axis] += o.size * u * u * u; break;
      case OutsideForce::Kind::velocity_hump:
      case OutsideForce::Kind::cross_velocity_hump: {
        const double w = v[outside_velocity_axis(o)] / o.width;
        f[o.axis] += o.size * w * std::exp(0.5 * (1.0 - w * w));
        break;
      }
      case OutsideForce::Kind::position_friction:
        // The switch of direction spread over 2 mm/s: a real contact's
        // pre-sliding, not a step (and not the estimator's own smoothing).
        f[o.axis] += o.size * (0.65 + 0.35 * u) * std::tanh(v[o.axis] / 2e-3);
        break;
    }
  }
  return f;
}

ctl::MachineModel true_model(const std::vector<PlantedEffect>& effects) {
  ctl::MachineModel m = ctl::MachineModel::elkady();
  for (const PlantedEffect& e : effects) ctl::add_effect(m, e.name, e.axis, e.values);
  return m;
}

GeneratedLog generate(const GeneratorSpec& spec) {
  if (!(spec.duration > 0.0)) throw Error("generator: duration must be > 0 s");
  const Clock clk = make_clock(spec);
  // The rotors' reflected inertia (actuator_inertia, m_i on actuator i) is
  // this generator's own: diag(m) added to J^T M J below, not the Machine's.
  Vec3 rotor = Vec3::Zero();
  std::vector<PlantedEffect> rigid;
  for (const PlantedEffect& e : spec.effects) {
    if (e.name != "actuator_inertia") {
      rigid.push_back(e);
      continue;
    }
    if (e.axis < 0 || e.axis > 2 || e.values.size() != 1) throw Error("generator: actuator_inertia needs an axis and m (kg)");
    rotor[e.axis] += e.values[0];
  }
  ctl::MachineModel truth_model = true_model(rigid);
  for (const std::string& u : spec.user_effects) ctl::add_user_effect(truth_model, u);
  const ctl::Machine truth(truth_model);
  if (truth.user_effects_use_acceleration()) throw Error("generator: user effects that read a1..a3 are not planted");
  const ctl::Machine nominal(ctl::MachineModel::elkady());
  if (!truth.has_constant_jacobian() || !nominal.has_constant_jacobian())
    throw Error("generator: only machines without kinematic effects (constant J)");
  const Mat3 Jt = truth.constant_jacobian();
  const Vec3 gain = truth.drive_gain();
  const double limit = nominal.force_limit();
  const kin::KinematicInputs kin_in{};

  // The truth's planes are affine: p = p0 + J d.
  ctl::TaskState ts0;
  check(truth.task_state(Vec3::Zero(), Vec3::Zero(), kin_in, ts0), "forward kinematics", 0.0);
  const Vec3 p0 = ts0.p;

  std::mt19937_64 rng_enc(spec.seed * 1000003ULL + 1), rng_dist(spec.seed * 1000003ULL + 2),
      rng_force(spec.seed * 1000003ULL + 3);
  std::normal_distribution<double> n01(0.0, 1.0);
  auto draw3 = [&](std::mt19937_64& g, double sigma) {
    return Vec3(sigma * n01(g), sigma * n01(g), sigma * n01(g));
  };

  // The controller: PD + the nominal model's feed-forward along the
  // reference, in task space, mapped to the actuators by J^T, clamped.
  const Excitation path = spec.circle_radius > 0.0 ? Excitation(spec.circle_radius, spec.circle_omega)
                                                  : Excitation(spec.seed);
  auto control = [&](double t, const Vec3& d_meas, const Vec3& v_meas) {
    const Reference ref = path(t);
    ctl::TaskState ts;
    check(nominal.task_state(d_meas, v_meas, kin_in, ts), "controller kinematics", t);
    ctl::RigidBodyTerms rb;
    check(nominal.rigid_body(ref.p, ref.v, rb), "controller dynamics", t);
    const Vec3 f_task =
        rb.M * ref.a + rb.Gv + rb.K + spec.kp * (ref.p - ts.p) + spec.kd * (ref.v - ts.p_dot);
    Vec3 f = ts.J.transpose() * f_task;
    for (int i = 0; i < 3; ++i) f[i] = std::clamp(f[i], -limit, limit);
    return f;
  };

  // The true plant in actuator coordinates (J constant, so p_dd = J d_dd):
  //   (J^T M J + diag(rotor)) d_dd = gain * u + w - f_eff(d, v) - J^T (G p_dot + K).
  auto accel = [&](double t, const Vec3& d, const Vec3& v, const Vec3& u, const Vec3& w) {
    const Vec3 p = p0 + Jt * d, p_dot = Jt * v;
    ctl::RigidBodyTerms rb;
    check(truth.rigid_body(p, p_dot, rb), "plant dynamics", t);
    const Mat3 Ma = Jt.transpose() * rb.M * Jt + Mat3(rotor.asDiagonal());
    const Vec3 rhs = gain.cwiseProduct(u) + w - truth.effect_forces(d, v) - outside_forces(spec.outside, d, v) -
                     Jt.transpose() * (rb.Gv + rb.K);
    return Vec3(Ma.ldlt().solve(rhs));
  };

  const long K = std::lround(spec.duration * spec.rate) + 1;
  GeneratedLog out;
  out.step = clk.h;
  out.substeps = clk.n;
  io::MotionData& L = out.log;
  L.info.path = std::string("independent-") + timing_name(spec.timing) + "-" + noise_name(spec.noise);
  L.rate = spec.rate;
  L.t.reserve(static_cast<std::size_t>(K));
  L.d.reserve(static_cast<std::size_t>(K));
  L.v.reserve(static_cast<std::size_t>(K));
  L.f.reserve(static_cast<std::size_t>(K));

  // Start at rest on the reference.
  const Reference r0 = path(0.0);
  Vec3 d = Jt.inverse() * (r0.p - p0), v = Vec3::Zero();
  const kin::Strokes& st = truth.model().strokes;
  out.d_min = out.d_max = d;

  for (long k = 0; k < K; ++k) {
    const double tk = static_cast<double>(k) * clk.T;
    for (int i = 0; i < 3; ++i)
      if (d[i] < st.min[i] || d[i] > st.max[i]) {
        std::ostringstream os;
        os << "generator: axis " << i + 1 << " left its stroke at t = " << tk << " s (d = " << d[i] << " m)";
        throw Error(os.str());
      }
    out.d_min = out.d_min.cwiseMin(d);
    out.d_max = out.d_max.cwiseMax(d);
    const Vec3 d_meas = d + draw3(rng_enc, spec.position_noise);
    const Vec3 v_meas = v + draw3(rng_enc, spec.velocity_noise);
    const Vec3 f_cmd = control(tk, d_meas, v_meas);
    out.commanded.push_back(f_cmd);
    out.d_true.push_back(d);
    out.v_true.push_back(v);
    out.max_abs_force = std::max(out.max_abs_force, f_cmd.cwiseAbs().maxCoeff());
    L.t.push_back(tk);
    L.d.push_back(d_meas);
    L.v.push_back(v_meas);
    L.f.push_back(spec.noise == NoisePlacement::command ? Vec3(f_cmd + draw3(rng_force, spec.force_noise_sigma))
                                                         : f_cmd);
    if (k + 1 == K) break;

    const Vec3 w = spec.noise == NoisePlacement::plant ? draw3(rng_dist, spec.disturbance_sigma) : Vec3::Zero();
    out.disturbance.push_back(w);
    auto held = [&](long j) { return out.commanded[static_cast<std::size_t>(std::max(j, 0L))]; };
    Vec3 mean = Vec3::Zero();
    Vec3 enc_d = d_meas - d, enc_v = v_meas - v;  // the controller's encoder noise over the current step
    for (int j = 0; j < clk.n; ++j) {
      const double t = tk + j * clk.h;
      if (spec.timing == Timing::sampled) {
        // A continuous controller: its force follows the state within the step.
        if (j > 0) {
          enc_d = draw3(rng_enc, spec.position_noise);
          enc_v = draw3(rng_enc, spec.velocity_noise);
        }
        auto u_at = [&](double ts_, const Vec3& ds, const Vec3& vs) { return control(ts_, ds + enc_d, vs + enc_v); };
        const Vec3 u1 = u_at(t, d, v);
        const Vec3 a1 = accel(t, d, v, u1, w);
        const Vec3 d2 = d + 0.5 * clk.h * v, v2 = v + 0.5 * clk.h * a1;
        const Vec3 u2 = u_at(t + 0.5 * clk.h, d2, v2);
        const Vec3 a2 = accel(t + 0.5 * clk.h, d2, v2, u2, w);
        const Vec3 d3 = d + 0.5 * clk.h * v2, v3 = v + 0.5 * clk.h * a2;
        const Vec3 u3 = u_at(t + 0.5 * clk.h, d3, v3);
        const Vec3 a3 = accel(t + 0.5 * clk.h, d3, v3, u3, w);
        const Vec3 d4 = d + clk.h * v3, v4 = v + clk.h * a3;
        const Vec3 u4 = u_at(t + clk.h, d4, v4);
        const Vec3 a4 = accel(t + clk.h, d4, v4, u4, w);
        d += clk.h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4);
        v += clk.h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4);
        mean += (u1 + 2.0 * u2 + 2.0 * u3 + u4) / (6.0 * clk.n);
        continue;
      }
      Vec3 u;
      switch (spec.timing) {
        case Timing::zoh: u = held(k); break;
        case Timing::delay1: u = held(k - 1); break;
        default: u = j < clk.n / 2 ? held(k - 2) : held(k - 1); break;  // delay1_5
      }
      // RK4 with the drive input constant over the step (it switches only on step boundaries).
      const Vec3 a1 = accel(t, d, v, u, w);
      const Vec3 d2 = d + 0.5 * clk.h * v, v2 = v + 0.5 * clk.h * a1;
      const Vec3 a2 = accel(t + 0.5 * clk.h, d2, v2, u, w);
      const Vec3 d3 = d + 0.5 * clk.h * v2, v3 = v + 0.5 * clk.h * a2;
      const Vec3 a3 = accel(t + 0.5 * clk.h, d3, v3, u, w);
      const Vec3 d4 = d + clk.h * v3, v4 = v + clk.h * a3;
      const Vec3 a4 = accel(t + clk.h, d4, v4, u, w);
      d += clk.h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4);
      v += clk.h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4);
      mean += u / clk.n;
    }
    out.applied_mean.push_back(mean);
  }
  L.info.metadata["generator"] = "tests/identification/independent";
  L.info.metadata["timing"] = timing_name(spec.timing);
  L.info.metadata["noise"] = noise_name(spec.noise);
  L.info.metadata["seed"] = std::to_string(spec.seed);
  return out;
}

}  // namespace cpm::indep

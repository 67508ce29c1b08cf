// SPDX-License-Identifier: Apache-2.0
#include "cpm/calibration/circular_test.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <sstream>

#include "cpm/sim/closed_loop.hpp"

namespace cpm::cal {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

double wrap(double a) {
  a = std::fmod(a, kTwoPi);
  return a < 0.0 ? a + kTwoPi : a;
}

// Linearised least-squares centre: dr = r0 + a cos + b sin.
Eigen::Vector3d lsc(const std::vector<const CircularTrace*>& traces) {
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d y = Eigen::Vector3d::Zero();
  for (const CircularTrace* t : traces)
    for (std::size_t k = 0; k < t->angle.size(); ++k) {
      const Eigen::Vector3d row(1.0, std::cos(t->angle[k]), std::sin(t->angle[k]));
      A += row * row.transpose();
      y += row * t->deviation[k];
    }
  return A.ldlt().solve(y);
}

double centred(const CircularTrace& t, std::size_t k, const Eigen::Vector3d& c) {
  return t.deviation[k] - c[1] * std::cos(t.angle[k]) - c[2] * std::sin(t.angle[k]);
}

CircularRunMetrics metrics(const CircularTrace& t) {
  CircularRunMetrics m;
  const Eigen::Vector3d c = lsc({&t});
  m.lsc_r0 = c[0];
  m.lsc_a = c[1];
  m.lsc_b = c[2];
  double lo = INFINITY, hi = -INFINITY;
  m.F_max = -INFINITY;
  m.F_min = INFINITY;
  for (std::size_t k = 0; k < t.angle.size(); ++k) {
    const double e = centred(t, k, c);
    lo = std::min(lo, e);
    hi = std::max(hi, e);
    m.F_max = std::max(m.F_max, t.deviation[k]);
    m.F_min = std::min(m.F_min, t.deviation[k]);
  }
  m.G = hi - lo;
  return m;
}

// Value of a trace at angle a by linear interpolation (the trace is sorted by angle, periodic).
double at_angle(const std::vector<std::pair<double, double>>& s, double a) {
  auto it = std::lower_bound(s.begin(), s.end(), std::make_pair(a, -std::numeric_limits<double>::infinity()));
  const auto& hi = it == s.end() ? s.front() : *it;
  const auto& lo = it == s.begin() ? s.back() : *(it - 1);
  double span = hi.first - lo.first;
  double x = a - lo.first;
  if (span <= 0.0) span += kTwoPi;
  if (x < 0.0) x += kTwoPi;
  return lo.second + (hi.second - lo.second) * (span > 0.0 ? x / span : 0.0);
}

// One run: returns the trace (and accumulates servo error).
CircularTrace run_one(const ctl::Machine& truth, const ctl::Machine& model, const CircularTestSpec& s,
                      const Vec3& pivot, double direction, double& servo_sq, long& servo_n) {
  const auto [ia, ib] = plane_axes(s.plane);
  ctl::CircleSpec c;
  c.centre = s.centre;
  c.radius = s.radius;
  c.plane = s.plane;
  c.angular_speed = direction * s.feed / s.radius;
  c.start_angle = 0.0;
  c.ramp_time = s.overshoot_time;
  c.cruise_time = kTwoPi * s.radius / s.feed;
  const ctl::CircleTrajectory traj(c);
  CircularTrace tr;
  double next = -1.0;  // keep a point every trace_step of travelled angle
  auto keep = [&](const Vec3& p_ref, const Vec3& p_true, double travelled) {
    // Kinematic runs pass travelled < 0: every point is kept.
    if (travelled >= 0.0 && travelled < next - 1e-6 * s.trace_step) return;
    next = std::max(next, 0.0) + s.trace_step;
    if (next <= travelled) next = travelled + s.trace_step;
    const double phi = wrap(std::atan2(p_ref[ib] - s.centre[ib], p_ref[ia] - s.centre[ia]));
    tr.angle.push_back(phi);
    tr.deviation.push_back((p_true - pivot).norm() - s.radius);
  };
  const double t0 = s.overshoot_time, t1 = s.overshoot_time + c.cruise_time;
  if (s.closed_loop) {
    const ctl::Gains g = s.gains ? *s.gains : ctl::table3_gains(s.law);
    const ctl::Controller ctrl(model, s.law, g);
    sim::Plant plant(truth, sim::PlantOptions{});
    sim::LoopOptions lo;
    lo.rate_hz = s.rate_hz;
    lo.keep_log = true;
    const sim::RunResult r = sim::run_closed_loop(ctrl, plant, traj, lo);
    if (!r.ok())
      throw Error(std::string("circular test (") + (direction > 0 ? "CCW" : "CW") +
                  "): the run stopped at t = " + std::to_string(r.fault_time) + " s: " +
                  describe(r.fault));
    for (const sim::LogRow& row : r.log) {
      if (row.t < t0 - 1e-9 || row.t > t1 + 1e-9) continue;
      keep(row.p_ref, row.p, std::abs(row.t - t0) * s.feed / s.radius);
      // The servo error as the controller sees it: reference minus its own estimate.
      Vec3 p_est;
      if (kin::forward(model.kinematics(), row.d, {}, p_est)) {
        servo_sq += (row.p_ref - p_est).squaredNorm();
        ++servo_n;
      }
    }
  } else {
    kin::KinematicInputs in;
    const int n = static_cast<int>(std::ceil(kTwoPi / s.trace_step));
    for (int k = 0; k < n; ++k) {  // the full circle, its end point (= start) once
      const double t = t0 + (t1 - t0) * k / n;
      const ctl::TrajectorySample ref = traj.sample(t);
      // The direction each axis moves in (backlash takes its side from it).
      for (int i = 0; i < 3; ++i)
        if (std::abs(ref.v[i]) > 1e-9) in.dir[i] = ref.v[i] > 0.0 ? +1 : -1;
      Vec3 d, p;
      if (Status st = kin::inverse(model.kinematics(), ref.p, in, d); !st)
        throw Error("circular test: the controller's model cannot reach the circle: " + describe(st));
      if (Status st = kin::forward(truth.kinematics(), d, in, p); !st)
        throw Error("circular test: the true machine cannot follow the circle: " + describe(st));
      keep(ref.p, p, -1.0);
    }
  }
  // Sort by angle for interpolation and plotting.
  std::vector<std::size_t> idx(tr.angle.size());
  for (std::size_t k = 0; k < idx.size(); ++k) idx[k] = k;
  std::sort(idx.begin(), idx.end(), [&](std::size_t a, std::size_t b) { return tr.angle[a] < tr.angle[b]; });
  CircularTrace sorted;
  for (std::size_t k : idx) {
    sorted.angle.push_back(tr.angle[k]);
    sorted.deviation.push_back(tr.deviation[k]);
  }
  return sorted;
}

}  // namespace

std::pair<int, int> plane_axes(ctl::CirclePlane p) {
  switch (p) {
    case ctl::CirclePlane::xy: return {0, 1};
    case ctl::CirclePlane::yz: return {1, 2};
    case ctl::CirclePlane::zx: return {2, 0};
  }
  return {0, 1};
}

const char* plane_name(ctl::CirclePlane p) {
  switch (p) {
    case ctl::CirclePlane::xy: return "XY";
    case ctl::CirclePlane::yz: return "YZ";
    case ctl::CirclePlane::zx: return "ZX";
  }
  return "?";
}

void CircularTestSpec::validate() const {
  if (!centre.allFinite()) throw Error("circular test: centre must be finite");
  if (!(radius > 0.0) || !std::isfinite(radius)) throw Error("circular test: radius must be > 0 m");
  if (!(feed > 0.0) || !std::isfinite(feed)) throw Error("circular test: feed must be > 0 m/s");
  if (feed > 1.0) throw Error("circular test: feed must be at most 1 m/s");
  if (!(overshoot_time > 0.0) || !std::isfinite(overshoot_time))
    throw Error("circular test: overshoot time must be > 0 s");
  if (!(trace_step > 0.0) || trace_step > 0.1) throw Error("circular test: trace step must be in (0, 0.1] rad");
  if (pivot && !pivot->allFinite()) throw Error("circular test: pivot must be finite");
}

CircularTestResult run_circular_test(const ctl::MachineModel& truth_model,
                                     const ctl::MachineModel& controller_model,
                                     const CircularTestSpec& s) {
  s.validate();
  const ctl::Machine truth(truth_model);
  const ctl::Machine model(controller_model);
  {
    // The whole path, overshoot arcs included, must be inside the controller's workspace.
    ctl::CircleSpec c;
    c.centre = s.centre;
    c.radius = s.radius;
    c.plane = s.plane;
    c.angular_speed = s.feed / s.radius;
    c.ramp_time = s.overshoot_time;
    c.cruise_time = kTwoPi * s.radius / s.feed;
    ctl::validate_trajectory(ctl::CircleTrajectory(c), model, 0.01);
  }
  CircularTestResult r;
  r.spec = s;
  if (s.pivot) {
    r.pivot = *s.pivot;
  } else {
    Vec3 d;
    if (Status st = kin::inverse(model.kinematics(), s.centre, {}, d); !st)
      throw Error("circular test: the centre is outside the controller's model: " + describe(st));
    if (Status st = kin::forward(truth.kinematics(), d, {}, r.pivot); !st)
      throw Error("circular test: the true machine cannot reach the centre: " + describe(st));
  }
  double servo_sq = 0.0;
  long servo_n = 0;
  r.ccw = run_one(truth, model, s, r.pivot, +1.0, servo_sq, servo_n);
  r.cw = run_one(truth, model, s, r.pivot, -1.0, servo_sq, servo_n);
  r.servo_rms = servo_n > 0 ? std::sqrt(servo_sq / static_cast<double>(servo_n)) : 0.0;
  evaluate_circular_traces(r);
  return r;
}

void evaluate_circular_traces(CircularTestResult& r) {
  r.ccw_metrics = metrics(r.ccw);
  r.cw_metrics = metrics(r.cw);
  r.F_max = std::max(r.ccw_metrics.F_max, r.cw_metrics.F_max);
  r.F_min = std::min(r.ccw_metrics.F_min, r.cw_metrics.F_min);
  r.max_abs_error = std::max(std::abs(r.F_max), std::abs(r.F_min));
  const Eigen::Vector3d c = lsc({&r.ccw, &r.cw});
  double lo = INFINITY, hi = -INFINITY;
  std::vector<std::pair<double, double>> cw_sorted;
  for (std::size_t k = 0; k < r.cw.angle.size(); ++k) {
    const double e = centred(r.cw, k, c);
    lo = std::min(lo, e);
    hi = std::max(hi, e);
    cw_sorted.emplace_back(r.cw.angle[k], e);
  }
  r.H = 0.0;
  for (std::size_t k = 0; k < r.ccw.angle.size(); ++k) {
    const double e = centred(r.ccw, k, c);
    lo = std::min(lo, e);
    hi = std::max(hi, e);
    r.H = std::max(r.H, std::abs(e - at_angle(cw_sorted, r.ccw.angle[k])));
  }
  r.G_bidirectional = hi - lo;
}

std::string circular_test_svg(const CircularTestResult& r, const std::string& title, double um_per_division) {
  // Plot on the left (rings up to R0 + 4 pitches, axes a little beyond), the
  // legend in its own column on the right, the title above everything.
  const double R0 = 180, cx = 330, cy = 370, W = 900, Hh = 710;
  // Scale: a "nice" number of µm per ring so that the largest deviation
  // spans about three rings; ring pitch 30 px.
  double maxdev = 1e-9;
  for (const CircularTrace* t : {&r.ccw, &r.cw})
    for (double v : t->deviation) maxdev = std::max(maxdev, std::abs(v - 0.0));
  const double target = maxdev * 1e6 / 3.0;
  const double nice[] = {0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000};
  double div = nice[14];
  for (double n : nice)
    if (n >= target) {
      div = n;
      break;
    }
  if (um_per_division > 0.0) div = um_per_division;
  const double pitch = 30.0;
  const double px_per_um = pitch / div;
  std::ostringstream o;
  o.setf(std::ios::fixed);
  o.precision(2);
  o << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << W << "\" height=\"" << Hh
    << "\" viewBox=\"0 0 " << W << ' ' << Hh << "\" font-family=\"sans-serif\" font-size=\"12\">\n";
  o << "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  o << "<text x=\"20\" y=\"28\" font-size=\"16\" font-weight=\"bold\">" << title << "</text>\n";
  // Scale rings.
  for (int k = -4; k <= 4; ++k) {
    const double rr = R0 + k * pitch;
    if (rr <= 10) continue;
    o << "<circle cx=\"" << cx << "\" cy=\"" << cy << "\" r=\"" << rr << "\" fill=\"none\" stroke=\""
      << (k == 0 ? "#444" : "#ccc") << "\" stroke-width=\"" << (k == 0 ? 1.2 : 0.7) << "\""
      << (k == 0 ? "" : " stroke-dasharray=\"3,3\"") << "/>\n";
    if (k != 0) {
      char lab[48];
      std::snprintf(lab, sizeof lab, "%+g µm", k * div);
      o << "<text x=\"" << cx + 4 << "\" y=\"" << cy - rr + 12 << "\" fill=\"#888\" font-size=\"10\">"
        << lab << "</text>\n";
    }
  }
  const auto [ia, ib] = plane_axes(r.spec.plane);
  const char* axn = "XYZ";
  o << "<line x1=\"" << cx - R0 - 140 << "\" y1=\"" << cy << "\" x2=\"" << cx + R0 + 140 << "\" y2=\"" << cy
    << "\" stroke=\"#ddd\"/>\n<line x1=\"" << cx << "\" y1=\"" << cy - R0 - 140 << "\" x2=\"" << cx
    << "\" y2=\"" << cy + R0 + 140 << "\" stroke=\"#ddd\"/>\n";
  o << "<text x=\"" << cx + R0 + 122 << "\" y=\"" << cy - 6 << "\">+" << axn[ia] << "</text>\n";
  o << "<text x=\"" << cx + 6 << "\" y=\"" << cy - R0 - 128 << "\">+" << axn[ib] << "</text>\n";
  // CW dashed over CCW solid, so both show where they coincide.
  auto path = [&](const CircularTrace& t, const char* colour) {
    o << "<polyline fill=\"none\" stroke=\"" << colour << "\" stroke-width=\"1.4\""
      << (&t == &r.cw ? " stroke-dasharray=\"6,4\"" : "") << " points=\"";
    for (std::size_t k = 0; k <= t.angle.size() && !t.angle.empty(); ++k) {
      const std::size_t j = k % t.angle.size();
      const double rr = R0 + t.deviation[j] * 1e6 * px_per_um;
      o << cx + rr * std::cos(t.angle[j]) << ',' << cy - rr * std::sin(t.angle[j]) << ' ';
    }
    o << "\"/>\n";
  };
  path(r.ccw, "#1f5fbf");
  path(r.cw, "#c0392b");
  const double tx = cx + R0 + 170;
  double ty = 80;
  auto line = [&](const std::string& s, const char* colour = "#000") {
    o << "<text x=\"" << tx << "\" y=\"" << ty << "\" fill=\"" << colour << "\">" << s << "</text>\n";
    ty += 18;
  };
  char buf[128];
  line("ISO 230-4 circular test");
  std::snprintf(buf, sizeof buf, "plane %s, radius %.1f mm", plane_name(r.spec.plane), r.spec.radius * 1e3);
  line(buf);
  std::snprintf(buf, sizeof buf, "feed %.0f mm/min, %s", r.spec.feed * 6e4,
                r.spec.closed_loop ? "closed loop" : "kinematic only");
  line(buf);
  std::snprintf(buf, sizeof buf, "centre (%.1f, %.1f, %.1f) mm", r.spec.centre.x() * 1e3,
                r.spec.centre.y() * 1e3, r.spec.centre.z() * 1e3);
  line(buf);
  std::snprintf(buf, sizeof buf, "scale %g µm / division", div);
  line(buf);
  ty += 8;
  line("— CCW (counter-clockwise)", "#1f5fbf");
  line("- - CW (clockwise)", "#c0392b");
  ty += 8;
  std::snprintf(buf, sizeof buf, "G CCW  %.2f µm", r.ccw_metrics.G * 1e6);
  line(buf);
  std::snprintf(buf, sizeof buf, "G CW   %.2f µm", r.cw_metrics.G * 1e6);
  line(buf);
  std::snprintf(buf, sizeof buf, "G both %.2f µm", r.G_bidirectional * 1e6);
  line(buf);
  std::snprintf(buf, sizeof buf, "H      %.2f µm", r.H * 1e6);
  line(buf);
  std::snprintf(buf, sizeof buf, "F max  %+.2f µm", r.F_max * 1e6);
  line(buf);
  std::snprintf(buf, sizeof buf, "F min  %+.2f µm", r.F_min * 1e6);
  line(buf);
  std::snprintf(buf, sizeof buf, "max |error| %.2f µm", r.max_abs_error * 1e6);
  line(buf);
  o << "</svg>\n";
  return o.str();
}

}  // namespace cpm::cal

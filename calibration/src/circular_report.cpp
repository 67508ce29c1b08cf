// SPDX-License-Identifier: Apache-2.0
#include "cpm/calibration/circular_report.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include <Eigen/Dense>
#include <nlohmann/json.hpp>
#include <yaml-cpp/yaml.h>

#include "cpm/kinematics/error.hpp"

namespace cpm::cal {
namespace {

double sgn(double v) { return v > 0.0 ? 1.0 : (v < 0.0 ? -1.0 : 0.0); }

// Columns of the fit at angle phi, direction s (+1 CCW, -1 CW); the order
// is the one diagnose_circular_test reads the coefficients in.
constexpr int kColumns = 8;
void columns(double phi, double s, double* c) {
  c[0] = 1.0;
  c[1] = std::cos(phi);
  c[2] = std::sin(phi);
  c[3] = std::sin(2 * phi);                               // squareness
  c[4] = std::cos(2 * phi);                               // scale mismatch
  c[5] = s * std::sin(2 * phi);                           // servo mismatch
  c[6] = s * sgn(std::sin(phi)) * std::cos(phi);          // backlash on a
  c[7] = -s * sgn(std::cos(phi)) * std::sin(phi);         // backlash on b
}

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

std::string html_escape(const std::string& s) {
  std::string o;
  for (char ch : s) {
    if (ch == '<') o += "&lt;";
    else if (ch == '>') o += "&gt;";
    else if (ch == '&') o += "&amp;";
    else if (ch == '"') o += "&quot;";
    else o += ch;
  }
  return o;
}

// The page's unit of a value of unit `u` (SI) and its scale.
std::pair<std::string, double> display_unit(const std::string& u) {
  if (u == "rad" || u == "1") return {"µm/m", 1e6};
  if (u == "s") return {"ms", 1e3};
  return {"µm", 1e6};
}

}  // namespace

std::vector<BallbarError> diagnose_circular_test(const CircularTestResult& r) {
  const std::size_t n = r.ccw.angle.size() + r.cw.angle.size();
  if (r.ccw.angle.size() < 16 || r.cw.angle.size() < 16)
    throw Error("ball-bar diagnosis: each run needs at least 16 points (has " + std::to_string(r.ccw.angle.size()) +
                " CCW, " + std::to_string(r.cw.angle.size()) + " CW)");
  Eigen::MatrixXd A(static_cast<Eigen::Index>(n), kColumns);
  Eigen::VectorXd y(static_cast<Eigen::Index>(n));
  Eigen::Index k = 0;
  for (const auto& [t, s] : {std::pair{&r.ccw, 1.0}, std::pair{&r.cw, -1.0}})
    for (std::size_t j = 0; j < t->angle.size(); ++j, ++k) {
      double c[kColumns];
      columns(t->angle[j], s, c);
      for (int q = 0; q < kColumns; ++q) A(k, q) = c[q];
      y(k) = t->deviation[j];
    }
  const Eigen::VectorXd x = A.colPivHouseholderQr().solve(y);
  const Eigen::VectorXd rest = y - A * x;
  const double R = r.spec.radius, w = r.spec.feed / r.spec.radius;
  const auto [ia, ib] = plane_axes(r.spec.plane);
  const char* axn = "xyz";
  std::vector<BallbarError> e;
  const std::string pl = std::string(1, axn[ia]) + axn[ib];
  e.push_back({"squareness", "squareness " + pl, 2 * x(3) / R, "rad", 2 * std::abs(x(3)), 0});
  e.push_back({"scale_mismatch", std::string("scale mismatch ") + axn[ia] + " - " + axn[ib], 2 * x(4) / R, "1",
               2 * std::abs(x(4)), 0});
  if (r.spec.closed_loop)
    e.push_back({"servo_mismatch", std::string("servo mismatch (") + axn[ia] + " lags " + axn[ib] + ")",
                 2 * x(5) / (w * R), "s", 2 * std::abs(x(5)), 0});
  e.push_back({std::string("backlash_") + axn[ia], std::string("backlash ") + axn[ia], 2 * x(6), "m",
               2 * std::abs(x(6)), 0});
  e.push_back({std::string("backlash_") + axn[ib], std::string("backlash ") + axn[ib], 2 * x(7), "m",
               2 * std::abs(x(7)), 0});
  std::sort(e.begin(), e.end(), [](const auto& a, const auto& b) { return a.contribution > b.contribution; });
  e.push_back({"not_explained", "not explained (residual of the fit)", rest.maxCoeff() - rest.minCoeff(), "m",
               rest.maxCoeff() - rest.minCoeff(), 0});
  double sum = 0.0;
  for (const auto& v : e) sum += v.contribution;
  for (auto& v : e) v.share = sum > 0.0 ? 100.0 * v.contribution / sum : 0.0;
  return e;
}

BallbarTolerances load_ballbar_tolerances(const std::string& path) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::Exception& ex) {
    throw Error(path + ": cannot read the tolerances: " + ex.what());
  }
  BallbarTolerances t;
  if (root.IsNull()) return t;
  if (!root.IsMap()) throw Error(path + ": the tolerances must be a map of key: value");
  struct Key { const char* name; std::optional<double>* field; double to_si; };
  const Key keys[] = {{"circularity_um", &t.circularity, 1e-6},   {"hysteresis_um", &t.hysteresis, 1e-6},
                      {"radial_deviation_um", &t.radial_deviation, 1e-6}, {"squareness_um_per_m", &t.squareness, 1e-6},
                      {"scale_mismatch_um_per_m", &t.scale_mismatch, 1e-6}, {"servo_mismatch_ms", &t.servo_mismatch, 1e-3},
                      {"backlash_um", &t.backlash, 1e-6}};
  for (const auto& kv : root) {
    const std::string name = kv.first.as<std::string>();
    const int line = kv.first.Mark().line + 1;
    const Key* key = nullptr;
    for (const auto& c : keys)
      if (name == c.name) key = &c;
    if (!key) {
      std::string known;
      for (const auto& c : keys) known += std::string(known.empty() ? "" : ", ") + c.name;
      throw Error(path + ":" + std::to_string(line) + ": unknown tolerance '" + name + "' (known: " + known + ")");
    }
    double v = -1.0;
    try {
      v = kv.second.as<double>();
    } catch (const YAML::Exception&) {
      v = -1.0;
    }
    if (!(v >= 0.0) || !std::isfinite(v))
      throw Error(path + ":" + std::to_string(line) + ": tolerance '" + name + "' must be a number >= 0");
    *key->field = v * key->to_si;
  }
  return t;
}

BallbarReport make_ballbar_report(const CircularTestResult& r, const BallbarTolerances& tol, double um_per_division) {
  BallbarReport b;
  b.test = r;
  b.um_per_division = um_per_division;
  b.errors = diagnose_circular_test(r);
  auto check = [&](const std::string& what, double value, const std::optional<double>& t, const char* unit,
                   double scale) {
    if (!t) return;
    b.checks.push_back({what, value, *t, unit, scale, std::abs(value) <= *t});
    b.pass = b.pass && b.checks.back().pass;
  };
  check("circularity G (both runs)", r.G_bidirectional, tol.circularity, "µm", 1e6);
  check("hysteresis H", r.H, tol.hysteresis, "µm", 1e6);
  check("radial deviation max |F|", r.max_abs_error, tol.radial_deviation, "µm", 1e6);
  for (const auto& e : b.errors) {
    if (e.key == "squareness") check(e.name, e.value, tol.squareness, "µm/m", 1e6);
    if (e.key == "scale_mismatch") check(e.name, e.value, tol.scale_mismatch, "µm/m", 1e6);
    if (e.key == "servo_mismatch") check(e.name, e.value, tol.servo_mismatch, "ms", 1e3);
    if (e.key.rfind("backlash_", 0) == 0) check(e.name, e.value, tol.backlash, "µm", 1e6);
  }
  return b;
}

std::string ballbar_report_json(const BallbarReport& b) {
  const auto& r = b.test;
  nlohmann::json errors = nlohmann::json::array();
  for (const auto& e : b.errors)
    errors.push_back({{"key", e.key}, {"name", e.name}, {"value", e.value}, {"unit", e.unit},
                      {"contribution_um", e.contribution * 1e6}, {"share_percent", e.share}});
  nlohmann::json checks = nlohmann::json::array();
  for (const auto& c : b.checks)
    checks.push_back({{"what", c.what}, {"value", c.value}, {"tolerance", c.tolerance}, {"pass", c.pass}});
  const nlohmann::json j{{"circularity_um", r.G_bidirectional * 1e6},
                         {"G_ccw_um", r.ccw_metrics.G * 1e6},
                         {"G_cw_um", r.cw_metrics.G * 1e6},
                         {"hysteresis_um", r.H * 1e6},
                         {"F_max_um", r.F_max * 1e6},
                         {"F_min_um", r.F_min * 1e6},
                         {"radius", r.spec.radius},
                         {"feed", r.spec.feed},
                         {"plane", plane_name(r.spec.plane)},
                         {"closed_loop", r.spec.closed_loop},
                         {"um_per_division", b.um_per_division},
                         {"errors", errors},
                         {"checks", checks},
                         {"pass", b.pass}};
  return j.dump(2) + "\n";
}

std::string ballbar_report_html(const BallbarReport& b, const std::string& title) {
  const auto& r = b.test;
  std::ostringstream o;
  // One A4 sheet: fixed margins, the plot scaled to the column, no element
  // that a printer may split across sheets.
  o << "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>" << html_escape(title) << "</title>\n<style>\n"
    << "@page { size: A4; margin: 12mm; }\n"
    << "html, body { margin: 0; font-family: sans-serif; font-size: 9.5pt; }\n"
    << ".sheet { width: 186mm; }\n"
    << "h1 { font-size: 12pt; margin: 0 0 2mm 0; }\n"
    << "h2 { font-size: 10.5pt; margin: 3mm 0 1mm 0; }\n"
    << "section, table, tr, svg, .plot { break-inside: avoid; page-break-inside: avoid; }\n"
    << ".plot svg { width: 100%; height: auto; max-height: 105mm; display: block; }\n"
    << "table { border-collapse: collapse; width: 100%; }\n"
    << "td, th { border-bottom: 1px solid #ccc; padding: 0.6mm 1.5mm; text-align: right; }\n"
    << "td:first-child, th:first-child { text-align: left; }\n"
    << ".pass { color: #17703a; font-weight: bold; } .fail { color: #b0202a; font-weight: bold; }\n"
    << ".bar { display: inline-block; height: 2.5mm; background: #1f5fbf; }\n"
    << ".note { color: #555; font-size: 8pt; }\n"
    << "</style></head><body><div class=\"sheet\">\n";
  o << "<h1>" << html_escape(title) << "</h1>\n";
  o << "<section class=\"plot\" id=\"polar\">"
    << circular_test_svg(r, "Ball-bar polar plot (ISO 230-4)", b.um_per_division) << "</section>\n";
  o << "<section id=\"figures\"><h2>ISO 230-4 figures</h2><table>\n"
    << "<tr><th></th><th>CCW</th><th>CW</th><th>both runs</th></tr>\n"
    << "<tr><td>circularity G (µm)</td><td>" << fmt("%.2f", r.ccw_metrics.G * 1e6) << "</td><td>"
    << fmt("%.2f", r.cw_metrics.G * 1e6) << "</td><td>" << fmt("%.2f", r.G_bidirectional * 1e6) << "</td></tr>\n"
    << "<tr><td>hysteresis H (µm)</td><td></td><td></td><td>" << fmt("%.2f", r.H * 1e6) << "</td></tr>\n"
    << "<tr><td>radial deviation F max / min (µm, centre as set)</td><td>" << fmt("%+.2f", r.ccw_metrics.F_max * 1e6)
    << " / " << fmt("%+.2f", r.ccw_metrics.F_min * 1e6) << "</td><td>" << fmt("%+.2f", r.cw_metrics.F_max * 1e6)
    << " / " << fmt("%+.2f", r.cw_metrics.F_min * 1e6) << "</td><td>" << fmt("%+.2f", r.F_max * 1e6) << " / "
    << fmt("%+.2f", r.F_min * 1e6) << "</td></tr>\n</table></section>\n";
  o << "<section id=\"errors\"><h2>Error sources</h2><table>\n"
    << "<tr><th>source</th><th>value</th><th>contribution (µm)</th><th>share</th><th></th></tr>\n";
  for (const auto& e : b.errors) {
    const auto [unit, scale] = display_unit(e.unit);
    o << "<tr><td>" << html_escape(e.name) << "</td><td>"
      // A value that rounds to zero is shown as 0.00, not -0.00.
      << (e.key == "not_explained" ? std::string()
                                   : fmt("%+.2f ", std::abs(e.value * scale) < 0.005 ? 0.0 : e.value * scale) + unit)
      << "</td><td>"
      << fmt("%.2f", e.contribution * 1e6) << "</td><td>" << fmt("%.0f %%", e.share)
      << "</td><td style=\"width:30mm;text-align:left\"><span class=\"bar\" style=\"width:" << fmt("%.1f", 0.3 * e.share)
      << "mm\"></span></td></tr>\n";
  }
  o << "</table><p class=\"note\">Contribution: peak-to-valley of the source's own radial signature over the circle; "
       "share: of the sum of the contributions. Centre offset and bar length are set-up, not listed.</p></section>\n";
  o << "<section id=\"tolerances\"><h2>Against tolerances</h2>";
  if (b.checks.empty()) {
    o << "<p>No tolerances given (--tolerances FILE).</p>";
  } else {
    o << "<table>\n<tr><th>figure</th><th>measured</th><th>tolerance</th><th>result</th></tr>\n";
    for (const auto& c : b.checks)
      o << "<tr><td>" << html_escape(c.what) << "</td><td>" << fmt("%.2f ", std::abs(c.value) * c.scale) << c.unit
        << "</td><td>" << fmt("%.2f ", c.tolerance * c.scale) << c.unit << "</td><td class=\""
        << (c.pass ? "pass\">pass" : "fail\">FAIL") << "</td></tr>\n";
    o << "</table><p>Overall: <span class=\"" << (b.pass ? "pass\">PASS" : "fail\">FAIL") << "</span></p>";
  }
  o << "</section>\n</div></body></html>\n";
  return o.str();
}

}  // namespace cpm::cal

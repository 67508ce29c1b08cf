// SPDX-License-Identifier: Apache-2.0
#include "open_world.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <sstream>

#include "cpm/identification/fit.hpp"

namespace cpm::indep {
namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Library effects the verdict names as missing; in the delay cells their own
// delay is the truth of the cell, not a claim.
std::vector<std::string> library_named(const ident::Diagnosis& D, Timing t) {
  std::vector<std::string> out;
  for (const NamedEffect& n : named_effects(D)) {
    if (n.effect == "outside_library") continue;
    if (n.effect == "actuation_delay" && delay_periods(t) > 0.0) continue;
    out.push_back(n.label());
  }
  return out;
}

double rms3(const Vec3& v) { return std::sqrt(v.squaredNorm() / 3.0); }

void diagnose_into(OpenWorldLog& L, const GeneratedLog& g, const OpenWorldOptions& o) {
  if (!o.write_logs.empty()) {
    std::ostringstream name;
    name << o.write_logs << "/outside-" << timing_name(L.timing) << "-" << noise_name(L.noise) << "-" << L.rate
         << "Hz-seed" << L.seed << "-" << (L.kind.empty() ? std::string("null") : L.kind + "-axis" +
                                            std::to_string(L.axis + 1) + "-x" + std::to_string(static_cast<int>(L.multiple)))
         << ".csv";
    io::write_motion(name.str(), g.log);
  }
  const ctl::Machine nominal(ctl::MachineModel::elkady());
  const auto t0 = std::chrono::steady_clock::now();
  const ident::Diagnosis D = ident::diagnose_motion(g.log, nominal, o.diagnose);
  L.diagnose_s = seconds_since(t0);
  L.floor = rms3(D.axis_floor);
  L.axis_floor = D.axis_floor;
  for (const NamedEffect& n : named_effects(D)) L.named.push_back(n.label());
  L.partial = D.partial;
  L.verdict = D.verdict_text;
  L.library_named = !library_named(D, L.timing).empty();
  if (!D.outside_library.empty()) {
    const ident::StructureFinding& f = D.outside_library.front();
    L.outside = true;
    L.lead = f.text;
    L.right_axis = f.axis == L.axis;
    const std::string want = "v" + std::to_string(L.from_axis + 1);
    if (L.from_axis >= 0) {
      L.right_variable = L.right_axis && f.coordinate == want;
      L.variable_listed = L.right_axis && (f.coordinate == want ||
                                           std::find(f.also_in.begin(), f.also_in.end(), want) != f.also_in.end());
    } else {
      L.right_variable = L.variable_listed = L.right_axis;
    }
  }
}

}  // namespace

OpenWorldResult run_open_world(const OpenWorldOptions& o) {
  OpenWorldResult R;
  R.options = o;
  const auto wall0 = std::chrono::steady_clock::now();
  if (!o.write_logs.empty()) std::filesystem::create_directories(o.write_logs);
  for (double rate : o.rates)
    for (Timing timing : o.timings)
      for (NoisePlacement noise : o.noises)
        for (int seed = o.first_seed; seed < o.first_seed + o.seeds; ++seed) {
          GeneratorSpec spec;
          spec.timing = timing;
          spec.noise = noise;
          spec.rate = rate;
          spec.duration = o.duration;
          spec.seed = static_cast<std::uint64_t>(seed) * 7919ULL + 17ULL;
          OpenWorldLog null_log{timing, noise, rate, seed};
          GeneratedLog g0;
          Vec3 floor0 = Vec3::Zero();
          try {
            g0 = generate(spec);
            diagnose_into(null_log, g0, o);
            floor0 = null_log.axis_floor;
            // The true model of a zoh null log is the nominal one.
            const ctl::Machine nominal(ctl::MachineModel::elkady());
            if (timing == Timing::zoh) null_log.true_rms = ident::motion_rms(g0.log, nominal.model(), o.diagnose.motion);
          } catch (const std::exception& e) {
            null_log.error = e.what();
            R.logs.push_back(null_log);
            continue;
          }
          R.logs.push_back(null_log);
          for (std::size_t k = 0; k < o.kinds.size(); ++k)
            for (double m : o.multiples) {
              OpenWorldLog L{timing, noise, rate, seed};
              L.kind = outside_kind_name(o.kinds[k]);
              L.axis = (seed + static_cast<int>(o.kinds[k])) % 3;
              const int other = (L.axis + 1 + seed % 2) % 3;
              L.multiple = m;
              const int i = L.axis;
              const double peak = m * floor0[i];
              const double lo = g0.d_min[i], hi = g0.d_max[i];
              OutsideForce f;
              f.kind = o.kinds[k];
              f.axis = i;
              if (f.kind == OutsideForce::Kind::cross_velocity || f.kind == OutsideForce::Kind::cross_velocity_hump)
                f.from_axis = other;
              L.from_axis = outside_velocity_axis(f);
              double vmax = 0.0;
              if (L.from_axis >= 0)
                for (const Vec3& v : g0.v_true) vmax = std::max(vmax, std::fabs(v[L.from_axis]));
              if (f.kind == OutsideForce::Kind::cross_velocity) {
                f.size = peak / std::max(vmax, 1e-6);
              } else if (L.from_axis >= 0) {
                // A hump that peaks at a sixth of the speed the axis reaches (the
                // expression of the hump found on a circle peaked at an eighth).
                f.width = std::max(vmax, 1e-6) / 6.0;
                f.size = peak;
              } else if (f.kind == OutsideForce::Kind::position_friction) {
                // A friction of `peak` at the far end, 0.3 of it at the near end.
                f.centre = 0.5 * (lo + hi);
                f.width = 0.5 * (hi - lo);
                f.size = peak;
              } else if (f.kind == OutsideForce::Kind::bump) {
                // A tight spot a third of the way along the travel, 1/30 of it wide.
                f.centre = lo + (hi - lo) / 3.0;
                f.width = (hi - lo) / 30.0;
                f.size = peak;
              } else {
                f.centre = 0.5 * (lo + hi);
                f.width = 0.5 * (hi - lo);
                f.size = peak;
              }
              L.size = f.size;
              GeneratorSpec s = spec;
              s.outside = {f};
              try {
                diagnose_into(L, generate(s), o);
              } catch (const std::exception& e) {
                L.error = e.what();
              }
              R.logs.push_back(std::move(L));
            }
        }
  R.wall_s = seconds_since(wall0);
  return R;
}

namespace {

struct Tally {
  int n = 0, outside = 0, axis = 0, variable = 0, listed = 0, clean_library = 0, errors = 0;
  double diag_s = 0.0;
};

std::string pct(int a, int n) {
  char b[32];
  std::snprintf(b, sizeof b, "%d/%d (%.0f %%)", a, n, n ? 100.0 * a / n : 0.0);
  return b;
}

}  // namespace

std::string open_world_table(const OpenWorldResult& r) {
  std::map<std::string, Tally> by;  // "kind xM"
  Tally nulls;
  std::vector<double> floor_ratio;
  for (const OpenWorldLog& L : r.logs) {
    if (L.kind.empty()) {
      ++nulls.n;
      nulls.errors += !L.error.empty();
      nulls.clean_library += L.error.empty() && !L.outside && !L.library_named;
      nulls.diag_s += L.diagnose_s;
      if (L.true_rms > 0.0) floor_ratio.push_back(L.floor / L.true_rms);
      continue;
    }
    char key[64];
    std::snprintf(key, sizeof key, "%s at %gx", L.kind.c_str(), L.multiple);
    Tally& t = by[key];
    ++t.n;
    t.errors += !L.error.empty();
    t.outside += L.outside;
    t.axis += L.right_axis;
    t.variable += L.right_variable;
    t.listed += L.variable_listed;
    t.clean_library += L.error.empty() && !L.library_named;
    t.diag_s += L.diagnose_s;
  }
  std::ostringstream os;
  os << "| planted | logs | outside_library | on the right axis | right variable (lead) | variable lead or alike "
        "| no library effect named | errors | diagnose s/log |\n|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& [k, t] : by) {
    char s[32];
    std::snprintf(s, sizeof s, "%.2f", t.n ? t.diag_s / t.n : 0.0);
    os << "| " << k << " | " << t.n << " | " << pct(t.outside, t.n) << " | " << pct(t.axis, t.n) << " | "
       << pct(t.variable, t.n) << " | " << pct(t.listed, t.n) << " | " << pct(t.clean_library, t.n) << " | "
       << t.errors << " | " << s << " |\n";
  }
  char s[32];
  std::snprintf(s, sizeof s, "%.2f", nulls.n ? nulls.diag_s / nulls.n : 0.0);
  os << "| null | " << nulls.n << " | | | | | none: " << pct(nulls.clean_library, nulls.n) << " | " << nulls.errors
     << " | " << s << " |\n";
  if (!floor_ratio.empty()) {
    std::sort(floor_ratio.begin(), floor_ratio.end());
    os << "\nhonest floor / residual RMS of the true model on zoh null logs: min " << floor_ratio.front() << ", median "
       << floor_ratio[floor_ratio.size() / 2] << ", max " << floor_ratio.back() << " (" << floor_ratio.size()
       << " logs)\n";
  }
  os << "\nwall time " << r.wall_s << " s\n";
  return os.str();
}

std::vector<std::string> open_world_failures(const OpenWorldResult& r) {
  std::vector<std::string> out;
  std::map<std::string, Tally> by;
  Tally nulls;
  for (const OpenWorldLog& L : r.logs) {
    Tally& t = L.kind.empty() ? nulls : by[L.kind];
    ++t.n;
    t.variable += L.right_variable;
    t.clean_library += L.error.empty() && !L.library_named && (!L.kind.empty() || !L.outside);
  }
  for (const auto& [k, t] : by) {
    if (t.variable < 0.9 * t.n) out.push_back(k + ": outside_library on the right axis and variable in " + pct(t.variable, t.n));
    if (t.clean_library < 0.9 * t.n) out.push_back(k + ": no library effect named in " + pct(t.clean_library, t.n));
  }
  if (nulls.clean_library < 0.95 * nulls.n) out.push_back("null logs none in " + pct(nulls.clean_library, nulls.n));
  for (const OpenWorldLog& L : r.logs) {
    const bool miss = L.kind.empty() ? (L.outside || L.library_named || !L.error.empty())
                                     : (!L.right_variable || L.library_named || !L.error.empty());
    if (!miss) continue;
    std::ostringstream os;
    os << "  " << (L.kind.empty() ? "null" : L.kind) << " axis " << L.axis + 1;
    if (L.from_axis >= 0) os << " following v" << L.from_axis + 1;
    os << " x" << L.multiple << " " << timing_name(L.timing) << "/" << noise_name(L.noise) << " " << L.rate
       << " Hz seed " << L.seed << ": named";
    for (const auto& n : L.named) os << " " << n;
    if (!L.lead.empty()) os << "; lead: " << L.lead;
    if (!L.error.empty()) os << "; error: " << L.error;
    if (std::getenv("CPM_OPEN_WORLD_VERDICTS")) os << "\n      verdict: " << L.verdict;
    out.push_back(os.str());
  }
  return out;
}

}  // namespace cpm::indep

#include "matrix.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <mutex>
#include <sstream>
#include <thread>

#include "cpm/identification/engine.hpp"
#include "cpm/identification/motion.hpp"

namespace cpm::indep {
namespace {

constexpr double kM1 = 1.892994, kL1 = 0.5;  // machine.md: first link mass (kg) and length (m)

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

std::string fmt(double x, int prec = 4) {
  std::ostringstream os;
  os.precision(prec);
  os << x;
  return os.str();
}

std::string rate_text(double r) { return fmt(r, 6) + " Hz"; }

bool is_delay_cell(Timing t) { return delay_periods(t) > 0.0; }

// The generator seed of a log: distinct per matrix seed, effect and multiple,
// the same in every cell (so cells differ only by their convention).
std::uint64_t log_seed(int seed, int effect_index, int multiple_index) {
  return static_cast<std::uint64_t>(seed) * 1000ULL + static_cast<std::uint64_t>(effect_index + 1) * 10ULL +
         static_cast<std::uint64_t>(multiple_index);
}

std::string json_escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '"' || c == '\\') o += '\\';
    if (c == '\n') {
      o += "\\n";
      continue;
    }
    o += c;
  }
  return o;
}

std::string json_num(double x) {
  if (!std::isfinite(x)) return "null";
  std::ostringstream os;
  os.precision(10);
  os << x;
  return os.str();
}

}  // namespace

std::string NamedEffect::label() const {
  if (axis < 0) return effect;
  return effect + "[axis " + std::to_string(axis + 1) + "]";
}

std::vector<NamedEffect> named_effects(const ident::Diagnosis& D) {
  std::vector<NamedEffect> out;
  auto take = [&](int i) {
    if (i < 0 || i >= static_cast<int>(D.candidates.size())) return;
    const ident::CandidateResult& c = D.candidates[static_cast<std::size_t>(i)];
    NamedEffect n;
    n.effect = c.effect;
    n.axis = c.axis;
    if (c.effect == "actuation_delay" && !c.params.empty()) n.tau = c.params[0].value;
    n.alternatives = c.alternatives;
    out.push_back(std::move(n));
  };
  // Structure no library effect describes is a claim too (verdict.missing = "outside_library").
  if (!D.outside_library.empty()) out.push_back({"outside_library", D.outside_library.front().axis, {}, {}});
  if (D.verdict >= 0) take(D.verdict);
  for (int i : D.also) take(i);
  return out;
}

const std::vector<EffectShape>& dynamic_library() {
  static const std::vector<EffectShape> lib = {
      {"viscous_friction", true, {1.0}, 0},
      {"coulomb_friction", true, {1.0}, 0},
      {"stribeck_friction", true, {1.0, 0.02}, 0},
      {"cogging", true, {1.0, 0.012, 0.5}, 0},
      {"spring", true, {1.0, 0.2}, 0},
      {"force_gain", true, {1.0}, 0},
      {"payload_mass", false, {1.0}, 0},
      // The first links' centre of mass lying further out than mid-length:
      // B and C change (m1 L1 / 2, m1 g), A and E do not (kLinkBalanceShape).
      {"inertia_error", false, {0.0, kM1 * kL1 / 2.0, kM1 * ctl::kGravity, 0.0}, -1},
  };
  return lib;
}

std::vector<double> planted_values(const EffectShape& e, double amplitude) {
  std::vector<double> v = e.shape;
  if (e.amp_index < 0)
    for (double& x : v) x *= amplitude;
  else
    v[static_cast<std::size_t>(e.amp_index)] = amplitude;
  return v;
}

// The amplitude's column fitted jointly with the base, or, for payload and
// inertia error, which are base directions themselves, against the model as
// given (the planted-effect tests of test_identification.cpp use it too). It
// only scales the planted amplitudes; the judgement is diagnose_motion's alone.
// (A probe fit at a tiny amplitude instead would search the shape in noise and
// give a standard error that varies fifty-fold between seeds.)
double amplitude_standard_error(const ident::MotionProblem& P, const ident::Engine& E, const EffectShape& e,
                                int axis) {
  Eigen::MatrixXd X(E.rows(), 1);
  bool with_base = true;
  if (e.amp_index < 0 || e.name == "payload_mass") {
    Eigen::VectorXd dir(4);
    if (e.amp_index < 0)
      for (int j = 0; j < 4; ++j) dir(j) = e.shape[static_cast<std::size_t>(j)];
    else
      dir << 0.5, 0.0, 0.0, ctl::kGravity;  // payload: dA = dm/2, dE = dm g
    X.col(0) = P.base.leftCols(4) * dir;
    with_base = false;
  } else if (e.name == "force_gain") {
    X.col(0) = P.force_gain_column(axis);
  } else {
    ctl::DynamicEffect d;
    d.type = *ctl::dynamic_effect_from_name(e.name);
    d.axis = static_cast<std::int8_t>(axis);
    for (std::size_t j = 0; j < e.shape.size(); ++j) d.param[j] = e.shape[j];
    X.col(0) = P.effect_force_column(d);
  }
  const ident::JointFit f = E.fit(X, with_base);
  return std::sqrt(E.covariance(X, f, (with_base ? E.base_rank() : 0) + 1, with_base)(0, 0));
}

namespace {

struct Job {
  Timing timing;
  NoisePlacement noise;
  double rate;
  int seed;
  int effect = -1;  // index in dynamic_library(), -1 null
  int multiple = -1;
};

// Score one diagnosed log against what was planted and the cell's convention.
void score(LogResult& r, double period) {
  const double true_delay = delay_periods(r.timing);
  for (const NamedEffect& n : r.named) {
    if (n.effect == "actuation_delay") {
      if (std::isfinite(n.tau)) r.tau_error_periods = std::fabs(n.tau / period - true_delay);
      if (is_delay_cell(r.timing)) continue;  // the cell's own convention: expected
    }
    // The planted effect named, or named as the alternative of an ambiguous verdict.
    NamedEffect p;
    p.effect = r.planted;
    p.axis = r.axis;
    const bool planted = !r.planted.empty() &&
                         ((n.effect == r.planted && n.axis == r.axis) ||
                          std::find(n.alternatives.begin(), n.alternatives.end(), p.label()) != n.alternatives.end());
    if (planted)
      r.hit = true;
    else
      r.phantoms.push_back(n.label());
  }
}

}  // namespace

MatrixResult run_matrix(const MatrixOptions& o, const std::function<void(const LogResult&, int, int)>& progress) {
  const auto t_start = std::chrono::steady_clock::now();
  MatrixResult res;
  res.options = o;
  const auto& lib = dynamic_library();
  std::vector<int> effect_idx;
  if (o.effects.empty()) {
    for (int i = 0; i < static_cast<int>(lib.size()); ++i) effect_idx.push_back(i);
  } else {
    for (const std::string& name : o.effects) {
      int found = -1;
      for (int i = 0; i < static_cast<int>(lib.size()); ++i)
        if (lib[static_cast<std::size_t>(i)].name == name) found = i;
      if (found < 0) throw Error("unknown effect '" + name + "' (the dynamic library of effects.md)");
      effect_idx.push_back(found);
    }
  }
  const ctl::Machine nominal(ctl::MachineModel::elkady());

  // Unit amplitudes per (noise, rate), effect and axis, on a zoh null log.
  std::map<std::pair<int, double>, std::vector<std::array<double, 3>>> unit;
  for (NoisePlacement nz : o.noises)
    for (double rate : o.rates) {
      GeneratorSpec s;
      s.timing = Timing::zoh;
      s.noise = nz;
      s.rate = rate;
      s.duration = o.duration;
      s.seed = 987654;
      const io::MotionData null_log = generate(s).log;
      const ident::MotionProblem P = ident::prepare_motion(null_log, nominal);
      const ident::Engine E(ident::motion_linear_problem(P));
      auto& u = unit[{static_cast<int>(nz), rate}];
      u.assign(lib.size(), {0.0, 0.0, 0.0});
      for (int ei : effect_idx) {
        const EffectShape& e = lib[static_cast<std::size_t>(ei)];
        for (int axis = 0; axis < (e.per_axis ? 3 : 1); ++axis) {
          const double v = 4.0 * amplitude_standard_error(P, E, e, e.per_axis ? axis : -1);
          u[static_cast<std::size_t>(ei)][static_cast<std::size_t>(axis)] = v;
          res.units.push_back({nz, rate, e.name, e.per_axis ? axis : -1, v});
        }
      }
    }

  std::vector<Job> jobs;
  for (int seed = o.first_seed; seed < o.first_seed + o.seeds; ++seed)
    for (double rate : o.rates)
      for (NoisePlacement nz : o.noises)
        for (Timing t : o.timings) {
          if (o.nulls) jobs.push_back({t, nz, rate, seed, -1, -1});
          for (int ei : effect_idx)
            for (int m = 0; m < static_cast<int>(o.multiples.size()); ++m) jobs.push_back({t, nz, rate, seed, ei, m});
        }

  res.logs.resize(jobs.size());
  std::atomic<std::size_t> next{0};
  std::atomic<int> done{0};
  std::mutex mu;
  if (!o.write_logs.empty()) std::filesystem::create_directories(o.write_logs);
  auto worker = [&]() {
    for (;;) {
      const std::size_t j = next.fetch_add(1);
      if (j >= jobs.size()) return;
      const Job& job = jobs[j];
      LogResult r;
      r.timing = job.timing;
      r.noise = job.noise;
      r.rate = job.rate;
      r.seed = job.seed;
      GeneratorSpec s;
      s.timing = job.timing;
      s.noise = job.noise;
      s.rate = job.rate;
      s.duration = o.duration;
      s.seed = r.log_seed = log_seed(job.seed, job.effect, job.multiple);
      if (job.effect >= 0) {
        const EffectShape& e = lib[static_cast<std::size_t>(job.effect)];
        // The planted axis varies with the seed (and with the effect).
        r.axis = e.per_axis ? (job.seed + job.effect) % 3 : -1;
        r.planted = e.name;
        r.multiple = o.multiples[static_cast<std::size_t>(job.multiple)];
        r.amplitude = r.multiple * unit.at({static_cast<int>(job.noise), job.rate})[static_cast<std::size_t>(
                                       job.effect)][static_cast<std::size_t>(std::max(r.axis, 0))];
        s.effects = {{e.name, r.axis, planted_values(e, r.amplitude)}};
      }
      try {
        auto t0 = std::chrono::steady_clock::now();
        const GeneratedLog g = generate(s);
        r.generate_s = seconds_since(t0);
        if (!o.write_logs.empty()) {
          std::ostringstream name;
          name << o.write_logs << "/" << timing_name(r.timing) << "_" << noise_name(r.noise) << "_"
               << static_cast<int>(r.rate) << "_" << (r.planted.empty() ? std::string("null") : r.planted);
          if (r.axis >= 0) name << "_axis" << r.axis + 1;
          if (r.multiple > 0) name << "_x" << static_cast<int>(r.multiple);
          name << "_seed" << r.seed << ".csv";
          io::write_motion(name.str(), g.log);
        }
        t0 = std::chrono::steady_clock::now();
        const ident::Diagnosis D = ident::diagnose_motion(g.log, nominal, o.diagnose);
        r.diagnose_s = seconds_since(t0);
        r.named = named_effects(D);
        score(r, 1.0 / r.rate);
      } catch (const std::exception& ex) {
        r.error = ex.what();
      }
      res.logs[j] = r;
      const int d = ++done;
      if (progress) {
        std::lock_guard<std::mutex> lock(mu);
        progress(res.logs[j], d, static_cast<int>(jobs.size()));
      }
    }
  };
  const int nt = std::max(1, o.threads);
  if (nt == 1) {
    worker();
  } else {
    std::vector<std::thread> pool;
    for (int i = 0; i < nt; ++i) pool.emplace_back(worker);
    for (auto& th : pool) th.join();
  }
  res.cells = summarise(res.logs, o);
  res.wall_s = seconds_since(t_start);
  return res;
}

std::vector<CellSummary> summarise(const std::vector<LogResult>& logs, const MatrixOptions& o) {
  std::vector<CellSummary> cells;
  for (double rate : o.rates)
    for (NoisePlacement nz : o.noises)
      for (Timing t : o.timings) {
        CellSummary c;
        c.timing = t;
        c.noise = nz;
        c.rate = rate;
        std::map<std::string, int> ph;
        std::vector<double> taus;
        std::map<double, std::pair<int, int>> by_mult;
        for (const LogResult& r : logs) {
          if (r.timing != t || r.noise != nz || r.rate != rate) continue;
          ++c.logs;
          if (!r.error.empty()) ++c.errors;
          if (r.planted.empty()) {
            ++c.n_null;
            if (r.error.empty() && r.phantoms.empty()) ++c.null_clean;
          } else {
            auto& bm = by_mult[r.multiple];
            ++bm.second;
            if (r.hit) ++bm.first;
            if (!r.hit) {
              std::ostringstream m;
              m << r.planted << (r.axis >= 0 ? "[axis " + std::to_string(r.axis + 1) + "]" : std::string()) << " x"
                << r.multiple << " seed " << r.seed;
              if (!r.error.empty()) m << " (error: " << r.error << ")";
              c.missed.push_back(m.str());
            }
          }
          c.named += static_cast<int>(r.named.size());
          c.phantoms += static_cast<int>(r.phantoms.size());
          if (!r.phantoms.empty()) ++c.logs_with_phantom;
          for (const std::string& p : r.phantoms) {
            // Count by effect name (axis kept): what is named instead.
            ++ph[p];
          }
          if (std::isfinite(r.tau_error_periods)) taus.push_back(r.tau_error_periods);
        }
        for (const auto& [m, hn] : by_mult) {
          c.hits_by_multiple.push_back({m, hn});
          if (m == 3.0) c.hits3 = hn.first, c.n3 = hn.second;
          if (m == 10.0) c.hits10 = hn.first, c.n10 = hn.second;
        }
        c.tau_named = static_cast<int>(taus.size());
        if (!taus.empty()) {
          std::sort(taus.begin(), taus.end());
          const std::size_t n = taus.size();
          c.median_tau_error = n % 2 ? taus[n / 2] : 0.5 * (taus[n / 2 - 1] + taus[n / 2]);
        }
        c.top_phantoms.assign(ph.begin(), ph.end());
        std::sort(c.top_phantoms.begin(), c.top_phantoms.end(),
                  [](const auto& a, const auto& b) { return a.second != b.second ? a.second > b.second : a.first < b.first; });
        if (c.logs > 0) cells.push_back(std::move(c));
      }
  return cells;
}

std::string markdown_table(const MatrixResult& r) {
  std::ostringstream os;
  os << "| timing | noise | rate | hits 3x | hits 10x | null clean | phantoms / named | logs with phantom | median "
        "abs(tau err)/T | named instead (count) |\n";
  os << "|---|---|---|---|---|---|---|---|---|---|\n";
  for (const CellSummary& c : r.cells) {
    os << "| " << timing_name(c.timing) << " | " << noise_name(c.noise) << " | " << c.rate << " | ";
    os << (c.n3 ? std::to_string(c.hits3) + "/" + std::to_string(c.n3) : "-") << " | ";
    os << (c.n10 ? std::to_string(c.hits10) + "/" + std::to_string(c.n10) : "-") << " | ";
    os << (c.n_null ? std::to_string(c.null_clean) + "/" + std::to_string(c.n_null) : "-") << " | ";
    os << c.phantoms << "/" << c.named << " | " << c.logs_with_phantom << "/" << c.logs << " | ";
    if (is_delay_cell(c.timing))
      os << (c.tau_named ? fmt(c.median_tau_error, 3) + " (" + std::to_string(c.tau_named) + " named)"
                         : std::string("not named"));
    else
      os << "-";
    os << " | ";
    int shown = 0;
    for (const auto& [label, n] : c.top_phantoms) {
      if (shown++ == 4) {
        os << ", ...";
        break;
      }
      os << (shown > 1 ? ", " : "") << label << " " << n;
    }
    if (c.errors) os << (shown ? "; " : "") << c.errors << " errors";
    os << " |\n";
  }
  return os.str();
}

std::string to_json(const MatrixResult& r) {
  std::ostringstream os;
  const MatrixOptions& o = r.options;
  os << "{\n  \"options\": {\"seeds\": " << o.seeds << ", \"first_seed\": " << o.first_seed << ", \"duration_s\": " << json_num(o.duration)
     << ", \"threads\": " << o.threads << ", \"rates\": [";
  for (std::size_t i = 0; i < o.rates.size(); ++i) os << (i ? ", " : "") << json_num(o.rates[i]);
  os << "], \"timings\": [";
  for (std::size_t i = 0; i < o.timings.size(); ++i) os << (i ? ", " : "") << '"' << timing_name(o.timings[i]) << '"';
  os << "], \"noise\": [";
  for (std::size_t i = 0; i < o.noises.size(); ++i) os << (i ? ", " : "") << '"' << noise_name(o.noises[i]) << '"';
  os << "], \"multiples\": [";
  for (std::size_t i = 0; i < o.multiples.size(); ++i) os << (i ? ", " : "") << json_num(o.multiples[i]);
  os << "]},\n  \"wall_s\": " << json_num(r.wall_s) << ",\n  \"unit_amplitudes\": [\n";
  for (std::size_t i = 0; i < r.units.size(); ++i) {
    const auto& u = r.units[i];
    os << "    {\"noise\": \"" << noise_name(u.noise) << "\", \"rate\": " << json_num(u.rate) << ", \"effect\": \""
       << u.effect << "\", \"axis\": " << u.axis << ", \"value\": " << json_num(u.value) << "}"
       << (i + 1 < r.units.size() ? "," : "") << "\n";
  }
  os << "  ],\n  \"cells\": [\n";
  for (std::size_t i = 0; i < r.cells.size(); ++i) {
    const CellSummary& c = r.cells[i];
    os << "    {\"timing\": \"" << timing_name(c.timing) << "\", \"noise\": \"" << noise_name(c.noise)
       << "\", \"rate\": " << json_num(c.rate) << ", \"hits\": {";
    for (std::size_t k = 0; k < c.hits_by_multiple.size(); ++k)
      os << (k ? ", " : "") << "\"" << json_num(c.hits_by_multiple[k].first) << "\": ["
         << c.hits_by_multiple[k].second.first << ", " << c.hits_by_multiple[k].second.second << "]";
    os << "}, \"null_clean\": [" << c.null_clean << ", " << c.n_null << "], \"phantoms\": " << c.phantoms
       << ", \"named\": " << c.named << ", \"logs\": " << c.logs << ", \"logs_with_phantom\": " << c.logs_with_phantom
       << ", \"errors\": " << c.errors << ", \"median_tau_error_periods\": " << json_num(c.median_tau_error)
       << ", \"tau_named\": " << c.tau_named << ", \"phantom_labels\": {";
    for (std::size_t k = 0; k < c.top_phantoms.size(); ++k)
      os << (k ? ", " : "") << "\"" << json_escape(c.top_phantoms[k].first) << "\": " << c.top_phantoms[k].second;
    os << "}}" << (i + 1 < r.cells.size() ? "," : "") << "\n";
  }
  os << "  ],\n  \"logs\": [\n";
  for (std::size_t i = 0; i < r.logs.size(); ++i) {
    const LogResult& l = r.logs[i];
    os << "    {\"timing\": \"" << timing_name(l.timing) << "\", \"noise\": \"" << noise_name(l.noise)
       << "\", \"rate\": " << json_num(l.rate) << ", \"seed\": " << l.seed << ", \"log_seed\": " << l.log_seed
       << ", \"planted\": " << (l.planted.empty() ? std::string("null") : "\"" + l.planted + "\"")
       << ", \"axis\": " << l.axis << ", \"multiple\": " << json_num(l.multiple)
       << ", \"amplitude\": " << json_num(l.amplitude) << ", \"named\": [";
    for (std::size_t k = 0; k < l.named.size(); ++k) {
      os << (k ? ", " : "") << "{\"effect\": \"" << l.named[k].effect << "\", \"axis\": " << l.named[k].axis;
      if (std::isfinite(l.named[k].tau)) os << ", \"tau\": " << json_num(l.named[k].tau);
      os << "}";
    }
    os << "], \"hit\": " << (l.hit ? "true" : "false") << ", \"phantoms\": [";
    for (std::size_t k = 0; k < l.phantoms.size(); ++k) os << (k ? ", " : "") << "\"" << json_escape(l.phantoms[k]) << "\"";
    os << "], \"tau_error_periods\": " << json_num(l.tau_error_periods) << ", \"error\": \"" << json_escape(l.error)
       << "\", \"generate_s\": " << json_num(l.generate_s) << ", \"diagnose_s\": " << json_num(l.diagnose_s) << "}"
       << (i + 1 < r.logs.size() ? "," : "") << "\n";
  }
  os << "  ]\n}\n";
  return os.str();
}

std::vector<std::string> threshold_failures(const MatrixResult& r, double phantom_rate) {
  std::vector<std::string> out;
  for (const CellSummary& c : r.cells) {
    std::ostringstream head;
    head << timing_name(c.timing) << " / " << noise_name(c.noise) << " / " << rate_text(c.rate) << ": ";
    std::vector<std::string> why;
    int hits = 0, planted = 0;
    for (const auto& [m, hn] : c.hits_by_multiple) hits += hn.first, planted += hn.second;
    if (hits < planted) {
      std::string s = "planted named " + std::to_string(hits) + "/" + std::to_string(planted) + " (missed:";
      for (const std::string& m : c.missed) s += " " + m + ";";
      why.push_back(s + ")");
    }
    if (c.null_clean < c.n_null)
      why.push_back("null clean " + std::to_string(c.null_clean) + "/" + std::to_string(c.n_null));
    if (static_cast<double>(c.logs_with_phantom) > phantom_rate * static_cast<double>(c.logs)) {
      std::string s = "phantoms in " + std::to_string(c.logs_with_phantom) + "/" + std::to_string(c.logs) +
                      " logs (allowed " + fmt(phantom_rate * c.logs, 3) + "):";
      for (const auto& [label, n] : c.top_phantoms) s += " " + label + " x" + std::to_string(n) + ";";
      why.push_back(s);
    }
    if (c.errors) why.push_back(std::to_string(c.errors) + " logs threw");
    if (why.empty()) continue;
    std::string line = head.str();
    for (std::size_t i = 0; i < why.size(); ++i) line += (i ? "; " : "") + why[i];
    out.push_back(line);
  }
  return out;
}

}  // namespace cpm::indep

// SPDX-License-Identifier: Apache-2.0
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

#include <nlohmann/json.hpp>

#include "cpm/identification/engine.hpp"
#include "cpm/identification/model_loop.hpp"
#include "cpm/identification/motion.hpp"

namespace cpm::indep {
namespace {

constexpr double kM1 = 1.892994, kL1 = 0.5;  // docs/model.md: first link mass (kg) and length (m)

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

}  // namespace

std::string effect_label(const std::string& effect, int axis) {
  if (axis < 0) return effect;
  return effect + "[axis " + std::to_string(axis + 1) + "]";
}

std::string NamedEffect::label() const { return effect_label(effect, axis); }

bool names_planted(const NamedEffect& n, const std::string& planted) {
  return n.label() == planted || std::find(n.alternatives.begin(), n.alternatives.end(), planted) != n.alternatives.end();
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
    for (const auto& q : c.params) {
      n.values.push_back(q.value);
      n.std_errors.push_back(q.std_error);
    }
    out.push_back(std::move(n));
  };
  // Structure no library effect describes is a claim too (verdict.missing = "outside_library").
  if (!D.outside_library.empty()) out.push_back({"outside_library", D.outside_library.front().axis, {}, {}, {}, {}});
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
      {"actuator_inertia", true, {1.0}, 0},
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

// ---- Combinations of effects planted at once ----------------------------------
namespace {

// Which placements of the two effects of a pair the rule covers.
enum class Where {
  any,        // wherever they are (machine-wide effects, or one of them is)
  same_axis,  // both on the same axis
  b_on_z,     // the second one on axis 3
};

// THE pairs that motion data cannot separate, so no combination plants both
// (docs/identification.md, "One statistic: forward selection" and
// "Confounding"). Only the pair is left out: each effect is still planted
// beside the others. Change the combinations here and only here.
struct Inseparable {
  const char* a;
  const char* b;
  Where where;
  const char* why;
};
const Inseparable kInseparable[] = {
    {"payload_mass", "inertia_error", Where::any,
     "a payload changes A and E (dA = dm/2, dE = dm g): it is an inertia error of the base model"},
    {"payload_mass", "force_gain", Where::b_on_z,
     "z carries the weight: a few grams of payload act as their weight only, which is what a drive gain on z "
     "also is"},
    {"inertia_error", "force_gain", Where::any, "a drive gain and the inertia of the same axis scale together"},
    {"coulomb_friction", "stribeck_friction", Where::same_axis, "the Stribeck bell overlaps a Coulomb step"},
    {"viscous_friction", "stribeck_friction", Where::same_axis,
     "one axis' friction is one curve of force against speed: over the speeds a log sweeps, the bell and a "
     "slope trade against each other"},
    {"coulomb_friction", "viscous_friction", Where::same_axis,
     "likewise a step and a slope (at one feed they are confounded outright)"},
    {"spring", "cogging", Where::same_axis,
     "the cogging search reaches lambda = 100 mm, over which a sine is a slope: on the stroke a log covers, a "
     "spring is a cogging of long wavelength"},
};

bool inseparable(const EffectOnAxis& x, const EffectOnAxis& y) {
  const auto& lib = dynamic_library();
  const std::string& nx = lib[static_cast<std::size_t>(x.effect)].name;
  const std::string& ny = lib[static_cast<std::size_t>(y.effect)].name;
  for (const Inseparable& rule : kInseparable) {
    const bool xy = nx == rule.a && ny == rule.b, yx = nx == rule.b && ny == rule.a;
    if (!xy && !yx) continue;
    const int b_axis = xy ? y.axis : x.axis;
    if (rule.where == Where::any || (rule.where == Where::same_axis && x.axis == y.axis) ||
        (rule.where == Where::b_on_z && b_axis == 2))
      return true;
  }
  return false;
}

void extend(const std::vector<int>& pool, std::size_t from, int n, std::vector<EffectOnAxis>& set,
            std::vector<std::vector<EffectOnAxis>>& out) {
  if (static_cast<int>(set.size()) == n) {
    out.push_back(set);
    return;
  }
  for (std::size_t i = from; i < pool.size(); ++i) {
    const bool per_axis = dynamic_library()[static_cast<std::size_t>(pool[i])].per_axis;
    for (int axis = per_axis ? 0 : -1; axis < (per_axis ? 3 : 0); ++axis) {
      set.push_back({pool[i], axis});
      if (separable(set)) extend(pool, i + 1, n, set, out);
      set.pop_back();
    }
  }
}

std::uint64_t splitmix64(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ULL;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
  return x ^ (x >> 31);
}

// The seed's combination of n effects: the same in every cell and at every
// multiple, so that cells differ only by their convention.
std::vector<EffectOnAxis> choose_combination(const std::vector<int>& pool, int n, int seed) {
  const auto all = separable_combinations(pool, n);
  if (all.empty()) throw Error("no separable combination of " + std::to_string(n) + " effects in the selected effects");
  const std::uint64_t key = splitmix64(static_cast<std::uint64_t>(seed) * 16ULL + static_cast<std::uint64_t>(n));
  return all[static_cast<std::size_t>(key % all.size())];
}

}  // namespace

bool separable(const std::vector<EffectOnAxis>& set) {
  for (std::size_t i = 0; i < set.size(); ++i)
    for (std::size_t j = i + 1; j < set.size(); ++j)
      if (set[i].effect == set[j].effect || inseparable(set[i], set[j])) return false;
  return true;
}

std::vector<std::vector<EffectOnAxis>> separable_combinations(const std::vector<int>& pool, int n) {
  std::vector<int> sorted = pool;
  std::sort(sorted.begin(), sorted.end());
  sorted.erase(std::unique(sorted.begin(), sorted.end()), sorted.end());
  std::vector<std::vector<EffectOnAxis>> out;
  std::vector<EffectOnAxis> set;
  if (n > 0) extend(sorted, 0, n, set, out);
  return out;
}

// ---- Scoring -------------------------------------------------------------------
namespace {

// Labels of what a log planted: its one effect, every effect of a combination, or none.
std::vector<std::string> planted_labels(const LogResult& r) {
  std::vector<std::string> out;
  if (!r.planted.empty()) out.push_back(effect_label(r.planted, r.axis));
  for (const PlantedEffect& p : r.combo) out.push_back(effect_label(p.name, p.axis));
  return out;
}

// Score one diagnosed log against what was planted and the cell's convention:
// each planted effect named or not, anything else named a phantom.
void score(LogResult& r, double period) {
  const double true_delay = delay_periods(r.timing);
  const std::vector<std::string> planted = planted_labels(r);
  std::vector<bool> named(planted.size(), false);
  for (const NamedEffect& n : r.named) {
    if (n.effect == "actuation_delay") {
      if (std::isfinite(n.tau)) r.tau_error_periods = std::fabs(n.tau / period - true_delay);
      if (is_delay_cell(r.timing)) continue;  // the cell's own convention: expected
    }
    bool any = false;
    for (std::size_t k = 0; k < planted.size(); ++k)
      if (names_planted(n, planted[k])) named[k] = any = true;
    if (!any) r.phantoms.push_back(n.label());
  }
  r.planted_named = static_cast<int>(std::count(named.begin(), named.end(), true));
  r.hit = !planted.empty() && r.planted_named == static_cast<int>(planted.size());
}

// amplitude_z of a single-effect log (LogResult).
void record_amplitude_z(LogResult& r) {
  if (r.planted.empty() || r.is_combo()) return;
  const auto& lib = dynamic_library();
  const auto e = std::find_if(lib.begin(), lib.end(), [&](const EffectShape& s) { return s.name == r.planted; });
  if (e == lib.end()) return;
  const std::vector<double> truth = planted_values(*e, r.amplitude);
  std::size_t j = 0;
  if (e->amp_index >= 0) j = static_cast<std::size_t>(e->amp_index);
  else
    for (std::size_t k = 1; k < e->shape.size(); ++k)
      if (std::fabs(e->shape[k]) > std::fabs(e->shape[j])) j = k;
  for (const NamedEffect& n : r.named)
    if (n.effect == r.planted && n.axis == r.axis && j < n.values.size() && n.std_errors[j] > 0.0)
      r.amplitude_z = (n.values[j] - truth[j]) / n.std_errors[j];
}

}  // namespace

double LogResult::final_over_floor() const {
  if (waterfall.empty() || !(waterfall.back().noise_floor > 0.0)) return std::numeric_limits<double>::quiet_NaN();
  return waterfall.back().rms / waterfall.back().noise_floor;
}

// ---- Running the matrix --------------------------------------------------------
namespace {

struct Job {
  Timing timing;
  NoisePlacement noise;
  double rate;
  int seed;
  int effect = -1;  // index in dynamic_library(), -1 null (or a combination)
  int multiple = -1;
  int combo = 0;    // combination size, 0: a single effect or a null log
};

// Unit amplitudes per (noise placement, rate): [effect index][axis].
using UnitTable = std::map<std::pair<int, double>, std::vector<std::array<double, 3>>>;

struct Context {
  std::vector<int> pool;  // effects planted (indices in dynamic_library())
  UnitTable unit;
  ctl::Machine nominal{ctl::MachineModel::elkady()};
};

// The generator seed of a combination log: apart from log_seed()'s (effect index + 1 <= 8).
std::uint64_t combo_log_seed(int seed, int n, int multiple_index) {
  return static_cast<std::uint64_t>(seed) * 1000ULL + 500ULL + static_cast<std::uint64_t>(n) * 10ULL +
         static_cast<std::uint64_t>(multiple_index);
}

std::vector<int> effect_pool(const MatrixOptions& o) {
  const auto& lib = dynamic_library();
  std::vector<int> pool;
  if (o.effects.empty()) {
    for (int i = 0; i < static_cast<int>(lib.size()); ++i) pool.push_back(i);
    return pool;
  }
  for (const std::string& name : o.effects) {
    int found = -1;
    for (int i = 0; i < static_cast<int>(lib.size()); ++i)
      if (lib[static_cast<std::size_t>(i)].name == name) found = i;
    if (found < 0) throw Error("unknown effect '" + name + "' (the dynamic library of docs/effects.md)");
    pool.push_back(found);
  }
  return pool;
}

// Unit amplitudes per (noise, rate), effect and axis, on a zoh null log.
UnitTable unit_amplitudes(const MatrixOptions& o, const Context& ctx, std::vector<MatrixResult::Unit>& units) {
  const auto& lib = dynamic_library();
  UnitTable unit;
  for (NoisePlacement nz : o.noises)
    for (double rate : o.rates) {
      GeneratorSpec s;
      s.timing = Timing::zoh;
      s.noise = nz;
      s.rate = rate;
      s.duration = o.duration;
      s.seed = 987654;
      const io::MotionData null_log = generate(s).log;
      const ident::MotionProblem P = ident::prepare_motion(null_log, ctx.nominal);
      const ident::Engine E(ident::motion_linear_problem(P));
      auto& u = unit[{static_cast<int>(nz), rate}];
      u.assign(lib.size(), {0.0, 0.0, 0.0});
      for (int ei : ctx.pool) {
        const EffectShape& e = lib[static_cast<std::size_t>(ei)];
        for (int axis = 0; axis < (e.per_axis ? 3 : 1); ++axis) {
          const double v = 4.0 * amplitude_standard_error(P, E, e, e.per_axis ? axis : -1);
          u[static_cast<std::size_t>(ei)][static_cast<std::size_t>(axis)] = v;
          units.push_back({nz, rate, e.name, e.per_axis ? axis : -1, v});
        }
      }
    }
  return unit;
}

std::vector<Job> make_jobs(const MatrixOptions& o, const std::vector<int>& pool) {
  std::vector<Job> jobs;
  const int nm = static_cast<int>(o.multiples.size());
  for (int seed = o.first_seed; seed < o.first_seed + o.seeds; ++seed)
    for (double rate : o.rates)
      for (NoisePlacement nz : o.noises)
        for (Timing t : o.timings) {
          if (!o.combos.empty()) {
            for (int n : o.combos)
              for (int m = 0; m < nm; ++m) jobs.push_back({t, nz, rate, seed, -1, m, n});
            continue;
          }
          if (o.nulls) jobs.push_back({t, nz, rate, seed, -1, -1});
          for (int ei : pool)
            for (int m = 0; m < nm; ++m) jobs.push_back({t, nz, rate, seed, ei, m});
        }
  return jobs;
}

double unit_of(const Context& ctx, const Job& job, int effect, int axis) {
  return ctx.unit.at({static_cast<int>(job.noise), job.rate})[static_cast<std::size_t>(effect)]
                    [static_cast<std::size_t>(std::max(axis, 0))];
}

// What the job plants: sets r's planted fields, returns the generator's effects.
std::vector<PlantedEffect> plant(const Job& job, const MatrixOptions& o, const Context& ctx, LogResult& r) {
  const auto& lib = dynamic_library();
  if (job.multiple < 0) return {};  // a null log
  r.multiple = o.multiples[static_cast<std::size_t>(job.multiple)];
  if (job.combo > 0) {
    for (const EffectOnAxis& p : choose_combination(ctx.pool, job.combo, job.seed)) {
      const EffectShape& e = lib[static_cast<std::size_t>(p.effect)];
      r.combo.push_back({e.name, p.axis, planted_values(e, r.multiple * unit_of(ctx, job, p.effect, p.axis))});
    }
    return r.combo;
  }
  const EffectShape& e = lib[static_cast<std::size_t>(job.effect)];
  // The planted axis varies with the seed (and with the effect).
  r.axis = e.per_axis ? (job.seed + job.effect) % 3 : -1;
  r.planted = e.name;
  r.amplitude = r.multiple * unit_of(ctx, job, job.effect, r.axis);
  return {{e.name, r.axis, planted_values(e, r.amplitude)}};
}

std::string log_file_name(const std::string& dir, const LogResult& r) {
  std::ostringstream name;
  name << dir << "/" << timing_name(r.timing) << "_" << noise_name(r.noise) << "_" << static_cast<int>(r.rate);
  if (r.is_combo())
    for (const PlantedEffect& p : r.combo) name << "_" << p.name << (p.axis >= 0 ? "_axis" + std::to_string(p.axis + 1) : "");
  else
    name << "_" << (r.planted.empty() ? std::string("null") : r.planted)
         << (r.axis >= 0 ? "_axis" + std::to_string(r.axis + 1) : "");
  if (r.multiple > 0) name << "_x" << static_cast<int>(r.multiple);
  name << "_seed" << r.seed << ".csv";
  return name.str();
}

// The user's loop from the nominal model on a combination log: the waterfall.
void run_loop_on(LogResult& r, const io::MotionData& log, const MatrixOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  const ident::LoopResult L = ident::run_loop(io::DataSet(log), ctl::MachineModel::elkady(), o.diagnose);
  r.loop_s = seconds_since(t0);
  r.waterfall = L.steps;
  r.loop_stop = L.stop;
  r.loop_within = !L.steps.empty() && L.steps.back().rms <= kLoopTolerance * L.steps.back().noise_floor;
}

LogResult run_job(const Job& job, const MatrixOptions& o, const Context& ctx) {
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
  s.seed = r.log_seed = job.combo > 0 ? combo_log_seed(job.seed, job.combo, job.multiple)
                                      : log_seed(job.seed, job.effect, job.multiple);
  s.effects = plant(job, o, ctx, r);
  try {
    auto t0 = std::chrono::steady_clock::now();
    const GeneratedLog g = generate(s);
    r.generate_s = seconds_since(t0);
    if (!o.write_logs.empty()) io::write_motion(log_file_name(o.write_logs, r), g.log);
    t0 = std::chrono::steady_clock::now();
    const ident::Diagnosis D = ident::diagnose_motion(g.log, ctx.nominal, o.diagnose);
    r.diagnose_s = seconds_since(t0);
    r.named = named_effects(D);
    score(r, 1.0 / r.rate);
    record_amplitude_z(r);
    if (r.is_combo()) run_loop_on(r, g.log, o);
  } catch (const std::exception& ex) {
    r.error = ex.what();
  }
  return r;
}

// fn(0 .. n-1), on `threads` threads taking the next index as they finish.
void run_parallel(std::size_t n, int threads, const std::function<void(std::size_t)>& fn) {
  std::atomic<std::size_t> next{0};
  auto worker = [&]() {
    for (std::size_t j = next.fetch_add(1); j < n; j = next.fetch_add(1)) fn(j);
  };
  if (threads <= 1) return worker();
  std::vector<std::thread> pool;
  for (int i = 0; i < threads; ++i) pool.emplace_back(worker);
  for (auto& th : pool) th.join();
}

}  // namespace

MatrixResult run_matrix(const MatrixOptions& o, const std::function<void(const LogResult&, int, int)>& progress) {
  const auto t_start = std::chrono::steady_clock::now();
  MatrixResult res;
  res.options = o;
  Context ctx;
  ctx.pool = effect_pool(o);
  for (int n : o.combos) (void)choose_combination(ctx.pool, n, o.first_seed);  // throws when there is none
  ctx.unit = unit_amplitudes(o, ctx, res.units);
  const std::vector<Job> jobs = make_jobs(o, ctx.pool);
  res.logs.resize(jobs.size());
  if (!o.write_logs.empty()) std::filesystem::create_directories(o.write_logs);
  std::atomic<int> done{0};
  std::mutex mu;
  run_parallel(jobs.size(), o.threads, [&](std::size_t j) {
    res.logs[j] = run_job(jobs[j], o, ctx);
    const int d = ++done;
    if (!progress) return;
    std::lock_guard<std::mutex> lock(mu);
    progress(res.logs[j], d, static_cast<int>(jobs.size()));
  });
  res.cells = summarise(res.logs, o);
  res.wall_s = seconds_since(t_start);
  return res;
}

// ---- Summaries and reports ---------------------------------------------------
namespace {

double median(std::vector<double> v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

std::string joined(const std::vector<std::string>& items) {
  std::string s;
  for (const std::string& x : items) s += (s.empty() ? "" : ", ") + x;
  return s;
}

std::string named_text(const LogResult& r) {
  std::vector<std::string> labels;
  for (const NamedEffect& n : r.named) labels.push_back(n.label());
  return "{" + joined(labels) + "}";
}

// A single-effect or null log in its cell's counts.
void add_single(CellSummary& c, const LogResult& r, std::map<double, std::pair<int, int>>& by_mult) {
  if (r.planted.empty()) {
    ++c.n_null;
    if (r.error.empty() && r.phantoms.empty()) ++c.null_clean;
    return;
  }
  auto& bm = by_mult[r.multiple];
  ++bm.second;
  if (r.hit) {
    ++bm.first;
    return;
  }
  std::ostringstream m;
  m << effect_label(r.planted, r.axis) << " x" << r.multiple << " seed " << r.seed;
  if (!r.error.empty()) m << " (error: " << r.error << ")";
  c.missed.push_back(m.str());
}

// A combination log in its cell's counts; `ratios` collects final RMS / floor.
void add_combo(CellSummary& c, const LogResult& r, std::vector<double>& ratios) {
  ++c.n_combo;
  if (r.hit) ++c.combo_all_named;
  if (r.loop_within) ++c.loop_within;
  if (std::isfinite(r.final_over_floor())) ratios.push_back(r.final_over_floor());
  if (!r.hit || !r.loop_within || !r.phantoms.empty() || !r.error.empty()) c.combo_failures.push_back(combo_log_text(r));
}

// The cell's phantoms, most frequent first (at most 4), then its errors.
std::string named_instead(const CellSummary& c) {
  std::ostringstream os;
  int shown = 0;
  for (const auto& [label, n] : c.top_phantoms) {
    if (shown++ == 4) {
      os << ", ...";
      break;
    }
    os << (shown > 1 ? ", " : "") << label << " " << n;
  }
  if (c.errors) os << (shown ? "; " : "") << c.errors << " errors";
  return os.str();
}

CellSummary summarise_cell(const std::vector<LogResult>& logs, Timing t, NoisePlacement nz, double rate) {
  CellSummary c;
  c.timing = t;
  c.noise = nz;
  c.rate = rate;
  std::map<std::string, int> ph;
  std::vector<double> taus, ratios;
  std::map<double, std::pair<int, int>> by_mult;
  for (const LogResult& r : logs) {
    if (r.timing != t || r.noise != nz || r.rate != rate) continue;
    ++c.logs;
    if (!r.error.empty()) ++c.errors;
    if (r.is_combo())
      add_combo(c, r, ratios);
    else
      add_single(c, r, by_mult);
    c.named += static_cast<int>(r.named.size());
    c.phantoms += static_cast<int>(r.phantoms.size());
    if (!r.phantoms.empty()) ++c.logs_with_phantom;
    for (const std::string& p : r.phantoms) ++ph[p];  // by label (axis kept): what is named instead
    if (std::isfinite(r.tau_error_periods)) taus.push_back(r.tau_error_periods);
  }
  for (const auto& [m, hn] : by_mult) {
    c.hits_by_multiple.push_back({m, hn});
    if (m == 3.0) c.hits3 = hn.first, c.n3 = hn.second;
    if (m == 10.0) c.hits10 = hn.first, c.n10 = hn.second;
  }
  c.tau_named = static_cast<int>(taus.size());
  c.median_tau_error = median(taus);
  c.median_final_over_floor = median(ratios);
  c.top_phantoms.assign(ph.begin(), ph.end());
  std::sort(c.top_phantoms.begin(), c.top_phantoms.end(),
            [](const auto& a, const auto& b) { return a.second != b.second ? a.second > b.second : a.first < b.first; });
  return c;
}

std::string count_of(int k, int n) { return n ? std::to_string(k) + "/" + std::to_string(n) : "-"; }

std::string cell_head(const CellSummary& c) {
  return "| " + std::string(timing_name(c.timing)) + " | " + noise_name(c.noise) + " | " + fmt(c.rate, 6) + " | ";
}

std::string single_table(const MatrixResult& r) {
  std::ostringstream os;
  os << "| timing | noise | rate | hits 3x | hits 10x | null clean | phantoms / named | logs with phantom | median "
        "abs(tau err)/T | named instead (count) |\n";
  os << "|---|---|---|---|---|---|---|---|---|---|\n";
  for (const CellSummary& c : r.cells) {
    os << cell_head(c) << count_of(c.hits3, c.n3) << " | " << count_of(c.hits10, c.n10) << " | "
       << count_of(c.null_clean, c.n_null) << " | ";
    os << c.phantoms << "/" << c.named << " | " << c.logs_with_phantom << "/" << c.logs << " | ";
    if (is_delay_cell(c.timing))
      os << (c.tau_named ? fmt(c.median_tau_error, 3) + " (" + std::to_string(c.tau_named) + " named)"
                         : std::string("not named"));
    else
      os << "-";
    os << " | " << named_instead(c) << " |\n";
  }
  return os.str();
}

std::string combo_table(const MatrixResult& r) {
  std::ostringstream os;
  os << "| timing | noise | rate | all planted named | phantoms / named | loop within 20 % of floor | median final "
        "RMS / floor | named instead (count) |\n";
  os << "|---|---|---|---|---|---|---|---|\n";
  for (const CellSummary& c : r.cells)
    os << cell_head(c) << count_of(c.combo_all_named, c.n_combo) << " | " << c.phantoms << "/" << c.named << " | "
       << count_of(c.loop_within, c.n_combo) << " | " << fmt(c.median_final_over_floor, 3) << " | "
       << named_instead(c) << " |\n";
  return os.str();
}

}  // namespace

std::string combo_log_text(const LogResult& r) {
  std::vector<std::string> planted;
  for (const PlantedEffect& p : r.combo) planted.push_back(effect_label(p.name, p.axis));
  std::ostringstream os;
  os.precision(3);
  os << timing_name(r.timing) << " " << noise_name(r.noise) << " " << rate_text(r.rate) << " seed " << r.seed << " x"
     << r.multiple << " {" << joined(planted) << "}: named " << named_text(r);
  if (!r.error.empty()) return os.str() + " (error: " + r.error + ")";
  os << (r.hit ? " ALL" : " MISSED") << "; waterfall";
  for (const ident::LoopStep& s : r.waterfall) os << (s.added.empty() ? " " : " -> +" + s.added + " ") << s.rms;
  os << " N, floor " << (r.waterfall.empty() ? 0.0 : r.waterfall.back().noise_floor) << " N ("
     << r.final_over_floor() << "x" << (r.loop_within ? ")" : ", NOT within 20 %)");
  if (!r.loop_within) os << "; stop: " << r.loop_stop;
  return os.str();
}

std::vector<CellSummary> summarise(const std::vector<LogResult>& logs, const MatrixOptions& o) {
  std::vector<CellSummary> cells;
  for (double rate : o.rates)
    for (NoisePlacement nz : o.noises)
      for (Timing t : o.timings) {
        CellSummary c = summarise_cell(logs, t, nz, rate);
        if (c.logs > 0) cells.push_back(std::move(c));
      }
  return cells;
}

std::string amplitude_bias_table(const MatrixResult& r) {
  std::map<std::pair<int, std::string>, std::vector<double>> z;  // (noise, effect) -> z of the logs
  for (const LogResult& l : r.logs)
    if (std::isfinite(l.amplitude_z)) z[{static_cast<int>(l.noise), l.planted}].push_back(l.amplitude_z);
  std::ostringstream os;
  os.precision(2);
  os << std::fixed << "| noise | effect | logs | mean z | sd z | mean z / its s.e. |\n|---|---|---|---|---|---|\n";
  for (const auto& [key, v] : z) {
    const double n = static_cast<double>(v.size());
    double m = 0.0, s2 = 0.0;
    for (double x : v) m += x / n;
    for (double x : v) s2 += (x - m) * (x - m) / std::max(1.0, n - 1.0);
    const double sd = std::sqrt(s2), se = n > 1 ? sd / std::sqrt(n) : 0.0;
    os << "| " << noise_name(static_cast<NoisePlacement>(key.first)) << " | " << key.second << " | " << v.size()
       << " | " << m << " | " << sd << " | " << (se > 0.0 ? m / se : 0.0) << " |\n";
  }
  return os.str();
}

std::string markdown_table(const MatrixResult& r) {
  return r.options.combos.empty() ? single_table(r) : combo_table(r);
}

namespace {

using Json = nlohmann::ordered_json;

// Names of enum values, as a JSON array.
template <class T, class Name>
Json names_json(const std::vector<T>& v, Name name) {
  Json a = Json::array();
  for (const T& x : v) a.push_back(name(x));
  return a;
}

Json options_json(const MatrixOptions& o) {
  return {{"seeds", o.seeds},
          {"first_seed", o.first_seed},
          {"duration_s", o.duration},
          {"threads", o.threads},
          {"rates", o.rates},
          {"timings", names_json(o.timings, timing_name)},
          {"noise", names_json(o.noises, noise_name)},
          {"multiples", o.multiples},
          {"combos", o.combos}};
}

Json cell_json(const CellSummary& c) {
  Json hits = Json::object();  // by multiple, "10": [named, planted]
  for (const auto& [multiple, hn] : c.hits_by_multiple) hits[fmt(multiple, 10)] = {hn.first, hn.second};
  Json phantoms = Json::object();
  for (const auto& [label, n] : c.top_phantoms) phantoms[label] = n;
  Json o = {{"timing", timing_name(c.timing)},
            {"noise", noise_name(c.noise)},
            {"rate", c.rate},
            {"hits", hits},
            {"null_clean", {c.null_clean, c.n_null}},
            {"phantoms", c.phantoms},
            {"named", c.named},
            {"logs", c.logs},
            {"logs_with_phantom", c.logs_with_phantom},
            {"errors", c.errors},
            {"median_tau_error_periods", c.median_tau_error},
            {"tau_named", c.tau_named},
            {"phantom_labels", phantoms}};
  if (c.n_combo)
    o["combo"] = {{"logs", c.n_combo},
                  {"all_named", c.combo_all_named},
                  {"loop_within", c.loop_within},
                  {"median_final_over_floor", c.median_final_over_floor}};
  return o;
}

// A combination log's planted list and waterfall.
void add_combo(Json& o, const LogResult& l) {
  Json combo = Json::array();
  for (const PlantedEffect& p : l.combo) combo.push_back({{"effect", p.name}, {"axis", p.axis}, {"values", p.values}});
  Json waterfall = Json::array();
  for (const ident::LoopStep& s : l.waterfall)
    waterfall.push_back({{"added", s.added.empty() ? Json() : Json(s.added)}, {"rms", s.rms},
                         {"noise_floor", s.noise_floor}, {"verdict", s.verdict}});
  o["combo"] = std::move(combo);
  o["planted_named"] = l.planted_named;
  o["waterfall"] = std::move(waterfall);
  o["loop_within"] = l.loop_within;
  o["loop_stop"] = l.loop_stop;
  o["final_over_floor"] = l.final_over_floor();
  o["loop_s"] = l.loop_s;
}

Json log_json(const LogResult& l) {
  Json named = Json::array();
  for (const NamedEffect& n : l.named) {
    Json e = {{"effect", n.effect}, {"axis", n.axis}};
    if (std::isfinite(n.tau)) e["tau"] = n.tau;
    named.push_back(std::move(e));
  }
  Json o = {{"timing", timing_name(l.timing)},
            {"noise", noise_name(l.noise)},
            {"rate", l.rate},
            {"seed", l.seed},
            {"log_seed", l.log_seed},
            {"planted", l.planted.empty() ? Json() : Json(l.planted)},
            {"axis", l.axis},
            {"multiple", l.multiple},
            {"amplitude", l.amplitude},
            {"named", named},
            {"hit", l.hit},
            {"phantoms", l.phantoms},
            {"tau_error_periods", l.tau_error_periods},
            {"amplitude_z", l.amplitude_z},
            {"error", l.error},
            {"generate_s", l.generate_s},
            {"diagnose_s", l.diagnose_s}};
  if (l.is_combo()) add_combo(o, l);
  return o;
}

Json unit_json(const MatrixResult::Unit& u) {
  return {{"noise", noise_name(u.noise)}, {"rate", u.rate}, {"effect", u.effect}, {"axis", u.axis}, {"value", u.value}};
}

template <class T, class F>
Json rows_json(const std::vector<T>& v, F item) {
  Json a = Json::array();
  for (const T& x : v) a.push_back(item(x));
  return a;
}

}  // namespace

std::string to_json(const MatrixResult& r) {
  const Json o = {{"options", options_json(r.options)},
                  {"wall_s", r.wall_s},
                  {"unit_amplitudes", rows_json(r.units, unit_json)},
                  {"cells", rows_json(r.cells, cell_json)},
                  {"logs", rows_json(r.logs, log_json)}};
  return o.dump(2, ' ', false, Json::error_handler_t::replace) + "\n";
}


namespace {

// Why a single-effect cell fails: a planted effect missed, a null log not
// clean, phantoms in more than phantom_rate of the logs.
std::vector<std::string> single_failures(const CellSummary& c, double phantom_rate) {
  std::vector<std::string> why;
  int hits = 0, planted = 0;
  for (const auto& [m, hn] : c.hits_by_multiple) hits += hn.first, planted += hn.second;
  if (hits < planted) {
    std::string s = "planted named " + std::to_string(hits) + "/" + std::to_string(planted) + " (missed:";
    for (const std::string& m : c.missed) s += " " + m + ";";
    why.push_back(s + ")");
  }
  if (c.null_clean < c.n_null) why.push_back("null clean " + std::to_string(c.null_clean) + "/" + std::to_string(c.n_null));
  if (static_cast<double>(c.logs_with_phantom) > phantom_rate * static_cast<double>(c.logs)) {
    std::string s = "phantoms in " + std::to_string(c.logs_with_phantom) + "/" + std::to_string(c.logs) +
                    " logs (allowed " + fmt(phantom_rate * c.logs, 3) + "):";
    for (const auto& [label, n] : c.top_phantoms) s += " " + label + " x" + std::to_string(n) + ";";
    why.push_back(s);
  }
  return why;
}

constexpr double kComboShare = 0.95;  // all planted named, and the loop within 20 %, in >= 95 % of the logs

// Why a combination cell fails: all planted named or the loop within 20 % of
// the floor in fewer than 95 % of its logs, phantoms above phantom_rate of the names.
std::vector<std::string> combo_cell_failures(const CellSummary& c, double phantom_rate) {
  std::vector<std::string> why;
  const double need = kComboShare * c.n_combo;
  if (c.combo_all_named < need)
    why.push_back("all planted named in " + count_of(c.combo_all_named, c.n_combo) + " logs");
  if (c.loop_within < need) why.push_back("loop within 20 % of the floor in " + count_of(c.loop_within, c.n_combo) + " logs");
  if (static_cast<double>(c.phantoms) > phantom_rate * static_cast<double>(c.named))
    why.push_back("phantoms " + std::to_string(c.phantoms) + "/" + std::to_string(c.named) + " named (allowed " +
                  fmt(phantom_rate * c.named, 3) + "): " + named_instead(c));
  return why;
}

}  // namespace

std::vector<std::string> threshold_failures(const MatrixResult& r, double phantom_rate) {
  std::vector<std::string> out;
  for (const CellSummary& c : r.cells) {
    std::vector<std::string> why = c.n_combo ? combo_cell_failures(c, phantom_rate) : single_failures(c, phantom_rate);
    if (c.errors) why.push_back(std::to_string(c.errors) + " logs threw");
    if (why.empty()) continue;
    std::string line = std::string(timing_name(c.timing)) + " / " + noise_name(c.noise) + " / " + rate_text(c.rate) + ": ";
    for (std::size_t i = 0; i < why.size(); ++i) line += (i ? "; " : "") + why[i];
    for (const std::string& l : c.combo_failures) line += "\n      " + l;  // the logs that miss, with their waterfall
    out.push_back(line);
  }
  return out;
}

}  // namespace cpm::indep

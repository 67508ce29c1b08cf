// SPDX-License-Identifier: Apache-2.0
// cpm_robustness: the robustness matrix of `cpm diagnose` on motion logs from
// the independent generator. Prints a markdown table (one row per cell) and,
// with --json FILE, every log's result.
//
//   cpm_robustness [--seeds N] [--first-seed K] [--rates 250,1000,4000] [--timings sampled,zoh,delay1,delay1_5]
//                  [--noise plant,command] [--effects viscous_friction,...|none] [--multiples 3,10]
//                  [--no-null] [--duration S] [--threads N] [--json FILE] [--write-logs DIR]
//                  [--combos 2,3] [--quick] [--quick-combos] [--check] [--estimate] [--quiet]
//
// --quick   the reduced matrix of the ctest identification.robustness_quick:
//           one seed, 1000 and 250 Hz, every timing and noise placement,
//           null + viscous, Coulomb and force gain at 10x, 15 s logs
//           (options after --quick override it).
// --combos N,...  combination logs instead: per seed, cell and size N one log
//           with N effects planted at once (a separable combination chosen
//           from the seed, matrix.cpp kInseparable), at --multiples (default
//           10); scored on all planted named and phantoms, then the loop
//           (ident::run_loop) from the nominal model: its waterfall, and
//           whether it ends within 20 % of the noise floor.
// --quick-combos  the reduced matrix of the ctest
//           identification.robustness_combos_quick: one seed, 1000 and 250 Hz,
//           zoh and delay1, both noise placements, combos 2 and 3 at 10x,
//           15 s logs (options after it override it).
// --check   exit 1 unless every planted effect is named, every null log is
//           clean and phantoms stay <= 1 in 50 logs in every cell; with
//           --combos, unless in every cell all planted are named and the loop
//           ends within 20 % of the floor in >= 95 % of the logs and phantoms
//           stay <= 1 in 50 named.
// --estimate  time one log (generate + diagnose) at each selected rate and
//           print how long the selected matrix would take; run nothing else.
#include <array>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "matrix.hpp"
#include "open_world.hpp"

namespace {

using namespace cpm::indep;

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ','))
    if (!item.empty()) out.push_back(item);
  return out;
}

std::vector<double> numbers(const std::string& s) {
  std::vector<double> out;
  for (const std::string& x : split(s)) out.push_back(std::stod(x));
  return out;
}

int logs_per_cell(const MatrixOptions& o) {
  if (!o.combos.empty()) return static_cast<int>(o.combos.size() * o.multiples.size());
  const std::size_t ne = o.effects.empty() ? dynamic_library().size() : o.effects.size();
  return (o.nulls ? 1 : 0) + static_cast<int>(ne * o.multiples.size());
}

// One null log per rate, zoh with plant noise: the time to generate and diagnose it.
void estimate(const MatrixOptions& o) {
  const cpm::ctl::Machine nominal(cpm::ctl::MachineModel::elkady());
  const int cells_per_rate = static_cast<int>(o.timings.size() * o.noises.size());
  const int per_cell = logs_per_cell(o) * o.seeds;
  double total = 0.0;
  std::printf("| rate | generate (s) | diagnose (s) | one log (s) | logs at this rate | estimate (min, %d thread%s) |\n",
              o.threads, o.threads > 1 ? "s" : "");
  std::printf("|---|---|---|---|---|---|\n");
  for (double rate : o.rates) {
    double gen = 0.0, diag = 0.0;
    for (Timing t : {Timing::zoh, Timing::sampled}) {
      GeneratorSpec s;
      s.timing = t;
      s.rate = rate;
      s.duration = o.duration;
      s.seed = 5;
      auto t0 = std::chrono::steady_clock::now();
      const GeneratedLog g = generate(s);
      const double tg = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      t0 = std::chrono::steady_clock::now();
      (void)cpm::ident::diagnose_motion(g.log, nominal, o.diagnose);
      const double td = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      gen += 0.5 * tg;  // the mean of the held and the continuous controller
      diag += 0.5 * td;
      std::fprintf(stderr, "  %s at %.0f Hz: generate %.2f s, diagnose %.2f s\n", timing_name(t), rate, tg, td);
    }
    const int n = cells_per_rate * per_cell;
    // Plus the unit-amplitude null logs (one per noise placement).
    const double t_rate = (n * (gen + diag)) / std::max(1, o.threads) + o.noises.size() * (gen + diag);
    total += t_rate;
    std::printf("| %.0f Hz | %.2f | %.2f | %.2f | %d | %.1f |\n", rate, gen, diag, gen + diag, n, t_rate / 60.0);
  }
  std::printf("\nestimated wall time of the selected matrix: %.1f min (%d seeds, %.0f s logs)\n", total / 60.0,
              o.seeds, o.duration);
  if (!o.combos.empty())
    std::printf("combination logs also run the loop: about N + 1 more diagnoses and N fits each (not included)\n");
}

// What the command line asks beyond the matrix itself.
struct Flags {
  std::string json_path;
  bool check = false, estimate = false, quiet = false;
  bool multiples_given = false;
  bool outside = false;  // the open-world matrix (open_world.hpp) instead
  std::vector<std::string> outside_kinds;  // its kinds (empty: all)
};

// The presets: options given after them override them.
void quick(MatrixOptions& o) {
  o.seeds = 1;
  o.rates = {1000.0, 250.0};
  o.effects = {"viscous_friction", "coulomb_friction", "force_gain"};
  o.multiples = {10.0};
  o.duration = 15.0;  // keeps the ctest under 3 min on one core
}
void quick_combos(MatrixOptions& o) {
  o.seeds = 1;
  o.rates = {1000.0, 250.0};
  o.timings = {Timing::zoh, Timing::delay1};
  o.combos = {2, 3};
  o.duration = 15.0;  // keeps the ctest at about 2 min on one core
}

// The options that shape the matrix. Every option takes effect where it
// stands on the command line (trigger_on_parse), so options after --quick
// or --quick-combos override the preset.
template <class T>
void option(CLI::App& app, const char* name, const char* value, const std::function<void(const T&)>& set,
            const char* help) {
  app.add_option_function<T>(name, set, help)->type_name(value)->trigger_on_parse();
}

void add_matrix_options(CLI::App& app, MatrixOptions& o, Flags& f) {
  using S = std::string;
  option<int>(app, "--seeds", "N", [&](int n) { o.seeds = n; }, "seeds per cell (default 1), e.g. --seeds 20");
  option<int>(app, "--first-seed", "K", [&](int n) { o.first_seed = n; }, "the first seed: seeds K .. K+N-1 (default 1)");
  option<S>(app, "--rates", "HZ,...", [&](const S& v) { o.rates = numbers(v); },
      "sampling rates in Hz, comma-separated (default 250,1000,4000)");
  option<S>(app, "--timings", "NAME,...", [&](const S& v) {
        o.timings.clear();
        for (const std::string& s : split(v)) o.timings.push_back(timing_from_name(s));
      }, "when the logged force acts: sampled, zoh, delay1, delay1_5, comma-separated (default all four)");
  option<S>(app, "--noise", "NAME,...", [&](const S& v) {
        o.noises.clear();
        for (const std::string& s : split(v)) o.noises.push_back(noise_from_name(s));
      }, "where the noise enters: plant, command, comma-separated (default both)");
  option<S>(app, "--effects", "NAME,...|none", [&](const S& v) { o.effects = v == "none" ? std::vector<std::string>{"__none__"} : split(v); },
      "effects to plant, comma-separated names of effects.md, or none (default: the whole dynamic library), "
      "e.g. --effects viscous_friction,coulomb_friction");
  option<S>(app, "--multiples", "X,...", [&](const S& v) { o.multiples = numbers(v), f.multiples_given = true; },
      "planted amplitudes in multiples of the effect's unit amplitude (default 3,10; with --combos 10)");
  option<S>(app, "--combos", "N,...", [&](const S& v) {
        o.combos.clear();
        for (double n : numbers(v)) o.combos.push_back(static_cast<int>(n));
      }, "combination logs instead: sizes N >= 2 of effects planted at once, e.g. --combos 2,3");
  option<double>(app, "--duration", "S", [&](double s) { o.duration = s; }, "seconds of motion per log (default 20)");
  option<int>(app, "--threads", "N", [&](int n) { o.threads = n; }, "logs run in parallel (default 1)");
  option<S>(app, "--write-logs", "DIR", [&](const S& d) { o.write_logs = d; }, "directory: write every log as CSV");
  app.add_flag_callback("--no-null", [&] { o.nulls = false; }, "no null logs (nothing planted)")->trigger_on_parse();
  app.add_flag_callback("--quick", [&] { quick(o); },
                        "the reduced matrix of the ctest: one seed, 1000 and 250 Hz, null + viscous, Coulomb and "
                        "force gain at 10x, 15 s logs (options after it override it)")
      ->trigger_on_parse();
  app.add_flag_callback("--quick-combos", [&] { quick_combos(o); },
                        "the reduced combination matrix of the ctest: one seed, 1000 and 250 Hz, zoh and delay1, "
                        "combos 2 and 3 at 10x, 15 s logs (options after it override it)")
      ->trigger_on_parse();
}

// What to do with the matrix.
void add_run_options(CLI::App& app, Flags& f, MatrixOptions& o) {
  app.add_flag_callback("--outside", [&] { f.outside = true; },
                        "the open-world matrix instead: null logs and logs with a force outside the library (a "
                        "cable carrier c v_j, a local bump, a cubic along the travel) at --multiples of the floor; "
                        "default cells zoh and delay1, plant and command, 1000 Hz")
      ->trigger_on_parse();
  app.add_option("--outside-kinds", f.outside_kinds,
                 "with --outside: the kinds planted (cross_velocity, bump, cubic, velocity_hump, cross_velocity_hump, "
                 "position_friction; "
                 "--quick-outside: the first three)")
      ->delimiter(',');
  app.add_flag_callback("--quick-outside", [&] {
        f.outside = true;
        o.seeds = 1;
        o.rates = {1000.0};
        o.timings = {Timing::zoh, Timing::delay1};
        o.duration = 15.0;
        // The ctest's time is tight: the three kinds it was sized for.
        if (f.outside_kinds.empty()) f.outside_kinds = {"cross_velocity", "bump", "cubic"};
      }, "the reduced open-world matrix of the ctest identification.robustness_outside_quick")
      ->trigger_on_parse();
  app.add_option("--json", f.json_path, "write every log's result and the cells as JSON to FILE")->type_name("FILE");
  app.add_flag("--check", f.check,
               "exit 1 unless every cell meets the thresholds (planted named, null clean, phantoms <= 1 in 50; "
               "combinations: all named and the loop within 20 % of the floor in >= 95 % of the logs)");
  app.add_flag("--estimate", f.estimate, "time one log per rate and print how long the selected matrix would take");
  app.add_flag("--quiet", f.quiet, "no progress line per log");
}

// The options after the command line: "" or what is wrong with them.
std::string finish_options(MatrixOptions& o, const Flags& f) {
  if (!o.combos.empty() && !f.multiples_given) o.multiples = {10.0};  // combinations: 10x unless asked
  if (o.effects.size() == 1 && o.effects[0] == "__none__") {
    o.effects.clear();
    o.multiples.clear();
  }
  for (int n : o.combos)
    if (n < 2) return "--combos takes sizes >= 2";
  if (o.seeds < 1 || o.threads < 1 || !(o.duration > 0.0)) return "seeds, threads and duration must be > 0";
  return "";
}

void print_progress(const LogResult& l, int done, int total) {
  if (l.is_combo()) {
    std::fprintf(stderr, "[%d/%d] %s (%.1f + %.1f + loop %.1f s)\n", done, total, combo_log_text(l).c_str(),
                 l.generate_s, l.diagnose_s, l.loop_s);
    return;
  }
  std::string named;
  for (const NamedEffect& n : l.named) named += (named.empty() ? "" : ", ") + n.label();
  std::fprintf(stderr, "[%d/%d] %s %s %.0f Hz seed %d %s%s%s: named {%s}%s%s (%.1f + %.1f s)\n", done, total,
               timing_name(l.timing), noise_name(l.noise), l.rate, l.seed, l.planted.empty() ? "null" : l.planted.c_str(),
               l.axis >= 0 ? ("[axis " + std::to_string(l.axis + 1) + "]").c_str() : "",
               l.multiple > 0 ? (" x" + std::to_string(static_cast<int>(l.multiple))).c_str() : "", named.c_str(),
               l.planted.empty() ? "" : (l.hit ? " HIT" : " MISS"), l.error.empty() ? "" : (" ERROR " + l.error).c_str(),
               l.generate_s, l.diagnose_s);
}

// The table, each combination log's waterfall, the time per log.
void print_report(const MatrixResult& r) {
  std::printf("%s", markdown_table(r).c_str());
  if (r.options.combos.empty())
    std::printf("\nthe planted amplitude as estimated, z = (estimate - planted) / standard error, where named:\n%s",
                amplitude_bias_table(r).c_str());
  if (!r.options.combos.empty()) {
    std::printf("\nwaterfalls (residual RMS of the model as given, then after each effect the loop added):\n");
    for (const LogResult& l : r.logs) std::printf("  %s\n", combo_log_text(l).c_str());
  }
  std::map<double, std::array<double, 4>> t;  // rate -> generate, diagnose, loop, logs
  for (const LogResult& l : r.logs) {
    auto& x = t[l.rate];
    x[0] += l.generate_s, x[1] += l.diagnose_s, x[2] += l.loop_s, x[3] += 1.0;
  }
  std::printf("\nper log (mean): ");
  for (const auto& [rate, x] : t) {
    std::printf("%.0f Hz generate %.2f s + diagnose %.2f s", rate, x[0] / x[3], x[1] / x[3]);
    if (!r.options.combos.empty()) std::printf(" + loop %.2f s", x[2] / x[3]);
    std::printf("; ");
  }
  std::printf("\nwall time %.1f s\n", r.wall_s);
}

int check_thresholds(const MatrixResult& r) {
  const auto fails = threshold_failures(r);
  if (fails.empty()) {
    std::printf("\nPASS: every cell meets the thresholds\n");
    return 0;
  }
  std::printf("\nFAIL: %zu of %zu cells miss the thresholds (%s):\n", fails.size(), r.cells.size(),
              r.options.combos.empty() ? "planted named, null clean, phantoms <= 1 in 50"
                                       : "all planted named and loop within 20 % of the floor in >= 95 % of the logs, "
                                         "phantoms <= 1 in 50 named");
  for (const std::string& s : fails) std::printf("  %s\n", s.c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  MatrixOptions o;
  Flags f;
  CLI::App app("cpm_robustness: the robustness matrix of `cpm diagnose` on motion logs from the independent "
               "generator; prints a markdown table (one row per cell)");
  add_matrix_options(app, o, f);
  add_run_options(app, f, o);
  try {
    try {
      app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
      if (e.get_exit_code() == 0) return app.exit(e);  // --help
      std::fprintf(stderr, "cpm_robustness: %s\n(cpm_robustness --help lists the options)\n", e.what());
      return 2;
    }
    if (const std::string bad = finish_options(o, f); !bad.empty()) {
      std::fprintf(stderr, "cpm_robustness: %s\n", bad.c_str());
      return 2;
    }
    if (f.outside) {
      OpenWorldOptions w;
      w.seeds = o.seeds;
      w.first_seed = o.first_seed;
      w.rates = o.rates;
      w.timings = o.timings;
      w.noises = o.noises;
      w.duration = o.duration;
      if (!o.multiples.empty()) w.multiples = o.multiples;
      w.diagnose = o.diagnose;
      w.write_logs = o.write_logs;
      if (!f.outside_kinds.empty()) {
        w.kinds.clear();
        for (const std::string& k : f.outside_kinds) {
          if (k == "cross_velocity") w.kinds.push_back(OutsideForce::Kind::cross_velocity);
          else if (k == "bump") w.kinds.push_back(OutsideForce::Kind::bump);
          else if (k == "cubic") w.kinds.push_back(OutsideForce::Kind::cubic);
          else if (k == "velocity_hump") w.kinds.push_back(OutsideForce::Kind::velocity_hump);
          else if (k == "cross_velocity_hump") w.kinds.push_back(OutsideForce::Kind::cross_velocity_hump);
          else if (k == "position_friction") w.kinds.push_back(OutsideForce::Kind::position_friction);
          else throw cpm::Error("--outside-kinds: unknown kind '" + k +
                                "' (cross_velocity, bump, cubic, velocity_hump, cross_velocity_hump, position_friction)");
        }
      }
      const OpenWorldResult r = run_open_world(w);
      std::printf("%s", open_world_table(r).c_str());
      const auto fails = open_world_failures(r);
      for (const std::string& s : fails) std::printf("%s\n", s.c_str());
      return f.check && !fails.empty() ? 1 : 0;
    }
    if (f.estimate) {
      estimate(o);
      return 0;
    }
    std::fprintf(stderr, "cpm_robustness: %zu rates x %zu timings x %zu noise placements, %d logs per cell, %d seed%s, "
                         "%.0f s logs, %d thread%s\n",
                 o.rates.size(), o.timings.size(), o.noises.size(), logs_per_cell(o), o.seeds, o.seeds > 1 ? "s" : "",
                 o.duration, o.threads, o.threads > 1 ? "s" : "");
    const MatrixResult r = run_matrix(o, [&](const LogResult& l, int done, int total) {
      if (!f.quiet) print_progress(l, done, total);
    });
    print_report(r);
    if (!f.json_path.empty()) {
      std::ofstream out(f.json_path);
      out << to_json(r);
      if (!out) throw cpm::Error("cannot write " + f.json_path);
    }
    return f.check ? check_thresholds(r) : 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cpm_robustness: %s\n", e.what());
    return 2;
  }
}

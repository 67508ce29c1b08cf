// SPDX-License-Identifier: Apache-2.0
// cpm excite: design an identification experiment for this machine and
// model (identification/excitation.hpp) and write it as the stream file
// `cpm stream` plays, checked first with cpmd's own segment checks
// (stream_file.hpp), as cpm stream checks a file before it sends anything.
#include <cstdio>
#include <sstream>

#include "cli.hpp"
#include "cmd_client_common.hpp"
#include "cpm/daemon/config.hpp"
#include "cpm/identification/excitation.hpp"
#include "stream_file.hpp"

namespace cpm::cli {
namespace {

struct Options {
  std::optional<std::string> model, config;
  std::string out;
  ident::ExcitationOptions design;
  std::vector<std::string> separate;
  bool plain = false;
  double rate = 1000.0;
  double margin = ident::ExcitationLimits{}.margin;
  long seed = 1;
};

std::string mm3(const Vec3& v) {
  char b[96];
  std::snprintf(b, sizeof b, "%.1f, %.1f, %.1f", v.x() * 1e3, v.y() * 1e3, v.z() * 1e3);
  return b;
}

int run(Options& o) {
  daemon::DaemonConfig cfg;
  if (o.config) cfg = daemon::load_config(*o.config);
  const std::string model_path = o.model ? *o.model : o.config ? cfg.model_file : model_or_default(std::nullopt);
  ctl::MachineModel mm = daemon::load_model(model_path);
  mm.force_limit = std::min(mm.force_limit, cfg.limits.force);
  const ctl::Machine model(mm);
  ident::ExcitationLimits L;
  L.workspace_min = cfg.limits.workspace_min;
  L.workspace_max = cfg.limits.workspace_max;
  L.velocity = cfg.limits.velocity;
  L.acceleration = cfg.limits.acceleration;
  L.force = mm.force_limit;
  L.margin = o.margin;
  o.design.seed = static_cast<std::uint64_t>(o.seed);
  o.design.optimise = !o.plain;
  if (!o.separate.empty()) {
    if (o.separate.size() != 2) throw UsageError("--separate takes two effects, e.g. --separate viscous_friction:2 coulomb_friction:2");
    o.design.separate = std::make_pair(o.separate[0], o.separate[1]);
  }
  const ident::ExcitationDesign D = ident::design_excitation(model, L, o.design);
  const ident::MultiSine& m = D.trajectory;

  // The rows as cpm stream plays them, through cpmd's checks.
  client::StreamRows s;
  for (const auto& r : ident::excitation_rows(m, o.rate)) {
    s.rows.push_back(r);
    s.line.push_back(static_cast<int>(s.rows.size()) + 2);  // after the comment and header lines
  }
  std::vector<std::size_t> first_row;
  const auto chunks = client::stream_chunks(s, first_row);
  if (const std::string bad = client::check_stream(s, chunks, first_row, model, cfg.limits, 1.0 / cfg.loop.rate_hz);
      !bad.empty())
    throw Error("the design breaks cpmd's limits (lower --margin): " + bad);

  std::ostringstream os;
  os << "# cpm excite: " << (o.plain ? "flat multi-sine, Schroeder phases" : "optimised multi-sine with constant-speed passes") << ", period "
     << m.period() << " s x " << m.periods() << ", model " << model_path << "\n";
  // Positions to 1 nm: at 1 kHz rows coarser rounding is acceleration noise (docs/cli.md, cpm stream).
  os.precision(9);
  os << std::fixed;
  os << "t,x,y,z,vx,vy,vz\n";
  for (const auto& r : s.rows) {
    for (int k = 0; k < 7; ++k) os << (k ? "," : "") << r[static_cast<std::size_t>(k)];
    os << "\n";
  }
  write_file_atomically(o.out, os.str());

  const ident::ExcitationFigures& F = D.figures;
  std::printf("%s: %zu rows at %.0f Hz, %.1f s: %.1f s fade in, %d periods of %.1f s, %.1f s fade out\n", o.out.c_str(),
              s.rows.size(), o.rate, m.duration(), m.ramp(), m.periods(), m.period(), m.ramp());
  std::printf("centre (%s) mm, peak displacement +-(%s) mm\n", mm3(m.centre()).c_str(), mm3(F.peak_displacement).c_str());
  std::printf("peaks: speed %.0f mm/s of %.0f, acceleration %.2f m/s^2 of %.2f, actuator force %.1f N of %.1f\n",
              F.peak_speed * 1e3, L.velocity * 1e3, F.peak_acceleration, L.acceleration, F.peak_force, L.force);
  for (int i = 0; i < 3; ++i) {
    std::printf("axis %d harmonics (Hz : mm):", i + 1);
    for (std::size_t j = 0; j < m.harmonic()[i].size(); ++j)
      std::printf(" %.2f:%.1f", m.harmonic()[i][j] / m.period(), std::abs(m.amplitude()[i][j]) * 1e3);
    std::printf("\n");
    const ident::Passes& q = m.passes()[static_cast<std::size_t>(i)];
    if (q.stroke > 0.0) {
      std::printf("axis %d passes over %.1f mm (mm/s):", i + 1, q.stroke * 1e3);
      for (std::size_t j = 0; j < q.share.size(); ++j) std::printf(" +-%.0f", m.pass_speed(i, j) * 1e3);
      std::printf("\n");
    }
  }
  std::printf("information (%zu columns: base, plane nuisance, every library effect): D-criterion %.1f (start %.1f), "
              "condition %.3g (start %.3g), %d designs tried\n",
              F.columns.size(), F.log_det, D.start.log_det, F.condition, D.start.condition, D.evaluations);
  if (o.design.separate)
    std::printf("separation of %s and %s beside the base: 1 - rho^2 = %.3f (start %.3f)\n",
                o.design.separate->first.c_str(), o.design.separate->second.c_str(), F.separation,
                D.start.separation);
  std::printf("within cpmd's limits (limits.velocity %.0f mm/s, limits.acceleration %.1f m/s^2, the soft limits and "
              "the workspace): play it with cpm stream %s\n",
              cfg.limits.velocity * 1e3, cfg.limits.acceleration, o.out.c_str());
  return 0;
}

Run setup(CLI::App& app) {
  auto o = std::make_shared<Options>();
  add_model_option(app, o->model, "the model the experiment is designed for (default: the daemon config's model_file)");
  app.add_option("--config", o->config, "the daemon's configuration: its limits bound the design")
      ->type_name("DAEMON.yaml");
  app.add_option("--out", o->out, "the stream file to write (t,x,y,z,vx,vy,vz; SI)")->type_name("OUT.csv")->required();
  add_number(app, "--period", o->design.period, "S", "one period of the multi-sine in s");
  app.add_option("--periods", o->design.periods, "periods played (averaged, noise from their differences)")
      ->default_val(o->design.periods);
  app.add_option("--harmonics", o->design.harmonics, "harmonics per axis (axis i: (3m + i) / period Hz)")
      ->default_val(o->design.harmonics);
  app.add_option("--speeds", o->design.speeds,
                 "speeds of constant-speed passes per axis and period, both ways (0: sines only)")
      ->default_val(o->design.speeds);
  app.add_option("--iterations", o->design.iterations, "designs the optimiser tries")->default_val(o->design.iterations);
  app.add_option("--searches", o->design.searches,
                 "searches from the best start, each on its own seed with its share of the designs")
      ->default_val(o->design.searches);
  app.add_option("--seed", o->seed, "the optimiser's random seed")->default_val(o->seed);
  add_number(app, "--margin", o->margin, "1", "share of each limit the design may use (0..1]");
  add_number(app, "--rate", o->rate, "HZ", "rows per second of the file");
  app.add_option("--separate", o->separate,
                 "design to tell two effects apart instead (e.g. --separate viscous_friction:2 coulomb_friction:2)")
      ->type_name("EFFECT[:AXIS] EFFECT[:AXIS]")
      ->expected(2);
  app.add_flag("--plain", o->plain, "the flat multi-sine with Schroeder phases, not optimised (a reference)");
  app.footer("The experiment: a periodic multi-sine per axis, each axis on its own harmonics, with constant-speed\n"
             "passes both ways at --speeds speeds, faded in and out, scaled to the workspace box and the speed,\n"
             "acceleration and force limits; the amplitudes and phases and the passes' stroke, speeds and offsets\n"
             "chosen for the information of diagnosis' regressor (D-criterion). Checked with cpmd's own segment\n"
             "checks before it is written.");
  return [o] {
    if (!(o->rate >= 100.0 && o->rate <= 10000.0)) throw UsageError("--rate must be within 100..10000 Hz");
    return run(*o);
  };
}

const Command reg{"excite", "design an identification experiment within cpmd's limits and write it as a stream file",
                  setup};

}  // namespace
}  // namespace cpm::cli

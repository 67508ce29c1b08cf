// SPDX-License-Identifier: Apache-2.0
// cpm identify: from an experiment to a better model on a running cpmd.
// The experiment file (cpm excite's, or any stream file) is checked whole
// against the limits cpmd publishes before anything moves, approached and
// played as cpm stream plays it (stream_file.hpp) while cpmd's state is
// recorded as cpm record records it (state_log.hpp); then the loop (cpm
// loop's) on that log, its waterfall, and the new model file.
#include <cstdio>
#include <filesystem>
#include <sstream>

#include "cli.hpp"
#include "cmd_client_common.hpp"
#include "cpm/daemon/config.hpp"
#include "cpm/identification/model_loop.hpp"
#include "cpm/io/data_files.hpp"
#include "cpm/io/model_file.hpp"
#include "ident_common.hpp"
#include "state_log.hpp"
#include "stream_file.hpp"

namespace cpm::cli {
namespace {

struct Options {
  std::string experiment, out;
  std::optional<std::string> model, log;
  client::Connection connection;
  client::Operator op;
  int max_steps = 6;
  bool apply = false;
  bool record_only = false;
};

using cpm_msgs::control_command_t;
using cpm_msgs::state_t;

// Wait (up to `timeout_s`) for cpmd's mode to be `mode`.
bool wait_mode(daemon::Client& c, std::int8_t mode, double timeout_s) {
  for (int i = 0; i < static_cast<int>(timeout_s / 0.2); ++i)
    if (const auto s = c.state(0.2); s && s->mode == mode) return true;
  return false;
}

// The paper's circle (Elkady's, full speed from rest) and its tracking error (m RMS).
std::optional<double> paper_circle(daemon::Client& c, const char* when) {
  std::printf("the paper's circle, %s:\n", when);
  client::CircleOptions co;
  co.paper = true;
  state_t end{};
  if (client::play_circle(c, ctl::CircleSpec{}, co, &end) != 0) return std::nullopt;
  return end.last_segment_rmse;
}

// The new model into cpmd: disable, load-model, enable (cpmd loads a model only when disabled).
// Each answer is waited for as long as the load's: a controller busy with its loop (or the SIL
// guest's emulated CPU) may answer later than a jog's 2 s.
bool load_into_cpmd(daemon::Client& c, const std::string& path) {
  if (!c.control(control_command_t::CMD_DISABLE, 10.0).accepted || !wait_mode(c, state_t::MODE_DISABLED, 10.0)) {
    std::printf("apply: cpmd did not disable\n");
    return false;
  }
  control_command_t cmd{};
  cmd.command = control_command_t::CMD_LOAD_MODEL;
  cmd.model_path = std::filesystem::absolute(path).lexically_normal().string();
  const auto ack = c.control(cmd, 10.0);
  std::printf("load-model %s: %s\n", cmd.model_path.c_str(), ack.accepted ? "accepted" : ack.message.c_str());
  if (!ack.accepted) return false;
  if (!c.control(control_command_t::CMD_ENABLE, 10.0).accepted || !wait_mode(c, state_t::MODE_HOLDING, 10.0)) {
    std::printf("apply: cpmd did not enable again\n");
    return false;
  }
  return true;
}

int run(const Options& o) {
  client::StreamRows s = client::read_stream(o.experiment);
  daemon::DaemonConfig cfg;
  if (o.connection.config) cfg = daemon::load_config(*o.connection.config);
  const std::string model_path = o.model ? *o.model : o.connection.config ? cfg.model_file : model_or_default(std::nullopt);
  io::ModelFile mf = io::load_model_file(model_path);
  ctl::MachineModel checked = mf.model;
  checked.force_limit = std::min(checked.force_limit, cfg.limits.force);
  const ctl::Machine machine(checked);

  daemon::Client c(client::lcm_options(o.connection), client::operator_key(o.op));
  // The limits cpmd holds now (cpm set may have changed them), before anything moves.
  const auto p = c.params(3.0);
  if (!p) throw Error("no parameter table from cpmd within 3 s (is it running?)");
  client::apply_published_limits(*p, cfg);
  client::append_stop(s, cfg.limits.acceleration);
  std::vector<std::size_t> first_row;
  const auto chunks = client::stream_chunks(s, first_row);
  if (const std::string bad = client::check_stream(s, chunks, first_row, machine, cfg.limits, 1.0 / cfg.loop.rate_hz);
      !bad.empty()) {
    std::fprintf(stderr, "%s: %s\ncpm identify: refused, nothing moved\n", o.experiment.c_str(), bad.c_str());
    return 1;
  }
  std::printf("%s: %zu rows, %.3f s, within cpmd's limits\n", o.experiment.c_str(), s.rows.size(),
              s.rows.back()[0] - s.rows.front()[0]);
  std::optional<double> before;
  if (o.apply && !(before = paper_circle(c, "with the model as given"))) return 1;

  // Recorded from the approach's end (at rest at the first row) to the experiment's end.
  StateToMotion rows;
  bool recording = false;
  c.on_state([&](const cpm_msgs::state_t& st) {
    if (recording) rows.add(st);
  });
  client::PlayOptions play;
  play.approach_vmax = std::min(0.1, cfg.limits.velocity);
  play.approach_amax = std::min(1.0, cfg.limits.acceleration);
  play.on_approached = [&] { recording = true; };
  if (client::play_stream(c, s, chunks, first_row, play) != 0) return 1;
  c.handle(0.1);  // the last states of the stop
  recording = false;
  if (rows.rows() == 0) throw Error("no state of cpmd with the drives applying force was recorded");
  const io::MotionData log = rows.finish(o.log.value_or("cpm identify"), "cpm identify: " + o.experiment);
  if (o.log) {
    io::write_motion(*o.log, log);
    std::printf("log: %zu rows over %.3f s to %s\n", log.t.size(), log.t.back() - log.t.front(), o.log->c_str());
  }
  if (o.record_only) {
    std::printf("recorded only: run the loop on the log elsewhere (cpm loop --model %s --data %s --out NEW.yaml), "
                "then cpm load-model NEW.yaml\n", model_path.c_str(), o.log->c_str());
    return 0;
  }

  const ident::LoopResult R = ident::run_loop(io::DataSet(log), mf.model, {}, o.max_steps);
  std::fputs(ident::loop_text(R).c_str(), stdout);
  mf.model = R.model;
  std::ostringstream note;
  note << "cpm identify added";
  for (std::size_t j = 1; j < R.steps.size(); ++j) note << " " << R.steps[j].added;
  if (R.steps.size() > 1) note << "; residual RMS " << R.steps.front().rms << " -> " << R.steps.back().rms << " " << R.units;
  record_fit(mf, R.fitted, "cpm identify", o.log.value_or(o.experiment), note.str());
  io::save_model_file(o.out, mf, model_path);
  if (!o.apply) {
    std::printf("new model: %s (load it with cpm load-model when the machine is disabled)\n", o.out.c_str());
    return 0;
  }
  std::printf("new model: %s\n", o.out.c_str());
  if (!load_into_cpmd(c, o.out)) return 1;
  const std::optional<double> after = paper_circle(c, "with the new model");
  if (!after) return 1;
  std::printf("the paper's circle, tracking error: %.1f um RMS with the model as given, %.1f um RMS with the new "
              "model (%.1fx lower)\n", *before * 1e6, *after * 1e6, *before / std::max(*after, 1e-12));
  return 0;
}

Run setup(CLI::App& app) {
  auto o = std::make_shared<Options>();
  app.add_option("EXPERIMENT", o->experiment, "the experiment as a stream file (cpm excite --out)")
      ->type_name("FILE.csv")
      ->required();
  add_model_option(app, o->model, "the model cpmd runs (default: the daemon config's model_file)");
  add_new_model_option(app, o->out);
  app.get_option("--out")->required(false);  // not with --record-only; checked below
  app.add_option("--log", o->log, "also write the recorded motion log")->type_name("LOG.csv");
  app.add_option("--max-steps", o->max_steps, "the loop's steps at most (1 .. 20)")->check(CLI::Range(1, 20));
  app.add_flag("--apply", o->apply,
               "engineer: run the paper's circle, then the experiment and the loop, load the new model into cpmd "
               "(disable, load-model, enable) and run the circle again; print the tracking error before and after");
  app.add_flag("--record-only", o->record_only,
               "play the experiment and write the log (--log), without the loop: for a controller too slow for the "
               "fit, run cpm loop on the log on another computer and cpm load-model the result")
      ->excludes("--apply")
      ->needs("--log");
  client::add_connection(app, o->connection);
  client::add_operator(app, o->op);
  app.footer("Checks the experiment against the limits cpmd publishes before anything moves, approaches its first\n"
             "point, plays it while recording cpmd's state, runs the loop (cpm loop) on the log and writes the new\n"
             "model. --apply loads it and shows the paper's circle before and after. --record-only --log LOG.csv\n"
             "stops after the recording: cpm loop on another computer, then cpm load-model.");
  return [o] {
    if (!o->record_only && o->out.empty()) throw UsageError("--out is required (the new model file)");
    return run(*o);
  };
}

const Command reg{"identify", "run an experiment on cpmd while recording, run the loop on the log, write the new model",
                  setup};

}  // namespace
}  // namespace cpm::cli

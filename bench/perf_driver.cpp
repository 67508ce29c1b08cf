// cpm_perf: the figures Google Benchmark's per-iteration means cannot give.
//
//   cpm_perf --source DIR [--cycles N] [--repeat R] [--kim-problem FILE] [--json FILE]
//
// - the control cycle's compute: cpmd's own ControlLoop::cycle (estimate,
//   commands, trajectory, calibrated IK, computed torque with the model's
//   effects, safety, publish), each of N cycles timed with clock_gettime,
//   with the machine's I/O replayed from a recorded run so that no plant
//   step is inside the timing; median, p99, p99.9, max, heap allocations;
// - the controller's step and the plant's step, each timed per call in a
//   closed loop of its own;
// - real-time factors: the plant alone, sim's closed loop, and cpmd's loop
//   on its simulator backend, unthrottled;
// - the CAN bus: load and highest rate of config/canopen.yaml's mapping, and
//   the frames and bits the master really sends on the fake bus;
// - Kim's 32-point ball-bar calibration: the solve and the whole fit, timed,
//   and the problem exported for bench/scipy_ballbar.py.
//
// Speed is reported here, never asserted: bench/run.sh checks the budgets.
#include <pthread.h>
#include <sched.h>
#include <time.h>

#include <algorithm>
#include <cmath>
#include <array>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "bench_models.hpp"
#include "cpm/io/model_file.hpp"
#include "cpm/calibration/ballbar.hpp"
#include "cpm/calibration/kim.hpp"
#include "cpm/calibration/workflow.hpp"
#include "cpm/daemon/config.hpp"
#include "cpm/daemon/loop.hpp"
#include "cpm/daemon/sim_backend.hpp"
#include "cpm/hal/fake_can.hpp"
#include "cpm/hal/master.hpp"
#include "cpm/hal/virtual_drive.hpp"
#include "cpm/sim/closed_loop.hpp"
#include "cpm/cli.hpp"
#include "support/allocation_counter.hpp"

namespace {

using namespace cpm;
using cal::json_num;
using cal::json_string;

std::int64_t now_ns() noexcept {
  timespec t{};
  clock_gettime(CLOCK_MONOTONIC, &t);  // vDSO, as the loop's own phase timers
  return std::int64_t{t.tv_sec} * 1000000000 + t.tv_nsec;
}

// Distribution of per-call times (ns). Percentiles by nearest rank.
struct Timing {
  std::vector<std::int64_t> ns;
  [[nodiscard]] std::int64_t percentile(double q) const {
    std::vector<std::int64_t> s = ns;
    std::sort(s.begin(), s.end());
    const auto n = static_cast<double>(s.size());
    const auto i = static_cast<std::size_t>(std::max(0.0, std::ceil(q * n) - 1.0));
    return s[std::min(i, s.size() - 1)];
  }
  [[nodiscard]] double mean() const {
    double sum = 0;
    for (auto v : ns) sum += static_cast<double>(v);
    return sum / static_cast<double>(ns.size());
  }
  // JSON members (no braces), shares of `period_s`.
  [[nodiscard]] std::string json(double period_s) const {
    const std::int64_t med = percentile(0.5), p99 = percentile(0.99);
    std::ostringstream o;
    o << "\"samples\": " << ns.size() << ", \"min_ns\": " << percentile(0.0) << ", \"median_ns\": " << med
      << ", \"mean_ns\": " << json_num(mean()) << ", \"p99_ns\": " << p99 << ", \"p999_ns\": " << percentile(0.999)
      << ", \"max_ns\": " << percentile(1.0) << ", \"period_s\": " << json_num(period_s)
      << ", \"median_share\": " << json_num(static_cast<double>(med) * 1e-9 / period_s)
      << ", \"p99_share\": " << json_num(static_cast<double>(p99) * 1e-9 / period_s);
    return o.str();
  }
};

// The cost of one clock_gettime pair around nothing: every per-call figure
// below includes it once.
std::int64_t timer_overhead_ns(int n) {
  Timing t;
  t.ns.reserve(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    const std::int64_t a = now_ns();
    t.ns.push_back(now_ns() - a);
  }
  return t.percentile(0.5);
}

// --- the control cycle, its I/O recorded then replayed ----------------------

// Forwards to the simulator backend and keeps what it read and what the loop wrote.
class RecordingBackend final : public daemon::Backend {
 public:
  RecordingBackend(daemon::Backend& inner, std::size_t cycles) : inner_(inner), in_(cycles), force_(cycles) {}
  [[nodiscard]] const char* name() const noexcept override { return "recording"; }
  void start(double period) override { inner_.start(period); }
  void stop() noexcept override { inner_.stop(); }
  daemon::BackendResult read(std::int64_t k, daemon::BackendInput& in) noexcept override {
    const auto r = inner_.read(k, in);
    in_[static_cast<std::size_t>(k)] = in;
    return r;
  }
  daemon::BackendResult write(std::int64_t k, const daemon::BackendOutput& out) noexcept override {
    force_[static_cast<std::size_t>(k)] = out.force;
    return inner_.write(k, out);
  }
  daemon::Backend& inner_;
  std::vector<daemon::BackendInput> in_;
  std::vector<std::array<double, 3>> force_;
};

// Plays the recorded feedback back; counts the cycles whose forces differ
// from the recording (0: the replayed loop did exactly the recorded work).
class ReplayBackend final : public daemon::Backend {
 public:
  explicit ReplayBackend(const RecordingBackend& rec) : rec_(rec) {}
  [[nodiscard]] const char* name() const noexcept override { return "replay"; }
  void start(double) override {}
  void stop() noexcept override {}
  daemon::BackendResult read(std::int64_t k, daemon::BackendInput& in) noexcept override {
    in = rec_.in_[static_cast<std::size_t>(k)];
    return daemon::BackendResult::ok;
  }
  daemon::BackendResult write(std::int64_t k, const daemon::BackendOutput& out) noexcept override {
    if (out.force != rec_.force_[static_cast<std::size_t>(k)]) ++mismatches;
    return daemon::BackendResult::ok;
  }
  long mismatches = 0;

 private:
  const RecordingBackend& rec_;
};

// Ramped full circles (0.5 s ramps: 2 pi in all) one after another, from
// the simulator's initial position: the machine is moving almost always.
ctl::CircleSpec bench_circle() {
  ctl::CircleSpec s;
  s.ramp_time = 0.5;
  s.cruise_time = 3.5;
  return s;
}

// What the LCM thread does between cycles, and the commands a client sends:
// enable at once, a new circle whenever the queue has run empty.
struct Operator {
  std::int64_t next_id = 1;
  long rejected = 0;
  daemon::Command command(daemon::CommandKind kind) {
    daemon::Command c;
    c.kind = kind;
    c.id = next_id++;
    return c;
  }
  void before(daemon::ControlLoop& loop, std::int64_t k) {
    if (k == 0) (void)loop.commands().push(command(daemon::CommandKind::enable));
    if (loop.mode() == daemon::Mode::holding) {
      daemon::Command c = command(daemon::CommandKind::segment);
      const auto& st = loop.last_state();
      c.segment.start = Vec3(st.queue_end[0], st.queue_end[1], st.queue_end[2]);
      c.segment.end = c.segment.start;
      c.segment.traj.emplace<ctl::CircleTrajectory>(bench_circle());
      (void)loop.commands().push(c);
    }
  }
  void after(daemon::ControlLoop& loop) {
    while (loop.snapshots().front()) loop.snapshots().release();
    daemon::Ack a;
    while (loop.acks().pop(a))
      if (!a.accepted) ++rejected;
    cpm_msgs::loop_stats_t s;
    while (loop.stats().pop(s)) {
    }
  }
};

struct CycleFigures {
  Timing cycle;
  long allocations = 0, mismatches = 0, rejected = 0;
  std::string mode_at_end;
  double daemon_rtf = 0;   // record phase: cpmd's loop + simulator backend, unthrottled
  std::array<double, daemon::kSeries> phase_mean_ns{};
};

CycleFigures control_cycle(const std::string& source, long cycles) {
  daemon::DaemonConfig cfg = daemon::load_config(source + "/config/sim.yaml");
  const ctl::Machine machine(bench::calibrated_model_with_effects());
  const double period = 1.0 / cfg.loop.rate_hz;
  daemon::SimBackendOptions so;
  so.plant = cfg.sim.plant;
  so.initial_position = cfg.sim.initial_position;
  so.enable_delay = cfg.sim.enable_delay;
  // The true machine is the model: tracking stays within the safety limits for the whole run.
  daemon::SimBackend sim(std::make_unique<ctl::Machine>(bench::calibrated_model_with_effects()), so);
  RecordingBackend rec(sim, static_cast<std::size_t>(cycles));
  rec.start(period);
  CycleFigures f;
  {
    daemon::ControlLoop loop(cfg, rec, machine, ctl::Controller(machine, cfg.controller.law, cfg.controller.gains));
    Operator op;
    const std::int64_t t0 = now_ns();
    for (std::int64_t k = 0; k < cycles; ++k) {
      op.before(loop, k);
      loop.cycle(k, 0);
      op.after(loop);
    }
    f.daemon_rtf = static_cast<double>(cycles) * period / (static_cast<double>(now_ns() - t0) * 1e-9);
  }
  ReplayBackend replay(rec);
  daemon::ControlLoop loop(cfg, replay, machine, ctl::Controller(machine, cfg.controller.law, cfg.controller.gains));
  Operator op;
  f.cycle.ns.reserve(static_cast<std::size_t>(cycles));
  for (std::int64_t k = 0; k < cycles; ++k) {
    op.before(loop, k);
    const test::CountAllocations count;
    const std::int64_t a = now_ns();
    loop.cycle(k, 0);
    const std::int64_t b = now_ns();
    f.allocations += static_cast<long>(count.count());
    f.cycle.ns.push_back(b - a);
    op.after(loop);
  }
  f.mismatches = replay.mismatches;
  f.rejected = op.rejected;
  f.mode_at_end = daemon::mode_name(loop.mode());
  const auto& st = loop.current_stats();
  for (int s = 0; s < daemon::kSeries; ++s)
    f.phase_mean_ns[static_cast<std::size_t>(s)] = st.count[s] ? st.sum_ns[s] / static_cast<double>(st.count[s]) : 0.0;
  return f;
}

// --- controller and plant, per call, in a closed loop of their own ----------

// The plant at fewer RK4 sub-steps than cpmd ships: its real-time factor
// and how far one period's step lands from a 40-sub-step reference from
// the same state (the integration error the speed costs).
struct SubstepFigures {
  int substeps = 0;
  double rtf = 0;
  double max_step_error_m = 0;
};

struct StepFigures {
  Timing controller, plant;
  int substeps = 0;
  double plant_rtf = 0, closed_loop_rtf = 0;
  // The plant as cpmd's simulator ships (config/sim.yaml: its truth model
  // file and sub-steps), back to back under the same forces: the budget's figure.
  double shipped_plant_rtf = 0;
  double tracking_rmse_m = 0;
  std::vector<SubstepFigures> sweep;
};

SubstepFigures substeps_figures(const ctl::Machine& truth, const sim::PlantOptions& shipped, int n,
                                const std::vector<std::pair<Vec3, Vec3>>& states, const std::vector<Vec3>& forces,
                                double dt) {
  sim::PlantOptions on = shipped, oref = shipped;
  on.substeps = n;
  oref.substeps = 40;
  sim::Plant plant(truth, on), reference(truth, oref);
  SubstepFigures f;
  f.substeps = n;
  std::int64_t total = 0;
  long steps = 0;
  for (std::size_t k = 0; k < states.size(); k += 10) {
    (void)plant.reset(states[k].first, states[k].second);
    (void)reference.reset(states[k].first, states[k].second);
    const std::int64_t a = now_ns();
    (void)plant.step(forces[k], dt);
    total += now_ns() - a;
    ++steps;
    (void)reference.step(forces[k], dt);
    f.max_step_error_m = std::max(f.max_step_error_m, (plant.position() - reference.position()).norm());
  }
  f.rtf = static_cast<double>(steps) * dt / (static_cast<double>(total) * 1e-9);
  return f;
}

StepFigures steps(const daemon::DaemonConfig& shipped, long cycles) {
  const sim::PlantOptions& plant_options = shipped.sim.plant;
  const ctl::Machine model(bench::calibrated_model_with_effects());
  const ctl::Machine truth(bench::calibrated_model_with_effects());
  const ctl::Controller controller(model, ctl::ControlLaw::computed_torque,
                                   ctl::table3_gains(ctl::ControlLaw::computed_torque));
  const ctl::CircleTrajectory circle(bench_circle());
  const double dt = 1e-3;
  const long per_circle = std::lround(circle.duration() / dt);
  StepFigures f;
  f.controller.ns.reserve(static_cast<std::size_t>(cycles));
  f.plant.ns.reserve(static_cast<std::size_t>(cycles));
  std::vector<Vec3> forces;
  std::vector<std::pair<Vec3, Vec3>> states;  // (p, p_dot) before each step
  forces.reserve(static_cast<std::size_t>(cycles));
  states.reserve(static_cast<std::size_t>(cycles));
  f.substeps = plant_options.substeps;
  sim::Plant plant(truth, plant_options);
  (void)plant.reset(circle.sample(0.0).p);
  ctl::ControlInput in;
  ctl::ControlOutput out;
  ctl::ControllerState history;
  const kin::DirectionTracker direction;
  for (long k = 0; k < cycles; ++k) {
    const double t = static_cast<double>(k % per_circle) * dt;  // the circle again and again
    const sim::EncoderReading enc = plant.read();
    in.d = enc.d;
    in.d_dot = enc.d_dot;
    in.ref = circle.sample(t);
    in.kin.t = static_cast<double>(k) * dt;
    direction.update(in.ref.v, in.kin);
    std::int64_t a = now_ns();
    (void)controller.step(in, history, out);
    std::int64_t b = now_ns();
    f.controller.ns.push_back(b - a);
    forces.push_back(out.force);
    states.emplace_back(plant.position(), plant.velocity());
    a = now_ns();
    (void)plant.step(out.force, dt);
    b = now_ns();
    f.plant.ns.push_back(b - a);
  }
  // The plant alone, back to back under the same forces (the same states):
  // simulated seconds per wall second, without the per-call timers.
  (void)plant.reset(circle.sample(0.0).p);
  std::int64_t t0 = now_ns();
  for (const Vec3& F : forces) (void)plant.step(F, dt);
  f.plant_rtf = static_cast<double>(cycles) * dt / (static_cast<double>(now_ns() - t0) * 1e-9);
  {
    const std::string truth_file = shipped.sim.truth_model_file.empty() ? shipped.model_file : shipped.sim.truth_model_file;
    const ctl::Machine shipped_truth(io::load_model_file(truth_file).model);
    sim::Plant sp(shipped_truth, plant_options);
    (void)sp.reset(circle.sample(0.0).p);
    t0 = now_ns();
    for (const Vec3& F : forces) (void)sp.step(F, dt);
    f.shipped_plant_rtf = static_cast<double>(cycles) * dt / (static_cast<double>(now_ns() - t0) * 1e-9);
  }
  // sim's closed loop (controller + plant + trajectory + metrics), no log kept.
  sim::LoopOptions lo;
  lo.keep_log = false;
  const long runs = std::max(1L, cycles / per_circle);
  double rmse = 0;
  t0 = now_ns();
  for (long r = 0; r < runs; ++r) rmse = sim::run_closed_loop(controller, plant, circle, lo).metrics.position_rmse;
  f.closed_loop_rtf = static_cast<double>(runs) * circle.duration() / (static_cast<double>(now_ns() - t0) * 1e-9);
  f.tracking_rmse_m = rmse;
  for (int n : {1, 2, 4, plant_options.substeps})
    f.sweep.push_back(substeps_figures(truth, plant_options, n, states, forces, dt));
  return f;
}

// --- the CAN bus ------------------------------------------------------------

std::string bus_json(const hal::BusLoad& L) {
  std::ostringstream o;
  o << "{\"frames_per_cycle\": " << L.frames_per_cycle << ", \"bits_per_cycle\": " << L.bits_per_cycle
    << ", \"periodic_bits_per_cycle\": " << json_num(L.periodic_bits_per_cycle)
    << ", \"bits_available\": " << json_num(L.bits_available) << ", \"load\": " << json_num(L.load)
    << ", \"worst_cycle_load\": " << json_num(L.worst_cycle_load) << ", \"max_rate_hz\": " << json_num(L.max_rate_hz)
    << ", \"fits\": " << (L.fits ? "true" : "false") << "}";
  return o.str();
}

// The master and three virtual drives on the fake bus, in operation
// enabled: what goes on the wire per cycle, counted (frames, worst-case
// stuffed bits of each frame sent), start-up excluded.
struct WireCount {
  double frames_per_cycle = 0, bits_per_cycle = 0;
  long cycles = 0;
};

WireCount count_on_fake_bus(const hal::MasterConfig& cfg, long cycles) {
  hal::FakeClock clock(0, 100'000);
  hal::FakeCanNetwork net(clock);
  auto& port = net.add_port("master");
  std::vector<std::unique_ptr<hal::VirtualDrive>> drives;
  for (const auto& d : cfg.drives) {
    hal::VirtualDriveConfig vc;
    vc.node_id = static_cast<std::uint8_t>(d.node_id);
    drives.push_back(std::make_unique<hal::VirtualDrive>(net.add_port("drive"), vc));
  }
  clock.set_hook([&](std::int64_t now) {
    for (auto& d : drives) d->poll(now);
  });
  for (auto& d : drives) d->power_on(0);
  hal::Master master(port, clock, cfg);
  master.start();
  hal::Commands cmd;
  hal::Feedback fb;
  for (std::size_t i = 0; i < cfg.drives.size(); ++i) cmd.drive[i].target = hal::cia402::Target::enabled;
  const auto period = static_cast<std::int64_t>(1e9 / cfg.rate_hz);
  auto run = [&](long n) {
    for (long k = 0; k < n; ++k) {
      master.read(fb);
      master.write(cmd);
      clock.wait(period);
    }
  };
  run(static_cast<long>(cfg.rate_hz));  // a second to reach operation enabled
  const std::uint64_t f0 = net.frames_on_wire(), b0 = net.bits_on_wire();
  run(cycles);
  WireCount w;
  w.cycles = cycles;
  w.frames_per_cycle = static_cast<double>(net.frames_on_wire() - f0) / static_cast<double>(cycles);
  w.bits_per_cycle = static_cast<double>(net.bits_on_wire() - b0) / static_cast<double>(cycles);
  if (fb.drive[0].state != hal::cia402::State::operation_enabled) w.cycles = -1;  // reported, not hidden
  return w;
}

std::string bus(const std::string& source) {
  const daemon::DaemonConfig cfg = daemon::load_config(source + "/config/canopen.yaml");
  const hal::MasterConfig& m = cfg.canopen.master;
  hal::MasterConfig with_velocity = m;
  with_velocity.velocity_from_drive = !m.velocity_from_drive;
  // The same frames without a single stuff bit: the best case of the wire
  // (8n + 47 bits with interframe space), beside the worst case the master checks.
  int best_bits = 47;  // SYNC, no data
  for (std::size_t i = 0; i < m.drives.size(); ++i)
    best_bits += (8 * hal::pdo::kRpdo1.bytes() + 47) + (8 * hal::pdo::kTpdo1.bytes() + 47) +
                 (m.velocity_from_drive ? 8 * hal::pdo::kTpdo2.bytes() + 47 : 0);
  const WireCount w = count_on_fake_bus(m, 2000);
  std::ostringstream o;
  o << "{\"config\": " << json_string("config/canopen.yaml") << ", \"drives\": " << m.drives.size()
    << ", \"bitrate\": " << json_num(m.bitrate) << ", \"rate_hz\": " << json_num(m.rate_hz)
    << ", \"max_bus_load\": " << json_num(m.max_bus_load)
    << ", \"velocity_from_drive\": " << (m.velocity_from_drive ? "true" : "false")
    << ", \"frame_bits_worst\": {\"sync\": " << hal::can_frame_bits_worst(0)
    << ", \"rpdo1\": " << hal::can_frame_bits_worst(hal::pdo::kRpdo1.bytes())
    << ", \"tpdo1\": " << hal::can_frame_bits_worst(hal::pdo::kTpdo1.bytes())
    << ", \"tpdo2\": " << hal::can_frame_bits_worst(hal::pdo::kTpdo2.bytes())
    << ", \"heartbeat\": " << hal::can_frame_bits_worst(1) << "}"
    << ", \"shipped\": " << bus_json(cfg.canopen.load) << ", \"alternative\": " << bus_json(hal::bus_load(with_velocity))
    << ", \"best_case_bits_per_cycle\": " << best_bits
    << ", \"rate_at_full_load_hz\": "
    << json_num((m.bitrate - cfg.canopen.load.periodic_bits_per_cycle * m.rate_hz) / cfg.canopen.load.bits_per_cycle)
    << ", \"fake_bus\": {\"cycles\": " << w.cycles << ", \"frames_per_cycle\": " << json_num(w.frames_per_cycle)
    << ", \"bits_per_cycle\": " << json_num(w.bits_per_cycle)
    << ", \"load\": " << json_num(w.bits_per_cycle / cfg.canopen.load.bits_available) << "}}";
  return o.str();
}

// --- Kim's 32-point ball-bar calibration -------------------------------------

std::string vec_json(const cal::VecX& v) {
  std::string s = "[";
  for (Eigen::Index i = 0; i < v.size(); ++i) s += (i ? ", " : "") + json_num(v[i]);
  return s + "]";
}

std::string kim(int repeat, const std::string& problem_path) {
  cal::KimOptions ko;
  ko.circular_test = false;
  const cal::KimReproduction k = cal::reproduce_kim(ko);
  const kin::KinematicModel nominal = kin::KinematicModel::nominal();
  const std::vector<Vec3>& d = k.data.d;
  const std::vector<double>& len = k.data.length;
  const Vec3 pivot = cal::kim_pivot();
  const cal::LmOptions lm;
  const cal::VecX eta0 = cal::BallbarParameters{}.vector(false);
  const cal::ResidualFunction f = [&](const cal::VecX& x, cal::VecX& r, cal::MatX* J) {
    cal::ballbar_residuals(x, nominal.d0, d, len, pivot, r, J);
  };
  // The solve alone (what SciPy's least_squares does), then the whole fit
  // (pose check, solve, identifiability, frame transform: what `cpm calibrate` does).
  Timing solve, fit;
  cal::VecX eta;
  cal::LmReport rep;
  for (int i = 0; i < repeat; ++i) {
    eta = eta0;
    const std::int64_t a = now_ns();
    rep = cal::levenberg_marquardt(f, eta, lm);
    solve.ns.push_back(now_ns() - a);
  }
  cal::BallbarFit full;
  for (int i = 0; i < repeat; ++i) {
    const std::int64_t a = now_ns();
    full = cal::fit_ballbar(nominal, d, len, pivot);
    fit.ns.push_back(now_ns() - a);
  }
  cal::VecX r;
  f(eta, r, nullptr);
  const auto names = cal::ballbar_parameter_names(false);
  std::ostringstream p;  // the problem, for bench/scipy_ballbar.py
  p << "{\"what\": \"Kim's 32-point ball-bar calibration (reproduce_kim), bar length known: 9 unknowns\",\n"
    << " \"names\": [";
  for (std::size_t i = 0; i < names.size(); ++i) p << (i ? ", " : "") << json_string(names[i]);
  p << "],\n \"d0\": " << vec_json(nominal.d0) << ",\n \"pivot\": " << vec_json(pivot) << ",\n \"d\": [";
  for (std::size_t j = 0; j < d.size(); ++j) p << (j ? ",\n  " : "") << vec_json(d[j]);
  p << "],\n \"length\": [";
  for (std::size_t j = 0; j < len.size(); ++j) p << (j ? ", " : "") << json_num(len[j]);
  p << "],\n \"eta0\": " << vec_json(eta0) << ",\n \"tolerances\": {\"gradient\": " << json_num(lm.gradient_tolerance)
    << ", \"step\": " << json_num(lm.step_tolerance) << ", \"cost\": " << json_num(lm.cost_tolerance) << "},\n"
    << " \"cpp\": {\"eta\": " << vec_json(eta) << ", \"std_error\": " << vec_json(full.identifiability.std_error)
    << ", \"cost\": " << json_num(rep.final_cost) << ", \"residual\": " << vec_json(r) << "}}\n";
  std::ofstream(problem_path) << p.str();
  std::ostringstream o;
  o << "{\"poses\": " << d.size() << ", \"unknowns\": " << eta.size() << ", \"repeat\": " << repeat
    << ", \"problem_file\": " << json_string(problem_path) << ", \"solve\": {" << solve.json(1.0)
    << ", \"iterations\": " << rep.iterations << ", \"evaluations\": " << rep.evaluations
    << ", \"converged\": " << (rep.converged ? "true" : "false") << ", \"reason\": " << json_string(rep.reason)
    << ", \"cost\": " << json_num(rep.final_cost) << "}, \"fit\": {" << fit.json(1.0) << "}, \"eta\": " << vec_json(eta)
    << ", \"fit_eta\": " << vec_json(full.params.vector(false))
    << ", \"std_error\": " << vec_json(full.identifiability.std_error) << "}";
  return o.str();
}

// --- main -------------------------------------------------------------------

// Keep this thread on one CPU: a migration in the middle of a timed call
// would be counted as compute.
int pin_to_last_cpu(bool& pinned) {
  cpu_set_t allowed;
  CPU_ZERO(&allowed);
  sched_getaffinity(0, sizeof allowed, &allowed);
  int cpu = -1;
  for (int c = 0; c < CPU_SETSIZE; ++c)
    if (CPU_ISSET(c, &allowed)) cpu = c;
  cpu_set_t one;
  CPU_ZERO(&one);
  CPU_SET(cpu, &one);
  pinned = pthread_setaffinity_np(pthread_self(), sizeof one, &one) == 0;
  return cpu;
}

}  // namespace

int main(int argc, char** argv) try {
  cli::Args args("cpm_perf", std::vector<std::string>(argv + 1, argv + argc));
  const std::string source = args.option_or("source", ".");
  const std::string json_path = args.option_or("json", "");
  const std::string problem = args.option_or("kim-problem", "kim_ballbar_problem.json");
  const long cycles = args.integer("cycles", 100000);
  const int repeat = static_cast<int>(args.integer("repeat", 200));
  args.finish();
  if (cycles < 1000 || repeat < 1) throw Error("cpm_perf: --cycles must be >= 1000 and --repeat >= 1");
  bool pinned = false;
  const int cpu = pin_to_last_cpu(pinned);
  const std::int64_t overhead = timer_overhead_ns(100000);
  const CycleFigures c = control_cycle(source, cycles);
  const StepFigures s = steps(daemon::load_config(source + "/config/sim.yaml"), cycles);
  static const char* phase[daemon::kSeries] = {"wakeup_latency", "read", "estimate", "trajectory",
                                                "inverse_kinematics", "controller", "safety", "write",
                                                "publish", "cycle"};
  std::ostringstream o;
  o << "{\"driver\": {\"cycles\": " << cycles << ", \"cpu\": " << cpu << ", \"pinned\": " << (pinned ? "true" : "false")
    << ", \"timer_overhead_ns\": " << overhead << "},\n"
    << "\"control_cycle\": {" << c.cycle.json(1e-3) << ", \"allocations\": " << c.allocations
    << ", \"replay_mismatches\": " << c.mismatches << ", \"rejected_commands\": " << c.rejected
    << ", \"mode_at_end\": " << json_string(c.mode_at_end) << ", \"phase_mean_ns\": {";
  for (int i = 1; i < daemon::kSeries; ++i)
    o << (i > 1 ? ", " : "") << '"' << phase[i] << "\": " << json_num(c.phase_mean_ns[static_cast<std::size_t>(i)]);
  o << "}},\n\"controller_step\": {" << s.controller.json(1e-3) << "},\n"
    << "\"plant_step\": {" << s.plant.json(1e-3) << ", \"substeps\": " << s.substeps << ", \"substeps_sweep\": [";
  for (std::size_t i = 0; i < s.sweep.size(); ++i)
    o << (i ? ", " : "") << "{\"substeps\": " << s.sweep[i].substeps << ", \"rtf\": " << json_num(s.sweep[i].rtf)
      << ", \"max_step_error_m\": " << json_num(s.sweep[i].max_step_error_m) << "}";
  o << "]},\n"
    << "\"rtf\": {\"plant\": " << json_num(s.plant_rtf) << ", \"plant_shipped\": " << json_num(s.shipped_plant_rtf)
    << ", \"closed_loop\": " << json_num(s.closed_loop_rtf)
    << ", \"daemon_loop_sim\": " << json_num(c.daemon_rtf) << ", \"closed_loop_rmse_m\": " << json_num(s.tracking_rmse_m)
    << "},\n\"bus\": " << bus(source) << ",\n\"kim\": " << kim(repeat, problem) << "}\n";
  if (json_path.empty()) std::fputs(o.str().c_str(), stdout);
  else std::ofstream(json_path) << o.str();
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr,
               "cpm_perf: %s\nusage: cpm_perf --source DIR [--cycles N] [--repeat R] [--kim-problem FILE] "
               "[--json FILE]\n",
               e.what());
  return 1;
}

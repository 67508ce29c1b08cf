// SPDX-License-Identifier: Apache-2.0
// cpm_perf: the figures Google Benchmark's per-iteration means cannot give.
//
//   cpm_perf --source DIR [--cycles N] [--repeat R] [--kim-problem FILE] [--json FILE]  (--help: each option)
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
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

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
#include "support/allocation_counter.hpp"

namespace {

using namespace cpm;
using Json = nlohmann::ordered_json;

// Eigen vectors (VecX, Vec3) as JSON arrays.
template <class V>
Json vec_json(const V& v) {
  return std::vector<double>(v.data(), v.data() + v.size());
}

std::string dumped(const Json& j) { return j.dump(2, ' ', false, Json::error_handler_t::replace) + "\n"; }

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
  // The distribution, with the median and p99 as shares of `period_s`.
  [[nodiscard]] Json json(double period_s) const {
    const std::int64_t med = percentile(0.5), p99 = percentile(0.99);
    return {{"samples", ns.size()},
            {"min_ns", percentile(0.0)},
            {"median_ns", med},
            {"mean_ns", mean()},
            {"p99_ns", p99},
            {"p999_ns", percentile(0.999)},
            {"max_ns", percentile(1.0)},
            {"period_s", period_s},
            {"median_share", static_cast<double>(med) * 1e-9 / period_s},
            {"p99_share", static_cast<double>(p99) * 1e-9 / period_s}};
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

Json bus_json(const hal::BusLoad& L) {
  return {{"frames_per_cycle", L.frames_per_cycle},
          {"bits_per_cycle", L.bits_per_cycle},
          {"periodic_bits_per_cycle", L.periodic_bits_per_cycle},
          {"bits_available", L.bits_available},
          {"load", L.load},
          {"worst_cycle_load", L.worst_cycle_load},
          {"max_rate_hz", L.max_rate_hz},
          {"fits", L.fits}};
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

Json frame_bits_json() {
  return {{"sync", hal::can_frame_bits_worst(0)},
          {"rpdo1", hal::can_frame_bits_worst(hal::pdo::kRpdo1.bytes())},
          {"tpdo1", hal::can_frame_bits_worst(hal::pdo::kTpdo1.bytes())},
          {"tpdo2", hal::can_frame_bits_worst(hal::pdo::kTpdo2.bytes())},
          {"heartbeat", hal::can_frame_bits_worst(1)}};
}

Json bus(const std::string& source) {
  const daemon::DaemonConfig cfg = daemon::load_config(source + "/config/canopen.yaml");
  const hal::MasterConfig& m = cfg.canopen.master;
  const hal::BusLoad& load = cfg.canopen.load;
  hal::MasterConfig with_velocity = m;
  with_velocity.velocity_from_drive = !m.velocity_from_drive;
  // The same frames without a single stuff bit: the best case of the wire
  // (8n + 47 bits with interframe space), beside the worst case the master checks.
  int best_bits = 47;  // SYNC, no data
  for (std::size_t i = 0; i < m.drives.size(); ++i)
    best_bits += (8 * hal::pdo::kRpdo1.bytes() + 47) + (8 * hal::pdo::kTpdo1.bytes() + 47) +
                 (m.velocity_from_drive ? 8 * hal::pdo::kTpdo2.bytes() + 47 : 0);
  const WireCount w = count_on_fake_bus(m, 2000);
  return {{"config", "config/canopen.yaml"},
          {"drives", m.drives.size()},
          {"bitrate", m.bitrate},
          {"rate_hz", m.rate_hz},
          {"max_bus_load", m.max_bus_load},
          {"velocity_from_drive", m.velocity_from_drive},
          {"frame_bits_worst", frame_bits_json()},
          {"shipped", bus_json(load)},
          {"alternative", bus_json(hal::bus_load(with_velocity))},
          {"best_case_bits_per_cycle", best_bits},
          {"rate_at_full_load_hz", (m.bitrate - load.periodic_bits_per_cycle * m.rate_hz) / load.bits_per_cycle},
          {"fake_bus",
           {{"cycles", w.cycles},
            {"frames_per_cycle", w.frames_per_cycle},
            {"bits_per_cycle", w.bits_per_cycle},
            {"load", w.bits_per_cycle / load.bits_available}}}};
}

// --- Kim's 32-point ball-bar calibration -------------------------------------

// Kim's data, the solver's start and tolerances, and what it found, timed.
struct KimFigures {
  kin::KinematicModel nominal = kin::KinematicModel::nominal();
  std::vector<Vec3> d;
  std::vector<double> length;
  Vec3 pivot = cal::kim_pivot();
  cal::LmOptions lm;
  cal::VecX eta0 = cal::BallbarParameters{}.vector(false), eta, residual;
  cal::LmReport report;
  cal::BallbarFit full;
  Timing solve, fit;
};

KimFigures kim_timed(int repeat) {
  cal::KimOptions ko;
  ko.circular_test = false;
  const cal::KimReproduction k = cal::reproduce_kim(ko);
  KimFigures K;
  K.d = k.data.d;
  K.length = k.data.length;
  const cal::ResidualFunction f = [&](const cal::VecX& x, cal::VecX& r, cal::MatX* J) {
    cal::ballbar_residuals(x, K.nominal.d0, K.d, K.length, K.pivot, r, J);
  };
  // The solve alone (what SciPy's least_squares does), then the whole fit
  // (pose check, solve, identifiability, frame transform: what `cpm calibrate` does).
  for (int i = 0; i < repeat; ++i) {
    K.eta = K.eta0;
    const std::int64_t a = now_ns();
    K.report = cal::levenberg_marquardt(f, K.eta, K.lm);
    K.solve.ns.push_back(now_ns() - a);
  }
  for (int i = 0; i < repeat; ++i) {
    const std::int64_t a = now_ns();
    K.full = cal::fit_ballbar(K.nominal, K.d, K.length, K.pivot);
    K.fit.ns.push_back(now_ns() - a);
  }
  f(K.eta, K.residual, nullptr);
  return K;
}

// The problem, for bench/scipy_ballbar.py.
Json kim_problem_json(const KimFigures& K) {
  Json d = Json::array();
  for (const Vec3& x : K.d) d.push_back(vec_json(x));
  return {{"what", "Kim's 32-point ball-bar calibration (reproduce_kim), bar length known: 9 unknowns"},
          {"names", cal::ballbar_parameter_names(false)},
          {"d0", vec_json(K.nominal.d0)},
          {"pivot", vec_json(K.pivot)},
          {"d", d},
          {"length", K.length},
          {"eta0", vec_json(K.eta0)},
          {"tolerances", {{"gradient", K.lm.gradient_tolerance}, {"step", K.lm.step_tolerance},
                          {"cost", K.lm.cost_tolerance}}},
          {"cpp", {{"eta", vec_json(K.eta)}, {"std_error", vec_json(K.full.identifiability.std_error)},
                   {"cost", K.report.final_cost}, {"residual", vec_json(K.residual)}}}};
}

Json kim(int repeat, const std::string& problem_path) {
  const KimFigures K = kim_timed(repeat);
  std::ofstream(problem_path) << dumped(kim_problem_json(K));
  Json solve = K.solve.json(1.0);
  solve["iterations"] = K.report.iterations;
  solve["evaluations"] = K.report.evaluations;
  solve["converged"] = K.report.converged;
  solve["reason"] = K.report.reason;
  solve["cost"] = K.report.final_cost;
  return {{"poses", K.d.size()},
          {"unknowns", K.eta.size()},
          {"repeat", repeat},
          {"problem_file", problem_path},
          {"solve", solve},
          {"fit", K.fit.json(1.0)},
          {"eta", vec_json(K.eta)},
          {"fit_eta", vec_json(K.full.params.vector(false))},
          {"std_error", vec_json(K.full.identifiability.std_error)}};
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

// The figures of the control cycle, replayed, and of its phases.
Json control_cycle_json(const CycleFigures& c) {
  static const char* phase[daemon::kSeries] = {"wakeup_latency", "read", "estimate", "trajectory",
                                                "inverse_kinematics", "controller", "safety", "write",
                                                "publish", "cycle"};
  Json o = c.cycle.json(1e-3);
  o["allocations"] = c.allocations;
  o["replay_mismatches"] = c.mismatches;
  o["rejected_commands"] = c.rejected;
  o["mode_at_end"] = c.mode_at_end;
  Json phases = Json::object();
  for (int i = 1; i < daemon::kSeries; ++i) phases[phase[i]] = c.phase_mean_ns[static_cast<std::size_t>(i)];
  o["phase_mean_ns"] = std::move(phases);
  return o;
}

Json plant_step_json(const StepFigures& s) {
  Json o = s.plant.json(1e-3);
  o["substeps"] = s.substeps;
  Json sweep = Json::array();
  for (const SubstepFigures& f : s.sweep)
    sweep.push_back({{"substeps", f.substeps}, {"rtf", f.rtf}, {"max_step_error_m", f.max_step_error_m}});
  o["substeps_sweep"] = std::move(sweep);
  return o;
}

struct PerfOptions {
  std::string source = ".", json_path, kim_problem = "kim_ballbar_problem.json";
  long cycles = 100000;
  int repeat = 200;
};

void add_options(CLI::App& app, PerfOptions& o) {
  app.add_option("--source", o.source, "the source tree, for config/sim.yaml and config/canopen.yaml (default .)")
      ->type_name("DIR");
  app.add_option("--cycles", o.cycles, "control cycles timed, >= 1000 (default 100000)")
      ->type_name("N")
      ->check(CLI::Range(1000L, 1000000000L));
  app.add_option("--repeat", o.repeat, "times Kim's calibration is solved and fitted, >= 1 (default 200)")
      ->type_name("R")
      ->check(CLI::Range(1, 1000000));
  app.add_option("--kim-problem", o.kim_problem,
                 "where to write Kim's ball-bar problem for bench/scipy_ballbar.py (default kim_ballbar_problem.json)")
      ->type_name("FILE");
  app.add_option("--json", o.json_path, "write the figures to FILE instead of standard output")->type_name("FILE");
}

Json measure(const PerfOptions& o) {
  bool pinned = false;
  const int cpu = pin_to_last_cpu(pinned);
  const std::int64_t overhead = timer_overhead_ns(100000);
  const CycleFigures c = control_cycle(o.source, o.cycles);
  const StepFigures s = steps(daemon::load_config(o.source + "/config/sim.yaml"), o.cycles);
  return {{"driver", {{"cycles", o.cycles}, {"cpu", cpu}, {"pinned", pinned}, {"timer_overhead_ns", overhead}}},
          {"control_cycle", control_cycle_json(c)},
          {"controller_step", s.controller.json(1e-3)},
          {"plant_step", plant_step_json(s)},
          {"rtf", {{"plant", s.plant_rtf}, {"plant_shipped", s.shipped_plant_rtf}, {"closed_loop", s.closed_loop_rtf},
                   {"daemon_loop_sim", c.daemon_rtf}, {"closed_loop_rmse_m", s.tracking_rmse_m}}},
          {"bus", bus(o.source)},
          {"kim", kim(o.repeat, o.kim_problem)}};
}

}  // namespace

int main(int argc, char** argv) {
  PerfOptions o;
  CLI::App app("cpm_perf: per-call percentiles of cpmd's control cycle, the controller's and the plant's steps, "
               "real-time factors, CAN bus figures and Kim's calibration timed (bench/run.sh runs it)");
  add_options(app, o);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);  // --help
    std::fprintf(stderr, "cpm_perf: %s\n(cpm_perf --help lists the options)\n", e.what());
    return 1;
  }
  try {
    const std::string text = dumped(measure(o));
    if (o.json_path.empty()) std::fputs(text.c_str(), stdout);
    else std::ofstream(o.json_path) << text;
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cpm_perf: %s\n", e.what());
    return 1;
  }
}

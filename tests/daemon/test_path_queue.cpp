// SPDX-License-Identifier: Apache-2.0
// The path queue (docs/path.md): programs as path_command_t chunks and back,
// a plan played by the loop without allocating, retired to the server's
// store and freed there; and the whole way in-process (the server on
// memq://, the loop on the simulator backend, cycle by cycle): a program
// sent in chunks, planned in the server's worker, played, its contour
// error measured against the programmed path; and every refusal with its
// reason and the program line.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <lcm/lcm-cpp.hpp>
#include <thread>
#include <vector>

#include "cpm/daemon/path_message.hpp"
#include "cpm/daemon/server.hpp"
#include "cpm/path/contour.hpp"
#include "cpm/path/planner.hpp"
#include "cpm/path/program.hpp"
#include "cpm/path/test_paths.hpp"
#include "loop_fixture.hpp"
#include "support/allocation_counter.hpp"
#include "support/test_operators.hpp"

namespace cpm::daemon {
namespace {

using cpm_msgs::ack_t;
using cpm_msgs::path_command_t;
using C = cpm_msgs::control_command_t;

// A program with every kind of segment: rapids, lines, arcs both ways and
// of several turns, a helix, a dwell.
path::PathQueue mixed_queue(const Vec3& start) {
  const Vec3 o(0.425, 0.425, 0.300);
  path::PathQueue q(start, 5e-5);
  q.rapid(o + Vec3(-0.04, 0, 0), 3);
  q.line(o + Vec3(-0.02, 0, 0), 0.1, 4);
  q.arc(o + Vec3(0.02, 0, 0), o, Vec3::UnitZ(), 1, 0.1, 5);
  q.arc(o + Vec3(0.02, 0, -0.005), o, Vec3::UnitZ(), -2, 0.05, 6);
  q.dwell(0.2, 7);
  q.line(o + Vec3(0.02, 0.01, -0.005), 0.1, 8);
  return q;
}

TEST(PathMessage, ChunksRoundTripToTheSameQueue) {
  path::PathQueue q = mixed_queue(Vec3(0.45, 0.42, 0.31));
  // Enough lines for three chunks.
  for (int k = 0; k < 2 * kPathChunkSegments + 14; ++k)
    q.line(q.end() + Vec3(k % 2 ? 1e-3 : -1e-3, 2e-4, 0), 0.05, 100 + k);
  const auto chunks = path_chunks(q, 42);
  ASSERT_EQ(chunks.size(), 3u);
  PathAssembly a;
  for (std::size_t k = 0; k < chunks.size(); ++k) {
    EXPECT_EQ(chunks[k].chunk, static_cast<int>(k));
    EXPECT_EQ(chunks[k].last, k + 1 == chunks.size());
    EXPECT_EQ(bad_number(chunks[k]), "");
    ASSERT_EQ(a.add(chunks[k]), "");
    EXPECT_EQ(a.complete(), k + 1 == chunks.size());
  }
  const path::PathQueue back = a.take();
  ASSERT_EQ(back.segments().size(), q.segments().size());
  EXPECT_EQ(back.start(), q.start());
  EXPECT_EQ(back.tolerance(), q.tolerance());
  for (std::size_t i = 0; i < q.segments().size(); ++i) {
    const path::Segment &x = q.segments()[i], &y = back.segments()[i];
    EXPECT_EQ(x.kind, y.kind) << i;
    EXPECT_EQ(x.start, y.start) << i;
    EXPECT_EQ(x.end, y.end) << i;
    EXPECT_EQ(x.centre, y.centre) << i;
    EXPECT_EQ(x.sweep, y.sweep) << i;
    EXPECT_EQ(x.feed, y.feed) << i;
    EXPECT_EQ(x.dwell, y.dwell) << i;
    EXPECT_EQ(x.line, y.line) << i;
  }
}

TEST(PathMessage, BadChunksAreRefusedAndDropTheProgram) {
  const auto chunks = path_chunks(mixed_queue(Vec3(0.45, 0.42, 0.31)), 7);
  ASSERT_EQ(chunks.size(), 1u);
  PathAssembly a;
  path_command_t m = chunks[0];
  m.last = false;
  ASSERT_EQ(a.add(m), "");
  path_command_t skip = m;
  skip.chunk = 2;  // chunk 1 was due
  EXPECT_NE(a.add(skip).find("came when chunk 1 was due"), std::string::npos);
  skip.chunk = 1;  // the program was dropped: nothing to continue
  EXPECT_NE(a.add(skip).find("belongs to no program"), std::string::npos);
  path_command_t nan = chunks[0];
  nan.end[2][1] = std::nan("");
  EXPECT_EQ(bad_number(nan), "end[2][1]");
  path_command_t zero_radius = chunks[0];
  for (int j = 0; j < 3; ++j) zero_radius.centre[2][j] = zero_radius.end[1][j];  // the arc's centre on its start
  EXPECT_NE(a.add(zero_radius).find("zero radius"), std::string::npos);
  path_command_t big = chunks[0];
  big.count = kPathChunkSegments + 1;
  EXPECT_NE(a.add(big).find("count must be"), std::string::npos);
  path_command_t kind = chunks[0];
  kind.kind[3] = 9;
  EXPECT_NE(a.add(kind).find("unknown kind 9"), std::string::npos);
  EXPECT_FALSE(a.complete());
}

TEST(PathMessage, DurationBoundIsTheFeedsAndDwells) {
  path::PathQueue q(Vec3(0.4, 0.4, 0.3), 0.0);
  q.line(Vec3(0.5, 0.4, 0.3), 0.05);  // 0.1 m at 0.05 m/s: 2 s
  q.dwell(1.5);
  q.rapid(Vec3(0.4, 0.4, 0.3));  // 0.1 m at 0.5 m/s: 0.2 s
  EXPECT_NEAR(program_duration_bound(q, 0.5), 3.7, 1e-12);
}

// A plan of `program` (G-code) from `start`, as cpmd plans it.
path::PreparedProgram plan_from(const std::string& program, const Vec3& start, const ctl::Machine& m,
                                const LimitsConfig& L) {
  path::ProgramOptions o;
  o.start = start;
  path::MachineLimits ml;
  ml.velocity = L.velocity;
  ml.acceleration = L.acceleration;
  ml.force = L.force;
  o.planner = path::planner_options(ml, m);
  return path::prepare_program(program, m, o);
}

// The segment the server hands the loop for a planned program.
Command plan_segment(const path::PreparedProgram& p, std::int64_t id = 0) {
  Command c;
  c.kind = CommandKind::segment;
  c.id = id;
  c.source = kPathAckSource;
  c.segment.start = p.queue.start();
  c.segment.end = p.queue.end();
  c.segment.traj = &*p.plan;
  return c;
}

TEST(PathQueueLoop, APlanPlaysWithoutAllocatingAndIsRetired) {
  test::LoopHarness h;
  h.to_holding();
  const path::PreparedProgram p =
      plan_from(path::square_diamond_circle(60.0, 6000.0), h.queue_end(), h.machine, h.cfg.limits);
  const path::Plan* plan = &*p.plan;
  ASSERT_TRUE(h.loop->commands().push(plan_segment(p, 77)));
  const auto cycles = static_cast<int>(std::ceil(plan->duration() / h.loop->period())) + 20;
  long allocations = 0;
  std::vector<int> lines;
  for (int i = 0; i < cycles; ++i) {
    {
      const cpm::test::CountAllocations count;
      h.loop->cycle(h.k++, 0);
      allocations += static_cast<long>(count.count());
    }
    h.drain_snapshots();
    const auto& s = h.state();
    if (s.segment_id == 77) {
      // The line the loop reports is that of the plan's segment at that time.
      const double t = s.segment_elapsed;
      EXPECT_EQ(s.program_line, path::line_of(*plan, plan->sample_path(t).segment)) << t;
      if (lines.empty() || lines.back() != s.program_line) lines.push_back(s.program_line);
    } else {
      EXPECT_EQ(s.program_line, 0);
    }
  }
  EXPECT_EQ(allocations, 0);
  EXPECT_EQ(h.mode(), Mode::holding);
  EXPECT_EQ(h.state().last_segment_id, 77);
  EXPECT_EQ(h.state().faults, 0);
  // The lines of the program, in order (the contour's moves are on lines 4..21).
  ASSERT_GE(lines.size(), 10u);
  EXPECT_TRUE(std::is_sorted(lines.begin(), lines.end()));
  // Handed back once, for the server to free.
  const path::Plan* retired = nullptr;
  ASSERT_TRUE(h.loop->retired_plans().pop(retired));
  EXPECT_EQ(retired, plan);
  EXPECT_FALSE(h.loop->retired_plans().pop(retired));
}

TEST(PathQueueLoop, AStopRetiresThePlayingAndTheQueuedPlans) {
  test::LoopHarness h;
  h.to_holding();
  const path::PreparedProgram a = plan_from("G21 G90 G1 X20 Y0 Z0 F3000\n", h.queue_end(), h.machine, h.cfg.limits);
  const path::PreparedProgram b = plan_from("G21 G90 G1 X20 Y10 Z0 F3000\n", a.queue.end(), h.machine, h.cfg.limits);
  for (const path::PreparedProgram* p : {&a, &b}) ASSERT_TRUE(h.command(plan_segment(*p)).accepted);
  h.run(300);
  ASSERT_EQ(h.mode(), Mode::moving);
  ASSERT_TRUE(h.simple(CommandKind::stop).accepted);
  std::vector<const path::Plan*> retired;
  for (const path::Plan* r = nullptr; h.loop->retired_plans().pop(r);) retired.push_back(r);
  ASSERT_EQ(retired.size(), 2u);
  EXPECT_EQ(retired[0], &*a.plan);
  EXPECT_EQ(retired[1], &*b.plan);
}

// The server on memq:// with the loop, cycle by cycle; commands signed by
// alice (an engineer) in her session.
struct Cell {
  test::LoopHarness h;
  ModelStore models{std::make_unique<ctl::Machine>(ctl::MachineModel::elkady())};
  std::unique_ptr<Server> server;
  std::vector<ack_t> acks;
  std::vector<path::RunSample> run;  // every cycle while the program plays
  std::int64_t playing = -1;
  std::int64_t next_id = 1, session = 0, seq = 0;
  Credentials who = test::credentials("alice");

  static DaemonConfig config(const LimitsConfig& limits) {
    DaemonConfig c = test::test_config();
    c.lcm.url = "memq://";
    c.limits = limits;
    return c;
  }
  explicit Cell(const LimitsConfig& limits = LimitsConfig{}) : h(config(limits)) {
    server = std::make_unique<Server>(h.cfg, *h.loop, models);
    server->set_clock([] { return 100.0; });
    server->set_wall_clock([] { return test::kWallClock; });
    server->set_operators(test::operator_table());
    server->set_boot_id(test::kTestBoot);
    server->bus().subscribe(h.cfg.lcm.ack_channel, &Cell::on_ack, this);
  }
  void on_ack(const lcm::ReceiveBuffer*, const std::string&, const ack_t* a) { acks.push_back(*a); }
  void pump() {
    while (server->bus().handleTimeout(0) > 0) {
    }
  }
  void cycles(int n) {
    for (int i = 0; i < n; ++i) {
      h.loop->cycle(h.k++, 0);
      const auto& s = h.state();
      if (s.segment_id == playing)
        run.push_back(path::RunSample{s.segment_elapsed, Vec3(s.position[0], s.position[1], s.position[2]),
                                      Vec3(s.velocity[0], s.velocity[1], s.velocity[2]),
                                      Vec3(s.force[0], s.force[1], s.force[2])});
      server->drain();
      pump();
    }
  }
  std::optional<ack_t> ack_of(std::int64_t id) const {
    for (auto it = acks.rbegin(); it != acks.rend(); ++it)
      if (it->id == id) return *it;
    return std::nullopt;
  }
  template <class M>
  void publish(const std::string& channel, M m) {
    const auto b = test::encode_signed(m, who);
    server->bus().publish(channel, b.data(), static_cast<unsigned>(b.size()));
    pump();
  }
  // Run the loop until the command's ack is out (a last chunk waits for the
  // worker: real time passes between cycles), then return it.
  ack_t await(std::int64_t id) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (std::chrono::steady_clock::now() < end) {
      if (auto a = ack_of(id)) return *a;
      cycles(1);
      if (server->planning()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    ADD_FAILURE() << "no ack for id " << id;
    return {};
  }
  ack_t control(std::int8_t cmd) {
    C m{};
    m.command = cmd;
    m.id = next_id++;
    m.session = cmd == C::CMD_ACQUIRE ? 4242 : session;
    m.seq = cmd == C::CMD_ACQUIRE ? test::acquire_seq() : ++seq;
    publish(h.cfg.lcm.control_channel, m);
    return await(m.id);
  }
  void acquire() {
    const ack_t a = control(C::CMD_ACQUIRE);
    ASSERT_TRUE(a.accepted) << a.message;
    session = a.session;
  }
  void enable() {
    if (session == 0) acquire();
    ASSERT_TRUE(control(C::CMD_ENABLE).accepted);
    cycles(30);
    ASSERT_EQ(h.mode(), Mode::holding);
  }
  // Send every chunk; returns the last chunk's ack (the others must be taken).
  ack_t send(std::vector<path_command_t> chunks) {
    ack_t last{};
    for (path_command_t& m : chunks) {
      m.id = next_id++;
      m.session = session;
      m.seq = ++seq;
      publish(h.cfg.lcm.path_channel, m);
      last = await(m.id);
      EXPECT_EQ(last.source, kPathAckSource);
      if (!m.last) {
        EXPECT_TRUE(last.accepted) << last.message;
      }
    }
    return last;
  }
};

path::PathQueue program_queue(const std::string& text, const Vec3& start, double tolerance = 5e-5) {
  path::ReaderOptions ro;
  const path::ProgramFrame frame;
  ro.start = frame.to_program(start);
  return path::to_queue(path::read_program(text, ro), frame, tolerance);
}

TEST(PathQueueServer, AProgramRunsEndToEndWithinItsTolerance) {
  Cell c;
  c.enable();
  // The square-diamond-circle contour, 100 mm, 6 m/min, 0.05 mm tolerance.
  const double tolerance = 5e-5;
  const path::PathQueue q = program_queue(path::square_diamond_circle(100.0, 6000.0), c.h.queue_end(), tolerance);
  const auto chunks = path_chunks(q, 9);
  const std::int64_t id = c.next_id + static_cast<std::int64_t>(chunks.size()) - 1;
  c.playing = id;
  const ack_t a = c.send(chunks);
  ASSERT_TRUE(a.accepted) << a.message;
  EXPECT_EQ(a.id, id);
  EXPECT_EQ(c.server->plans_held(), 1u);
  // The plan cpmd made is this one (the same queue, limits and model).
  const path::PreparedProgram local = plan_from(path::square_diamond_circle(100.0, 6000.0), q.start(), c.h.machine,
                                                c.h.cfg.limits);
  const double duration = local.plan->duration();
  c.cycles(static_cast<int>(duration / c.h.loop->period()) + 50);
  const auto& s = c.h.state();
  EXPECT_EQ(s.faults, 0);
  EXPECT_EQ(c.h.mode(), Mode::holding);
  EXPECT_EQ(s.last_segment_id, id);
  EXPECT_NEAR(static_cast<double>(s.last_segment_cycles) * c.h.loop->period(), duration, 3e-3);
  // Retired by the loop and freed by the server.
  EXPECT_EQ(c.server->plans_held(), 0u);
  // The contour error: within the tolerance plus what the controller adds
  // (docs/path.md: 36 um on the 250 mm contour at this feed in the
  // in-process closed loop); the plan's own corners within the tolerance.
  const path::ContourFigures f = path::contour(q, *local.plan, c.run, c.h.cfg.limits.velocity);
  EXPECT_LT(f.max_rounding, tolerance * 1.001);
  EXPECT_LT(f.max_error, tolerance);
  EXPECT_GT(f.max_error, 1e-6);  // the measurement sees something
  EXPECT_LT(f.max_tracking, 1e-4);
  std::printf("contour error max %.1f um, rms %.2f um; tracking max %.1f um; rounding %.1f um; %.3f s\n",
              f.max_error * 1e6, f.rms_error * 1e6, f.max_tracking * 1e6, f.max_rounding * 1e6, duration);
}

TEST(PathQueueServer, RefusalsSayWhyAndWhere) {
  LimitsConfig L;
  L.workspace_max.y() = 0.425 + 0.030;  // program Y30 is the soft limit
  Cell c(L);
  c.acquire();
  c.cycles(5);  // the server has heard the state: where the queue ends
  // Disabled: the loop refuses the planned program; the plan is freed.
  const ack_t off = c.send(path_chunks(program_queue("G21 G90 G1 X10 Y0 Z0 F3000\n", c.h.queue_end()), 1));
  EXPECT_FALSE(off.accepted);
  EXPECT_EQ(off.reason, ack_t::REASON_ILLEGAL_IN_MODE) << off.message;
  EXPECT_EQ(c.server->plans_held(), 0u);
  c.enable();
  const Vec3 end = c.h.queue_end();
  // Not from the queue's end.
  const ack_t away = c.send(path_chunks(program_queue("G21 G90 G1 X10 Y0 Z0 F3000\n", end + Vec3(0.001, 0, 0)), 2));
  EXPECT_EQ(away.reason, ack_t::REASON_NOT_CONTINUOUS) << away.message;
  // Past the soft limit on line 3 (the rapid and line 2 stay inside).
  const ack_t out = c.send(path_chunks(
      program_queue("G21 G90 G0 X0 Y0 Z0\nG1 X10 Y20 F3000\nG1 X10 Y40\nG1 X0 Y0\n", end), 3));
  EXPECT_EQ(out.reason, ack_t::REASON_WORKSPACE) << out.message;
  EXPECT_EQ(out.message.rfind("line 3:", 0), 0u) << out.message;
  EXPECT_NE(out.message.find("soft limits on y"), std::string::npos) << out.message;
  // A chunk out of order.
  auto two = path_chunks(program_queue(path::square_diamond_circle(60.0, 3000.0), end), 4);
  path_command_t odd = two[0];
  odd.chunk = 1;
  const ack_t order = c.send({odd});
  EXPECT_EQ(order.reason, ack_t::REASON_INVALID) << order.message;
  // A number that is not one.
  path_command_t nan = two[0];
  nan.feed[1] = std::nan("");
  const ack_t bad = c.send({nan});
  EXPECT_EQ(bad.reason, ack_t::REASON_INVALID);
  EXPECT_NE(bad.message.find("feed[1]"), std::string::npos) << bad.message;
  // An observer may not move the machine.
  c.who = test::credentials("olga");
  const ack_t olga = c.send(path_chunks(program_queue("G21 G90 G1 X10 Y0 Z0 F3000\n", end), 5));
  EXPECT_EQ(olga.reason, ack_t::REASON_NOT_AUTHORIZED);
  c.who = test::credentials("alice");
  // Nothing moved, nothing is held.
  c.cycles(10);
  EXPECT_EQ(c.h.mode(), Mode::holding);
  EXPECT_EQ(c.server->plans_held(), 0u);
  EXPECT_LT((c.h.queue_end() - end).norm(), 1e-12);
}

TEST(PathQueueServer, AProgramTheDrivesCannotHoldIsRefusedByTheLimit) {
  LimitsConfig L;
  L.force = 5.0;  // N: not even the platform's weight on z
  Cell c(L);
  c.enable();
  const ack_t a = c.send(path_chunks(program_queue("G21 G90 G1 X10 Y0 Z0 F3000\n", c.h.queue_end()), 1));
  EXPECT_FALSE(a.accepted);
  EXPECT_EQ(a.reason, ack_t::REASON_LIMIT) << a.message;
  EXPECT_NE(a.message.find("no plan"), std::string::npos) << a.message;
  EXPECT_EQ(c.server->plans_held(), 0u);
}

}  // namespace
}  // namespace cpm::daemon

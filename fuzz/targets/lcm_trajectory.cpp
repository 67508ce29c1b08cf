// SPDX-License-Identifier: Apache-2.0
// The bytes of a trajectory_command_t as they arrive on CPMD_TRAJ, decoded as
// the daemon's LCM thread decodes them, then daemon::validate_segment (the
// check every segment passes before the loop sees it). Oracle:
// validate_segment never throws; a refusal has a reason and a message; an
// accepted segment starts where the queue ends, stays inside the soft
// limits and under the speed limit at every check step, and ends at `end`.
#include <cmath>
#include <memory>

#include "cpm/daemon/server.hpp"
#include "fuzz_common.hpp"

using namespace cpm;
using cpm_msgs::ack_t;
using cpm_msgs::trajectory_command_t;

namespace {
const ctl::Machine& machine() {
  static const ctl::Machine m{ctl::MachineModel::elkady()};
  return m;
}

// Where the segment would start if it were continuous with the queue: for a
// stream its first point, for a circle its first sample; P1 otherwise.
Vec3 own_start(const trajectory_command_t& m) {
  const Vec3 p1(0.600, 0.425, 0.300);
  if (m.kind == trajectory_command_t::KIND_STREAM && m.count >= 1 && m.count <= 100)
    return Vec3(m.position[0][0], m.position[0][1], m.position[0][2]);
  if (m.kind == trajectory_command_t::KIND_CIRCLE && m.plane >= 0 && m.plane <= 2) {
    ctl::CircleSpec s;
    s.centre = Vec3(m.centre[0], m.centre[1], m.centre[2]);
    s.radius = m.radius;
    s.plane = static_cast<ctl::CirclePlane>(m.plane);
    s.angular_speed = m.angular_speed;
    s.start_angle = m.start_angle;
    s.cruise_time = m.cruise_time;
    s.ramp_time = m.ramp_time;
    try {
      return ctl::CircleTrajectory(s).sample(0.0).p;
    } catch (const Error&) {
    }
  }
  return p1;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > (1u << 20)) return 0;
  auto m = std::make_unique<trajectory_command_t>();
  if (m->decode(data, 0, static_cast<int>(size)) < 0) return 0;  // LCM drops it
  daemon::LimitsConfig limits;
  // The check step: 250 Hz (a legal loop rate) keeps an execution of a
  // long segment short; the code walked is the same as at 1 kHz.
  const double dt = 4e-3;
  // The low bit of utime (informative only) picks the start: P1 or the segment's own.
  const Vec3 start = (m->utime & 1) ? own_start(*m) : Vec3(0.600, 0.425, 0.300);
  daemon::Validation v;
  try {
    v = daemon::validate_segment(*m, start, machine(), limits, dt);
  } catch (const std::exception& e) {
    fuzz::fail(__FILE__, __LINE__, std::string("validate_segment threw: ") + e.what());
  }
  if (!v.ok) {
    FUZZ_CHECK(v.reason > ack_t::REASON_NONE && v.reason <= ack_t::REASON_BUSY, "a refusal without a reason");
    FUZZ_CHECK(!v.message.empty(), "a refusal without a message");
    return 0;
  }
  const ctl::Trajectory* tr = v.segment.get();
  FUZZ_CHECK(tr != nullptr, "accepted without a trajectory");
  const double T = tr->duration();
  FUZZ_CHECK(std::isfinite(T) && T >= 0, "accepted a duration that is not a finite time >= 0");
  FUZZ_CHECK((tr->sample(0.0).p - start).norm() <= 1e-6, "accepted a segment that does not start at the queue's end");
  FUZZ_CHECK((tr->sample(T).p - v.segment.end).norm() <= 1e-9, "segment.end is not where the trajectory ends");
  // Every check step, thinned to at most ~2000 samples.
  const long n = static_cast<long>(std::ceil(T / dt));
  const long stride = std::max(1L, n / 2000);
  for (long k = 0; k <= n; k += stride) {
    const auto s = tr->sample(std::min(T, k * dt));
    FUZZ_CHECK(s.p.allFinite() && s.v.allFinite() && s.a.allFinite(), "a non-finite sample was accepted");
    for (int i = 0; i < 3; ++i)
      FUZZ_CHECK(s.p[i] >= limits.workspace_min[i] - 1e-8 && s.p[i] <= limits.workspace_max[i] + 1e-8,
                 "an accepted segment leaves the soft limits at t = " + std::to_string(k * dt));
    FUZZ_CHECK(s.v.norm() <= limits.velocity * (1 + 1e-6), "an accepted segment exceeds limits.velocity");
  }
  return 0;
}

// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/homing.hpp"

#include <cmath>
#include <limits>

namespace cpm::daemon {

const char* homing_phase_name(HomingPhase p) noexcept {
  switch (p) {
    case HomingPhase::idle: return "idle";
    case HomingPhase::search: return "search";
    case HomingPhase::back_off: return "back_off";
    case HomingPhase::latch: return "latch";
    case HomingPhase::index: return "index";
    case HomingPhase::drive: return "drive";
    case HomingPhase::final_: return "final";
  }
  return "?";
}

void AxisHoming::start(const AxisHomingConfig& cfg, double t0, bool switch_now) noexcept {
  cfg_ = cfg;
  t0_ = t0;
  offset_ = 0.0;
  event_seen_ = false;
  stopping_ = false;
  drive_started_ = false;
  failure_ = {};
  mark_ = std::numeric_limits<double>::quiet_NaN();  // taken at the first step
  switch (cfg.method) {
    case HomingMethod::absolute: phase_ = HomingPhase::final_; event_seen_ = true; break;
    case HomingMethod::drive: phase_ = HomingPhase::drive; break;
    case HomingMethod::switch_: phase_ = switch_now ? HomingPhase::back_off : HomingPhase::search; break;
  }
}

AxisHoming::Outcome AxisHoming::fail(const char* cause, double value, double limit) noexcept {
  failure_ = {cause, value, limit};
  phase_ = HomingPhase::idle;
  return Outcome::failed;
}

AxisHoming::Outcome AxisHoming::begin_final(const Inputs& in, Request& req) noexcept {
  phase_ = HomingPhase::final_;
  mark_ = in.raw;
  return step(in, req);
}

// Long (about 100 lines) on purpose: one switch over the homing phases, each
// case a row of the sequence docs/daemon.md tables, so that the whole
// sequence reads in one place.
AxisHoming::Outcome AxisHoming::step(const Inputs& in, Request& req) noexcept {
  req = Request{};
  if (phase_ == HomingPhase::idle) return Outcome::failed;
  if (std::isnan(mark_)) mark_ = in.raw;
  const double elapsed = in.t - t0_;
  if (elapsed > cfg_.timeout) return fail("timeout", elapsed, cfg_.timeout);
  const double toward = cfg_.search_velocity > 0.0 ? 1.0 : -1.0;  // the switch's side
  const double travel = std::abs(in.raw - mark_);
  switch (phase_) {
    case HomingPhase::back_off:
      // Started on the switch: leave it at the search speed, stop, then search.
      if (!stopping_) {
        if (!in.home_switch) {
          stopping_ = true;
        } else if (travel > cfg_.max_travel) {
          return fail("switch_stuck", travel, cfg_.max_travel);
        } else {
          req.velocity = -toward * std::abs(cfg_.search_velocity);
          return Outcome::running;
        }
      }
      if (!in.reference_at_rest) return Outcome::running;
      stopping_ = false;
      phase_ = HomingPhase::search;
      mark_ = in.raw;
      return Outcome::running;
    case HomingPhase::search:
      if (!stopping_) {
        if (in.home_switch) {
          stopping_ = true;  // met it at speed: stop, then latch its edge slowly
        } else if (travel > cfg_.max_travel) {
          return fail("switch_not_found", travel, cfg_.max_travel);
        } else {
          req.velocity = cfg_.search_velocity;
          return Outcome::running;
        }
      }
      if (!in.reference_at_rest) return Outcome::running;
      stopping_ = false;
      phase_ = HomingPhase::latch;
      mark_ = in.raw;
      return Outcome::running;
    case HomingPhase::latch:
      // Leave the switch slowly: the edge is the homing event.
      if (in.home_switch) {
        if (travel > cfg_.max_travel) return fail("switch_stuck", travel, cfg_.max_travel);
        req.velocity = -toward * cfg_.latch_velocity;
        return Outcome::running;
      }
      if (cfg_.use_index) {
        phase_ = HomingPhase::index;
        mark_ = in.raw;
        req.velocity = -toward * cfg_.latch_velocity;
        return Outcome::running;
      }
      offset_ = cfg_.home_position - in.raw;
      event_seen_ = true;
      return begin_final(in, req);
    case HomingPhase::index:
      if (!in.index) {
        if (travel > cfg_.max_travel) return fail("index_not_found", travel, cfg_.max_travel);
        req.velocity = -toward * cfg_.latch_velocity;
        return Outcome::running;
      }
      offset_ = cfg_.home_position - in.raw;
      event_seen_ = true;
      return begin_final(in, req);
    case HomingPhase::drive:
      req.kind = Request::Kind::drive;
      if (in.drive == DriveHoming::error) return fail("drive_error", elapsed, cfg_.timeout);
      if (in.drive == DriveHoming::running) drive_started_ = true;
      if (in.drive == DriveHoming::attained) {
        offset_ = 0.0;  // the drive's counts now read its home position there
        event_seen_ = true;
        return begin_final(in, req);
      }
      return Outcome::running;
    case HomingPhase::final_: {
      if (std::isnan(cfg_.final_position)) {
        if (!in.reference_at_rest) return Outcome::running;  // (a drive that homed itself is at rest)
        phase_ = HomingPhase::idle;
        return Outcome::homed;
      }
      const double target = cfg_.final_position - offset_;
      req.kind = Request::Kind::position;
      req.position = target;
      req.speed = std::abs(cfg_.search_velocity);
      if (in.reference_at_rest && std::abs(in.reference - target) < 1e-9) {
        phase_ = HomingPhase::idle;
        return Outcome::homed;
      }
      return Outcome::running;
    }
    case HomingPhase::idle:
      break;
  }
  return Outcome::failed;
}

}  // namespace cpm::daemon

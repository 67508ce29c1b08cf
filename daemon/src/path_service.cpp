// SPDX-License-Identifier: Apache-2.0
// The path queue's server side (path_service.hpp).
#include "path_service.hpp"

#include <cstdio>

#include <cpm_msgs/ack_t.hpp>

#include "cpm/path/planner.hpp"
#include "cpm/path/program.hpp"

namespace cpm::daemon {

using cpm_msgs::ack_t;

PathService::PathService(const LimitsConfig& limits) : limits_(limits), worker_([this] { work(); }) {}

PathService::~PathService() {
  {
    const std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  worker_.join();
}

std::optional<PathAnswer> PathService::add(const cpm_msgs::path_command_t& m, const ctl::MachineModel& model,
                                           const Vec3& queue_end) {
  if (m.last && busy()) {
    assembly_.clear();
    return PathAnswer{false, ack_t::REASON_BUSY, "another program is being planned; send this one again after it"};
  }
  if (std::string why = assembly_.add(m); !why.empty()) return PathAnswer{false, ack_t::REASON_INVALID, why};
  if (!assembly_.complete()) return PathAnswer{true, 0, "chunk " + std::to_string(m.chunk) + " taken"};
  Job job;
  job.id = m.id;
  job.queue.emplace(assembly_.take());
  if ((job.queue->start() - queue_end).norm() > 1e-6) {
    char b[200];
    std::snprintf(b, sizeof b, "the program starts at (%.3f, %.3f, %.3f) mm, not where the queue ends (%.3f, %.3f, %.3f) mm",
                  job.queue->start().x() * 1e3, job.queue->start().y() * 1e3, job.queue->start().z() * 1e3,
                  queue_end.x() * 1e3, queue_end.y() * 1e3, queue_end.z() * 1e3);
    return PathAnswer{false, ack_t::REASON_NOT_CONTINUOUS, b};
  }
  job.model.emplace(model);  // a copy: a load_model meanwhile frees nothing the worker uses
  {
    const std::lock_guard<std::mutex> lock(mu_);
    job_ = std::move(job);
    working_ = true;
  }
  cv_.notify_all();
  return std::nullopt;
}

bool PathService::busy() const {
  const std::lock_guard<std::mutex> lock(mu_);
  return working_;
}

std::vector<PlannedPath> PathService::finished() {
  const std::lock_guard<std::mutex> lock(mu_);
  std::vector<PlannedPath> out;
  out.swap(done_);
  return out;
}

void PathService::sent(std::int64_t id, const path::Plan* plan) { sent_[id] = plan; }

void PathService::answered(std::int64_t id, bool accepted) {
  const auto it = sent_.find(id);
  if (it == sent_.end()) return;
  if (!accepted) release(it->second);
  sent_.erase(it);
}

void PathService::release(const path::Plan* plan) {
  std::unique_ptr<path::Plan> freed;  // freed outside the lock
  const std::lock_guard<std::mutex> lock(mu_);
  if (const auto it = plans_.find(plan); it != plans_.end()) {
    freed = std::move(it->second);
    plans_.erase(it);
  }
}

std::size_t PathService::plans() const {
  const std::lock_guard<std::mutex> lock(mu_);
  return plans_.size();
}

void PathService::work() {
  std::unique_lock<std::mutex> lock(mu_);
  for (;;) {
    cv_.wait(lock, [this] { return stop_ || job_; });
    if (!job_) return;  // stopping, nothing left to plan
    const Job job = std::move(*job_);
    job_.reset();
    lock.unlock();
    PlannedPath done = plan(job);
    lock.lock();
    done_.push_back(std::move(done));
    working_ = false;
  }
}

PlannedPath PathService::plan(const Job& job) {
  PlannedPath out;
  out.id = job.id;
  const path::PathQueue& q = *job.queue;
  const auto refuse = [&](std::int16_t reason, std::string why) {
    out.answer = PathAnswer{false, reason, std::move(why)};
    return out;
  };
  char b[320];
  const double least = program_duration_bound(q, limits_.velocity);
  if (!(least <= kMaxProgramDuration)) {
    std::snprintf(b, sizeof b, "the program takes at least %.0f s at its feeds, more than the %.0f s cpmd plans at once",
                  least, kMaxProgramDuration);
    return refuse(ack_t::REASON_LIMIT, b);
  }
  try {
    const ctl::Machine machine(*job.model);
    path::MachineLimits limits;
    limits.velocity = limits_.velocity;
    limits.acceleration = limits_.acceleration;
    limits.force = limits_.force;
    limits.soft = path::SoftLimits{limits_.workspace_min, limits_.workspace_max};
    auto plan = std::make_unique<path::Plan>(path::plan_path(q, machine, path::planner_options(limits, machine)));
    // The planner bounds the actuators, not |a|: corners may exceed
    // limits.acceleration by design; its own check is what counts.
    if (!plan->summary().actuators_within_limits)
      return refuse(ack_t::REASON_LIMIT, "the plan does not keep every actuator within its limits");
    if (const auto f = path::check_plan(*plan, machine, limits.soft)) {
      std::snprintf(b, sizeof b, "line %d: the planned path passes (%.3f, %.3f, %.3f) mm at t = %.3f s: %s", f->line,
                    f->p.x() * 1e3, f->p.y() * 1e3, f->p.z() * 1e3, f->t, f->why.c_str());
      return refuse(ack_t::REASON_WORKSPACE, b);
    }
    out.start = q.start();
    out.end = q.end();
    out.plan = plan.get();
    out.answer = PathAnswer{true, 0, ""};
    const std::lock_guard<std::mutex> lock(mu_);
    plans_.emplace(out.plan, std::move(plan));
  } catch (const std::exception& e) {
    const std::string m = e.what();
    return refuse(m.find("workspace") != std::string::npos ? ack_t::REASON_WORKSPACE : ack_t::REASON_LIMIT,
                  "no plan: " + m);
  }
  return out;
}

}  // namespace cpm::daemon

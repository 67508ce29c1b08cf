// SPDX-License-Identifier: Apache-2.0
// The server's path-queue hooks (server.hpp): a program's chunks are
// authenticated and sessioned as trajectory commands are, assembled and
// planned by the PathService, and the planned program goes to the loop as
// one segment holding the plan.
#include <cpm_msgs/ack_t.hpp>

#include "cpm/daemon/path_message.hpp"
#include "cpm/daemon/server.hpp"
#include "path_service.hpp"

namespace cpm::daemon {

using cpm_msgs::ack_t;

void Server::on_path(const std::uint8_t* raw, std::size_t size, const cpm_msgs::path_command_t* m) {
  const std::shared_ptr<const OperatorTable> table = operators();
  const Operator* op = authenticate(table.get(), raw, size, m->operator_name, m->id, kPathAckSource, 0);
  if (!op) return;
  const auto refuse = [&](std::int16_t reason, const std::string& why) {
    publish_ack(m->id, kPathAckSource, 0, false, reason, why, loop_.mode(), latest_.queue_depth);
  };
  if (op->role < Role::operator_) {
    ++counts_.refused_role;
    return refuse(ack_t::REASON_NOT_AUTHORIZED, "operator " + op->name + " (role " + role_name(op->role) +
                                                    ") may not move the machine: that needs role operator");
  }
  if (!admit(m->id, kPathAckSource, 0, m->session, m->seq, *op)) return;
  if (const std::string b = bad_number(*m); !b.empty())
    return refuse(ack_t::REASON_INVALID, b + " is not a finite number, zero or normal");
  if (const std::string why = not_homed(); !why.empty()) return refuse(ack_t::REASON_NOT_HOMED, why);
  if (const auto a = paths_->add(*m, models_.current().model(), queue_end_now().position))
    publish_ack(m->id, kPathAckSource, 0, a->ok, a->reason, a->message, loop_.mode(), latest_.queue_depth);
}

void Server::drain_paths() {
  const path::Plan* retired = nullptr;
  while (loop_.retired_plans().pop(retired)) paths_->release(retired);
  for (const PlannedPath& d : paths_->finished()) {
    if (!d.answer.ok) {
      publish_ack(d.id, kPathAckSource, 0, false, d.answer.reason, d.answer.message, loop_.mode(), latest_.queue_depth);
      continue;
    }
    Command& c = *scratch_;
    c = Command{};
    c.kind = CommandKind::segment;
    c.id = d.id;
    c.source = kPathAckSource;
    c.segment.start = d.start;
    c.segment.end = d.end;
    c.segment.traj = d.plan;
    if (send(c)) {
      paths_->sent(d.id, d.plan);
      inflight_segments_++;
      planned_end_ = d.end;
      planned_end_v_.setZero();  // a plan ends at rest
    } else {
      paths_->release(d.plan);
    }
  }
}

std::size_t Server::plans_held() const { return paths_->plans(); }
bool Server::planning() const { return paths_->busy(); }

}  // namespace cpm::daemon

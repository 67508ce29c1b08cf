// SPDX-License-Identifier: Apache-2.0
// SIL smoke test of the kernel CAN stack the runner provides: CAN_RAW on
// $CPM_SIL_CAN (vcan0), non-blocking sockets, error frames enabled, a frame
// from one socket to another with a kernel receive timestamp, acceptance
// filters, and an error frame delivered only to sockets that asked for it.
#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <poll.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <cstdint>
#include <cstring>
#include <optional>

#include "sil_check.hpp"

namespace {

constexpr int kPollGuardMs = 10000;  // a hang guard, not a deadline: TCG is slow

int64_t now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return int64_t{ts.tv_sec} * 1000000000 + ts.tv_nsec;
}

int open_raw(int ifindex) {
  const int s = socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
  if (s < 0) return -1;
  can_err_mask_t err_mask = CAN_ERR_MASK;
  const int on = 1;
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = ifindex;
  if (setsockopt(s, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &err_mask, sizeof err_mask) != 0 ||
      setsockopt(s, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof on) != 0 ||
      bind(s, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
    close(s);
    return -1;
  }
  return s;
}

struct Received {
  can_frame frame{};
  std::optional<int64_t> stamp_ns;
};

// Waits until s is readable (or the hang guard expires), then reads one frame.
std::optional<Received> receive(int s, int guard_ms = kPollGuardMs) {
  pollfd p{s, POLLIN, 0};
  if (poll(&p, 1, guard_ms) != 1) return std::nullopt;
  Received r;
  iovec iov{&r.frame, sizeof r.frame};
  alignas(cmsghdr) char control[CMSG_SPACE(sizeof(timespec)) * 2];
  msghdr msg{};
  msg.msg_iov = &iov;
  msg.msg_iovlen = 1;
  msg.msg_control = control;
  msg.msg_controllen = sizeof control;
  const ssize_t n = recvmsg(s, &msg, 0);
  if (n != static_cast<ssize_t>(sizeof(can_frame))) return std::nullopt;
  for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c != nullptr; c = CMSG_NXTHDR(&msg, c)) {
    if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SCM_TIMESTAMPNS) {
      timespec ts{};
      std::memcpy(&ts, CMSG_DATA(c), sizeof ts);
      r.stamp_ns = int64_t{ts.tv_sec} * 1000000000 + ts.tv_nsec;
    }
  }
  return r;
}

// True when nothing is waiting on s (the frame was not delivered to it).
bool nothing_pending(int s) {
  can_frame f{};
  return recv(s, &f, sizeof f, MSG_DONTWAIT) < 0 && (errno == EAGAIN || errno == EWOULDBLOCK);
}

bool send_frame(int s, const can_frame& f) { return write(s, &f, sizeof f) == static_cast<ssize_t>(sizeof f); }

}  // namespace

int main() {
  const char* ifname = sil::env_or("CPM_SIL_CAN", "vcan0");
  const unsigned ifindex = if_nametoindex(ifname);
  SIL_REQUIRE(ifindex != 0, std::string("no interface ") + ifname + ": " + sil::errno_text());

  const int a = open_raw(static_cast<int>(ifindex));
  SIL_REQUIRE(a >= 0, "CAN_RAW socket A on " + std::string(ifname) + ": " + sil::errno_text());
  const int b = open_raw(static_cast<int>(ifindex));
  SIL_REQUIRE(b >= 0, "CAN_RAW socket B: " + sil::errno_text());

  // 1. A standard frame from A reaches B, unchanged, with a kernel timestamp
  //    taken between the send and the receive.
  can_frame tx{};
  tx.can_id = 0x181;  // TPDO1 of node 1
  tx.len = 8;
  for (uint8_t i = 0; i < 8; ++i) tx.data[i] = static_cast<uint8_t>(0xA0 + i);
  const int64_t before = now_ns();
  SIL_REQUIRE(send_frame(a, tx), "write to A: " + sil::errno_text());
  const auto rx = receive(b);
  const int64_t after = now_ns();
  SIL_REQUIRE(rx.has_value(), "B received nothing");
  SIL_CHECK(rx->frame.can_id == tx.can_id);
  SIL_CHECK(rx->frame.len == 8);
  SIL_CHECK(std::memcmp(rx->frame.data, tx.data, 8) == 0);
  SIL_REQUIRE(rx->stamp_ns.has_value(), "no SCM_TIMESTAMPNS on the received frame");
  SIL_CHECK_MSG(*rx->stamp_ns >= before && *rx->stamp_ns <= after,
                "stamp " + std::to_string(*rx->stamp_ns) + " outside [" + std::to_string(before) + ", " +
                    std::to_string(after) + "]");
  // Without CAN_RAW_RECV_OWN_MSGS the sender does not hear itself.
  SIL_CHECK(nothing_pending(a));

  // 2. An extended (29-bit) frame keeps its flag and identifier.
  can_frame ext{};
  ext.can_id = 0x1ABCDEF0 | CAN_EFF_FLAG;
  ext.len = 2;
  ext.data[0] = 0x12;
  ext.data[1] = 0x34;
  SIL_CHECK(send_frame(a, ext));
  const auto rx_ext = receive(b);
  SIL_CHECK(rx_ext.has_value() && rx_ext->frame.can_id == ext.can_id && rx_ext->frame.len == 2);

  // 3. Acceptance filter on B: only 0x200 passes, 0x201 is dropped.
  const can_filter only_200{0x200, CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG};
  SIL_CHECK(setsockopt(b, SOL_CAN_RAW, CAN_RAW_FILTER, &only_200, sizeof only_200) == 0);
  can_frame f201{};
  f201.can_id = 0x201;
  f201.len = 1;
  can_frame f200{};
  f200.can_id = 0x200;
  f200.len = 1;
  f200.data[0] = 0x5A;
  SIL_CHECK(send_frame(a, f201));
  SIL_CHECK(send_frame(a, f200));
  const auto rx_f = receive(b);
  SIL_CHECK(rx_f.has_value() && rx_f->frame.can_id == 0x200 && rx_f->frame.data[0] == 0x5A);
  SIL_CHECK(nothing_pending(b));  // 0x201 was filtered out, and came first

  // 4. Error frames: a socket listening to errors only (no data filter)
  //    receives one injected on the bus; a socket with error frames off does
  //    not. On vcan the kernel delivers an error frame written by a raw
  //    socket, which is how a SIL test can play "error passive" or "bus off".
  const int c = open_raw(static_cast<int>(ifindex));
  SIL_REQUIRE(c >= 0, "CAN_RAW socket C: " + sil::errno_text());
  SIL_CHECK(setsockopt(c, SOL_CAN_RAW, CAN_RAW_FILTER, nullptr, 0) == 0);
  const int d = open_raw(static_cast<int>(ifindex));
  SIL_REQUIRE(d >= 0, "CAN_RAW socket D: " + sil::errno_text());
  const can_err_mask_t no_errors = 0;
  SIL_CHECK(setsockopt(d, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &no_errors, sizeof no_errors) == 0);
  can_frame err{};
  err.can_id = CAN_ERR_FLAG | CAN_ERR_CRTL | CAN_ERR_BUSOFF;
  err.len = CAN_ERR_DLC;
  err.data[1] = CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE;
  SIL_CHECK_MSG(send_frame(a, err), "writing an error frame: " + sil::errno_text());
  const auto rx_err = receive(c);
  SIL_CHECK(rx_err.has_value());
  if (rx_err) {
    SIL_CHECK((rx_err->frame.can_id & CAN_ERR_FLAG) != 0);
    SIL_CHECK((rx_err->frame.can_id & CAN_ERR_BUSOFF) != 0);
    SIL_CHECK(rx_err->frame.data[1] == (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE));
  }
  // D also gets a data frame, proving it is live, but never the error frame.
  SIL_CHECK(send_frame(a, f200));
  const auto rx_d = receive(d);
  SIL_CHECK(rx_d.has_value() && rx_d->frame.can_id == 0x200);
  SIL_CHECK(nothing_pending(d));

  close(a);
  close(b);
  close(c);
  close(d);
  return sil::finish("smoke_can");
}

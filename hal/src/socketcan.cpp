// SPDX-License-Identifier: Apache-2.0
#include "cpm/hal/socketcan.hpp"

#include <fcntl.h>
#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <vector>

namespace cpm::hal {

namespace {
std::string no_can_text(int err) {
  if (err == EAFNOSUPPORT)
    return "SocketCAN is not available: socket(PF_CAN, SOCK_RAW, CAN_RAW) failed with "
           "EAFNOSUPPORT (this kernel has no CAN support; load the can and can_raw modules, or "
           "run the test in the SIL VM runner)";
  return errno_text("socket(PF_CAN, SOCK_RAW, CAN_RAW)", err);
}
}  // namespace

bool SocketCanBus::available(std::string* why) {
  const int fd = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
  if (fd < 0) {
    if (why) *why = no_can_text(errno);
    return false;
  }
  ::close(fd);
  return true;
}

SocketCanBus::SocketCanBus(const std::string& interface) : interface_(interface) {
  if (interface.empty() || interface.size() >= IFNAMSIZ)
    throw Error("CAN interface name \"" + interface + "\" is empty or longer than " +
                std::to_string(IFNAMSIZ - 1) + " characters");
  fd_ = ::socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
  if (fd_ < 0) throw Error(no_can_text(errno));
  auto fail = [&](const std::string& what) {
    const int err = errno;
    ::close(fd_);
    fd_ = -1;
    throw Error(errno_text("CAN interface " + interface + ": " + what, err));
  };
  ifreq ifr{};
  std::memcpy(ifr.ifr_name, interface.c_str(), interface.size() + 1);
  if (::ioctl(fd_, SIOCGIFINDEX, &ifr) < 0) fail("no such interface (SIOCGIFINDEX)");
  const can_err_mask_t err_mask = CAN_ERR_MASK;
  if (::setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &err_mask, sizeof err_mask) < 0)
    fail("setsockopt(CAN_RAW_ERR_FILTER)");
  const int on = 1;
  if (::setsockopt(fd_, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof on) < 0) fail("setsockopt(SO_TIMESTAMPNS)");
  // The kernel then reports how many frames it dropped for want of room.
  if (::setsockopt(fd_, SOL_SOCKET, SO_RXQ_OVFL, &on, sizeof on) < 0) fail("setsockopt(SO_RXQ_OVFL)");
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = ifr.ifr_ifindex;
  if (::bind(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0) fail("bind");
}

SocketCanBus::~SocketCanBus() {
  if (fd_ >= 0) ::close(fd_);
}

Status SocketCanBus::send(const CanFrame& f) noexcept {
  can_frame cf{};
  cf.can_id = f.id;
  cf.can_dlc = f.len > 8 ? 8 : f.len;
  std::memcpy(cf.data, f.data.data(), cf.can_dlc);
  const ssize_t n = ::write(fd_, &cf, sizeof cf);
  if (n == static_cast<ssize_t>(sizeof cf)) {
    ++stats_.tx_frames;
    return {};
  }
  const int err = n < 0 ? errno : EIO;
  // ENOBUFS: the interface's transmit queue is full (the usual sign of a
  // bus with no partner or bus-off on real controllers).
  if (err == EAGAIN || err == ENOBUFS) {
    ++stats_.tx_would_block;
    return {Code::would_block, -1, err};
  }
  if (err == ENETDOWN) return {Code::bus_off, -1, err};
  return {Code::io_error, -1, err};
}

Status SocketCanBus::receive(CanFrame& f) noexcept {
  can_frame cf{};
  iovec iov{&cf, sizeof cf};
  alignas(cmsghdr) char control[CMSG_SPACE(sizeof(timespec)) + CMSG_SPACE(sizeof(std::uint32_t))];
  msghdr msg{};
  msg.msg_iov = &iov;
  msg.msg_iovlen = 1;
  msg.msg_control = control;
  msg.msg_controllen = sizeof control;
  const ssize_t n = ::recvmsg(fd_, &msg, MSG_DONTWAIT);
  if (n < 0) {
    if (errno == EAGAIN || errno == EWOULDBLOCK) return {Code::would_block, -1, 0};
    return {Code::io_error, -1, errno};
  }
  if (n != static_cast<ssize_t>(sizeof cf)) return {Code::bad_frame, -1, static_cast<std::int32_t>(n)};
  f.id = cf.can_id;
  f.len = cf.can_dlc > 8 ? 8 : cf.can_dlc;
  std::memcpy(f.data.data(), cf.data, 8);
  f.timestamp_ns = 0;
  for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c != nullptr; c = CMSG_NXTHDR(&msg, c)) {
    if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SO_TIMESTAMPNS) {
      timespec ts{};
      std::memcpy(&ts, CMSG_DATA(c), sizeof ts);
      f.timestamp_ns = std::int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
    } else if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SO_RXQ_OVFL) {
      std::uint32_t dropped = 0;
      std::memcpy(&dropped, CMSG_DATA(c), sizeof dropped);
      stats_.rx_dropped = dropped;
    }
  }
  if (f.is_error()) ++stats_.error_frames;
  else ++stats_.rx_frames;
  return {};
}

void SocketCanBus::set_filters(std::span<const CanFilter> filters, bool error_frames) {
  std::vector<can_filter> k;
  k.reserve(filters.size());
  for (const auto& fl : filters) k.push_back(can_filter{fl.id, fl.mask});
  if (k.empty()) k.push_back(can_filter{0, 0});
  if (::setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_FILTER, k.data(),
                   static_cast<socklen_t>(k.size() * sizeof(can_filter))) < 0)
    throw Error(errno_text("CAN interface " + interface_ + ": setsockopt(CAN_RAW_FILTER)", errno));
  const can_err_mask_t err_mask = error_frames ? CAN_ERR_MASK : 0;
  if (::setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &err_mask, sizeof err_mask) < 0)
    throw Error(errno_text("CAN interface " + interface_ + ": setsockopt(CAN_RAW_ERR_FILTER)", errno));
}

bool SocketCanBus::wait_receivable(std::int64_t timeout_ns) {
  pollfd p{fd_, POLLIN, 0};
  const int ms = timeout_ns <= 0 ? 0 : static_cast<int>((timeout_ns + 999'999) / 1'000'000);
  return ::poll(&p, 1, ms) > 0;
}

}  // namespace cpm::hal

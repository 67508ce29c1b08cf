// SPDX-License-Identifier: Apache-2.0
#include "cpm/sim/control_socket.hpp"

#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "cpm/hal/common.hpp"
#include "cpm/kinematics/types.hpp"

namespace cpm::sim {

bool serve_lines(int fd, std::string& buffer, bool answer, const LineHandler& handle) {
  char b[512];
  for (;;) {
    const ssize_t n = read(fd, b, sizeof b);
    if (n == 0) return false;
    if (n < 0) return errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR;
    buffer.append(b, static_cast<std::size_t>(n));
    for (std::size_t nl; (nl = buffer.find('\n')) != std::string::npos;) {
      const std::string line = buffer.substr(0, nl);
      buffer.erase(0, nl + 1);
      const std::string reply = handle(line) + "\n";
      if (answer) (void)!write(fd, reply.data(), reply.size());
    }
  }
}

ControlSocket::ControlSocket(const std::string& path) : path_(path) {
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  if (path.size() >= sizeof addr.sun_path) throw Error("--control: path too long");
  std::strcpy(addr.sun_path, path.c_str());
  unlink(path.c_str());
  listen_fd_ = socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (listen_fd_ < 0 || bind(listen_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 ||
      listen(listen_fd_, 4) != 0) {
    const int e = errno;
    if (listen_fd_ >= 0) close(listen_fd_);
    throw Error(hal::errno_text("--control " + path, e));
  }
}

ControlSocket::~ControlSocket() {
  for (auto& c : clients_) close(c.fd);
  close(listen_fd_);
  unlink(path_.c_str());
}

void ControlSocket::poll(const LineHandler& handle) {
  for (int fd; (fd = accept4(listen_fd_, nullptr, nullptr, SOCK_NONBLOCK | SOCK_CLOEXEC)) >= 0;) clients_.push_back({fd, {}});
  for (std::size_t i = 0; i < clients_.size();) {
    if (!serve_lines(clients_[i].fd, clients_[i].buffer, true, handle)) {
      close(clients_[i].fd);
      clients_.erase(clients_.begin() + static_cast<std::ptrdiff_t>(i));
    } else {
      ++i;
    }
  }
}

}  // namespace cpm::sim

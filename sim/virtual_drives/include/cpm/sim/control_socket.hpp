// SPDX-License-Identifier: Apache-2.0
// The drives' fault-injection channel: text lines from a UNIX stream socket
// (each answered with one line) or from stdin, handed to a command handler.
// Shared by virtual-drives and the CANopenNode drive nodes of the tests, so
// that a test injects faults into either the same way.
#pragma once

#include <functional>
#include <string>
#include <vector>

namespace cpm::sim {

using LineHandler = std::function<std::string(const std::string& line)>;

// Every complete line readable now from non-blocking `fd` to `handle`, its
// answer written back when `answer`. False when the fd has closed.
bool serve_lines(int fd, std::string& buffer, bool answer, const LineHandler& handle);

class ControlSocket {
 public:
  // Binds `path` (an old socket file there is removed); throws Error.
  explicit ControlSocket(const std::string& path);
  ~ControlSocket();
  ControlSocket(const ControlSocket&) = delete;
  ControlSocket& operator=(const ControlSocket&) = delete;
  // Accepts waiting clients and serves every line they sent.
  void poll(const LineHandler& handle);

 private:
  struct Client {
    int fd;
    std::string buffer;
  };
  std::string path_;
  int listen_fd_ = -1;
  std::vector<Client> clients_;
};

}  // namespace cpm::sim

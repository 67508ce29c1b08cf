// cpmd as a child process on its simulator backend, and an LCM client to it.
#pragma once

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "cpm/daemon/client.hpp"

extern char** environ;

namespace cpm::daemon::test {

extern bool g_netns;

class CpmdProcess {
 public:
  CpmdProcess(const std::string& config, const std::string& log) : log_(log) {
    const char* argv[] = {CPMD_EXE, "--config", config.c_str(), nullptr};
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 2, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int rc = posix_spawn(&pid_, CPMD_EXE, &fa, nullptr, const_cast<char**>(argv), environ);
    posix_spawn_file_actions_destroy(&fa);
    if (rc != 0) pid_ = -1;
  }
  ~CpmdProcess() { kill9(); }
  CpmdProcess(const CpmdProcess&) = delete;
  CpmdProcess& operator=(const CpmdProcess&) = delete;
  [[nodiscard]] pid_t pid() const { return pid_; }
  // SIGKILL: no handler runs, nothing is disabled by cpmd itself.
  void kill9() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
      pid_ = -1;
    }
  }
  int terminate() {
    if (pid_ <= 0) return -1;
    kill(pid_, SIGTERM);
    return wait_exit();
  }
  int wait_exit() {
    int st = 0;
    waitpid(pid_, &st, 0);
    pid_ = -1;
    return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
  }
  bool running() {
    if (pid_ <= 0) return false;
    int st = 0;
    if (waitpid(pid_, &st, WNOHANG) == pid_) {
      pid_ = -1;
      return false;
    }
    return true;
  }
  std::string log() const {
    std::ifstream f(log_);
    std::stringstream ss;
    ss << f.rdbuf();
    return ss.str();
  }

 private:
  pid_t pid_ = -1;
  std::string log_;
};

inline std::string tmp_dir(const std::string& what) {
  const auto d = std::filesystem::temp_directory_path() / ("cpm-reliab-" + what + "-" + std::to_string(getpid()));
  std::filesystem::create_directories(d);
  return d.string();
}

// config/sim.yaml with a private LCM port (host loopback), absolute model
// paths, tolerant of a noisy CI machine, and `edits` (regex -> replacement).
inline std::string sim_config(const std::string& dir, const std::string& name,
                              const std::vector<std::pair<std::string, std::string>>& edits = {}) {
  std::ifstream f(std::string(CPM_SOURCE_DIR) + "/config/sim.yaml");
  std::stringstream ss;
  ss << f.rdbuf();
  std::string text = ss.str();
  const int port = g_netns ? 7667 : 20000 + getpid() % 20000;
  text = std::regex_replace(text, std::regex("udpm://239.255.76.67:7667"), "udpm://239.255.76.67:" + std::to_string(port));
  text = std::regex_replace(text, std::regex(" machine\\.yaml"), std::string(" ") + CPM_SOURCE_DIR + "/config/machine.yaml");
  text = std::regex_replace(text, std::regex("max_consecutive_overruns: 5"), "max_consecutive_overruns: 100000");
  for (const auto& [from, to] : edits) text = std::regex_replace(text, std::regex(from), to);
  const std::string path = dir + "/" + name;
  std::ofstream(path) << text;
  return path;
}

inline Vec3 vec(const double* v) { return Vec3(v[0], v[1], v[2]); }

}  // namespace cpm::daemon::test

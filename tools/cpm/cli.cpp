#include "cli.hpp"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

#include <fcntl.h>
#include <unistd.h>

namespace cpm::cli {

std::map<std::string, CommandEntry>& registry() {
  static std::map<std::string, CommandEntry> r;
  return r;
}

Command::Command(const char* name, const char* summary, Run run, const char* usage) {
  registry()[name] = {summary, std::move(run), usage};
}

Args::Args(std::string command, std::vector<std::string> argv)
    : command_(std::move(command)), argv_(std::move(argv)), used_(argv_.size(), false) {}

bool Args::flag(const std::string& name) {
  const std::string key = "--" + name;
  bool found = false;
  for (std::size_t i = 0; i < argv_.size(); ++i)
    if (!used_[i] && argv_[i] == key) used_[i] = found = true;
  return found;
}

std::optional<std::string> Args::option(const std::string& name) {
  std::vector<std::string> all = options(name);
  if (all.size() > 1) throw UsageError("option --" + name + " given more than once");
  if (all.empty()) return std::nullopt;
  return all.front();
}

std::vector<std::string> Args::options(const std::string& name) {
  const std::string key = "--" + name;
  std::vector<std::string> values;
  for (std::size_t i = 0; i < argv_.size(); ++i) {
    if (used_[i]) continue;
    if (argv_[i] == key) {
      if (i + 1 >= argv_.size()) throw UsageError("option " + key + " needs a value");
      used_[i] = used_[i + 1] = true;
      values.push_back(argv_[i + 1]);
      ++i;
    } else if (argv_[i].rfind(key + "=", 0) == 0) {
      used_[i] = true;
      values.push_back(argv_[i].substr(key.size() + 1));
    }
  }
  return values;
}

std::string Args::option_or(const std::string& name, const std::string& fallback) {
  return option(name).value_or(fallback);
}

double Args::number(const std::string& name, double fallback) {
  const auto v = option(name);
  if (!v) return fallback;
  char* end = nullptr;
  const double x = std::strtod(v->c_str(), &end);
  if (v->empty() || *end != '\0' || !std::isfinite(x))
    throw UsageError("option --" + name + ": '" + *v + "' is not a finite number");
  return x;
}

long Args::integer(const std::string& name, long fallback) {
  const auto v = option(name);
  if (!v) return fallback;
  char* end = nullptr;
  const long x = std::strtol(v->c_str(), &end, 10);
  if (v->empty() || *end != '\0') throw UsageError("option --" + name + ": '" + *v + "' is not an integer");
  return x;
}

std::vector<std::string> Args::positionals() {
  std::vector<std::string> out;
  for (std::size_t i = 0; i < argv_.size(); ++i)
    if (!used_[i] && argv_[i].rfind("--", 0) != 0) {
      used_[i] = true;
      out.push_back(argv_[i]);
    }
  return out;
}

void Args::finish() {
  for (std::size_t i = 0; i < argv_.size(); ++i)
    if (!used_[i]) throw UsageError("unknown option or argument '" + argv_[i] + "'");
}

std::string json_number(double v) {
  if (!std::isfinite(v)) return "null";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

void write_file_atomically(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw std::runtime_error("cannot write " + tmp);
  std::size_t off = 0;
  while (off < text.size()) {
    const ssize_t n = ::write(fd, text.data() + off, text.size() - off);
    if (n <= 0) {
      ::close(fd);
      ::unlink(tmp.c_str());
      throw std::runtime_error("write to " + tmp + " failed (disk full?)");
    }
    off += static_cast<std::size_t>(n);
  }
  if (::fsync(fd) != 0 || ::close(fd) != 0) {
    ::unlink(tmp.c_str());
    throw std::runtime_error("cannot flush " + tmp);
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    ::unlink(tmp.c_str());
    throw std::runtime_error("cannot rename " + tmp + " to " + path);
  }
}

}  // namespace cpm::cli

#include "cli.hpp"

#include <cmath>
#include <filesystem>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "cpm/io/model_file.hpp"

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
  io::write_file_atomically(path, text);
}

void record_fit(io::ModelFile& mf, const std::vector<io::FittedParameter>& fitted, const std::string& tool,
                const std::string& data_path, const std::string& note) {
  for (const auto& p : fitted) {
    std::erase_if(mf.fitted, [&](const io::FittedParameter& q) { return q.name == p.name; });
    mf.fitted.push_back(p);
  }
  mf.history.push_back({tool, data_path, io::sha256_file(data_path), io::utc_now_iso8601(), note});
}

std::string default_model_path() {
  namespace fs = std::filesystem;
  const fs::path published = "config/machine.yaml";
  std::error_code ec;
  if (fs::exists(published, ec)) return published.string();
  const fs::path exe_dir = fs::read_symlink("/proc/self/exe", ec).parent_path();
  if (!ec) {
    for (const fs::path& candidate :
         {exe_dir / ".." / ".." / published, exe_dir / ".." / "etc" / "cpmd" / "machine.yaml"})
      if (fs::exists(candidate, ec)) return fs::weakly_canonical(candidate, ec).string();
  }
  if (fs::exists("/etc/cpmd/machine.yaml", ec)) return "/etc/cpmd/machine.yaml";
  return published.string();
}

Vec3 parse_point(const std::string& what, const std::string& text, bool allow_non_finite) {
  Vec3 v;
  std::istringstream is(text);
  std::string part;
  int n = 0;
  while (std::getline(is, part, ',')) {
    char* end = nullptr;
    const double x = std::strtod(part.c_str(), &end);
    if (n >= 3 || part.empty() || *end != '\0' || (!allow_non_finite && !std::isfinite(x)))
      throw UsageError(what + ": expected three finite numbers x,y,z in metres, got '" + text + "'");
    v[n++] = x;
  }
  if (n != 3) throw UsageError(what + ": expected three numbers x,y,z in metres, got '" + text + "'");
  return v;
}

}  // namespace cpm::cli

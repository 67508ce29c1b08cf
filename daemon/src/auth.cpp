// SPDX-License-Identifier: Apache-2.0
#include "cpm/daemon/auth.hpp"

#include <dirent.h>
#include <fcntl.h>
#include <pwd.h>
#include <sys/inotify.h>
#include <sys/stat.h>
#include <unistd.h>

#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>
#include <openssl/rand.h>
#include <yaml-cpp/yaml.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include <cpm_msgs/control_command_t.hpp>

namespace cpm::daemon {

namespace {

// A key file is 64 hex digits and a newline; anything much bigger is not one.
constexpr off_t kMaxKeyFileBytes = 256;
constexpr off_t kMaxRolesFileBytes = 64 * 1024;

struct Fd {
  int fd = -1;
  explicit Fd(int f) : fd(f) {}
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
};

std::string octal_mode(mode_t m) {
  char b[8];
  std::snprintf(b, sizeof b, "%04o", static_cast<unsigned>(m & 07777));
  return b;
}

std::string read_fd(int fd, off_t limit, const std::string& where) {
  std::string text;
  char buf[4096];
  for (;;) {
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw Error(where + ": cannot read: " + std::strerror(errno));
    }
    if (n == 0) break;
    text.append(buf, static_cast<std::size_t>(n));
    if (static_cast<off_t>(text.size()) > limit) throw Error(where + ": bigger than " + std::to_string(limit) + " bytes");
  }
  return text;
}

// Open `name` beneath `dirfd` (or a path when dirfd is AT_FDCWD) as a
// secret: no symlink, a regular file, this user's, nobody else's.
Key read_key_at(int dirfd, const std::string& name, const std::string& where) {
  Fd f(::openat(dirfd, name.c_str(), O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC | O_NOCTTY));
  if (f.fd < 0) {
    if (errno == ELOOP) throw Error(where + ": is a symbolic link: a key file must be the file itself");
    throw Error(where + ": cannot open the key file: " + std::strerror(errno));
  }
  struct stat st {};
  if (::fstat(f.fd, &st) != 0) throw Error(where + ": cannot stat: " + std::strerror(errno));
  if (!S_ISREG(st.st_mode)) throw Error(where + ": not a regular file");
  if (st.st_uid != ::geteuid())
    throw Error(where + ": owned by uid " + std::to_string(st.st_uid) + ", not by the user reading it (uid " +
                std::to_string(::geteuid()) + "): a key file must belong to its reader (chown)");
  if (st.st_mode & 077)
    throw Error(where + ": permissions " + octal_mode(st.st_mode) +
                " are too open: a key file must be readable by its owner only (chmod 600 " + where + ")");
  if (st.st_size > kMaxKeyFileBytes) throw Error(where + ": too big for a key file (" + std::to_string(st.st_size) + " bytes)");
  return parse_key(read_fd(f.fd, kMaxKeyFileBytes, where), where);
}

int hex_digit(char c) noexcept {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

bool is_space(char c) noexcept { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; }

// A directory trusted with keys: a directory, owned by root or this user,
// writable by nobody else (else anyone could plant a key).
void check_trusted_dir(const struct stat& st, const std::string& dir) {
  if (!S_ISDIR(st.st_mode)) throw Error(dir + ": not a directory");
  if (st.st_uid != 0 && st.st_uid != ::geteuid())
    throw Error(dir + ": owned by uid " + std::to_string(st.st_uid) +
                ", neither root nor the user reading it: its keys cannot be trusted");
  if (st.st_mode & 022)
    throw Error(dir + ": permissions " + octal_mode(st.st_mode) +
                " let group or others write in it: its keys cannot be trusted (chmod go-w " + dir + ")");
}

}  // namespace

const char* role_name(Role r) noexcept {
  switch (r) {
    case Role::observer: return "observer";
    case Role::operator_: return "operator";
    case Role::engineer: return "engineer";
  }
  return "?";
}

std::optional<Role> role_from_name(std::string_view s) noexcept {
  if (s == "observer") return Role::observer;
  if (s == "operator") return Role::operator_;
  if (s == "engineer") return Role::engineer;
  return std::nullopt;
}

std::optional<Role> role_needed(std::int8_t command) noexcept {
  using C = cpm_msgs::control_command_t;
  switch (command) {
    case C::CMD_STOP: return std::nullopt;
    case C::CMD_SELECT_CONTROLLER:
    case C::CMD_LOAD_MODEL:
    case C::CMD_SET_PARAM: return Role::engineer;
    default: return Role::operator_;  // unknown commands too: refused later, but never for free
  }
}

bool valid_operator_name(std::string_view name) noexcept {
  if (name.empty() || name.size() >= kOperatorNameBytes) return false;
  if (name.front() == '.' || name.front() == '-') return false;
  for (char c : name)
    if (!((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '.' ||
          c == '-'))
      return false;
  return true;
}

Key parse_key(std::string_view bytes, const std::string& where) {
  Key k{};
  std::string_view t = bytes;
  while (!t.empty() && is_space(t.front())) t.remove_prefix(1);
  while (!t.empty() && is_space(t.back())) t.remove_suffix(1);
  bool hex = t.size() == 2 * kKeyBytes;
  for (std::size_t i = 0; hex && i < t.size(); ++i) hex = hex_digit(t[i]) >= 0;
  if (hex) {
    for (std::size_t i = 0; i < kKeyBytes; ++i)
      k[i] = static_cast<std::uint8_t>(hex_digit(t[2 * i]) * 16 + hex_digit(t[2 * i + 1]));
  } else if (bytes.size() == kKeyBytes) {
    std::memcpy(k.data(), bytes.data(), kKeyBytes);
  } else {
    throw Error(where + ": not a key: expected 64 hexadecimal digits or 32 raw bytes (cpm keygen FILE makes one)");
  }
  bool zero = true;
  for (auto b : k) zero = zero && b == 0;
  if (zero) throw Error(where + ": the key is all zeros");
  return k;
}

std::string key_to_hex(const Key& k) {
  static const char* hex = "0123456789abcdef";
  std::string s(2 * kKeyBytes, '0');
  for (std::size_t i = 0; i < kKeyBytes; ++i) {
    s[2 * i] = hex[k[i] >> 4];
    s[2 * i + 1] = hex[k[i] & 15];
  }
  return s;
}

Key generate_key() {
  Key k{};
  if (RAND_bytes(k.data(), static_cast<int>(k.size())) != 1) throw Error("cannot make a key: OpenSSL's RAND_bytes failed");
  return k;
}

Key read_key_file(const std::string& path) { return read_key_at(AT_FDCWD, path, path); }

void write_key_file(const std::string& path, const Key& k) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0600);
  if (fd < 0) {
    if (errno == EEXIST) throw Error(path + ": exists already; a key file is never overwritten (remove it first)");
    throw Error(path + ": cannot create: " + std::strerror(errno));
  }
  const std::string text = key_to_hex(k) + "\n";
  const bool ok = ::fchmod(fd, 0600) == 0 && ::write(fd, text.data(), text.size()) == static_cast<ssize_t>(text.size()) &&
                  ::fsync(fd) == 0;
  const int e = errno;
  ::close(fd);
  if (!ok) {
    ::unlink(path.c_str());
    throw Error(path + ": cannot write the key: " + std::strerror(e));
  }
}

std::optional<Credentials> find_credentials(const std::optional<std::string>& key_file,
                                            const std::optional<std::string>& name) {
  std::string path;
  if (key_file) {
    path = *key_file;
  } else if (const char* env = std::getenv("CPM_KEY_FILE"); env && *env) {
    path = env;
  } else {
    const char* home = std::getenv("HOME");
    if (!home || !*home) return std::nullopt;
    path = std::string(home) + "/.config/cpm/operator.key";
    struct stat st {};
    if (::lstat(path.c_str(), &st) != 0) return std::nullopt;
  }
  Credentials c;
  c.key = read_key_file(path);
  if (name) {
    c.name = *name;
  } else if (const char* env = std::getenv("CPM_OPERATOR"); env && *env) {
    c.name = env;
  } else {
    std::string stem = path.substr(path.find_last_of('/') == std::string::npos ? 0 : path.find_last_of('/') + 1);
    if (stem.size() > 4 && stem.compare(stem.size() - 4, 4, ".key") == 0) stem.resize(stem.size() - 4);
    if (stem != "operator" && valid_operator_name(stem)) {
      c.name = stem;
    } else if (const passwd* pw = ::getpwuid(::geteuid()); pw && pw->pw_name) {
      c.name = pw->pw_name;
    }
  }
  if (!valid_operator_name(c.name))
    throw Error("operator name '" + c.name.substr(0, 40) +
                "' is not valid: 1 to 31 of A-Z a-z 0-9 _ . - (give --operator NAME or set CPM_OPERATOR)");
  return c;
}

Mac hmac_sha256(const Key& key, const void* data, std::size_t size) {
  Mac m{};
  unsigned int len = 0;
  if (!HMAC(EVP_sha256(), key.data(), static_cast<int>(key.size()), static_cast<const unsigned char*>(data), size,
            m.data(), &len) ||
      len != kMacBytes)
    m.fill(0);  // matches no honest MAC (an HMAC of all zeros is 2^-256 likely)
  return m;
}

bool is_acquire(const std::uint8_t* data, std::size_t size) {
  // The type's hash (8 bytes), utime, id, session, seq (8 each), then command.
  constexpr std::size_t kCommandAt = 40;
  if (size <= kCommandAt) return false;
  std::uint64_t hash = 0;
  for (std::size_t i = 0; i < 8; ++i) hash = (hash << 8) | data[i];
  return hash == static_cast<std::uint64_t>(cpm_msgs::control_command_t::getHash()) &&
         static_cast<std::int8_t>(data[kCommandAt]) == cpm_msgs::control_command_t::CMD_ACQUIRE;
}

namespace {
// The MAC of an encoded command (without its last kMacBytes), an acquire's
// with its boot id before it.
Mac command_mac(const std::uint8_t* data, std::size_t size, const Key& key, std::int64_t boot) {
  if (!is_acquire(data, size)) return hmac_sha256(key, data, size - kMacBytes);
  std::vector<std::uint8_t> b(8 + size - kMacBytes);
  for (int i = 0; i < 8; ++i) b[static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(static_cast<std::uint64_t>(boot) >> (56 - 8 * i));
  std::memcpy(b.data() + 8, data, size - kMacBytes);
  return hmac_sha256(key, b.data(), b.size());
}
}  // namespace

void sign_encoded(std::uint8_t* data, std::size_t size, const Key& key, std::int64_t boot) {
  if (size < kMacBytes) return;
  const Mac m = command_mac(data, size, key, boot);
  std::memcpy(data + size - kMacBytes, m.data(), kMacBytes);
}

bool verify_encoded(const std::uint8_t* data, std::size_t size, const Key& key, std::int64_t boot) {
  if (size < kMacBytes) return false;
  const Mac m = command_mac(data, size, key, boot);
  bool zero = true;
  for (auto b : m) zero = zero && b == 0;
  return !zero && CRYPTO_memcmp(m.data(), data + size - kMacBytes, kMacBytes) == 0;
}

void set_operator_name(std::uint8_t (&field)[kOperatorNameBytes], std::string_view name) {
  std::memset(field, 0, kOperatorNameBytes);
  std::memcpy(field, name.data(), std::min(name.size(), kOperatorNameBytes - 1));
}

std::string operator_name_of(const std::uint8_t (&field)[kOperatorNameBytes]) {
  const void* nul = std::memchr(field, 0, kOperatorNameBytes);
  if (!nul) return {};
  std::string s(reinterpret_cast<const char*>(field), static_cast<const std::uint8_t*>(nul) - field);
  return valid_operator_name(s) ? s : std::string();
}

std::string OperatorTable::who_may_command() const {
  std::size_t engineers = 0, operators_ = 0, observers = 0;
  for (const auto& [name, op] : operators) {
    if (op.role == Role::engineer) ++engineers;
    else if (op.role == Role::operator_) ++operators_;
    else ++observers;
  }
  std::string s = std::to_string(engineers + operators_) + " operators may command (" + std::to_string(engineers) +
                  " engineer" + (engineers == 1 ? "" : "s") + ", " + std::to_string(operators_) + " operator" +
                  (operators_ == 1 ? "" : "s") + ")";
  if (observers) s += "; " + std::to_string(observers) + (observers == 1 ? " observer reads" : " observers read") + " only";
  return s;
}

const Operator* OperatorTable::find(std::string_view name) const {
  const auto it = operators.find(name);
  return it == operators.end() ? nullptr : &it->second;
}

std::map<std::string, Role> parse_roles(const std::string& text, const std::string& where,
                                       std::vector<std::string>& problems) {
  std::map<std::string, Role> roles;
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw Error(where + ":" + std::to_string(e.mark.line + 1) + ": not valid YAML: " + e.msg);
  }
  if (!root || root.IsNull() || (root.IsScalar() && root.Scalar().empty())) return roles;
  if (!root.IsMap()) throw Error(where + ": expected lines of 'NAME: ROLE'");
  for (const auto& kv : root) {
    const std::string at = where + ":" + std::to_string(kv.first.Mark().line + 1);
    if (!kv.first.IsScalar() || !valid_operator_name(kv.first.Scalar())) {
      problems.push_back(at + ": not a valid operator name (1 to 31 of A-Z a-z 0-9 _ . -)");
      continue;
    }
    const auto role = kv.second.IsScalar() ? role_from_name(kv.second.Scalar()) : std::nullopt;
    if (!role) {
      problems.push_back(at + ": " + kv.first.Scalar() + ": the role must be observer, operator or engineer");
      continue;
    }
    if (!roles.emplace(kv.first.Scalar(), *role).second) {
      problems.push_back(at + ": " + kv.first.Scalar() + " is given twice: neither role is taken");
      roles.erase(kv.first.Scalar());
    }
  }
  return roles;
}

std::shared_ptr<const OperatorTable> load_operators(const std::string& dir) {
  auto t = std::make_shared<OperatorTable>();
  t->dir = dir;
  Fd d(::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
  if (d.fd < 0) throw Error(dir + ": cannot open the operators directory: " + std::strerror(errno));
  struct stat st {};
  if (::fstat(d.fd, &st) != 0) throw Error(dir + ": cannot stat: " + std::strerror(errno));
  check_trusted_dir(st, dir);

  // roles.yaml: authorization, not a secret; it must not be writable by others.
  std::map<std::string, Role> roles;
  {
    const std::string where = dir + "/roles.yaml";
    Fd r(::openat(d.fd, "roles.yaml", O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC | O_NOCTTY));
    if (r.fd < 0) throw Error(where + ": cannot open: " + std::strerror(errno) + " (it gives each operator's role)");
    struct stat rs {};
    if (::fstat(r.fd, &rs) != 0 || !S_ISREG(rs.st_mode)) throw Error(where + ": not a regular file");
    if (rs.st_uid != 0 && rs.st_uid != ::geteuid())
      throw Error(where + ": owned by uid " + std::to_string(rs.st_uid) + ", neither root nor the user reading it");
    if (rs.st_mode & 022)
      throw Error(where + ": permissions " + octal_mode(rs.st_mode) + " let group or others change roles (chmod go-w)");
    roles = parse_roles(read_fd(r.fd, kMaxRolesFileBytes, where), where, t->problems);
  }

  std::unique_ptr<DIR, int (*)(DIR*)> ls(::fdopendir(::dup(d.fd)), ::closedir);
  if (!ls) throw Error(dir + ": cannot list: " + std::strerror(errno));
  while (const dirent* e = ::readdir(ls.get())) {
    const std::string file = e->d_name;
    if (file.size() <= 4 || file.compare(file.size() - 4, 4, ".key") != 0) continue;
    const std::string name = file.substr(0, file.size() - 4);
    const std::string where = dir + "/" + file;
    if (!valid_operator_name(name)) {
      t->problems.push_back(where + ": not a valid operator name (1 to 31 of A-Z a-z 0-9 _ . -)");
      continue;
    }
    const auto role = roles.find(name);
    if (role == roles.end()) {
      t->problems.push_back(where + ": no role for " + name + " in roles.yaml: not loaded");
      continue;
    }
    try {
      Operator op;
      op.name = name;
      op.role = role->second;
      op.key = read_key_at(d.fd, file, where);
      t->operators.emplace(name, op);
    } catch (const Error& err) {
      t->problems.push_back(std::string(err.what()) + ": not loaded");
    }
  }
  for (const auto& [name, role] : roles)
    if (!t->operators.count(name) && role != Role::observer) {
      bool noted = false;
      for (const auto& p : t->problems) noted = noted || p.find("/" + name + ".key") != std::string::npos;
      if (!noted) t->problems.push_back(dir + "/roles.yaml: " + name + " has a role but no key file " + name + ".key");
    }
  return t;
}

OperatorsWatch::OperatorsWatch(std::string dir) : dir_(std::move(dir)) {
  fd_ = ::inotify_init1(IN_NONBLOCK | IN_CLOEXEC);
  rearm();
}

OperatorsWatch::~OperatorsWatch() {
  if (fd_ >= 0) ::close(fd_);
}

void OperatorsWatch::rearm() {
  if (fd_ < 0 || wd_ >= 0) return;
  wd_ = ::inotify_add_watch(fd_, dir_.c_str(),
                            IN_CLOSE_WRITE | IN_MOVED_TO | IN_MOVED_FROM | IN_CREATE | IN_DELETE | IN_ATTRIB |
                                IN_DELETE_SELF | IN_MOVE_SELF | IN_ONLYDIR);
}

bool OperatorsWatch::changed() {
  if (fd_ < 0) return false;
  bool any = false;
  alignas(inotify_event) char buf[4096];
  for (;;) {
    const ssize_t n = ::read(fd_, buf, sizeof buf);
    if (n <= 0) break;
    any = true;
    for (ssize_t off = 0; off < n;) {
      const auto* ev = reinterpret_cast<const inotify_event*>(buf + off);
      if (ev->mask & (IN_IGNORED | IN_DELETE_SELF | IN_MOVE_SELF)) wd_ = -1;  // the directory went: watch again later
      off += static_cast<ssize_t>(sizeof(inotify_event) + ev->len);
    }
  }
  return any;
}

}  // namespace cpm::daemon

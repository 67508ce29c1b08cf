// SPDX-License-Identifier: Apache-2.0
// Atomic writes, file hashes and timestamps for the io module.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <openssl/evp.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <memory>

#include "cpm/io/model_file.hpp"
#include "util.hpp"

namespace cpm::io {
namespace {

std::string errno_text(int e) { return std::strerror(e); }

// Owns a descriptor; closes it on every path out.
struct Fd {
  int fd = -1;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

}  // namespace

namespace detail {

std::string read_whole_file(const std::string& path) {
  Fd f{::open(path.c_str(), O_RDONLY | O_CLOEXEC)};
  if (f.fd < 0) throw Error(path + ": cannot read: " + errno_text(errno));
  struct stat st {};
  if (::fstat(f.fd, &st) != 0) throw Error(path + ": cannot read: " + errno_text(errno));
  if (S_ISDIR(st.st_mode)) throw Error(path + ": cannot read: it is a directory");
  std::string text;
  if (S_ISREG(st.st_mode)) text.reserve(static_cast<std::size_t>(st.st_size));
  char buf[1 << 16];
  for (;;) {
    const ssize_t n = ::read(f.fd, buf, sizeof buf);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw Error(path + ": cannot read: " + errno_text(errno));
    }
    if (n == 0) break;
    text.append(buf, static_cast<std::size_t>(n));
  }
  return text;
}

}  // namespace detail

void write_file_atomically(const std::string& path, const std::string& text) {
  namespace fs = std::filesystem;
  if (path.empty()) throw Error("write: empty file name");
  const fs::path target(path);
  const fs::path dir = target.has_parent_path() ? target.parent_path() : fs::path(".");
  // The temporary file lives beside the target so that rename() is atomic
  // (same file system) and a crash leaves either the old or the new file.
  std::string leaf = ".";  // hidden, and named after the target so a stray one is recognisable
  leaf.append(target.filename().string()).append(".tmp.XXXXXX");
  std::string tmpl = (dir / leaf).string();
  Fd f{::mkstemp(tmpl.data())};
  if (f.fd < 0) throw Error(path + ": cannot create a temporary file in " + dir.string() + ": " +
                            errno_text(errno));
  const std::string tmp = tmpl;
  auto fail = [&](const std::string& what, int e) {
    ::unlink(tmp.c_str());
    throw Error(path + ": " + what + ": " + errno_text(e) + " (the old file, if any, is unchanged)");
  };
  // Keep the old file's permissions; a new file gets the usual 0644.
  struct stat st {};
  const mode_t mode = (::stat(path.c_str(), &st) == 0 && S_ISREG(st.st_mode)) ? (st.st_mode & 07777) : 0644;
  if (::fchmod(f.fd, mode) != 0) fail("cannot set the permissions of " + tmp, errno);
  std::size_t off = 0;
  while (off < text.size()) {
    const ssize_t n = ::write(f.fd, text.data() + off, text.size() - off);
    if (n < 0) {
      if (errno == EINTR) continue;
      fail("cannot write " + tmp, errno);
    }
    if (n == 0) fail("cannot write " + tmp, EIO);
    off += static_cast<std::size_t>(n);
  }
  if (::fsync(f.fd) != 0) fail("cannot flush " + tmp, errno);
  const int fd = f.fd;
  f.fd = -1;
  if (::close(fd) != 0) fail("cannot close " + tmp, errno);
  if (::rename(tmp.c_str(), path.c_str()) != 0) fail("cannot rename " + tmp + " to " + path, errno);
  // Make the rename itself durable.
  Fd d{::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC)};
  if (d.fd >= 0) ::fsync(d.fd);
}

std::string sha256_file(const std::string& path) {
  // Streamed, so that a large log is hashed without holding it in memory.
  Fd f{::open(path.c_str(), O_RDONLY | O_CLOEXEC)};
  if (f.fd < 0) throw Error(path + ": cannot read: " + errno_text(errno));
  std::unique_ptr<EVP_MD_CTX, decltype(&EVP_MD_CTX_free)> ctx(EVP_MD_CTX_new(), EVP_MD_CTX_free);
  if (!ctx || EVP_DigestInit_ex(ctx.get(), EVP_sha256(), nullptr) != 1)
    throw Error(path + ": SHA-256 failed (OpenSSL)");
  char buf[1 << 16];
  for (;;) {
    const ssize_t n = ::read(f.fd, buf, sizeof buf);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw Error(path + ": cannot read: " + errno_text(errno));
    }
    if (n == 0) break;
    if (EVP_DigestUpdate(ctx.get(), buf, static_cast<std::size_t>(n)) != 1)
      throw Error(path + ": SHA-256 failed (OpenSSL)");
  }
  unsigned char md[EVP_MAX_MD_SIZE];
  unsigned int len = 0;
  if (EVP_DigestFinal_ex(ctx.get(), md, &len) != 1 || len != 32)
    throw Error(path + ": SHA-256 failed (OpenSSL)");
  static const char* hex = "0123456789abcdef";
  std::string out(64, '0');
  for (unsigned i = 0; i < 32; ++i) {
    out[2 * i] = hex[md[i] >> 4];
    out[2 * i + 1] = hex[md[i] & 15];
  }
  return out;
}

std::string utc_now_iso8601() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  ::gmtime_r(&now, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

Provenance make_provenance(const std::string& tool, const std::string& data_file,
                           const std::string& note) {
  Provenance p;
  p.tool = tool;
  p.data_file = data_file;
  if (!data_file.empty()) p.data_sha256 = sha256_file(data_file);
  p.date = utc_now_iso8601();
  p.note = note;
  return p;
}

}  // namespace cpm::io

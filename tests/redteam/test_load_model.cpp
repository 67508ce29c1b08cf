// The red team against CMD_LOAD_MODEL, in-process (cell.hpp): paths outside
// the model directory, .. and symlinks out of it, /proc, devices, FIFOs,
// directories, huge files, files that are no model. Each is refused with a
// reason that carries at most kMaxEcho bytes of the path and none of the
// file; the model in use stays. A model inside the directory loads.
#include <fcntl.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include <fstream>
#include <sstream>

#include "redteam/cell.hpp"

namespace cpm::redteam {
namespace {

std::string read(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

struct LoadModel : ::testing::Test {
  Cell c;
  std::int64_t session = 0, seq = 0;
  std::string passwd = read("/etc/passwd");
  void SetUp() override {
    session = c.acquire(c.alice);  // an engineer, the machine disabled: loading is legal
    ASSERT_NE(session, 0);
  }
  std::string in_dir(const std::string& name) const { return c.model_dir + "/" + name; }
  ack_t load(const std::string& path) { return c.control(&c.alice, C::CMD_LOAD_MODEL, session, ++seq, [&](C& m) { m.model_path = path; }); }
  // Refused, nothing of the file or more than kMaxEcho of the path said, the model unchanged.
  void expect_refused(const std::string& path, const std::string& what, const std::string& content = "") {
    const ctl::Machine* before = &c.models.current();
    const ack_t a = load(path);
    c.cycles(3);
    EXPECT_FALSE(a.accepted) << what;
    EXPECT_EQ(a.reason, ack_t::REASON_LOAD_FAILED) << what << ": " << a.message;
    EXPECT_FALSE(a.message.empty()) << what;
    expect_no_echo(a.message, path, what + " (the path)");
    expect_no_echo(a.message, passwd, what + " (/etc/passwd)");
    if (!content.empty()) expect_no_echo(a.message, content, what + " (the file)");
    EXPECT_EQ(a.message.find("root:"), std::string::npos) << a.message;
    EXPECT_EQ(&c.models.current(), before) << what << ": the model changed";
    std::printf("  %-42s -> %s\n", what.c_str(), a.message.c_str());
  }
};

TEST_F(LoadModel, PathsOutsideTheModelDirectoryAreRefused) {
  for (const std::string& p :
       {std::string("/etc/passwd"), std::string("/etc/shadow"), std::string("../../../../../../etc/passwd"),
        std::string("../../../../../../etc/passwd.yaml"), std::string("sub/../../x.yaml"),
        c.model_dir + "/../../../../../etc/passwd.yaml", std::string("/proc/self/environ"),
        std::string("/proc/self/root/etc/passwd"), std::string("/proc/self/fd/0"), std::string("/dev/zero"),
        std::string("/"), c.model_dir, c.model_dir + "/", std::string("/tmp/x.yaml")})
    expect_refused(p, p);
}

TEST_F(LoadModel, SymlinksOutOfTheDirectoryAreRefused) {
  namespace fs = std::filesystem;
  fs::create_symlink("/etc/passwd", in_dir("passwd.yaml"));
  fs::create_symlink("/proc/self/environ", in_dir("environ.yaml"));
  fs::create_symlink("/dev/zero", in_dir("zero.yaml"));
  fs::create_symlink("../../../../../../../etc/passwd", in_dir("up.yaml"));
  fs::create_directories(in_dir("sub"));
  fs::create_symlink("/etc", in_dir("sub/etc"));
  fs::create_symlink("/", in_dir("root"));
  for (const std::string p : {"passwd.yaml", "environ.yaml", "zero.yaml", "up.yaml", "sub/etc/passwd.yaml",
                               "root/etc/passwd.yaml"})
    expect_refused(p, "symlink " + p);
  expect_refused(in_dir("passwd.yaml"), "the same symlink by its absolute path");
  // A relative symlink that stays inside is followed.
  fs::copy_file(std::string(CPM_SOURCE_DIR) + "/config/machine.yaml", in_dir("machine.yaml"));
  fs::create_symlink("machine.yaml", in_dir("current.yaml"));
  const ack_t a = load("current.yaml");
  EXPECT_TRUE(a.accepted) << a.message;
}

TEST_F(LoadModel, FifosDevicesDirectoriesAndHugeFilesAreRefusedWithoutAHang) {
  ASSERT_EQ(::mkfifo(in_dir("fifo.yaml").c_str(), 0600), 0);
  std::filesystem::create_directories(in_dir("dir.yaml"));
  {
    const int fd = ::open(in_dir("huge.yaml").c_str(), O_WRONLY | O_CREAT, 0600);
    ASSERT_GE(fd, 0);
    ASSERT_EQ(::ftruncate(fd, daemon::kMaxModelFileBytes + 1), 0);  // sparse: costs no disk
    ::close(fd);
  }
  if (::geteuid() == 0) {
    ASSERT_EQ(::mknod(in_dir("null.yaml").c_str(), S_IFCHR | 0600, makedev(1, 3)), 0);
  }
  for (const std::string p : {"fifo.yaml", "dir.yaml", "huge.yaml", "null.yaml", "missing.yaml", "notes.txt",
                               "builtin:secret", ""})
    expect_refused(p, p.empty() ? "(empty path)" : p);
  // A file cpmd may not read (as root, every file is readable: skipped).
  if (::geteuid() != 0) {
    std::ofstream(in_dir("secret.yaml")) << "cpmd_model: 1\n";
    ::chmod(in_dir("secret.yaml").c_str(), 0);
    expect_refused("secret.yaml", "unreadable secret.yaml");
  }
}

TEST_F(LoadModel, HostilePathsAreNotEchoed) {
  const std::string long_path(10000, 'A');
  expect_refused(long_path + ".yaml", "a 10 kB path");
  expect_refused(std::string("a\nb\r\x1b[2J%s%n%x.yaml"), "control characters and format strings");
  expect_refused(std::string(4096, '/') + "etc/passwd", "4096 slashes then etc/passwd");
}

TEST_F(LoadModel, ErrorsNameTheLineAndTheReasonNeverTheContent) {
  // /etc/passwd copied into the model directory: read, refused as YAML/model, not quoted.
  std::ofstream(in_dir("passwd-copy.yaml")) << passwd;
  expect_refused("passwd-copy.yaml", "/etc/passwd copied inside", passwd);
  // A model whose values hide a secret: the line is named, the secret is not.
  const std::string machine = read(std::string(CPM_SOURCE_DIR) + "/config/machine.yaml");
  const std::string secret = "SECRET-TOKEN-0123456789abcdef";
  for (auto [name, from, to] : std::vector<std::tuple<std::string, std::string, std::string>>{
           {"value.yaml", "  L: 0.105 ", "  L: " + secret + " "},
           {"key.yaml", "cpmd_model: 1", "cpmd_model: 1\n" + secret + ": 1"},
           {"effect.yaml", "dynamic_effects: []", "dynamic_effects:\n  - {effect: " + secret + ", axis: 1}"},
           {"yaml.yaml", "  L: 0.105 ", "  L: [" + secret + " "}}) {
    std::string text = machine;
    const auto at = text.find(from);
    ASSERT_NE(at, std::string::npos) << from;
    text.replace(at, from.size(), to);
    std::ofstream(in_dir(name)) << text;
    const ack_t a = load(name);
    EXPECT_EQ(a.reason, ack_t::REASON_LOAD_FAILED) << name;
    EXPECT_EQ(a.message.find("SECRET"), std::string::npos) << name << ": " << a.message;
    EXPECT_NE(a.message.find("line "), std::string::npos) << name << ": " << a.message;
    expect_no_echo(a.message, text, name);
    std::printf("  %-42s -> %s\n", name.c_str(), a.message.c_str());
  }
}

TEST_F(LoadModel, AModelInsideTheDirectoryLoads) {
  std::filesystem::copy_file(std::string(CPM_SOURCE_DIR) + "/config/machine.yaml", in_dir("machine.yaml"));
  const ctl::Machine* before = &c.models.current();
  const ack_t a = load("machine.yaml");
  EXPECT_TRUE(a.accepted) << a.message;
  c.cycles(3);
  EXPECT_NE(&c.models.current(), before);
  EXPECT_TRUE(load(in_dir("machine.yaml")).accepted) << "by its absolute path beneath the directory";
  EXPECT_TRUE(load("builtin:elkady").accepted);
}

}  // namespace
}  // namespace cpm::redteam

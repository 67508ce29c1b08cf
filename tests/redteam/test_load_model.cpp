// SPDX-License-Identifier: Apache-2.0
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
    testing::internal::CaptureStderr();  // cpmd's journal
    const ack_t a = load(name);
    const std::string journal = testing::internal::GetCapturedStderr();
    EXPECT_EQ(journal.find("SECRET"), std::string::npos) << name << ": the journal quotes the file: " << journal;
    EXPECT_NE(journal.find(name), std::string::npos) << name << ": the journal does not name the file: " << journal;
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

// The largest model file allowed: the machine's model with `extra` lines
// and then a comment up to exactly kMaxModelFileBytes.
std::string largest_model(const std::string& extra = "") {
  std::string text = read(std::string(CPM_SOURCE_DIR) + "/config/machine.yaml") + extra;
  while (text.size() + 81 <= static_cast<std::size_t>(daemon::kMaxModelFileBytes))
    text += "# " + std::string(77, '-') + "\n";
  text += "#" + std::string(static_cast<std::size_t>(daemon::kMaxModelFileBytes) - text.size() - 2, '-') + "\n";
  return text;
}

TEST_F(LoadModel, RefusedUnlessDisabledBeforeTheFileIsRead) {
  std::filesystem::copy_file(std::string(CPM_SOURCE_DIR) + "/config/machine.yaml", in_dir("machine.yaml"));
  ASSERT_EQ(::mkfifo(in_dir("fifo.yaml").c_str(), 0600), 0);
  ASSERT_TRUE(c.control(&c.alice, C::CMD_ENABLE, session, ++seq).accepted);
  c.cycles(20);
  ASSERT_EQ(c.h.mode(), daemon::Mode::holding);
  const ctl::Machine* before = &c.models.current();
  // A good model, a FIFO and a missing file alike: the mode is said, not the file's fate (nothing was opened).
  for (const std::string p : {"machine.yaml", "fifo.yaml", "missing.yaml"}) {
    const ack_t a = load(p);
    EXPECT_FALSE(a.accepted) << p;
    EXPECT_EQ(a.reason, ack_t::REASON_ILLEGAL_IN_MODE) << p << ": " << a.message;
    EXPECT_NE(a.message.find("only when it is disabled"), std::string::npos) << a.message;
    EXPECT_FALSE(c.server->loading_model()) << p << ": a load was started";
  }
  EXPECT_EQ(&c.models.current(), before);
  std::printf("  while holding -> %s\n", load("machine.yaml").message.c_str());
  // Disabled again: the same file loads.
  ASSERT_TRUE(c.control(&c.alice, C::CMD_DISABLE, session, ++seq).accepted);
  c.cycles(5);
  EXPECT_TRUE(load("machine.yaml").accepted);
}

TEST_F(LoadModel, SizeNodesAndDepthAreBoundedAndARealModelFits) {
  const std::string machine = read(std::string(CPM_SOURCE_DIR) + "/config/machine.yaml");
  // Exactly the size allowed loads; one byte more is refused (before reading, from its size).
  std::ofstream(in_dir("largest.yaml")) << largest_model();
  ASSERT_EQ(std::filesystem::file_size(in_dir("largest.yaml")), static_cast<std::uintmax_t>(daemon::kMaxModelFileBytes));
  const ack_t ok = load("largest.yaml");
  EXPECT_TRUE(ok.accepted) << ok.message;
  std::ofstream(in_dir("over.yaml")) << largest_model() << "\n";
  const ack_t over = load("over.yaml");
  EXPECT_EQ(over.reason, ack_t::REASON_LOAD_FAILED);
  EXPECT_NE(over.message.find("1 MiB"), std::string::npos) << over.message;
  // Nodes: a sequence of kMaxModelNodes scalars after the model.
  std::string many = machine + "notes: [";
  for (long i = 0; i < daemon::kMaxModelNodes; ++i) many += "0,";
  many += "0]\n";
  std::ofstream(in_dir("nodes.yaml")) << many;
  const ack_t nodes = load("nodes.yaml");
  EXPECT_EQ(nodes.reason, ack_t::REASON_LOAD_FAILED);
  EXPECT_NE(nodes.message.find("more than 20000 YAML nodes"), std::string::npos) << nodes.message;
  const std::string line = "line " + std::to_string(std::count(machine.begin(), machine.end(), '\n') + 1) + ":";
  EXPECT_NE(nodes.message.find(line), std::string::npos) << nodes.message << " (expected " << line << ")";
  // Depth: 33 nested flow sequences (and 100 000: the parser never goes that deep).
  for (const int d : {daemon::kMaxModelDepth + 1, 100000}) {
    std::ofstream(in_dir("deep.yaml")) << machine << "notes: " << std::string(static_cast<std::size_t>(d), '[')
                                       << std::string(static_cast<std::size_t>(d), ']') << "\n";
    const ack_t deep = load("deep.yaml");
    EXPECT_EQ(deep.reason, ack_t::REASON_LOAD_FAILED) << d;
    EXPECT_NE(deep.message.find("nested more than 32 levels"), std::string::npos) << deep.message;
  }
  // At the depth limit the bounds pass (and the model's own schema refuses the unknown key).
  std::ofstream(in_dir("deep32.yaml")) << machine << "notes: " << std::string(daemon::kMaxModelDepth - 1, '[')
                                       << std::string(daemon::kMaxModelDepth - 1, ']') << "\n";
  const ack_t d32 = load("deep32.yaml");
  EXPECT_EQ(d32.message.find("nested"), std::string::npos) << d32.message;
  std::printf("  %-42s -> %s\n  %-42s -> %s\n", "1 MiB + 1 byte", over.message.c_str(), "20001 nodes",
              nodes.message.c_str());
}

// Stop nothing can block: the largest model file allowed is sent with a
// stop while the machine moves; the loop brakes within 2 cycles of the
// stop's arrival (the load is refused at once, unread).
TEST_F(LoadModel, AStopSentWithTheLargestModelBrakesWithinTwoCycles) {
  std::ofstream(in_dir("largest.yaml")) << largest_model();
  ASSERT_TRUE(c.control(&c.alice, C::CMD_ENABLE, session, ++seq).accepted);
  c.cycles(20);
  ASSERT_EQ(c.h.mode(), daemon::Mode::holding);
  ASSERT_TRUE(c.trajectory(&c.alice, move_to(Vec3(0.40, 0.425, 0.300)), session, ++seq).accepted);
  for (int i = 0; i < 50 && c.h.mode() != daemon::Mode::moving; ++i) c.cycles(1);
  ASSERT_EQ(c.h.mode(), daemon::Mode::moving);
  c.cycles(200);
  C load_m{};
  load_m.command = C::CMD_LOAD_MODEL;
  load_m.id = c.next_id++;
  load_m.session = session;
  load_m.seq = ++seq;
  load_m.model_path = "largest.yaml";
  C stop{};
  stop.command = C::CMD_STOP;
  stop.id = c.next_id++;
  // Both on the bus before the daemon's thread looks: the load first.
  const Bytes lb = c.sign(load_m, &c.alice);
  c.server->bus().publish(c.h.cfg.lcm.control_channel, lb.data(), static_cast<unsigned>(lb.size()));
  const Bytes sb = encode(stop);
  c.server->bus().publish(c.h.cfg.lcm.control_channel, sb.data(), static_cast<unsigned>(sb.size()));
  c.pump();  // both arrive
  int cycles = 0;
  while (c.h.mode() == daemon::Mode::moving && cycles < 100) {
    c.h.loop->cycle(c.h.k++, 0);
    ++cycles;
  }
  EXPECT_LE(cycles, 2) << "cycles from the stop's arrival to braking";
  EXPECT_EQ(c.h.mode(), daemon::Mode::stopping);
  c.cycles(3);
  const ack_t* la = c.ack_of(load_m.id);
  ASSERT_NE(la, nullptr);
  EXPECT_EQ(la->reason, ack_t::REASON_ILLEGAL_IN_MODE) << la->message;
  EXPECT_FALSE(c.server->loading_model());
  std::printf("  stop with the largest model: braking after %d cycle(s); the load: %s\n", cycles, la->message.c_str());
}

}  // namespace
}  // namespace cpm::redteam

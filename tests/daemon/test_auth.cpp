// SPDX-License-Identifier: Apache-2.0
// Keys, key files, the MAC and the operators directory (docs/security.md):
// what cpmd and cpm accept, and what they refuse with a sentence saying why.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdlib>
#include <cstring>
#include <functional>
#include <filesystem>
#include <fstream>

#include <cpm_msgs/control_command_t.hpp>

#include "cpm/daemon/auth.hpp"
#include "support/test_operators.hpp"

namespace cpm::daemon {
namespace {

namespace fs = std::filesystem;

struct Dir {
  std::string path = testing::TempDir() + "cpm-auth-" + std::to_string(::getpid()) + "-" +
                     ::testing::UnitTest::GetInstance()->current_test_info()->name();
  Dir() {
    fs::remove_all(path);
    fs::create_directories(path);
    ::chmod(path.c_str(), 0700);
  }
  ~Dir() { fs::remove_all(path); }
  std::string file(const std::string& name, const std::string& text, mode_t mode = 0600) const {
    const std::string p = path + "/" + name;
    std::ofstream(p, std::ios::binary) << text;
    ::chmod(p.c_str(), mode);
    return p;
  }
};

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

const std::string kHex = "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f";

TEST(KeyFile, HexAndRawKeysAreRead) {
  Dir d;
  Key expected{};
  for (std::size_t i = 0; i < expected.size(); ++i) expected[i] = static_cast<std::uint8_t>(i);
  EXPECT_EQ(read_key_file(d.file("hex.key", kHex + "\n")), expected);
  EXPECT_EQ(read_key_file(d.file("upper.key", "  000102030405060708090A0B0C0D0E0F101112131415161718191A1B1C1D1E1F\r\n")), expected);
  EXPECT_EQ(read_key_file(d.file("raw.key", std::string(reinterpret_cast<const char*>(expected.data()), 32))), expected);
}

TEST(KeyFile, WhatIsNoKeyIsRefused) {
  Dir d;
  for (const std::string& text : {kHex.substr(1), kHex + "0", std::string(33, 'x'), std::string(), std::string(64, '0'),
                                  std::string(32, '\0')})
    EXPECT_NE(error_of([&] { (void)read_key_file(d.file("bad.key", text)); }), "") << "'" << text << "'";
  EXPECT_NE(error_of([&] { (void)read_key_file(d.file("big.key", std::string(4096, 'a'))); }).find("too big"),
            std::string::npos);
}

TEST(KeyFile, OneOthersMayReadIsRefusedAsSshWould) {
  Dir d;
  for (mode_t mode : {0640, 0604, 0660, 0606, 0644, 0666}) {
    const std::string p = d.file("open.key", kHex, mode);
    const std::string e = error_of([&] { (void)read_key_file(p); });
    EXPECT_NE(e.find("too open"), std::string::npos) << std::oct << mode << ": " << e;
    EXPECT_NE(e.find("chmod 600"), std::string::npos) << e;
  }
  EXPECT_EQ(error_of([&] { (void)read_key_file(d.file("owner.key", kHex, 0400)); }), "");
}

TEST(KeyFile, ASymlinkADirectoryOrAnotherUsersFileIsRefused) {
  Dir d;
  const std::string real = d.file("real.key", kHex);
  fs::create_symlink(real, d.path + "/link.key");
  EXPECT_NE(error_of([&] { (void)read_key_file(d.path + "/link.key"); }).find("symbolic link"), std::string::npos);
  fs::create_directories(d.path + "/dir.key");
  EXPECT_NE(error_of([&] { (void)read_key_file(d.path + "/dir.key"); }).find("not a regular file"), std::string::npos);
  if (::geteuid() != 0) GTEST_SKIP() << "needs root to give a file to another user";
  ASSERT_EQ(::chown(real.c_str(), 65534, 65534), 0);
  EXPECT_NE(error_of([&] { (void)read_key_file(real); }).find("owned by uid 65534"), std::string::npos);
}

TEST(KeyFile, ANewKeyIsRandomPrivateAndNeverOverwritesAnother) {
  Dir d;
  const std::string p = d.path + "/new.key";
  const Key a = generate_key(), b = generate_key();
  EXPECT_NE(a, b);
  write_key_file(p, a);
  struct stat st {};
  ASSERT_EQ(::stat(p.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 07777, 0600u);
  EXPECT_EQ(read_key_file(p), a);
  EXPECT_NE(error_of([&] { write_key_file(p, b); }).find("exists already"), std::string::npos);
  EXPECT_EQ(read_key_file(p), a);
}

// The MAC is standard HMAC-SHA256, so other languages' clients can compute it
// (the reference from Python's hmac module).
TEST(Mac, IsHmacSha256) {
  Key k{};
  for (std::size_t i = 0; i < k.size(); ++i) k[i] = static_cast<std::uint8_t>(i);
  const Mac m = hmac_sha256(k, "cpmd", 4);
  std::string hex;
  for (auto b : m) {
    char c[3];
    std::snprintf(c, sizeof c, "%02x", b);
    hex += c;
  }
  EXPECT_EQ(hex, "4d59650cd9c184383752407dce14499874891854edf33acbd326f9b0c6aed7a4");
}

// An acquire is signed for one start of cpmd (its boot id): the same bytes
// do not verify for another; other commands do not depend on it.
// cpmd --check and the journal: observers are not counted among those who command.
TEST(Operators, ObserversAreNotCountedAmongThoseWhoMayCommand) {
  EXPECT_EQ(test::operator_table()->who_may_command(),
            "2 operators may command (1 engineer, 1 operator); 1 observer reads only");
  OperatorTable only_observers;
  only_observers.operators.emplace("olga", Operator{"olga", Role::observer, {}});
  EXPECT_EQ(only_observers.who_may_command(), "0 operators may command (0 engineers, 0 operators); 1 observer reads only");
}

TEST(Mac, AnAcquireIsBoundToTheBootIdOtherCommandsAreNot) {
  cpm_msgs::control_command_t m{};
  m.command = cpm_msgs::control_command_t::CMD_ACQUIRE;
  m.session = 5, m.seq = 1'800'000'000'000'000;
  const Key& key = test::credentials("alice").key;
  std::vector<std::uint8_t> b = test::encode_signed(m, test::credentials("alice"));
  ASSERT_TRUE(is_acquire(b.data(), b.size()));
  EXPECT_TRUE(verify_encoded(b.data(), b.size(), key, test::kTestBoot));
  EXPECT_FALSE(verify_encoded(b.data(), b.size(), key, test::kTestBoot + 1));
  EXPECT_FALSE(verify_encoded(b.data(), b.size(), key, 0));
  m.command = cpm_msgs::control_command_t::CMD_ENABLE;
  b = test::encode_signed(m, test::credentials("alice"));
  EXPECT_FALSE(is_acquire(b.data(), b.size()));
  EXPECT_TRUE(verify_encoded(b.data(), b.size(), key, test::kTestBoot + 1));
}

TEST(Mac, EveryByteOfASignedCommandIsCovered) {
  cpm_msgs::control_command_t m{};
  m.command = cpm_msgs::control_command_t::CMD_ENABLE;
  m.session = 42, m.seq = 7;
  m.model_path = "machine.yaml";
  std::vector<std::uint8_t> b = test::encode_signed(m, test::credentials("alice"));
  const Key& key = test::credentials("alice").key;
  ASSERT_TRUE(verify_encoded(b.data(), b.size(), key, test::kTestBoot));
  EXPECT_FALSE(verify_encoded(b.data(), b.size(), test::credentials("bob").key, test::kTestBoot));
  for (std::size_t i = 0; i < b.size(); ++i) {
    b[i] ^= 0x01;
    EXPECT_FALSE(verify_encoded(b.data(), b.size(), key, test::kTestBoot)) << "byte " << i << " is not covered";
    b[i] ^= 0x01;
  }
  EXPECT_FALSE(verify_encoded(b.data(), kMacBytes - 1, key, test::kTestBoot));
}

TEST(Operators, NamesAreFileNamesWithoutSurprises) {
  for (const char* ok : {"alice", "Bob_2", "x", "a.b-c", "abcdefghijklmnopqrstuvwxyz01234"})
    EXPECT_TRUE(valid_operator_name(ok)) << ok;
  for (const char* bad : {"", ".hidden", "-rf", "a/b", "../x", "a b", "a\n", "abcdefghijklmnopqrstuvwxyz012345", "é"})
    EXPECT_FALSE(valid_operator_name(bad)) << bad;
  std::uint8_t field[kOperatorNameBytes];
  set_operator_name(field, "alice");
  EXPECT_EQ(operator_name_of(field), "alice");
  std::memset(field, 'a', sizeof field);  // no NUL: no name
  EXPECT_EQ(operator_name_of(field), "");
}

TEST(Operators, TheDirectoryLoadsWhatIsGoodAndSaysWhatIsNot) {
  Dir d;
  d.file("alice.key", kHex);
  d.file("bob.key", kHex, 0644);          // too open
  d.file("carol.key", kHex);              // no role
  d.file("notes.txt", "not a key");       // not a .key: ignored
  d.file("roles.yaml", "alice: engineer\nbob: operator\ndave: operator\neve: admin\n../x: engineer\n", 0644);
  const auto t = load_operators(d.path);
  ASSERT_EQ(t->operators.size(), 1u);
  ASSERT_NE(t->find("alice"), nullptr);
  EXPECT_EQ(t->find("alice")->role, Role::engineer);
  std::string all;
  for (const auto& p : t->problems) all += p + "\n";
  for (const char* said : {"bob.key: permissions 0644 are too open", "carol.key: no role", "dave has a role but no key",
                           "the role must be observer, operator or engineer", "not a valid operator name"})
    EXPECT_NE(all.find(said), std::string::npos) << said << " not in:\n" << all;
}

TEST(Operators, ADirectoryOthersMayWriteOrABadRolesFileIsRefusedWhole) {
  Dir d;
  d.file("alice.key", kHex);
  d.file("roles.yaml", "alice: engineer\n", 0644);
  ASSERT_EQ(load_operators(d.path)->operators.size(), 1u);
  ::chmod(d.path.c_str(), 0777);
  EXPECT_NE(error_of([&] { (void)load_operators(d.path); }).find("let group or others write"), std::string::npos);
  ::chmod(d.path.c_str(), 0700);
  ::chmod((d.path + "/roles.yaml").c_str(), 0666);
  EXPECT_NE(error_of([&] { (void)load_operators(d.path); }).find("change roles"), std::string::npos);
  d.file("roles.yaml", "[alice, engineer", 0644);
  EXPECT_NE(error_of([&] { (void)load_operators(d.path); }).find("not valid YAML"), std::string::npos);
  fs::remove(d.path + "/roles.yaml");
  EXPECT_NE(error_of([&] { (void)load_operators(d.path); }).find("roles.yaml"), std::string::npos);
  EXPECT_NE(error_of([&] { (void)load_operators(d.path + "/missing"); }), "");
}

// cpm's order: --key, then $CPM_KEY_FILE, then ~/.config/cpm/operator.key;
// the name: --operator, then $CPM_OPERATOR, then the file's name.
TEST(Credentials, AreFoundInTheDocumentedOrder) {
  Dir d;
  fs::create_directories(d.path + "/home/.config/cpm");
  write_key_file(d.path + "/home/.config/cpm/operator.key", test::credentials("home").key);
  write_key_file(d.path + "/env.key", test::credentials("env").key);
  write_key_file(d.path + "/given.key", test::credentials("given").key);
  ::setenv("HOME", (d.path + "/home").c_str(), 1);
  ::unsetenv("CPM_KEY_FILE");
  ::setenv("CPM_OPERATOR", "ops", 1);
  auto c = find_credentials(std::nullopt, std::nullopt);
  ASSERT_TRUE(c);
  EXPECT_EQ(c->key, test::credentials("home").key);
  EXPECT_EQ(c->name, "ops");
  ::setenv("CPM_KEY_FILE", (d.path + "/env.key").c_str(), 1);
  ::unsetenv("CPM_OPERATOR");
  c = find_credentials(std::nullopt, std::nullopt);
  EXPECT_EQ(c->key, test::credentials("env").key);
  EXPECT_EQ(c->name, "env");
  c = find_credentials(d.path + "/given.key", std::string("alice"));
  EXPECT_EQ(c->key, test::credentials("given").key);
  EXPECT_EQ(c->name, "alice");
  EXPECT_NE(error_of([&] { (void)find_credentials(d.path + "/missing.key", std::nullopt); }), "");
  EXPECT_NE(error_of([&] { (void)find_credentials(std::nullopt, std::string("../x")); }).find("not valid"), std::string::npos);
  ::unsetenv("CPM_KEY_FILE");
  ::setenv("HOME", (d.path + "/nohome").c_str(), 1);
  EXPECT_FALSE(find_credentials(std::nullopt, std::nullopt)) << "no key anywhere is no credentials, not an error";
}

}  // namespace
}  // namespace cpm::daemon

// SPDX-License-Identifier: Apache-2.0
// Who may command cpmd (docs/security.md): operators, their keys and roles,
// and the MAC every command but a stop carries.
//
// An operator is a name and a 32-byte key. The daemon knows every operator's
// key and role from its operators directory (security.operators_dir:
// NAME.key files and roles.yaml); an operator's `cpm` reads its own key from
// a file it owns. A command is authenticated by HMAC-SHA256 under the key of
// the operator it names, over the command's LCM encoding without its last 32
// bytes (the `mac` field, the encoding's last field). Key files are read as
// ssh reads private keys: a regular file, not a symlink, owned by the user
// that reads it and readable by nobody else.
//
// Nothing here runs in the control cycle: the server (LCM thread) verifies,
// and the housekeeping thread loads a new table and hands it over whole.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "cpm/kinematics/error.hpp"

namespace cpm::daemon {

inline constexpr std::size_t kKeyBytes = 32;
inline constexpr std::size_t kMacBytes = 32;
// control_command_t / trajectory_command_t operator_name: NUL-padded ASCII.
inline constexpr std::size_t kOperatorNameBytes = 32;

using Key = std::array<std::uint8_t, kKeyBytes>;
using Mac = std::array<std::uint8_t, kMacBytes>;

// What an operator may do. observer: read the state (needs no key; anyone
// may also stop the machine); operator: take the session and move (enable,
// disable, reset, trajectories); engineer: also load models and change gains.
enum class Role : std::uint8_t { observer = 0, operator_ = 1, engineer = 2 };
const char* role_name(Role r) noexcept;
std::optional<Role> role_from_name(std::string_view s) noexcept;
// The least role a control command (control_command_t::CMD_*) needs;
// std::nullopt for CMD_STOP, which anyone may send.
std::optional<Role> role_needed(std::int8_t control_command) noexcept;
// Every trajectory command needs Role::operator_.

// 1 to 31 characters of [A-Za-z0-9_.-], not starting with '.' or '-' (it
// names the file NAME.key).
bool valid_operator_name(std::string_view name) noexcept;

// A key from a key file's bytes: 64 hexadecimal digits (whitespace around
// them allowed) or exactly 32 raw bytes. `where` names the file in the Error.
Key parse_key(std::string_view bytes, const std::string& where);
std::string key_to_hex(const Key& k);
// 32 bytes from OpenSSL's CSPRNG.
Key generate_key();
// Read a key file, refusing (Error, saying why and how to fix it) one that is
// a symlink, not a regular file, not owned by this process's effective user,
// readable or writable by group or others, or bigger than a key file can be.
Key read_key_file(const std::string& path);
// Write a new key file (hex, mode 0600); refuses to replace an existing file.
void write_key_file(const std::string& path, const Key& k);

struct Credentials {
  std::string name;  // valid_operator_name
  Key key{};
  // The boot id of the cpmd an acquire is for (state_t.boot_id): an
  // acquire's MAC covers it (sign_encoded).
  std::int64_t boot = 0;
};

// The operator's key for `cpm`, in this order: `key_file` (--key FILE), then
// $CPM_KEY_FILE, then ~/.config/cpm/operator.key. The name: `name`
// (--operator NAME), then $CPM_OPERATOR, then the key file's name without
// ".key" (unless it is "operator"), then the login name. nullopt when no key
// file is given and the default one does not exist; Error when a key file is
// named but unusable, or when the name is not a valid operator name.
std::optional<Credentials> find_credentials(const std::optional<std::string>& key_file,
                                            const std::optional<std::string>& name);

Mac hmac_sha256(const Key& key, const void* data, std::size_t size);

// An encoded command whose last kMacBytes bytes are its mac field: write the
// MAC of the bytes before them (sign), or check it in constant time (verify).
// An acquire's MAC (a control_command_t whose command is CMD_ACQUIRE) covers
// `boot` too, the receiving cpmd's boot id as 8 big-endian bytes before the
// encoding: HMAC(key, boot || encoding without the MAC). Every other command
// carries the session, which only an acquire of this boot grants, so every
// signed command is bound to one start of cpmd; `boot` is ignored for them.
void sign_encoded(std::uint8_t* data, std::size_t size, const Key& key, std::int64_t boot);
bool verify_encoded(const std::uint8_t* data, std::size_t size, const Key& key, std::int64_t boot);
// Whether encoded bytes are an acquire (control_command_t, CMD_ACQUIRE).
bool is_acquire(const std::uint8_t* data, std::size_t size);

// Put `name` into an operator_name field (NUL-padded), and read one back
// ("" when it is not NUL-terminated or not a valid name).
void set_operator_name(std::uint8_t (&field)[kOperatorNameBytes], std::string_view name);
std::string operator_name_of(const std::uint8_t (&field)[kOperatorNameBytes]);

// Sign an LCM command (control_command_t, trajectory_command_t) in place:
// its operator_name set to the credentials', its mac to the HMAC of its
// encoding.
template <class M>
void sign(M& m, const Credentials& c) {
  set_operator_name(m.operator_name, c.name);
  std::vector<std::uint8_t> b(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(b.data(), 0, static_cast<int>(b.size()));
  sign_encoded(b.data(), b.size(), c.key, c.boot);
  for (std::size_t i = 0; i < kMacBytes; ++i) m.mac[i] = b[b.size() - kMacBytes + i];
}

struct Operator {
  std::string name;
  Role role = Role::observer;
  Key key{};
};

// The operators cpmd knows, as loaded from its operators directory at one
// moment. Immutable once loaded: a reload makes a new table.
struct OperatorTable {
  std::string dir;
  std::map<std::string, Operator, std::less<>> operators;
  // What was skipped and why ("alice.key: permissions 0644 are too open ..."),
  // for the journal. A skipped operator cannot command.
  std::vector<std::string> problems;
  [[nodiscard]] const Operator* find(std::string_view name) const;
  // Who may command and who only reads: "2 operators may command (1 engineer,
  // 1 operator); 1 observer reads only". Observers command nothing but stop
  // (which anyone may), so they are not counted among those who command.
  [[nodiscard]] std::string who_may_command() const;
};

// roles.yaml's text: "NAME: ROLE" lines. A bad line is skipped and noted in
// `problems` (a name given twice keeps neither role); Error when the text is
// not YAML or not a mapping.
std::map<std::string, Role> parse_roles(const std::string& text, const std::string& where,
                                       std::vector<std::string>& problems);

// Load `dir`: every NAME.key (read_key_file's rules) with its role from
// dir/roles.yaml ("NAME: observer|operator|engineer"). A key without a
// role, or a role without a key, is skipped and noted in `problems`. Throws
// Error when the directory as a whole cannot be trusted: missing, not a
// directory, writable by group or others, owned by another user than root
// or this one; or roles.yaml unreadable, too open or not valid.
std::shared_ptr<const OperatorTable> load_operators(const std::string& dir);

// Tells when the operators directory changed (inotify): the housekeeping
// thread reloads then, as on SIGHUP. Watches nothing (changed() stays false)
// when the directory does not exist yet; call rearm() after a reload.
class OperatorsWatch {
 public:
  explicit OperatorsWatch(std::string dir);
  ~OperatorsWatch();
  OperatorsWatch(const OperatorsWatch&) = delete;
  OperatorsWatch& operator=(const OperatorsWatch&) = delete;
  // Whether anything in the directory changed since the last call (never blocks).
  bool changed();
  void rearm();

 private:
  std::string dir_;
  int fd_ = -1;
  int wd_ = -1;
};

}  // namespace cpm::daemon

// SPDX-License-Identifier: Apache-2.0
// Effects a user adds in the model file without writing C++ (docs/effects.md,
// "Effects you add"; the file's spelling is docs/model-file.md):
//   - table:      a force (N) on one axis, linearly interpolated against one
//                 axis' position d_j (m) or velocity v_j (m/s), held constant
//                 beyond the first and last node (a friction map, a cable
//                 carrier's pull, a local force excess);
//   - expression: a force (N) on one axis from a formula over d1..d3 (m),
//                 v1..v3 (m/s), a1..a3 (m/s^2), t (s) and named parameters,
//                 parsed by muparser.
// The kinematic pitch table is kin::PitchTable (kinematics/pitch_table.hpp).
//
// They add to the actuator forces exactly as the library's additive effects:
//     F_d = J^T F_p + sum of library effects + sum of user effects.
// A UserEffect is the description (model file, identification); the prepared
// UserEffectsRuntime (inside ctl::Machine) evaluates them in the control
// cycle without allocating or throwing.
#pragma once

#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "cpm/kinematics/types.hpp"

namespace cpm::ctl {

enum class UserEffectKind : std::uint8_t { table, expression };

struct UserParameter {
  std::string name;   // a name of letters, digits and '_', not a variable's name
  std::string unit;   // free text, for the reader ("N s/m")
  double value = 0.0;
  double lower = -std::numeric_limits<double>::infinity();  // bounds for fitting, inclusive
  double upper = std::numeric_limits<double>::infinity();
  bool operator==(const UserParameter&) const = default;
};

struct UserEffect {
  UserEffectKind kind = UserEffectKind::table;
  int axis = 0;                 // 0..2: the axis the force acts on
  // table: the input variable, 'd' (position, m) or 'v' (velocity, m/s) of input_axis (0..2)
  char input = 'd';
  int input_axis = 0;
  std::vector<double> nodes;    // strictly increasing, in the input's unit
  std::vector<double> values;   // force (N) at each node
  // expression
  std::string formula;
  std::vector<UserParameter> params;

  [[nodiscard]] std::string input_name() const;  // "d2", "v1"
  bool operator==(const UserEffect&) const = default;
};

inline constexpr int kUserTableCapacity = 1024;  // nodes of one dynamic table

// The formula's variables, in the order the runtime binds them.
inline constexpr const char* kUserVariables[10] = {"d1", "d2", "d3", "v1", "v2", "v3",
                                                   "a1", "a2", "a3", "t"};

// Throws Error "user_effects[INDEX].KEY: reason" when an effect is not
// usable: axis outside 1..3, nodes not strictly increasing or not finite,
// nodes and values of different lengths, a parameter outside its bounds or
// with a bad name, a formula that does not parse (muparser's message and the
// position, counted from 0) or that uses an unknown variable.
void validate_user_effect(const UserEffect& e, int index);

// The names of the formula's variables and parameters that it uses (parsing
// it); throws like validate_user_effect.
std::vector<std::string> formula_variables(const UserEffect& e, int index);

struct MachineModel;

// Add a user effect given in the command line's short form (cpm sim
// --truth-effect, tests), SI units:
//   table:AXIS:INPUT:N1,N2,...:V1,V2,...   e.g. table:2:d2:0.1,0.2,0.3:0,1.5,0 (force in N)
//   expression:AXIS:FORMULA[:NAME=VALUE,...] e.g. expression:2:c*v1:c=3 (no bounds)
//   pitch_table:AXIS:N1,N2,...:E1,E2,...   e.g. pitch_table:1:0,0.2,0.4:0,5e-6,12e-6 (m)
// Throws Error naming the spec and what is wrong (and validates the effect).
void add_user_effect(MachineModel& model, const std::string& spec);
// The spec names a user effect kind (table, expression, pitch_table).
bool is_user_effect_spec(const std::string& spec) noexcept;

// The user effects, prepared: tables copied into arrays, formulas parsed,
// bound to their variables and evaluated once (so muparser has compiled them
// to bytecode and its stack is sized). Construction and copying allocate
// and may throw; add_forces() does neither. Up to 8 threads may evaluate one
// runtime at once (each formula is prepared 8 times; an evaluation takes a
// free copy by an atomic test-and-set, never waiting while one is free).
class UserEffectsRuntime {
 public:
  UserEffectsRuntime();
  explicit UserEffectsRuntime(const std::vector<UserEffect>& effects);
  UserEffectsRuntime(const UserEffectsRuntime& other);
  UserEffectsRuntime& operator=(const UserEffectsRuntime& other);
  UserEffectsRuntime(UserEffectsRuntime&&) noexcept;
  UserEffectsRuntime& operator=(UserEffectsRuntime&&) noexcept;
  ~UserEffectsRuntime();

  [[nodiscard]] bool empty() const noexcept;
  // Some formula uses a1..a3: the plant's equation is then implicit in the
  // acceleration (Machine::forward_dynamics solves it).
  [[nodiscard]] bool uses_acceleration() const noexcept;
  // Adds each effect's force (N) to f[axis] at positions d (m), velocities
  // v (m/s), accelerations a (m/s^2) of the three axes and time t (s).
  void add_forces(const Vec3& d, const Vec3& v, const Vec3& a, double t, Vec3& f) const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;  // on the heap: the parsers hold its variables' addresses
};

}  // namespace cpm::ctl

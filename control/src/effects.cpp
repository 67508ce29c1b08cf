// SPDX-License-Identifier: Apache-2.0
#include "cpm/control/effects.hpp"

#include <cmath>
#include <numbers>
#include <sstream>

#include "cpm/kinematics/types.hpp"

namespace cpm::ctl {
namespace {

constexpr double kInf = 1e300;
constexpr double kTwoPi = 2.0 * std::numbers::pi;

constexpr DynamicEffectInfo kInfo[kDynamicEffectTypes] = {
    {DynamicEffectType::viscous_friction, "viscous_friction", true, {true, true, false, false}, 1,
     {{{"b", "N s/m", 0.0, 1e4, false}}},
     "lubricant shear in the guides and screw",
     "force residual proportional to velocity, odd in v, no jump at v = 0"},
    {DynamicEffectType::coulomb_friction, "coulomb_friction", true, {true, false, false, false}, 1,
     {{{"f_c", "N", 0.0, 500.0, false}}},
     "dry sliding friction in guides, seals and screw nut",
     "a constant force opposing motion: a step of 2 f_c when the axis reverses"},
    {DynamicEffectType::stribeck_friction, "stribeck_friction", true, {true, true, false, false}, 2,
     {{{"f_s", "N", 0.0, 500.0, false}, {"v_s", "m/s", 1e-5, 1.0, true}}},
     "breakaway (static) friction above the sliding level near rest",
     "a spike of force at low speed around each reversal, decaying with |v| on the scale v_s"},
    {DynamicEffectType::cogging, "cogging", true, {false, false, true, false}, 3,
     {{{"a", "N", 0.0, 500.0, false},
       {"lambda", "m", 1e-3, 0.2, true},
       {"phi", "rad", -kTwoPi, kTwoPi, false}}},
     "magnet/tooth interaction in the motor or detents in the screw",
     "force residual periodic in the axis position with a fixed wavelength, at any speed"},
    {DynamicEffectType::spring, "spring", true, {false, false, true, false}, 2,
     {{{"k", "N/m", -1e5, 1e5, false}, {"d_ref", "m", -1.0, 1.0, false}}},
     "a cable carrier, hose or counterbalance pulling the carriage",
     "force residual linear in the axis position, the same in both directions"},
    {DynamicEffectType::force_gain, "force_gain", true, {false, false, false, true}, 1,
     {{{"k", "1", -0.9, 10.0, false}}},
     "drive current scaling or motor force constant off its rated value",
     "force residual proportional to the commanded force itself"},
    {DynamicEffectType::payload_mass, "payload_mass", false, {false, false, false, true}, 1,
     {{{"dm", "kg", -0.3, 100.0, false}}},
     "a tool or payload on the platform that the model does not know",
     "force residual proportional to acceleration on every axis plus a constant on z (weight)"},
    {DynamicEffectType::inertia_error, "inertia_error", false, {false, false, false, true}, 4,
     {{{"dA", "kg", -kInf, kInf, false},
       {"dB", "kg m^2", -kInf, kInf, false},
       {"dC", "N m", -kInf, kInf, false},
       {"dE", "N", -kInf, kInf, false}}},
     "the link masses of the model differ from the real ones",
     "force residual in the directions of the rigid-body regressor (accelerations, limb angles, weight)"},
    {DynamicEffectType::actuation_delay, "actuation_delay", false, {false, false, false, true}, 1,
     {{{"tau", "s", 0.0, 0.05, false}}},
     "dead time between command and force: a synchronous PDO acts at the next SYNC, the current loop lags",
     "force residual proportional to the rate of change of the commanded force (looks like viscous friction)"},
    // Bounds: a 1e-4 kg m^2 rotor on a 5 mm lead screw reflects (2 pi / 5 mm)^2 1e-4 = 158 kg; a
    // large servo (6e-4 kg m^2) on a 4 mm lead ~1500 kg. Negative down to -5 kg so that a model
    // which puts too much mass on one actuator can be corrected (Elkady's machine carries
    // 2A = 3.8 kg per axis; the Machine refuses a total that is no longer positive definite).
    {DynamicEffectType::actuator_inertia, "actuator_inertia", true, {false, false, false, true}, 1,
     {{{"m", "kg", -5.0, 2000.0, false}}},
     "the motor rotor, coupling and screw of one axis, reflected onto its carriage",
     "force residual proportional to that axis' own acceleration, on that axis only"},
};

inline double sgn_eps(double v) noexcept { return std::tanh(v / kSignEpsilon); }

}  // namespace

const DynamicEffectInfo& info(DynamicEffectType t) noexcept {
  return kInfo[static_cast<int>(t)];
}

std::optional<DynamicEffectType> dynamic_effect_from_name(std::string_view name) noexcept {
  for (const auto& i : kInfo)
    if (name == i.name) return i.type;
  return std::nullopt;
}

std::string DynamicEffect::label() const {
  std::string s = info(type).name;
  if (info(type).per_axis) s += "[axis " + std::to_string(axis + 1) + "]";
  return s;
}

void DynamicEffect::validate() const {
  if (static_cast<int>(type) >= kDynamicEffectTypes) throw Error("dynamic effect: unknown type");
  const DynamicEffectInfo& in = info(type);
  if (in.per_axis && (axis < 0 || axis > 2))
    throw Error(std::string(in.name) + ": axis must be 1, 2 or 3");
  if (!in.per_axis && axis != -1)
    throw Error(std::string(in.name) + " acts on all axes together; it takes no axis");
  for (int j = 0; j < in.n_params; ++j) {
    const EffectParameter& p = in.params[j];
    const double v = param[j];
    std::ostringstream os;
    if (!std::isfinite(v)) {
      os << label() << ": parameter " << p.name << " is not a finite number";
      throw Error(os.str());
    }
    if (v < p.lower || v > p.upper) {
      os << label() << ": parameter " << p.name << " = " << v << " " << p.unit
         << " is outside its physical range [" << p.lower << ", " << p.upper << "]";
      throw Error(os.str());
    }
  }
}

double effect_force(const DynamicEffect& e, double d, double v) noexcept {
  const auto& p = e.param;
  switch (e.type) {
    case DynamicEffectType::viscous_friction: return p[0] * v;
    case DynamicEffectType::coulomb_friction: return p[0] * sgn_eps(v);
    case DynamicEffectType::stribeck_friction: {
      const double r = v / p[1];
      return p[0] * std::exp(-r * r) * sgn_eps(v);
    }
    case DynamicEffectType::cogging: return p[0] * std::sin(kTwoPi * d / p[1] + p[2]);
    case DynamicEffectType::spring: return p[0] * (d - p[1]);
    case DynamicEffectType::force_gain:
    case DynamicEffectType::payload_mass:
    case DynamicEffectType::inertia_error:
    case DynamicEffectType::actuation_delay:
    case DynamicEffectType::actuator_inertia: return 0.0;
  }
  return 0.0;
}

double effect_force_gradient(const DynamicEffect& e, int j, double d, double v) noexcept {
  const auto& p = e.param;
  switch (e.type) {
    case DynamicEffectType::viscous_friction: return v;
    case DynamicEffectType::coulomb_friction: return sgn_eps(v);
    case DynamicEffectType::stribeck_friction: {
      const double r = v / p[1];
      const double base = std::exp(-r * r) * sgn_eps(v);
      return j == 0 ? base : p[0] * base * 2.0 * r * r / p[1];
    }
    case DynamicEffectType::cogging: {
      const double arg = kTwoPi * d / p[1] + p[2];
      if (j == 0) return std::sin(arg);
      if (j == 1) return p[0] * std::cos(arg) * (-kTwoPi * d / (p[1] * p[1]));
      return p[0] * std::cos(arg);
    }
    case DynamicEffectType::spring: return j == 0 ? d - p[1] : -p[0];
    case DynamicEffectType::force_gain:
    case DynamicEffectType::payload_mass:
    case DynamicEffectType::inertia_error:
    case DynamicEffectType::actuation_delay:
    case DynamicEffectType::actuator_inertia: return 0.0;
  }
  return 0.0;
}

void DynamicEffects::add(const DynamicEffect& e) {
  e.validate();
  if (count_ >= kCapacity)
    throw Error("model: more than " + std::to_string(kCapacity) + " dynamic effects");
  items_[count_++] = e;
}

}  // namespace cpm::ctl

// SPDX-License-Identifier: Apache-2.0
// Shared by the fuzz targets: what counts as a finding besides a sanitizer
// report. A parser or validator may refuse its input only with the project's
// error types (cpm::Error, or hal::Error in the hardware layer), whose
// messages say what and where; any other exception escaping (yaml-cpp's,
// std::out_of_range, std::length_error, ...) is a bug, and so is a broken
// invariant checked with FUZZ_CHECK.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <typeinfo>
#include <string>

#include "cpm/kinematics/types.hpp"

namespace cpm::fuzz {

[[noreturn]] inline void fail(const char* file, int line, const std::string& what) {
  std::fprintf(stderr, "\n*** FUZZ FINDING at %s:%d: %s\n", file, line, what.c_str());
  std::fflush(stderr);
  std::abort();  // libFuzzer saves the input as crash-*
}

#define FUZZ_CHECK(cond, msg)                                                        \
  do {                                                                               \
    if (!(cond)) ::cpm::fuzz::fail(__FILE__, __LINE__, std::string(#cond ": ") + (msg)); \
  } while (0)

// Run f; cpm::Error (and the types in Allowed...) are a refusal and return
// false; anything else escaping is a finding.
template <class... Allowed, class F>
bool refused_cleanly(F&& f, std::string* message = nullptr) {
  try {
    f();
    return true;
  } catch (const cpm::Error& e) {
    if (message) *message = e.what();
    return false;
  } catch (const std::exception& e) {
    if constexpr (sizeof...(Allowed) > 0) {
      if ((dynamic_cast<const Allowed*>(&e) || ...)) {
        if (message) *message = e.what();
        return false;
      }
    }
    fail(__FILE__, __LINE__, std::string("an exception that is not the project's error escaped: ") +
                                 typeid(e).name() + ": " + e.what());
  }
}

// Byte reader over the input (little helpers for structured targets).
class Bytes {
 public:
  Bytes(const std::uint8_t* d, std::size_t n) : d_(d), n_(n) {}
  [[nodiscard]] bool empty() const { return i_ >= n_; }
  [[nodiscard]] std::size_t left() const { return n_ - i_; }
  std::uint8_t u8() { return i_ < n_ ? d_[i_++] : 0; }
  std::uint16_t u16() { return static_cast<std::uint16_t>(u8() | (u8() << 8)); }
  std::uint32_t u32() { return u16() | (std::uint32_t{u16()} << 16); }
  // Up to n bytes.
  std::size_t take(std::uint8_t* out, std::size_t n) {
    std::size_t k = 0;
    while (k < n && i_ < n_) out[k++] = d_[i_++];
    return k;
  }
  const std::uint8_t* here() const { return d_ + i_; }
  void skip(std::size_t n) { i_ = n > left() ? n_ : i_ + n; }

 private:
  const std::uint8_t* d_;
  std::size_t n_, i_ = 0;
};

}  // namespace cpm::fuzz

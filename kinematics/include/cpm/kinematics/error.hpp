// SPDX-License-Identifier: Apache-2.0
// cpm::Error, on its own: the client library's public headers need it
// without the rest of types.hpp (Eigen).
#pragma once

#include <stdexcept>

namespace cpm {

// Error thrown by the non-real-time entry points (loading, validating,
// preparing). The message says what is wrong and where. Real-time functions
// never throw: they return a Status.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace cpm

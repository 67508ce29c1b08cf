// SPDX-License-Identifier: Apache-2.0
// The files cpm scope serves (tools/cpm/scope/: its page, and uPlot, the
// chart library it plots with, vendored: packaging/copyright), compiled into
// cpm by tools/cpm/scope/embed.cmake so that the installed program needs no
// data folder.
#pragma once

#include <cstddef>
#include <span>

namespace cpm::cli {

struct ScopeAsset {
  const char* name;  // file name; index.html is served as "/"
  const char* type;  // MIME type
  const unsigned char* data;
  std::size_t size;
};

std::span<const ScopeAsset> scope_assets();

}  // namespace cpm::cli

// SPDX-License-Identifier: Apache-2.0
// io::parse_model_file on arbitrary YAML. Oracle: refused only with
// cpm::Error (never a yaml-cpp exception); an accepted model prepares a
// ctl::Machine or is refused by it with cpm::Error, and renders to text that
// parses again and renders identically.
#include "cpm/io/model_file.hpp"
#include "fuzz_common.hpp"

using namespace cpm;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  io::ModelFile m;
  if (!fuzz::refused_cleanly([&] { m = io::parse_model_file(text, "fuzz.yaml"); })) return 0;
  fuzz::refused_cleanly([&] { ctl::Machine machine(m.model); });
  const std::string once = io::render_model_file(m);
  io::ModelFile again;
  std::string why;
  FUZZ_CHECK(fuzz::refused_cleanly([&] { again = io::parse_model_file(once, "rendered.yaml"); }, &why),
             "an accepted model renders to a file the loader refuses: " + why + "\n--- rendered:\n" + once);
  const std::string twice = io::render_model_file(again);
  FUZZ_CHECK(twice == once, "render(parse(render(x))) != render(x)\n--- once:\n" + once + "\n--- twice:\n" + twice);
  return 0;
}

// SPDX-License-Identifier: Apache-2.0
// io::parse_data on arbitrary text: the three measurement-file kinds of
// docs/data-formats.md (the `# kind = ...` line picks the kind, so the corpus
// holds all three). Oracle: refused only with cpm::Error; what is accepted
// renders to text that parses again and renders to the same text.
#include "cpm/io/data_files.hpp"
#include "fuzz_common.hpp"

using namespace cpm;

namespace {
std::string render(const io::DataSet& ds) {
  return std::visit(
      [](const auto& d) -> std::string {
        using T = std::decay_t<decltype(d)>;
        if constexpr (std::is_same_v<T, io::BallbarData>) return io::render_ballbar(d);
        else if constexpr (std::is_same_v<T, io::PositionData>) return io::render_position(d);
        else return io::render_motion(d);
      },
      ds);
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  io::DataSet ds;
  if (!fuzz::refused_cleanly([&] { ds = io::parse_data(text, "fuzz.csv"); })) return 0;
  const std::string once = render(ds);
  io::DataSet again;
  std::string why;
  FUZZ_CHECK(fuzz::refused_cleanly([&] { again = io::parse_data(once, "rendered.csv"); }, &why),
             "accepted data renders to text the reader refuses: " + why + "\n--- rendered:\n" + once);
  FUZZ_CHECK(io::kind_of(again) == io::kind_of(ds), "the kind changed in a round trip");
  FUZZ_CHECK(io::sample_count(again) == io::sample_count(ds), "the row count changed in a round trip");
  const std::string twice = render(again);
  FUZZ_CHECK(twice == once, "render(parse(render(x))) != render(x)\n--- once:\n" + once + "\n--- twice:\n" + twice);
  return 0;
}

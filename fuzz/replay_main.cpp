// SPDX-License-Identifier: Apache-2.0
// A driver for the fuzz targets without libFuzzer (the g++ build): runs
// LLVMFuzzerTestOneInput once on every file named, or in every folder named.
// CTest uses it to replay the committed corpora as regression tests.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "cpm/program_cli.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace fs = std::filesystem;

int main(int argc, char** argv) {
  std::vector<std::string> paths;
  CLI::App app{"replay: runs the fuzz target once on every input file named, or in every folder named", "replay"};
  cpm::program::setup(app);
  app.add_option("PATH", paths, "an input file, or a folder of them")->type_name("PATH");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return cpm::program::parse_exit(app, e, "replay");
  }
  std::vector<fs::path> files;
  for (const std::string& arg : paths) {
    const fs::path p(arg);
    if (fs::is_directory(p)) {
      for (const auto& e : fs::recursive_directory_iterator(p))
        if (e.is_regular_file()) files.push_back(e.path());
    } else if (fs::is_regular_file(p)) {
      files.push_back(p);
    } else {
      std::fprintf(stderr, "replay: %s: no such file or folder\n", arg.c_str());
      return 2;
    }
  }
  std::sort(files.begin(), files.end());
  for (const auto& f : files) {
    std::ifstream in(f, std::ios::binary);
    const std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    LLVMFuzzerTestOneInput(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size());
  }
  std::printf("replay: %zu inputs, no finding\n", files.size());
  return files.empty() ? 3 : 0;
}

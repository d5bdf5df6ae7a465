// Writes the seed inputs of every fuzz target into DIR/TARGET/seed-N (scripts/fuzz.sh).
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "tests/fuzz/fuzz_targets.h"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: fuzz_seeds DIR\n");
    return 2;
  }
  for (const auto& target : objdb::fuzz::targets()) {
    const std::filesystem::path dir = std::filesystem::path(argv[1]) / target.name;
    std::filesystem::create_directories(dir);
    const auto seeds = objdb::fuzz::seeds(target.name);
    for (size_t i = 0; i < seeds.size(); ++i) {
      std::ofstream out(dir / ("seed-" + std::to_string(i)), std::ios::binary);
      out << seeds[i];
      if (!out) {
        std::fprintf(stderr, "fuzz_seeds: cannot write %s\n", (dir / "seed").c_str());
        return 1;
      }
    }
    std::printf("%s: %zu seeds in %s\n", target.name, seeds.size(), dir.c_str());
  }
  return 0;
}

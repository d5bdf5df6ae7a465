// Replays the committed fuzz corpus (tests/fuzz/corpus/TARGET/, minimised by scripts/fuzz.sh)
// and the inputs of the bugs the fuzzers found (tests/fuzz/regressions/TARGET/) through every
// target: each input must
// end in OK or a Status. Also the seeds: valid inputs that every target must accept, and a few
// hostile ones it must reject.
#include "tests/fuzz/fuzz_targets.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

namespace objdb::fuzz {
namespace {

std::string readAll(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

Outcome run(const Target& target, const std::string& bytes) {
  return target.run(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
}

TEST(FuzzTargets, EverySeedIsAccepted) {
  for (const Target& target : targets()) {
    const std::vector<std::string> inputs = seeds(target.name);
    EXPECT_GE(inputs.size(), 4u) << target.name;
    for (size_t i = 0; i < inputs.size(); ++i) {
      ASSERT_FALSE(inputs[i].empty()) << target.name << " seed " << i;
      EXPECT_EQ(run(target, inputs[i]), Outcome::kAccepted) << target.name << " seed " << i;
    }
  }
}

TEST(FuzzTargets, DamagedSeedsAreRejectedNotCrashed) {
  for (const Target& target : targets()) {
    for (const std::string& seed : seeds(target.name)) {
      if (seed.empty()) continue;  // EverySeedIsAccepted reports it
      // Truncations and a flipped byte in the middle: each is an error or, rarely, still valid.
      for (size_t keep : {size_t(0), size_t(1), seed.size() / 2, seed.size() - 1}) {
        (void)run(target, seed.substr(0, keep));
      }
      std::string flipped = seed;
      flipped[flipped.size() / 2] ^= 0x5a;
      (void)run(target, flipped);
    }
  }
  // Known answers: nothing, garbage and a wrong type are rejected.
  EXPECT_EQ(run(targets()[2], "not json"), Outcome::kRejected);
  EXPECT_EQ(run(targets()[2], R"({"tsdf": {"voxel_size_m": "big"}})"), Outcome::kRejected);
  EXPECT_EQ(run(targets()[1], ""), Outcome::kRejected);
  EXPECT_EQ(run(targets()[1], std::string("\0ODBB", 5)), Outcome::kRejected);
}

// Every file under root/TARGET/ through its target; returns how many.
size_t replayAll(const std::filesystem::path& root) {
  size_t replayed = 0;
  for (const Target& target : targets()) {
    const std::filesystem::path dir = root / target.name;
    if (!std::filesystem::is_directory(dir)) continue;
    for (const auto& entry : std::filesystem::directory_iterator(dir)) {
      if (!entry.is_regular_file()) continue;
      (void)run(target, readAll(entry.path()));  // must return; ASan builds also check memory
      ++replayed;
    }
  }
  return replayed;
}

TEST(FuzzTargets, TheCommittedCorpusReplaysCleanly) {
  const std::filesystem::path root = OBJDB_FUZZ_DIR "/corpus";
  ASSERT_TRUE(std::filesystem::is_directory(root)) << root;
  const size_t replayed = replayAll(root);
  EXPECT_GT(replayed, 100u) << "the corpus under " << root << " is missing";
  std::printf("replayed %zu corpus inputs\n", replayed);
}

// Inputs that found bugs (docs/fuzzing.md), each named after what it found.
TEST(FuzzTargets, EveryRegressionInputEndsInAStatus) {
  const std::filesystem::path root = OBJDB_FUZZ_DIR "/regressions";
  EXPECT_GE(replayAll(root), 4u) << root;
}

}  // namespace
}  // namespace objdb::fuzz

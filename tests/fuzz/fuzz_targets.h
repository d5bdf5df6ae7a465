// Fuzz targets (docs/fuzzing.md): the decoders that read bytes from outside the process.
// Each takes arbitrary bytes and must end in OK or a Status — never crash, hang, leak or read out
// of bounds. libFuzzer drives them under ASan/UBSan (scripts/fuzz.sh, tests/fuzz/fuzz_main.cpp);
// corpus_replay_test replays the committed corpus (tests/fuzz/corpus/TARGET/) on every test run.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace objdb::fuzz {

enum class Outcome { kAccepted, kRejected };

// Bytes → objdb.v1.IngestRequest (what a client sends on Ingest) → a header's intrinsics, pose
// and parameter overrides, or a frame's pose, depth and colour decoded against a 40 × 30 camera.
Outcome frame(const uint8_t* data, size_t size);
// The first byte picks a storage blob decoder (byte % 10) — and for whole blobs the kind expected
// (byte / 10 % 8 + 1); the rest is either a whole blob (header checks: magic, version, kind,
// sizes, CRC, zstd) or, wrapped into a valid blob, a payload for the typed
// decoder (TSDF grid / block, point cloud, indices, label block, descriptors, voxels, transform).
Outcome blob(const uint8_t* data, size_t size);
// Config text → the JSON parameter loader (what --config and a session header's params carry).
Outcome config(const uint8_t* data, size_t size);

struct Target {
  const char* name;
  Outcome (*run)(const uint8_t*, size_t);
};
const std::vector<Target>& targets();

// Valid inputs for each target (seeds): frames of the synthetic world, blobs of real layers,
// clouds and descriptors, config files. Every seed is accepted by its target.
std::vector<std::string> seeds(const std::string& target);

}  // namespace objdb::fuzz

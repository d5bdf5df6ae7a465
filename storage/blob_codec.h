// Blob codec of the SQLite store: every binary column is a self-describing blob —
// a 32-byte header {magic "ODBB", format version, kind, codec, payload sizes, CRC32 of the
// stored payload} followed by the payload, raw or zstd-compressed. Decoding checks the magic,
// version, kind, sizes (before any allocation) and checksum, and decompresses in steps (memory
// follows the real output, not the declared size), so a damaged blob is an error that names
// what is wrong, never garbage. SQLite cannot see inside row data (testing.html §4.2);
// these checks are how objdb notices a flipped byte.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/mesh.h"
#include "core/common/status.h"
#include "core/common/transform.h"
#include "core/model/object_model.h"
#include "core/tsdf/tsdf_layer.h"

namespace objdb::storage {

enum class BlobKind : uint16_t {
  kTsdfGrid = 1,     // a whole TsdfLayer (voxel size, block side, blocks)
  kTsdfBlock = 2,    // one block of a scene map
  kPointCloud = 3,   // points, optional normals and colours
  kIndices = 4,      // uint32 list (keypoint indices)
  kDescriptors = 5,  // FPFH histograms
  kVoxelList = 6,    // global voxel indices
  kTransform = 7,    // a rigid transform, 12 doubles (rotation column-major, translation)
  kLabelBlock = 8,   // one block of a scene map's main labels (uint32 per voxel)
  kGlobalDescriptor = 9,  // a model's global descriptor (model/global_descriptor.h), versioned
};

const char* blobKindName(BlobKind kind);

enum class BlobCodec : uint8_t { kRaw = 0, kZstd = 1 };

struct BlobOptions {
  bool compress = true;        // zstd when it makes the blob smaller
  int zstd_level = 3;          // 1..19; 3 is zstd's default speed/ratio trade
  size_t min_compress_bytes = 256;  // smaller payloads are stored raw
};

// Largest payload a blob may declare (uncompressed); far below SQLite's 1e9 length limit.
inline constexpr uint64_t kMaxBlobPayloadBytes = 512ull << 20;
inline constexpr uint16_t kBlobFormatVersion = 1;
inline constexpr size_t kBlobHeaderBytes = 32;

// Wraps a payload into a blob of `kind`.
std::string encodeBlob(BlobKind kind, std::string_view payload, const BlobOptions& options = {});
// Checks a blob and returns its payload. Errors (DATA_LOSS): too short, wrong magic, unsupported
// version, other kind than expected, sizes out of range, checksum mismatch (expected and found),
// decompression failure.
StatusOr<std::string> decodeBlob(BlobKind expected, std::string_view blob);

// Typed encoders/decoders (payload + blob in one call). Decoders validate every count against
// the payload size before allocating.
std::string encodeTsdfGrid(const tsdf::TsdfLayer& grid, const BlobOptions& options = {});
StatusOr<tsdf::TsdfLayer> decodeTsdfGrid(std::string_view blob);

// One block of a layer: its voxels only (index and geometry are stored beside it).
std::string encodeTsdfBlock(const tsdf::TsdfBlock& block, const BlobOptions& options = {});
// Fills `block` (of `voxels_per_side`); errors when the blob's voxel count differs.
Status decodeTsdfBlock(std::string_view blob, int voxels_per_side, tsdf::TsdfBlock* block);

std::string encodePointCloud(const PointCloud& cloud, const BlobOptions& options = {});
StatusOr<PointCloud> decodePointCloud(std::string_view blob);

std::string encodeIndices(const std::vector<uint32_t>& indices, const BlobOptions& options = {});
StatusOr<std::vector<uint32_t>> decodeIndices(std::string_view blob);

// A scene map block's labels (one per voxel, the block's voxel order).
std::string encodeLabelBlock(const std::vector<uint32_t>& labels, const BlobOptions& options = {});
StatusOr<std::vector<uint32_t>> decodeLabelBlock(std::string_view blob);

std::string encodeDescriptors(const std::vector<model::Fpfh>& descriptors,
                              const BlobOptions& options = {});
StatusOr<std::vector<model::Fpfh>> decodeDescriptors(std::string_view blob);

// A model's global descriptor and the codebook version it was computed with
// (model::kCodebookVersion).
struct GlobalDescriptorBlob {
  int codebook_version = 0;
  std::vector<float> values;
};
std::string encodeGlobalDescriptor(const GlobalDescriptorBlob& descriptor,
                                   const BlobOptions& options = {});
StatusOr<GlobalDescriptorBlob> decodeGlobalDescriptor(std::string_view blob);

std::string encodeVoxelList(const std::vector<tsdf::VoxelIndex>& voxels,
                            const BlobOptions& options = {});
StatusOr<std::vector<tsdf::VoxelIndex>> decodeVoxelList(std::string_view blob);

std::string encodeTransform(const Transform& T);
// Errors also when the rotation is not orthonormal (|RᵀR − I| > 1e-6) or a value is not finite.
StatusOr<Transform> decodeTransform(std::string_view blob);

}  // namespace objdb::storage

#include "storage/blob_codec.h"

#include <sys/resource.h>

#include <cstring>
#include <limits>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/storage/store_fixtures.h"

namespace objdb::storage {
namespace {

using ::testing::HasSubstr;

TEST(BlobCodec, EveryKindRoundTripsBitExact) {
  const model::ObjectModel m = objdb::testing::makeStoreModel(7, 3);
  for (const bool compress : {false, true}) {
    BlobOptions options;
    options.compress = compress;
    const auto grid = decodeTsdfGrid(encodeTsdfGrid(m.grid, options));
    ASSERT_TRUE(grid.ok()) << grid.status();
    EXPECT_EQ(objdb::testing::diffLayers(*grid, m.grid), "");

    tsdf::TsdfBlock block(8);
    const tsdf::TsdfBlock& original = *m.grid.blocks().begin()->second;
    ASSERT_TRUE(decodeTsdfBlock(encodeTsdfBlock(original, options), 8, &block).ok());
    for (size_t i = 0; i < original.voxels().size(); ++i) {
      const auto& a = block.voxels()[i];
      const auto& b = original.voxels()[i];
      ASSERT_TRUE(a.distance == b.distance && a.weight == b.weight && a.color == b.color) << i;
    }

    const auto cloud = decodePointCloud(encodePointCloud(m.cloud, options));
    ASSERT_TRUE(cloud.ok()) << cloud.status();
    EXPECT_EQ(cloud->points, m.cloud.points);
    EXPECT_EQ(cloud->normals, m.cloud.normals);
    EXPECT_TRUE(cloud->colors == m.cloud.colors);

    EXPECT_EQ(decodeIndices(encodeIndices(m.keypoint_indices, options)).value(), m.keypoint_indices);
    EXPECT_EQ(decodeDescriptors(encodeDescriptors(m.descriptors, options)).value(), m.descriptors);
    EXPECT_EQ(decodeVoxelList(encodeVoxelList(m.surface_voxels, options)).value(), m.surface_voxels);
  }
  const Transform T = m.observations[1].T_world_object;
  EXPECT_TRUE(decodeTransform(encodeTransform(T)).value().matrix() == T.matrix());
}

// Empty lists copy zero bytes from or to a null data(): fine only with the count-0 guard
// (UBSan under -DOBJDB_SANITIZE=ON / scripts/fuzz.sh flags the unguarded memcpy).
TEST(BlobCodec, EmptyValuesRoundTrip) {
  EXPECT_TRUE(decodePointCloud(encodePointCloud(PointCloud{})).value().points.empty());
  EXPECT_TRUE(decodeIndices(encodeIndices({})).value().empty());
  EXPECT_TRUE(decodeLabelBlock(encodeLabelBlock({})).value().empty());
  EXPECT_TRUE(decodeVoxelList(encodeVoxelList({})).value().empty());
  EXPECT_TRUE(decodeDescriptors(encodeDescriptors({})).value().empty());
  const auto grid = decodeTsdfGrid(encodeTsdfGrid(tsdf::TsdfLayer::create(0.01f, 16).value()));
  ASSERT_TRUE(grid.ok());
  EXPECT_EQ(grid->numBlocks(), 0u);
  EXPECT_EQ(grid->voxelsPerSide(), 16);
}

TEST(BlobCodec, CompressesTsdfGrids) {
  const model::ObjectModel m = objdb::testing::makeStoreModel(3, 1);
  tsdf::TsdfLayer sparse = tsdf::TsdfLayer::create(0.01f, 8).value();
  for (int b = 0; b < 10; ++b) sparse.allocateBlock({b, 0, 0}).voxels()[5].weight = 1.0f;
  BlobOptions raw;
  raw.compress = false;
  EXPECT_LT(encodeTsdfGrid(sparse).size() * 5, encodeTsdfGrid(sparse, raw).size());
}

// Found by fuzzing (tests/fuzz/regressions/blob/declared-size-amplification): the header's
// payload size (not covered by the CRC) was allocated before decompressing, so a small damaged
// blob cost up to kMaxBlobPayloadBytes of memory. Now memory follows the stream's real output.
TEST(BlobCodec, AnInflatedDeclaredSizeIsAnErrorWithoutAllocatingIt) {
  std::string blob = encodeLabelBlock(std::vector<uint32_t>(4096, 7));  // compresses well
  ASSERT_EQ(blob[8], char(BlobCodec::kZstd));
  const uint64_t declared = kMaxBlobPayloadBytes;  // 512 MiB
  std::memcpy(blob.data() + 16, &declared, sizeof(declared));
  rusage before{};
  getrusage(RUSAGE_SELF, &before);
  const auto decoded = decodeLabelBlock(blob);
  rusage after{};
  getrusage(RUSAGE_SELF, &after);
  ASSERT_FALSE(decoded.ok());
  EXPECT_EQ(decoded.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(decoded.status().message(), HasSubstr("bytes, header says 536870912"));
  // ru_maxrss is the peak in KiB: it must not have grown by anything like the declared size.
  EXPECT_LT(after.ru_maxrss - before.ru_maxrss, 64 * 1024) << "KiB of peak memory added";
}

// The decoder caps zstd's window (a forged frame header cannot make it allocate 128 MiB): the
// strongest level the encoder accepts must still decode, on a payload larger than one window.
TEST(BlobCodec, TheStrongestCompressionLevelStillDecodes) {
  std::vector<uint32_t> labels(9 << 18);  // 9 MiB, more than the 8 MiB window
  for (size_t i = 0; i < labels.size(); ++i) labels[i] = uint32_t(i / 64 % 5000);
  BlobOptions strongest;
  strongest.zstd_level = 19;
  const std::string blob = encodeLabelBlock(labels, strongest);
  ASSERT_EQ(blob[8], char(BlobCodec::kZstd));
  const auto decoded = decodeLabelBlock(blob);
  ASSERT_TRUE(decoded.ok()) << decoded.status();
  EXPECT_EQ(*decoded, labels);
}

TEST(BlobCodec, AFlippedPayloadByteIsAChecksumMismatch) {
  const model::ObjectModel m = objdb::testing::makeStoreModel(11, 2);
  for (const bool compress : {false, true}) {
    BlobOptions options;
    options.compress = compress;
    std::string blob = encodeDescriptors(m.descriptors, options);
    blob[kBlobHeaderBytes + (blob.size() - kBlobHeaderBytes) / 2] ^= 0x10;
    const auto decoded = decodeDescriptors(blob);
    ASSERT_FALSE(decoded.ok());
    EXPECT_EQ(decoded.status().code(), absl::StatusCode::kDataLoss);
    EXPECT_THAT(decoded.status().message(), HasSubstr("descriptors blob: checksum mismatch"));
  }
}

TEST(BlobCodec, DamagedHeadersAreNamed) {
  const std::string good = encodeIndices({1, 2, 3, 4});
  auto message = [](const StatusOr<std::vector<uint32_t>>& r) {
    EXPECT_EQ(r.status().code(), absl::StatusCode::kDataLoss);
    return std::string(r.status().message());
  };
  EXPECT_THAT(message(decodeIndices(good.substr(0, good.size() - 1))), HasSubstr("header says"));
  EXPECT_THAT(message(decodeIndices(good.substr(0, 10))), HasSubstr("shorter than the 32-byte header"));
  EXPECT_THAT(message(decodeIndices("")), HasSubstr("shorter"));
  std::string version = good;
  version[4] = 9;
  EXPECT_THAT(message(decodeIndices(version)), HasSubstr("unsupported blob version 9"));
  std::string magic = good;
  magic[0] = 'X';
  EXPECT_THAT(message(decodeIndices(magic)), HasSubstr("bad magic"));
  EXPECT_THAT(message(decodeIndices(encodeVoxelList({{1, 2, 3}}))), HasSubstr("expected 4"));
  // A huge declared size is refused before anything is allocated.
  std::string huge = good;
  const uint64_t size = std::numeric_limits<uint64_t>::max();
  std::memcpy(huge.data() + 16, &size, 8);
  EXPECT_THAT(message(decodeIndices(huge)), HasSubstr("over the"));
}

TEST(BlobCodec, CountsBeyondThePayloadAreRefused) {
  // A well-formed blob whose payload claims more elements than it holds.
  std::string payload(4, '\0');
  const uint32_t n = 1u << 30;
  std::memcpy(payload.data(), &n, 4);
  const auto decoded = decodeIndices(encodeBlob(BlobKind::kIndices, payload));
  ASSERT_FALSE(decoded.ok());
  EXPECT_THAT(decoded.status().message(), HasSubstr("payload ends early"));
}

TEST(BlobCodec, TransformsMustBeRigid) {
  Transform T = Transform::Identity();
  T.linear() *= 1.01;
  const auto decoded = decodeTransform(encodeTransform(T));
  ASSERT_FALSE(decoded.ok());
  EXPECT_THAT(decoded.status().message(), HasSubstr("not orthonormal"));
  T = Transform::Identity();
  T.translation().x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(decodeTransform(encodeTransform(T)).status().message(), HasSubstr("not finite"));
}

TEST(BlobCodec, NonFiniteVoxelsAreRefused) {
  tsdf::TsdfLayer grid = tsdf::TsdfLayer::create(0.02f, 8).value();
  grid.allocateBlock({0, 0, 0}).voxels()[3].distance = std::numeric_limits<float>::infinity();
  const auto decoded = decodeTsdfGrid(encodeTsdfGrid(grid));
  ASSERT_FALSE(decoded.ok());
  EXPECT_THAT(decoded.status().message(), HasSubstr("voxel 3"));
}

}  // namespace
}  // namespace objdb::storage

#include "storage/blob_codec.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <memory>
#include <vector>

#include <zlib.h>
#include <zstd.h>

#include "absl/strings/str_format.h"

namespace objdb::storage {

// Largest zstd window a blob may use: levels up to 19 (BlobOptions) write at most 2^23.
constexpr int kMaxZstdWindowLog = 23;

namespace {

static_assert(std::endian::native == std::endian::little,
              "blobs are little-endian; a big-endian port needs byte swaps here");

constexpr char kMagic[4] = {'O', 'D', 'B', 'B'};

// Header layout (32 bytes, little-endian):
//   0  magic "ODBB"        4  u16 format version   6  u16 kind
//   8  u8 codec            9  u8[3] reserved (0)
//  12  u32 CRC32 of the stored payload (after compression)
//  16  u64 payload size (uncompressed)
//  24  u64 stored size (bytes after the header)
struct Header {
  uint16_t version = 0;
  uint16_t kind = 0;
  uint8_t codec = 0;
  uint32_t crc = 0;
  uint64_t payload_bytes = 0;
  uint64_t stored_bytes = 0;
};

template <typename T>
void put(std::string* out, const T& value) {
  out->append(reinterpret_cast<const char*>(&value), sizeof(T));
}
template <typename T>
T get(const char* p) {
  T value{};
  std::memcpy(&value, p, sizeof(T));
  return value;
}

uint32_t crc32Of(std::string_view bytes) {
  uLong crc = crc32(0L, Z_NULL, 0);
  // zlib takes uInt lengths; feed large payloads in pieces.
  size_t done = 0;
  while (done < bytes.size()) {
    const size_t n = std::min<size_t>(bytes.size() - done, 1u << 30);
    crc = crc32(crc, reinterpret_cast<const Bytef*>(bytes.data() + done), uInt(n));
    done += n;
  }
  return uint32_t(crc);
}

Status dataLoss(BlobKind kind, const std::string& what) {
  return absl::DataLossError(absl::StrFormat("%s blob: %s", blobKindName(kind), what));
}

// Reads a payload front to back; every read is bounds-checked.
class Reader {
 public:
  Reader(BlobKind kind, std::string_view payload) : kind_(kind), data_(payload) {}
  template <typename T>
  StatusOr<T> read() {
    if (data_.size() - pos_ < sizeof(T)) return truncated();
    T value = get<T>(data_.data() + pos_);
    pos_ += sizeof(T);
    return value;
  }
  // A pointer to `count` elements of `element_bytes` each, checked against what is left.
  StatusOr<const char*> span(uint64_t count, size_t element_bytes) {
    const uint64_t left = data_.size() - pos_;
    if (element_bytes != 0 && count > left / element_bytes) return truncated();
    const char* p = data_.data() + pos_;
    pos_ += size_t(count * element_bytes);
    return p;
  }
  Status finish() const {
    if (pos_ != data_.size()) {
      return dataLoss(kind_, absl::StrFormat("%d trailing bytes after the data",
                                             data_.size() - pos_));
    }
    return absl::OkStatus();
  }

 private:
  Status truncated() const {
    return dataLoss(kind_, absl::StrFormat("payload ends early (%d bytes, read %d)", data_.size(),
                                           pos_));
  }
  BlobKind kind_;
  std::string_view data_;
  size_t pos_ = 0;
};

// An empty vector's data() may be null, and memcpy / append with a null pointer is undefined
// even for zero bytes (found by fuzzing: tests/fuzz/regressions/blob/empty-label-list).
template <typename T>
void putArray(std::string* out, const T* data, size_t count) {
  if (count == 0) return;
  out->append(reinterpret_cast<const char*>(data), count * sizeof(T));
}
template <typename T>
void readArray(const char* p, size_t count, T* out) {
  if (count == 0) return;
  std::memcpy(static_cast<void*>(out), p, count * sizeof(T));
}

// Block voxels as structure of arrays (distances, weights, colours): compresses far better
// than interleaved records.
void putVoxels(std::string* out, const std::vector<tsdf::TsdfVoxel>& voxels) {
  const size_t n = voxels.size();
  put(out, uint32_t(n));
  const size_t start = out->size();
  out->resize(start + n * 11);
  char* d = out->data() + start;
  char* w = d + 4 * n;
  char* c = w + 4 * n;
  for (size_t i = 0; i < n; ++i) {
    const auto& v = voxels[i];
    std::memcpy(d + 4 * i, &v.distance, 4);
    std::memcpy(w + 4 * i, &v.weight, 4);
    c[3 * i] = char(v.color.r);
    c[3 * i + 1] = char(v.color.g);
    c[3 * i + 2] = char(v.color.b);
  }
}

Status readVoxels(Reader* reader, BlobKind kind, std::vector<tsdf::TsdfVoxel>* voxels) {
  OBJDB_ASSIGN_OR_RETURN(const uint32_t n, reader->read<uint32_t>());
  if (n != voxels->size()) {
    return dataLoss(kind, absl::StrFormat("block holds %d voxels, expected %d", n, voxels->size()));
  }
  OBJDB_ASSIGN_OR_RETURN(const char* d, reader->span(n, sizeof(float)));
  OBJDB_ASSIGN_OR_RETURN(const char* w, reader->span(n, sizeof(float)));
  OBJDB_ASSIGN_OR_RETURN(const char* c, reader->span(n, 3));
  for (uint32_t i = 0; i < n; ++i) {
    auto& v = (*voxels)[i];
    v.distance = get<float>(d + 4 * size_t(i));
    v.weight = get<float>(w + 4 * size_t(i));
    v.color = {uint8_t(c[3 * size_t(i)]), uint8_t(c[3 * size_t(i) + 1]),
               uint8_t(c[3 * size_t(i) + 2])};
    if (!(std::isfinite(v.distance) && std::isfinite(v.weight) && v.weight >= 0.0f)) {
      return dataLoss(kind, absl::StrFormat("voxel %d has distance %g, weight %g", i, v.distance,
                                            v.weight));
    }
  }
  return absl::OkStatus();
}

}  // namespace

const char* blobKindName(BlobKind kind) {
  switch (kind) {
    case BlobKind::kTsdfGrid: return "TSDF grid";
    case BlobKind::kTsdfBlock: return "TSDF block";
    case BlobKind::kPointCloud: return "point cloud";
    case BlobKind::kIndices: return "keypoint indices";
    case BlobKind::kDescriptors: return "descriptors";
    case BlobKind::kVoxelList: return "voxel list";
    case BlobKind::kTransform: return "transform";
    case BlobKind::kLabelBlock: return "label block";
    case BlobKind::kGlobalDescriptor: return "global descriptor";
  }
  return "unknown";
}

std::string encodeBlob(BlobKind kind, std::string_view payload, const BlobOptions& options) {
  std::string stored;
  BlobCodec codec = BlobCodec::kRaw;
  if (options.compress && payload.size() >= options.min_compress_bytes) {
    stored.resize(ZSTD_compressBound(payload.size()));
    const size_t n = ZSTD_compress(stored.data(), stored.size(), payload.data(), payload.size(),
                                   std::clamp(options.zstd_level, 1, 19));
    if (!ZSTD_isError(n) && n < payload.size()) {
      stored.resize(n);
      codec = BlobCodec::kZstd;
    }
  }
  if (codec == BlobCodec::kRaw) stored.assign(payload.data(), payload.size());
  std::string blob;
  blob.reserve(kBlobHeaderBytes + stored.size());
  blob.append(kMagic, 4);
  put(&blob, kBlobFormatVersion);
  put(&blob, uint16_t(kind));
  put(&blob, uint8_t(codec));
  blob.append(3, '\0');
  put(&blob, crc32Of(stored));
  put(&blob, uint64_t(payload.size()));
  put(&blob, uint64_t(stored.size()));
  blob += stored;
  return blob;
}

StatusOr<std::string> decodeBlob(BlobKind expected, std::string_view blob) {
  if (blob.size() < kBlobHeaderBytes) {
    return dataLoss(expected, absl::StrFormat("%d bytes, shorter than the %d-byte header",
                                              blob.size(), kBlobHeaderBytes));
  }
  if (std::memcmp(blob.data(), kMagic, 4) != 0) return dataLoss(expected, "not an objdb blob (bad magic)");
  Header h;
  h.version = get<uint16_t>(blob.data() + 4);
  h.kind = get<uint16_t>(blob.data() + 6);
  h.codec = get<uint8_t>(blob.data() + 8);
  h.crc = get<uint32_t>(blob.data() + 12);
  h.payload_bytes = get<uint64_t>(blob.data() + 16);
  h.stored_bytes = get<uint64_t>(blob.data() + 24);
  if (h.version != kBlobFormatVersion) {
    return dataLoss(expected, absl::StrFormat("unsupported blob version %d (this build reads %d)",
                                              h.version, kBlobFormatVersion));
  }
  if (h.kind != uint16_t(expected)) {
    return dataLoss(expected, absl::StrFormat("holds kind %d, expected %d (%s)", h.kind,
                                              int(expected), blobKindName(expected)));
  }
  if (h.stored_bytes != blob.size() - kBlobHeaderBytes) {
    return dataLoss(expected, absl::StrFormat("header says %d payload bytes, found %d",
                                              h.stored_bytes, blob.size() - kBlobHeaderBytes));
  }
  if (h.payload_bytes > kMaxBlobPayloadBytes) {
    return dataLoss(expected, absl::StrFormat("declared size %d is over the %d-byte limit",
                                              h.payload_bytes, kMaxBlobPayloadBytes));
  }
  const std::string_view stored = blob.substr(kBlobHeaderBytes);
  const uint32_t crc = crc32Of(stored);
  if (crc != h.crc) {
    return dataLoss(expected, absl::StrFormat("checksum mismatch (expected %08x, found %08x)",
                                              h.crc, crc));
  }
  if (h.codec == uint8_t(BlobCodec::kRaw)) {
    if (h.payload_bytes != stored.size()) {
      return dataLoss(expected, absl::StrFormat("raw payload of %d bytes, header says %d",
                                                stored.size(), h.payload_bytes));
    }
    return std::string(stored);
  }
  if (h.codec != uint8_t(BlobCodec::kZstd)) {
    return dataLoss(expected, absl::StrFormat("unknown codec %d", h.codec));
  }
  // Streamed in 64 KiB steps: memory grows with what the stream really produces, never with
  // what a damaged header declares (found by fuzzing: a 100-byte blob declaring 256 MB made the
  // decoder allocate them up front). Output beyond the declared size stops the decoding.
  const unsigned long long content = ZSTD_getFrameContentSize(stored.data(), stored.size());
  if (content == ZSTD_CONTENTSIZE_ERROR) return dataLoss(expected, "zstd: not a zstd frame");
  if (content != ZSTD_CONTENTSIZE_UNKNOWN && content != h.payload_bytes) {
    return dataLoss(expected, absl::StrFormat("zstd frame holds %d bytes, header says %d",
                                              content, h.payload_bytes));
  }
  struct FreeDctx {
    void operator()(ZSTD_DCtx* d) const { ZSTD_freeDCtx(d); }
  };
  std::unique_ptr<ZSTD_DCtx, FreeDctx> dctx(ZSTD_createDCtx());
  if (!dctx) return absl::ResourceExhaustedError("zstd: cannot create a decompression context");
  // zstd sizes its window buffer from the frame header: cap it at what the encoder writes
  // (levels ≤ 19 use at most 2^23), so a forged header cannot ask for 128 MiB.
  ZSTD_DCtx_setParameter(dctx.get(), ZSTD_d_windowLogMax, kMaxZstdWindowLog);
  std::string payload;
  const size_t chunk_size = size_t(std::clamp<uint64_t>(h.payload_bytes, 1, uint64_t(1) << 16));
  std::unique_ptr<char[]> chunk(new char[chunk_size]);  // not zero-filled
  ZSTD_inBuffer in{stored.data(), stored.size(), 0};
  size_t remaining_in_frame = 1;
  while (remaining_in_frame != 0) {
    ZSTD_outBuffer out{chunk.get(), chunk_size, 0};
    remaining_in_frame = ZSTD_decompressStream(dctx.get(), &out, &in);
    if (ZSTD_isError(remaining_in_frame)) {
      return dataLoss(expected, absl::StrFormat("zstd: %s", ZSTD_getErrorName(remaining_in_frame)));
    }
    if (payload.size() + out.pos > h.payload_bytes) {
      return dataLoss(expected, absl::StrFormat("decompresses to more than the %d bytes the header "
                                                "says", h.payload_bytes));
    }
    payload.append(chunk.get(), out.pos);
    if (remaining_in_frame != 0 && in.pos == in.size && out.pos < out.size) {
      return dataLoss(expected, "zstd: the stream ends inside its frame");
    }
  }
  if (in.pos != in.size) {
    return dataLoss(expected, absl::StrFormat("%d bytes after the end of the zstd frame",
                                              in.size - in.pos));
  }
  if (payload.size() != h.payload_bytes) {
    return dataLoss(expected, absl::StrFormat("decompressed to %d bytes, header says %d",
                                              payload.size(), h.payload_bytes));
  }
  return payload;
}

std::string encodeTsdfGrid(const tsdf::TsdfLayer& grid, const BlobOptions& options) {
  std::vector<tsdf::BlockIndex> indices;
  indices.reserve(grid.numBlocks());
  for (const auto& [index, block] : grid.blocks()) indices.push_back(index);
  std::sort(indices.begin(), indices.end(), [](const auto& a, const auto& b) {
    return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
  });
  std::string payload;
  put(&payload, grid.voxelSize());
  put(&payload, int32_t(grid.voxelsPerSide()));
  put(&payload, uint32_t(indices.size()));
  for (const auto& b : indices) putArray(&payload, b.data(), 3);
  for (const auto& b : indices) putVoxels(&payload, grid.block(b)->voxels());
  return encodeBlob(BlobKind::kTsdfGrid, payload, options);
}

StatusOr<tsdf::TsdfLayer> decodeTsdfGrid(std::string_view blob) {
  constexpr BlobKind kKind = BlobKind::kTsdfGrid;
  OBJDB_ASSIGN_OR_RETURN(const std::string payload, decodeBlob(kKind, blob));
  Reader reader(kKind, payload);
  OBJDB_ASSIGN_OR_RETURN(const float voxel_size, reader.read<float>());
  OBJDB_ASSIGN_OR_RETURN(const int32_t vps, reader.read<int32_t>());
  auto layer = tsdf::TsdfLayer::create(voxel_size, vps);
  if (!layer.ok()) return dataLoss(kKind, std::string(layer.status().message()));
  OBJDB_ASSIGN_OR_RETURN(const uint32_t n, reader.read<uint32_t>());
  OBJDB_ASSIGN_OR_RETURN(const char* index_bytes, reader.span(n, 3 * sizeof(int32_t)));
  for (uint32_t i = 0; i < n; ++i) {
    tsdf::BlockIndex b;
    readArray(index_bytes + 12 * size_t(i), 3, b.data());
    if (layer->block(b) != nullptr) {
      return dataLoss(kKind, absl::StrFormat("block (%d, %d, %d) stored twice", b.x(), b.y(), b.z()));
    }
    tsdf::TsdfBlock& block = layer->allocateBlock(b);
    OBJDB_RETURN_IF_ERROR(readVoxels(&reader, kKind, &block.voxels()));
  }
  OBJDB_RETURN_IF_ERROR(reader.finish());
  return std::move(*layer);
}

std::string encodeTsdfBlock(const tsdf::TsdfBlock& block, const BlobOptions& options) {
  std::string payload;
  putVoxels(&payload, block.voxels());
  return encodeBlob(BlobKind::kTsdfBlock, payload, options);
}

Status decodeTsdfBlock(std::string_view blob, int voxels_per_side, tsdf::TsdfBlock* block) {
  constexpr BlobKind kKind = BlobKind::kTsdfBlock;
  OBJDB_ASSIGN_OR_RETURN(const std::string payload, decodeBlob(kKind, blob));
  Reader reader(kKind, payload);
  if (block->voxels().size() != size_t(voxels_per_side) * voxels_per_side * voxels_per_side) {
    return absl::InvalidArgumentError("decodeTsdfBlock: block size does not match voxels_per_side");
  }
  OBJDB_RETURN_IF_ERROR(readVoxels(&reader, kKind, &block->voxels()));
  return reader.finish();
}

std::string encodePointCloud(const PointCloud& cloud, const BlobOptions& options) {
  const size_t n = cloud.points.size();
  const bool normals = cloud.normals.size() == n && n > 0;
  const bool colors = cloud.colors.size() == n && n > 0;
  std::string payload;
  put(&payload, uint32_t(n));
  put(&payload, uint8_t(normals));
  put(&payload, uint8_t(colors));
  for (const auto& p : cloud.points) putArray(&payload, p.data(), 3);
  if (normals) {
    for (const auto& v : cloud.normals) putArray(&payload, v.data(), 3);
  }
  if (colors) {
    for (const auto& c : cloud.colors) {
      put(&payload, c.r);
      put(&payload, c.g);
      put(&payload, c.b);
    }
  }
  return encodeBlob(BlobKind::kPointCloud, payload, options);
}

StatusOr<PointCloud> decodePointCloud(std::string_view blob) {
  constexpr BlobKind kKind = BlobKind::kPointCloud;
  OBJDB_ASSIGN_OR_RETURN(const std::string payload, decodeBlob(kKind, blob));
  Reader reader(kKind, payload);
  OBJDB_ASSIGN_OR_RETURN(const uint32_t n, reader.read<uint32_t>());
  OBJDB_ASSIGN_OR_RETURN(const uint8_t normals, reader.read<uint8_t>());
  OBJDB_ASSIGN_OR_RETURN(const uint8_t colors, reader.read<uint8_t>());
  if (normals > 1 || colors > 1) return dataLoss(kKind, "bad flags");
  PointCloud cloud;
  OBJDB_ASSIGN_OR_RETURN(const char* points, reader.span(n, 12));
  cloud.points.resize(n);
  for (uint32_t i = 0; i < n; ++i) readArray(points + 12 * size_t(i), 3, cloud.points[i].data());
  if (normals) {
    OBJDB_ASSIGN_OR_RETURN(const char* bytes, reader.span(n, 12));
    cloud.normals.resize(n);
    for (uint32_t i = 0; i < n; ++i) readArray(bytes + 12 * size_t(i), 3, cloud.normals[i].data());
  }
  if (colors) {
    OBJDB_ASSIGN_OR_RETURN(const char* bytes, reader.span(n, 3));
    cloud.colors.resize(n);
    for (uint32_t i = 0; i < n; ++i) {
      cloud.colors[i] = {uint8_t(bytes[3 * size_t(i)]), uint8_t(bytes[3 * size_t(i) + 1]),
                         uint8_t(bytes[3 * size_t(i) + 2])};
    }
  }
  OBJDB_RETURN_IF_ERROR(reader.finish());
  return cloud;
}

namespace {

std::string encodeU32List(BlobKind kind, const std::vector<uint32_t>& values,
                          const BlobOptions& options) {
  std::string payload;
  put(&payload, uint32_t(values.size()));
  putArray(&payload, values.data(), values.size());
  return encodeBlob(kind, payload, options);
}

StatusOr<std::vector<uint32_t>> decodeU32List(BlobKind kind, std::string_view blob) {
  const BlobKind kKind = kind;
  OBJDB_ASSIGN_OR_RETURN(const std::string payload, decodeBlob(kKind, blob));
  Reader reader(kKind, payload);
  OBJDB_ASSIGN_OR_RETURN(const uint32_t n, reader.read<uint32_t>());
  OBJDB_ASSIGN_OR_RETURN(const char* bytes, reader.span(n, 4));
  std::vector<uint32_t> values(n);
  readArray(bytes, n, values.data());
  OBJDB_RETURN_IF_ERROR(reader.finish());
  return values;
}

}  // namespace

std::string encodeIndices(const std::vector<uint32_t>& indices, const BlobOptions& options) {
  return encodeU32List(BlobKind::kIndices, indices, options);
}
StatusOr<std::vector<uint32_t>> decodeIndices(std::string_view blob) {
  return decodeU32List(BlobKind::kIndices, blob);
}
std::string encodeLabelBlock(const std::vector<uint32_t>& labels, const BlobOptions& options) {
  return encodeU32List(BlobKind::kLabelBlock, labels, options);
}
StatusOr<std::vector<uint32_t>> decodeLabelBlock(std::string_view blob) {
  return decodeU32List(BlobKind::kLabelBlock, blob);
}

std::string encodeDescriptors(const std::vector<model::Fpfh>& descriptors,
                              const BlobOptions& options) {
  std::string payload;
  put(&payload, uint32_t(descriptors.size()));
  put(&payload, uint32_t(std::tuple_size_v<model::Fpfh>));
  for (const auto& d : descriptors) putArray(&payload, d.data(), d.size());
  return encodeBlob(BlobKind::kDescriptors, payload, options);
}

StatusOr<std::vector<model::Fpfh>> decodeDescriptors(std::string_view blob) {
  constexpr BlobKind kKind = BlobKind::kDescriptors;
  constexpr uint32_t kDims = std::tuple_size_v<model::Fpfh>;
  OBJDB_ASSIGN_OR_RETURN(const std::string payload, decodeBlob(kKind, blob));
  Reader reader(kKind, payload);
  OBJDB_ASSIGN_OR_RETURN(const uint32_t n, reader.read<uint32_t>());
  OBJDB_ASSIGN_OR_RETURN(const uint32_t dims, reader.read<uint32_t>());
  if (dims != kDims) {
    return dataLoss(kKind, absl::StrFormat("descriptors of %d bins, expected %d", dims, kDims));
  }
  OBJDB_ASSIGN_OR_RETURN(const char* bytes, reader.span(n, kDims * sizeof(float)));
  std::vector<model::Fpfh> descriptors(n);
  for (uint32_t i = 0; i < n; ++i) {
    readArray(bytes + kDims * sizeof(float) * size_t(i), kDims, descriptors[i].data());
  }
  OBJDB_RETURN_IF_ERROR(reader.finish());
  return descriptors;
}

std::string encodeGlobalDescriptor(const GlobalDescriptorBlob& descriptor,
                                   const BlobOptions& options) {
  std::string payload;
  put(&payload, uint32_t(descriptor.codebook_version));
  put(&payload, uint32_t(descriptor.values.size()));
  putArray(&payload, descriptor.values.data(), descriptor.values.size());
  return encodeBlob(BlobKind::kGlobalDescriptor, payload, options);
}

StatusOr<GlobalDescriptorBlob> decodeGlobalDescriptor(std::string_view blob) {
  constexpr BlobKind kKind = BlobKind::kGlobalDescriptor;
  OBJDB_ASSIGN_OR_RETURN(const std::string payload, decodeBlob(kKind, blob));
  Reader reader(kKind, payload);
  GlobalDescriptorBlob out;
  OBJDB_ASSIGN_OR_RETURN(const uint32_t version, reader.read<uint32_t>());
  OBJDB_ASSIGN_OR_RETURN(const uint32_t n, reader.read<uint32_t>());
  OBJDB_ASSIGN_OR_RETURN(const char* bytes, reader.span(n, sizeof(float)));
  out.codebook_version = int(version);
  out.values.resize(n);
  readArray(bytes, n, out.values.data());
  OBJDB_RETURN_IF_ERROR(reader.finish());
  return out;
}

std::string encodeVoxelList(const std::vector<tsdf::VoxelIndex>& voxels,
                            const BlobOptions& options) {
  std::string payload;
  put(&payload, uint32_t(voxels.size()));
  for (const auto& v : voxels) putArray(&payload, v.data(), 3);
  return encodeBlob(BlobKind::kVoxelList, payload, options);
}

StatusOr<std::vector<tsdf::VoxelIndex>> decodeVoxelList(std::string_view blob) {
  constexpr BlobKind kKind = BlobKind::kVoxelList;
  OBJDB_ASSIGN_OR_RETURN(const std::string payload, decodeBlob(kKind, blob));
  Reader reader(kKind, payload);
  OBJDB_ASSIGN_OR_RETURN(const uint32_t n, reader.read<uint32_t>());
  OBJDB_ASSIGN_OR_RETURN(const char* bytes, reader.span(n, 12));
  std::vector<tsdf::VoxelIndex> voxels(n);
  for (uint32_t i = 0; i < n; ++i) readArray(bytes + 12 * size_t(i), 3, voxels[i].data());
  OBJDB_RETURN_IF_ERROR(reader.finish());
  return voxels;
}

std::string encodeTransform(const Transform& T) {
  std::string payload;
  const Eigen::Matrix3d R = T.linear();
  putArray(&payload, R.data(), 9);
  const Eigen::Vector3d t = T.translation();
  putArray(&payload, t.data(), 3);
  BlobOptions raw;
  raw.compress = false;
  return encodeBlob(BlobKind::kTransform, payload, raw);
}

StatusOr<Transform> decodeTransform(std::string_view blob) {
  constexpr BlobKind kKind = BlobKind::kTransform;
  OBJDB_ASSIGN_OR_RETURN(const std::string payload, decodeBlob(kKind, blob));
  Reader reader(kKind, payload);
  OBJDB_ASSIGN_OR_RETURN(const char* bytes, reader.span(12, sizeof(double)));
  OBJDB_RETURN_IF_ERROR(reader.finish());
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  readArray(bytes, 9, R.data());
  readArray(bytes + 9 * sizeof(double), 3, t.data());
  if (!R.allFinite() || !t.allFinite()) return dataLoss(kKind, "a value is not finite");
  const double error = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (!(error <= 1e-6)) {
    return dataLoss(kKind, absl::StrFormat("rotation is not orthonormal (|RᵀR − I| = %g)", error));
  }
  Transform T = Transform::Identity();
  T.linear() = R;
  T.translation() = t;
  return T;
}

}  // namespace objdb::storage

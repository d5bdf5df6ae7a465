#include "tests/fuzz/fuzz_targets.h"

#include <cmath>
#include <cstdint>
#include <string_view>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/common/params_io.h"
#include "core/sim/generator.h"
#include "core/sim/lounge.h"
#include "objdb/v1/objdb.pb.h"
#include "server/proto_convert.h"
#include "storage/blob_codec.h"

namespace objdb::fuzz {
namespace {

// Frames are decoded against a small camera so that the fuzzer spends its time in the decoders,
// not in copying megabytes.
Intrinsics fuzzCamera() {
  Intrinsics k;
  k.width = 40;
  k.height = 30;
  k.fx = k.fy = 36.0;
  k.cx = 19.5;
  k.cy = 14.5;
  return k;
}

Outcome outcome(bool ok) { return ok ? Outcome::kAccepted : Outcome::kRejected; }

// Blob decoders by the selector byte. The typed ones get the rest of the input as a payload,
// wrapped into a valid blob so that the fuzzer is not stopped by the CRC.
enum Mode : uint8_t {
  kWholeBlob = 0,  // header checks of decodeBlob
  kGrid,
  kBlock,
  kCloud,
  kIndices,
  kLabels,
  kDescriptors,
  kVoxels,
  kTransform,
  kWholeGrid,  // decodeTsdfGrid on the bytes as a blob (compressed payloads included)
  kModes
};

storage::BlobKind kindOf(uint8_t mode) {
  switch (mode) {
    case kGrid:
    case kWholeGrid:
      return storage::BlobKind::kTsdfGrid;
    case kBlock:
      return storage::BlobKind::kTsdfBlock;
    case kCloud:
      return storage::BlobKind::kPointCloud;
    case kIndices:
      return storage::BlobKind::kIndices;
    case kLabels:
      return storage::BlobKind::kLabelBlock;
    case kDescriptors:
      return storage::BlobKind::kDescriptors;
    case kVoxels:
      return storage::BlobKind::kVoxelList;
    default:
      return storage::BlobKind::kTransform;
  }
}

std::string withSelector(uint8_t mode, std::string_view bytes) {
  return std::string(1, char(mode)) + std::string(bytes);
}

// The payload of a valid blob, behind its selector byte.
std::string payloadSeed(uint8_t mode, const std::string& blob) {
  const auto payload = storage::decodeBlob(kindOf(mode), blob);
  return payload.ok() ? withSelector(mode, *payload) : std::string();
}

tsdf::TsdfLayer sampleGrid() {
  tsdf::TsdfLayer grid = tsdf::TsdfLayer::create(0.02f, 8).value();
  for (int b = 0; b < 3; ++b) {
    tsdf::TsdfBlock& block = grid.allocateBlock(tsdf::BlockIndex(b, -b, 1));
    for (size_t i = 0; i < block.voxels().size(); ++i) {
      block.voxel(i).distance = 0.01f * std::sin(float(i));
      block.voxel(i).weight = float(i % 5);
      block.voxel(i).color = Rgb8{uint8_t(i), uint8_t(2 * i), uint8_t(3 * i)};
    }
  }
  return grid;
}

std::string serialized(const v1::IngestRequest& request) {
  std::string bytes;
  request.SerializeToString(&bytes);
  return bytes;
}

}  // namespace

Outcome frame(const uint8_t* data, size_t size) {
  v1::IngestRequest request;
  if (size > size_t(INT32_MAX) || !request.ParseFromArray(data, int(size))) {
    return Outcome::kRejected;
  }
  if (request.has_header()) {
    const v1::SessionHeader& header = request.header();
    const StatusOr<Intrinsics> k = server::fromProto(header.intrinsics(), "header.intrinsics");
    Params params;
    const bool params_ok =
        header.params_json().empty() || applyParamsJson(header.params_json(), &params).ok();
    return outcome(k.ok() && params_ok);
  }
  if (!request.has_frame()) return Outcome::kRejected;
  const v1::Frame& f = request.frame();
  const Intrinsics k = fuzzCamera();
  const StatusOr<Transform> pose = server::fromProto(f.t_world_camera(), "frame.T_world_camera");
  server::DepthCounts counts;
  const StatusOr<DepthImage> depth = server::decodeDepth(f.depth(), k, &counts);
  bool ok = pose.ok() && depth.ok();
  if (f.has_color()) ok &= server::decodeColor(f.color(), k.width, k.height).ok();
  return outcome(ok);
}

Outcome blob(const uint8_t* data, size_t size) {
  if (size == 0) return Outcome::kRejected;
  const uint8_t mode = data[0] % kModes;
  const std::string_view rest(reinterpret_cast<const char*>(data + 1), size - 1);
  if (mode == kWholeBlob) {
    const auto kind = storage::BlobKind(1 + (data[0] / kModes) % 8);  // the selector's high part
    return outcome(storage::decodeBlob(kind, rest).ok());
  }
  if (mode == kWholeGrid) return outcome(storage::decodeTsdfGrid(rest).ok());
  storage::BlobOptions raw;
  raw.compress = false;
  const std::string wrapped = storage::encodeBlob(kindOf(mode), rest, raw);
  switch (mode) {
    case kGrid:
      return outcome(storage::decodeTsdfGrid(wrapped).ok());
    case kBlock: {
      tsdf::TsdfBlock block(8);
      return outcome(storage::decodeTsdfBlock(wrapped, 8, &block).ok());
    }
    case kCloud:
      return outcome(storage::decodePointCloud(wrapped).ok());
    case kIndices:
      return outcome(storage::decodeIndices(wrapped).ok());
    case kLabels:
      return outcome(storage::decodeLabelBlock(wrapped).ok());
    case kDescriptors:
      return outcome(storage::decodeDescriptors(wrapped).ok());
    case kVoxels:
      return outcome(storage::decodeVoxelList(wrapped).ok());
    default:
      return outcome(storage::decodeTransform(wrapped).ok());
  }
}

Outcome config(const uint8_t* data, size_t size) {
  Params params;
  const absl::string_view text(reinterpret_cast<const char*>(data), size);
  return outcome(applyParamsJson(text, &params).ok());
}

const std::vector<Target>& targets() {
  static const std::vector<Target> all = {{"frame", &frame}, {"blob", &blob}, {"config", &config}};
  return all;
}

std::vector<std::string> seeds(const std::string& target) {
  std::vector<std::string> out;
  if (target == "frame") {
    const Intrinsics k = fuzzCamera();
    v1::IngestRequest header;
    header.mutable_header()->set_session_name("fuzz-1");
    *header.mutable_header()->mutable_intrinsics() = server::toProto(k);
    out.push_back(serialized(header));
    header.mutable_header()->set_params_json(R"({"tsdf": {"voxel_size_m": 0.01}})");
    out.push_back(serialized(header));

    sim::Scene scene = sim::twoBoxesScene("tango", 2);
    scene.intrinsics = k;
    const sim::BuiltScene built = sim::buildScene(scene).value();
    const auto poses = sim::sampleTrajectory(scene.trajectory).value();
    const sim::Renderer renderer(scene.intrinsics);
    const Frame rendered = sim::renderFrame(scene, built, renderer, poses.front(), 0, true);
    v1::IngestRequest request;
    v1::Frame* f = request.mutable_frame();
    f->set_index(7);
    f->set_timestamp_s(1.5);
    *f->mutable_t_world_camera() = server::toProto(rendered.T_world_camera);
    *f->mutable_depth() = server::encodeDepth(rendered.depth);  // FLOAT32
    if (rendered.color) *f->mutable_color() = server::encodeColor(*rendered.color);  // RGB8
    out.push_back(serialized(request));

    // UINT16 millimetres, PNG16 of the same, PNG and JPEG colour.
    cv::Mat mm(k.height, k.width, CV_16U);
    for (int v = 0; v < k.height; ++v) {
      for (int u = 0; u < k.width; ++u) {
        mm.at<uint16_t>(v, u) = uint16_t(std::lround(rendered.depth.at(u, v) * 1000.0f));
      }
    }
    v1::DepthImage* d = f->mutable_depth();
    d->set_encoding(v1::DepthImage::UINT16);
    d->set_metres_per_unit(0.001);
    d->set_data(std::string(reinterpret_cast<const char*>(mm.data), mm.total() * 2));
    f->clear_color();
    out.push_back(serialized(request));
    std::vector<uchar> png;
    cv::imencode(".png", mm, png);
    d->set_encoding(v1::DepthImage::PNG16);
    d->set_data(std::string(png.begin(), png.end()));
    if (rendered.color) {
      cv::Mat bgr(k.height, k.width, CV_8UC3);
      for (int v = 0; v < k.height; ++v) {
        for (int u = 0; u < k.width; ++u) {
          const Rgb8 c = rendered.color->at(u, v);
          bgr.at<cv::Vec3b>(v, u) = cv::Vec3b(c.b, c.g, c.r);
        }
      }
      for (const auto& [ext, encoding] :
           {std::pair{".png", v1::ColorImage::PNG}, std::pair{".jpg", v1::ColorImage::JPEG}}) {
        std::vector<uchar> bytes;
        cv::imencode(ext, bgr, bytes);
        v1::ColorImage* c = f->mutable_color();
        c->set_width(uint32_t(k.width));
        c->set_height(uint32_t(k.height));
        c->set_encoding(encoding);
        c->set_data(std::string(bytes.begin(), bytes.end()));
        out.push_back(serialized(request));
      }
    }
  } else if (target == "blob") {
    const tsdf::TsdfLayer grid = sampleGrid();
    const std::string grid_blob = storage::encodeTsdfGrid(grid);
    out.push_back(withSelector(kWholeGrid, grid_blob));
    out.push_back(withSelector(kWholeBlob, grid_blob));
    out.push_back(payloadSeed(kGrid, grid_blob));
    const tsdf::TsdfBlock* block = grid.block(tsdf::BlockIndex(0, 0, 1));
    out.push_back(payloadSeed(kBlock, storage::encodeTsdfBlock(*block)));
    PointCloud cloud;
    for (int i = 0; i < 20; ++i) {
      cloud.points.emplace_back(0.01f * i, 0.5f, -0.2f * i);
      cloud.normals.emplace_back(0.0f, 0.0f, 1.0f);
      cloud.colors.push_back(Rgb8{uint8_t(i), 9, 200});
    }
    out.push_back(payloadSeed(kCloud, storage::encodePointCloud(cloud)));
    out.push_back(payloadSeed(kIndices, storage::encodeIndices({1, 5, 9, 4000000000u})));
    out.push_back(payloadSeed(kLabels, storage::encodeLabelBlock(std::vector<uint32_t>(512, 3))));
    std::vector<model::Fpfh> descriptors(3);
    for (size_t i = 0; i < descriptors.size(); ++i) descriptors[i].fill(float(i) + 0.5f);
    out.push_back(payloadSeed(kDescriptors, storage::encodeDescriptors(descriptors)));
    out.push_back(payloadSeed(
        kVoxels, storage::encodeVoxelList({tsdf::VoxelIndex(1, 2, 3), tsdf::VoxelIndex(-4, 0, 9)})));
    Transform T = Transform::Identity();
    T.translation() = Eigen::Vector3d(1, 2, 3);
    out.push_back(payloadSeed(kTransform, storage::encodeTransform(T)));
  } else if (target == "config") {
    out.push_back("{}");
    out.push_back(R"({"tsdf": {"voxel_size_m": 0.01, "truncation_voxels": 4}})");
    out.push_back(R"({"segmentation": {"min_segment_px": 300}, "matching": {"k_nn": 8}})");
    out.push_back(paramsToJson(Params()));
  }
  return out;
}

}  // namespace objdb::fuzz

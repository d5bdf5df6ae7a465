#include "core/io/objdb_dataset.h"

#include <cmath>

#include "core/common/logging.h"
#include "core/io/image_io.h"
#include "core/io/io_util.h"
#include "core/io/tum_dataset.h"

namespace objdb::io {
namespace {
namespace fs = std::filesystem;

constexpr const char* kScaleKey = "depth_scale_m";
constexpr double kDefaultMetresPerUnit = 0.001;

std::string frameFileName(size_t index) { return absl::StrFormat("%06d.png", index); }

Status checkScale(double metres_per_unit) {
  if (std::isfinite(metres_per_unit) && metres_per_unit > 0.0) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrFormat(
      "depth scale must be finite and > 0 metres per unit (got %g)", metres_per_unit));
}

}  // namespace

StatusOr<Intrinsics> readIntrinsicsJson(const fs::path& path, double* metres_per_unit) {
  OBJDB_ASSIGN_OR_RETURN(const auto file, internal::readIntrinsicsFile(path, kScaleKey));
  if (metres_per_unit) *metres_per_unit = file.depth_scale.value_or(kDefaultMetresPerUnit);
  return file.intrinsics;
}

Status writeIntrinsicsJson(const fs::path& path, const Intrinsics& intrinsics,
                           double metres_per_unit) {
  return internal::writeIntrinsicsFile(path, intrinsics, kScaleKey, metres_per_unit);
}

StatusOr<std::unique_ptr<ObjdbDataset>> ObjdbDataset::open(const fs::path& root,
                                                           const DatasetOptions& options) {
  OBJDB_RETURN_IF_ERROR(internal::checkDirectory(root, "objdb dataset folder"));
  auto dataset = std::unique_ptr<ObjdbDataset>(new ObjdbDataset());
  dataset->root_ = root;
  std::error_code ec;
  const fs::path intrinsics_path = root / "intrinsics.json";
  if (fs::exists(intrinsics_path, ec)) {
    OBJDB_ASSIGN_OR_RETURN(dataset->intrinsics_,
                           readIntrinsicsJson(intrinsics_path, &dataset->metres_per_unit_));
  } else if (!options.intrinsics) {
    return absl::NotFoundError(
        absl::StrCat("objdb dataset ", root.string(), " has no intrinsics.json"));
  }
  if (options.intrinsics) {
    OBJDB_RETURN_IF_ERROR(annotate(options.intrinsics->validate(), "intrinsics override"));
    dataset->intrinsics_ = *options.intrinsics;
  }
  OBJDB_ASSIGN_OR_RETURN(dataset->poses_, readTumTrajectory(root / "poses.txt"));
  dataset->has_color_ = fs::is_directory(root / "color", ec);
  dataset->has_instances_ = fs::is_directory(root / "instances", ec);
  const fs::path objects_path = root / "objects.json";
  if (fs::exists(objects_path, ec)) {
    OBJDB_ASSIGN_OR_RETURN(dataset->objects_, readObjectsJson(objects_path));
  }
  logger("io")->debug("opened objdb dataset {}: {} frames{}{}, {} ground-truth objects, {}",
                     root.string(), dataset->poses_.size(), dataset->has_color_ ? ", colour" : "",
                     dataset->has_instances_ ? ", instances" : "", dataset->objects_.size(),
                     toString(dataset->intrinsics_));
  return dataset;
}

StatusOr<Frame> ObjdbDataset::loadFrame(size_t i) const {
  if (!(i < poses_.size())) {
    return absl::OutOfRangeError(absl::StrFormat("frame %d is out of range: %s has %d frames", i,
                                                 root_.string(), poses_.size()));
  }
  const std::string name = frameFileName(i);
  Frame frame;
  frame.index = i;
  frame.timestamp = poses_[i].timestamp;
  OBJDB_ASSIGN_OR_RETURN(frame.T_world_camera, transformFromTumPose(poses_[i]));

  const fs::path depth_path = root_ / "depth" / name;
  OBJDB_ASSIGN_OR_RETURN(const RawDepthImage raw, readUint16Png(depth_path));
  OBJDB_RETURN_IF_ERROR(intrinsics_.checkImageSize(
      raw.width, raw.height, absl::StrCat("depth image ", depth_path.string())));
  OBJDB_ASSIGN_OR_RETURN(frame.depth, depthFromRaw(raw, metres_per_unit_));

  if (has_color_) {
    const fs::path color_path = root_ / "color" / name;
    OBJDB_ASSIGN_OR_RETURN(ColorImage color, readColorImage(color_path));
    OBJDB_RETURN_IF_ERROR(intrinsics_.checkImageSize(
        color.width, color.height, absl::StrCat("colour image ", color_path.string())));
    frame.color = std::move(color);
  }
  if (has_instances_) {
    OBJDB_ASSIGN_OR_RETURN(frame.instances,
                           readInstanceImage(root_ / "instances" / name, intrinsics_));
  }
  return frame;
}

StatusOr<std::unique_ptr<ObjdbDatasetWriter>> ObjdbDatasetWriter::create(
    const fs::path& root, const Intrinsics& intrinsics, double metres_per_unit, bool overwrite) {
  OBJDB_RETURN_IF_ERROR(annotate(intrinsics.validate(), "objdb dataset writer"));
  OBJDB_RETURN_IF_ERROR(annotate(checkScale(metres_per_unit), "objdb dataset writer"));
  std::error_code ec;
  if (fs::exists(root / "poses.txt", ec)) {
    if (!overwrite) {
      return absl::AlreadyExistsError(absl::StrCat(
          root.string(), " already holds an objdb dataset (poses.txt); refusing to overwrite it"));
    }
    // poses.txt goes first: from here on the folder no longer claims to hold a whole dataset.
    for (const char* name : {"poses.txt", "objects.json", "intrinsics.json"}) {
      fs::remove(root / name, ec);
    }
    for (const char* name : {"depth", "color", "instances"}) fs::remove_all(root / name, ec);
  }
  fs::create_directories(root / "depth", ec);
  if (ec) {
    return absl::UnavailableError(
        absl::StrCat("cannot create ", (root / "depth").string(), ": ", ec.message()));
  }
  OBJDB_RETURN_IF_ERROR(writeIntrinsicsJson(root / "intrinsics.json", intrinsics, metres_per_unit));
  auto writer = std::unique_ptr<ObjdbDatasetWriter>(new ObjdbDatasetWriter());
  writer->root_ = root;
  writer->intrinsics_ = intrinsics;
  writer->metres_per_unit_ = metres_per_unit;
  return writer;
}

Status ObjdbDatasetWriter::addFrame(const Frame& frame) {
  if (finished_) {
    return absl::FailedPreconditionError("objdb dataset writer is already finished");
  }
  const size_t index = poses_.size();
  if (frame.index != index) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "frames must be added in order: expected frame %d, got frame %d", index, frame.index));
  }
  if (!std::isfinite(frame.timestamp)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("frame %d has a non-finite timestamp", index));
  }
  // Colour and instances are per dataset: the reader expects them on every frame or none.
  if (index == 0) {
    has_color_ = frame.color.has_value();
    has_instances_ = frame.instances.has_value();
  } else if (frame.color.has_value() != has_color_ ||
             frame.instances.has_value() != has_instances_) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "frame %d has colour=%s instances=%s but frame 0 had colour=%s instances=%s; every "
        "frame of a dataset must carry the same images",
        index, frame.color ? "yes" : "no", frame.instances ? "yes" : "no",
        has_color_ ? "yes" : "no", has_instances_ ? "yes" : "no"));
  }
  OBJDB_RETURN_IF_ERROR(validateFrame(frame, intrinsics_));
  size_t clipped = 0;
  OBJDB_ASSIGN_OR_RETURN(const RawDepthImage raw,
                         depthToRaw(frame.depth, metres_per_unit_, &clipped));
  const std::string name = frameFileName(index);
  OBJDB_RETURN_IF_ERROR(writeUint16Png(root_ / "depth" / name, raw));
  std::error_code ec;
  if (frame.color) {
    fs::create_directories(root_ / "color", ec);
    OBJDB_RETURN_IF_ERROR(writeColorPng(root_ / "color" / name, *frame.color));
  }
  if (frame.instances) {
    fs::create_directories(root_ / "instances", ec);
    OBJDB_RETURN_IF_ERROR(writeUint16Png(root_ / "instances" / name, *frame.instances));
  }
  clipped_ += clipped;
  poses_.push_back(tumPoseFromTransform(frame.T_world_camera, frame.timestamp));
  return absl::OkStatus();
}

Status ObjdbDatasetWriter::finish(const std::vector<GroundTruthObject>& objects) {
  if (finished_) {
    return absl::FailedPreconditionError("objdb dataset writer is already finished");
  }
  if (!objects.empty()) {
    OBJDB_RETURN_IF_ERROR(writeObjectsJson(root_ / "objects.json", objects));
  }
  // poses.txt last: its presence marks a complete dataset.
  OBJDB_RETURN_IF_ERROR(writeTumTrajectory(
      root_ / "poses.txt", poses_,
      "objdb dataset: T_world_camera per frame, line k = frame k (depth/k.png)"));
  finished_ = true;
  if (clipped_ > 0) {
    logger("io")->warn("{}: {} depth values beyond {:.3f} m were written as 0", root_.string(),
                       clipped_, 65535.0 * metres_per_unit_);
  }
  return absl::OkStatus();
}

}  // namespace objdb::io

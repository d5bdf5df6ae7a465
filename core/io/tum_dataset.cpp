#include "core/io/tum_dataset.h"

#include <algorithm>
#include <cmath>

#include "core/common/logging.h"
#include "core/io/image_io.h"
#include "core/io/io_util.h"

namespace objdb::io {
namespace {
namespace fs = std::filesystem;

// A path from a list file must stay inside the dataset folder.
bool isSafeRelativePath(absl::string_view text) {
  const fs::path path{std::string(text)};
  if (path.empty() || path.is_absolute() || path.has_root_name()) return false;
  for (const auto& part : path) {
    if (part == "..") return false;
  }
  return true;
}

// Index of the entry whose time is nearest to `t` in `times` (sorted), or -1 when none lies
// within `max_dt`.
long nearestWithin(const std::vector<std::pair<double, size_t>>& times, double t, double max_dt) {
  if (times.empty()) return -1;
  const auto it = std::lower_bound(times.begin(), times.end(), std::make_pair(t, size_t{0}));
  long best = -1;
  double best_dt = 0.0;
  const auto consider = [&](std::vector<std::pair<double, size_t>>::const_iterator c) {
    const double dt = std::abs(c->first - t);
    if (dt <= max_dt && (best < 0 || dt < best_dt)) {
      best = static_cast<long>(c->second);
      best_dt = dt;
    }
  };
  if (it != times.end()) consider(it);
  if (it != times.begin()) consider(std::prev(it));
  return best;
}

template <typename T>
std::vector<std::pair<double, size_t>> sortedTimes(const std::vector<T>& entries) {
  std::vector<std::pair<double, size_t>> times;
  times.reserve(entries.size());
  for (size_t i = 0; i < entries.size(); ++i) times.emplace_back(entries[i].timestamp, i);
  std::sort(times.begin(), times.end());
  return times;
}

std::string frameFileName(size_t index) { return absl::StrFormat("%06d.png", index); }

Status writeTumList(const fs::path& path, const std::vector<TumEntry>& entries,
                    absl::string_view comment) {
  std::string text = absl::StrCat("# ", comment, "\n# timestamp filename\n");
  for (const auto& e : entries) {
    absl::StrAppend(&text, internal::formatDouble(e.timestamp), " ", e.path, "\n");
  }
  return internal::writeFileAtomic(path, text);
}

}  // namespace

StatusOr<std::vector<TumEntry>> readTumList(const fs::path& path) {
  OBJDB_ASSIGN_OR_RETURN(const std::string text, internal::readFile(path));
  internal::LineReader lines(text, path.string());
  std::vector<TumEntry> entries;
  absl::string_view line;
  while (lines.next(&line)) {
    if (internal::isCommentOrBlank(line)) continue;
    const auto fields = internal::splitFields(line);
    if (fields.size() != 2) {
      return lines.error(
          absl::StrFormat("expected 'timestamp path', got %d fields", fields.size()));
    }
    TumEntry entry;
    if (!(internal::parseDouble(fields[0], &entry.timestamp) && std::isfinite(entry.timestamp))) {
      return lines.error(absl::StrCat("timestamp '", fields[0], "' is not a finite number"));
    }
    if (!isSafeRelativePath(fields[1])) {
      return lines.error(absl::StrCat("path '", fields[1],
                                      "' must be relative to the dataset folder, without '..'"));
    }
    entry.path = std::string(fields[1]);
    entries.push_back(std::move(entry));
  }
  OBJDB_RETURN_IF_ERROR(lines.status());
  return entries;
}

StatusOr<std::vector<TumPose>> readTumTrajectory(const fs::path& path) {
  OBJDB_ASSIGN_OR_RETURN(const std::string text, internal::readFile(path));
  internal::LineReader lines(text, path.string());
  std::vector<TumPose> poses;
  absl::string_view line;
  static constexpr const char* kNames[8] = {"timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw"};
  while (lines.next(&line)) {
    if (internal::isCommentOrBlank(line)) continue;
    const auto fields = internal::splitFields(line);
    if (fields.size() != 8) {
      return lines.error(absl::StrFormat(
          "expected 8 fields 'timestamp tx ty tz qx qy qz qw', got %d", fields.size()));
    }
    double values[8];
    for (int k = 0; k < 8; ++k) {
      if (!(internal::parseDouble(fields[k], &values[k]) && std::isfinite(values[k]))) {
        return lines.error(absl::StrCat(kNames[k], " '", fields[k], "' is not a finite number"));
      }
    }
    TumPose pose;
    pose.timestamp = values[0];
    pose.t = Eigen::Vector3d(values[1], values[2], values[3]);
    pose.q_xyzw = {values[4], values[5], values[6], values[7]};
    const auto T = transformFromTumPose(pose);
    if (!T.ok()) return lines.error(T.status().message());
    poses.push_back(pose);
  }
  OBJDB_RETURN_IF_ERROR(lines.status());
  return poses;
}

Status writeTumTrajectory(const fs::path& path, const std::vector<TumPose>& poses,
                          absl::string_view comment) {
  std::string text;
  if (!comment.empty()) {
    size_t start = 0;
    while (start <= comment.size()) {
      size_t end = comment.find('\n', start);
      if (end == absl::string_view::npos) end = comment.size();
      absl::StrAppend(&text, "# ", comment.substr(start, end - start), "\n");
      start = end + 1;
    }
  }
  text += "# timestamp tx ty tz qx qy qz qw\n";
  for (size_t i = 0; i < poses.size(); ++i) {
    const TumPose& p = poses[i];
    if (!std::isfinite(p.timestamp)) {
      return absl::InvalidArgumentError(
          absl::StrFormat("writing %s: pose %d has a non-finite timestamp", path.string(), i));
    }
    OBJDB_RETURN_IF_ERROR(annotate(transformFromTumPose(p).status(),
                                   absl::StrFormat("writing %s: pose %d", path.string(), i)));
    absl::StrAppend(&text, internal::formatDouble(p.timestamp));
    for (int k = 0; k < 3; ++k) absl::StrAppend(&text, " ", internal::formatDouble(p.t[k]));
    for (int k = 0; k < 4; ++k) absl::StrAppend(&text, " ", internal::formatDouble(p.q_xyzw[k]));
    text += '\n';
  }
  return internal::writeFileAtomic(path, text);
}

StatusOr<std::unique_ptr<TumDataset>> TumDataset::open(const fs::path& root,
                                                       const DatasetOptions& options) {
  OBJDB_RETURN_IF_ERROR(internal::checkDirectory(root, "TUM dataset folder"));
  if (!(std::isfinite(options.max_time_difference_s) && options.max_time_difference_s >= 0.0)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "max_time_difference_s must be finite and >= 0 (got %g)", options.max_time_difference_s));
  }
  auto dataset = std::unique_ptr<TumDataset>(new TumDataset());
  dataset->root_ = root;

  const fs::path intrinsics_path = root / "intrinsics.json";
  std::error_code ec;
  if (fs::exists(intrinsics_path, ec)) {
    OBJDB_ASSIGN_OR_RETURN(const auto file,
                           internal::readIntrinsicsFile(intrinsics_path, "depth_factor"));
    dataset->intrinsics_ = file.intrinsics;
    dataset->depth_factor_ = file.depth_scale.value_or(kTumDepthFactor);
  } else if (!options.intrinsics) {
    return absl::NotFoundError(absl::StrCat(
        "TUM dataset ", root.string(),
        " has no intrinsics.json; provide the camera intrinsics (DatasetOptions::intrinsics)"));
  }
  if (options.intrinsics) {
    OBJDB_RETURN_IF_ERROR(annotate(options.intrinsics->validate(), "intrinsics override"));
    dataset->intrinsics_ = *options.intrinsics;
  }

  OBJDB_ASSIGN_OR_RETURN(const auto depth_list, readTumList(root / "depth.txt"));
  const fs::path groundtruth_path = root / "groundtruth.txt";
  if (!fs::exists(groundtruth_path, ec)) {
    return absl::NotFoundError(
        absl::StrCat("TUM dataset ", root.string(), " has no groundtruth.txt (camera poses)"));
  }
  OBJDB_ASSIGN_OR_RETURN(const auto poses, readTumTrajectory(groundtruth_path));
  std::vector<TumEntry> rgb_list;
  const fs::path rgb_path = root / "rgb.txt";
  if (fs::exists(rgb_path, ec)) {
    OBJDB_ASSIGN_OR_RETURN(rgb_list, readTumList(rgb_path));
  }

  for (const char* folder : {"instances", "labels"}) {
    if (!dataset->has_instances_ && fs::is_directory(root / folder, ec)) {
      dataset->has_instances_ = true;
      dataset->instances_folder_ = folder;
    }
  }
  const fs::path objects_path = root / "objects.json";
  if (fs::exists(objects_path, ec)) {
    OBJDB_ASSIGN_OR_RETURN(dataset->objects_, readObjectsJson(objects_path));
  }

  const auto pose_times = sortedTimes(poses);
  const auto rgb_times = sortedTimes(rgb_list);
  const double max_dt = options.max_time_difference_s;
  size_t without_color = 0;
  dataset->frames_.reserve(depth_list.size());
  for (const auto& depth : depth_list) {
    const long pose_index = nearestWithin(pose_times, depth.timestamp, max_dt);
    if (pose_index < 0) {
      ++dataset->frames_without_pose_;
      continue;
    }
    Associated frame;
    frame.depth = depth;
    frame.pose = poses[size_t(pose_index)];
    const long rgb_index = nearestWithin(rgb_times, depth.timestamp, max_dt);
    if (rgb_index >= 0) {
      frame.color_path = rgb_list[size_t(rgb_index)].path;
      dataset->has_color_ = true;
    } else {
      ++without_color;
    }
    dataset->frames_.push_back(std::move(frame));
  }
  logger("io")->debug(
      "opened TUM dataset {}: {} frames ({} depth images without a pose within {} s skipped, {} "
      "frames without colour){}, {} ground-truth objects, {}",
      root.string(), dataset->frames_.size(), dataset->frames_without_pose_, max_dt, without_color,
      dataset->has_instances_ ? ", instances" : "", dataset->objects_.size(),
      toString(dataset->intrinsics_));
  return dataset;
}

StatusOr<Frame> TumDataset::loadFrame(size_t i) const {
  if (!(i < frames_.size())) {
    return absl::OutOfRangeError(absl::StrFormat("frame %d is out of range: %s has %d frames", i,
                                                 root_.string(), frames_.size()));
  }
  const Associated& entry = frames_[i];
  Frame frame;
  frame.index = i;
  frame.timestamp = entry.depth.timestamp;
  const fs::path depth_path = root_ / entry.depth.path;
  OBJDB_ASSIGN_OR_RETURN(const RawDepthImage raw, readUint16Png(depth_path));
  OBJDB_RETURN_IF_ERROR(intrinsics_.checkImageSize(
      raw.width, raw.height, absl::StrCat("depth image ", depth_path.string())));
  OBJDB_ASSIGN_OR_RETURN(frame.depth, depthFromRaw(raw, 1.0 / depth_factor_));
  OBJDB_ASSIGN_OR_RETURN(frame.T_world_camera, transformFromTumPose(entry.pose));
  if (!entry.color_path.empty()) {
    const fs::path color_path = root_ / entry.color_path;
    OBJDB_ASSIGN_OR_RETURN(ColorImage color, readColorImage(color_path));
    OBJDB_RETURN_IF_ERROR(intrinsics_.checkImageSize(
        color.width, color.height, absl::StrCat("colour image ", color_path.string())));
    frame.color = std::move(color);
  }
  if (has_instances_) {
    const fs::path name = depth_path.stem().string() + ".png";
    OBJDB_ASSIGN_OR_RETURN(frame.instances,
                           readInstanceImage(root_ / instances_folder_ / name, intrinsics_));
  }
  return frame;
}

StatusOr<std::unique_ptr<TumDatasetWriter>> TumDatasetWriter::create(const fs::path& root,
                                                                     const Intrinsics& intrinsics,
                                                                     bool overwrite) {
  OBJDB_RETURN_IF_ERROR(annotate(intrinsics.validate(), "TUM dataset writer"));
  std::error_code ec;
  if (fs::exists(root / "depth.txt", ec)) {
    if (!overwrite) {
      return absl::AlreadyExistsError(absl::StrCat(
          root.string(), " already holds a TUM dataset (depth.txt); refusing to overwrite it"));
    }
    for (const char* name : {"depth.txt", "rgb.txt", "groundtruth.txt", "intrinsics.json"}) {
      fs::remove(root / name, ec);
    }
    fs::remove_all(root / "depth", ec);
    fs::remove_all(root / "rgb", ec);
  }
  fs::create_directories(root / "depth", ec);
  if (ec) {
    return absl::UnavailableError(
        absl::StrCat("cannot create ", (root / "depth").string(), ": ", ec.message()));
  }
  auto writer = std::unique_ptr<TumDatasetWriter>(new TumDatasetWriter());
  writer->root_ = root;
  writer->intrinsics_ = intrinsics;
  return writer;
}

Status TumDatasetWriter::addFrame(const Frame& frame) {
  if (finished_) return absl::FailedPreconditionError("TUM dataset writer is already finished");
  const size_t index = poses_.size();
  if (frame.index != index) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "frames must be added in order: expected frame %d, got frame %d", index, frame.index));
  }
  if (!std::isfinite(frame.timestamp)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("frame %d has a non-finite timestamp", index));
  }
  if (!poses_.empty() && !(frame.timestamp > poses_.back().timestamp)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "frame %d timestamp %.9f is not after the previous frame's %.9f (TUM association needs "
        "increasing timestamps)",
        index, frame.timestamp, poses_.back().timestamp));
  }
  OBJDB_RETURN_IF_ERROR(validateFrame(frame, intrinsics_));
  size_t clipped = 0;
  OBJDB_ASSIGN_OR_RETURN(const RawDepthImage raw,
                         depthToRaw(frame.depth, 1.0 / kTumDepthFactor, &clipped));
  const std::string name = frameFileName(index);
  OBJDB_RETURN_IF_ERROR(writeUint16Png(root_ / "depth" / name, raw));
  if (frame.color) {
    std::error_code ec;
    fs::create_directories(root_ / "rgb", ec);
    OBJDB_RETURN_IF_ERROR(writeColorPng(root_ / "rgb" / name, *frame.color));
    rgb_.push_back({frame.timestamp, "rgb/" + name});
  }
  clipped_ += clipped;
  depth_.push_back({frame.timestamp, "depth/" + name});
  poses_.push_back(tumPoseFromTransform(frame.T_world_camera, frame.timestamp));
  return absl::OkStatus();
}

Status TumDatasetWriter::finish() {
  if (finished_) return absl::FailedPreconditionError("TUM dataset writer is already finished");
  OBJDB_RETURN_IF_ERROR(internal::writeIntrinsicsFile(root_ / "intrinsics.json", intrinsics_,
                                                      "depth_factor", kTumDepthFactor));
  if (!rgb_.empty()) {
    OBJDB_RETURN_IF_ERROR(writeTumList(root_ / "rgb.txt", rgb_, "colour images (8-bit RGB PNG)"));
  }
  OBJDB_RETURN_IF_ERROR(writeTumTrajectory(root_ / "groundtruth.txt", poses_,
                                           "T_world_camera (camera to world), metres"));
  OBJDB_RETURN_IF_ERROR(writeTumList(root_ / "depth.txt", depth_,
                                     "depth maps (16-bit PNG, metres = value / 5000, 0 = none)"));
  finished_ = true;
  if (clipped_ > 0) {
    logger("io")->warn("{}: {} depth values beyond {:.3f} m were written as 0", root_.string(),
                       clipped_, 65535.0 / kTumDepthFactor);
  }
  return absl::OkStatus();
}

}  // namespace objdb::io

// The TUM RGB-D layout: depth.txt / rgb.txt ("timestamp path" lines, '#' comments),
// groundtruth.txt ("timestamp tx ty tz qx qy qz qw", T_world_camera), 16-bit depth PNGs with
// 5000 units per metre. Intrinsics come from an intrinsics.json beside them
// ({"width","height","fx","fy","cx","cy","depth_factor"}, docs/dataset-format.md) or from
// DatasetOptions. Each depth frame is associated with the ground-truth pose and the colour image
// nearest in time (within DatasetOptions::max_time_difference_s); depth frames without a pose
// are skipped and counted (framesWithoutPose()).
// Ground-truth variant: an instances/ folder with one 16-bit instance-id PNG per depth image (same
// file name: instances/NNNNNN.png for depth/NNNNNN.png) and an objects.json, both exactly as in
// the objdb layout (ground_truth.h). Without instances/, a labels/ folder of per-pixel class ids
// (label-fusion's layout, 8- or 16-bit, 0 = background) serves as the instances; without an
// objects.json each id is then one object of kind "label <id>" (idObjects below).
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "core/io/dataset.h"
#include "core/io/ground_truth.h"

namespace objdb::io {

inline constexpr double kTumDepthFactor = 5000.0;  // units per metre

struct TumEntry {
  double timestamp = 0.0;
  std::string path;  // relative to the dataset root
};

// Parses a TUM "timestamp path" list; errors name the file and line.
StatusOr<std::vector<TumEntry>> readTumList(const std::filesystem::path& path);
// Parses a TUM trajectory; errors name the file and line.
StatusOr<std::vector<TumPose>> readTumTrajectory(const std::filesystem::path& path);
Status writeTumTrajectory(const std::filesystem::path& path, const std::vector<TumPose>& poses,
                          absl::string_view comment);

class TumDataset : public Dataset {
 public:
  static StatusOr<std::unique_ptr<TumDataset>> open(const std::filesystem::path& root,
                                                    const DatasetOptions& options = {});
  std::string layout() const override { return "tum"; }
  const std::filesystem::path& root() const override { return root_; }
  const Intrinsics& intrinsics() const override { return intrinsics_; }
  double metresPerDepthUnit() const override { return 1.0 / depth_factor_; }
  size_t size() const override { return frames_.size(); }
  bool hasColor() const override { return has_color_; }
  bool hasInstances() const override { return has_instances_; }
  StatusOr<Frame> loadFrame(size_t i) const override;
  size_t framesWithoutPose() const { return frames_without_pose_; }
  // Ground-truth objects (empty when objects.json is absent).
  const std::vector<GroundTruthObject>& objects() const { return objects_; }
  // The folder the instances come from: "instances" or "labels" (empty: none).
  const std::string& instancesFolder() const { return instances_folder_; }

 private:
  struct Associated {
    TumEntry depth;
    TumPose pose;
    std::string color_path;  // empty when no colour image is close enough
  };
  std::filesystem::path root_;
  Intrinsics intrinsics_;
  double depth_factor_ = kTumDepthFactor;
  std::vector<Associated> frames_;
  bool has_color_ = false;
  bool has_instances_ = false;  // instances/ or labels/ exists: every frame must have its image
  std::string instances_folder_;
  std::vector<GroundTruthObject> objects_;
  size_t frames_without_pose_ = 0;
};

// Writes frames as a TUM folder (depth/ and rgb/ PNGs, the three lists, intrinsics.json).
class TumDatasetWriter {
 public:
  static StatusOr<std::unique_ptr<TumDatasetWriter>> create(const std::filesystem::path& root,
                                                            const Intrinsics& intrinsics,
                                                            bool overwrite = false);
  // Frames must come in order 0, 1, 2, ... with strictly increasing timestamps (association by
  // time needs them distinct).
  Status addFrame(const Frame& frame);
  // Writes intrinsics.json, rgb.txt, groundtruth.txt and, last, depth.txt.
  Status finish();
  size_t framesWritten() const { return poses_.size(); }
  // Depth values beyond 65535 / 5000 m (written as 0).
  size_t clippedDepthPixels() const { return clipped_; }

 private:
  std::filesystem::path root_;
  Intrinsics intrinsics_;
  std::vector<TumEntry> depth_, rgb_;
  std::vector<TumPose> poses_;
  size_t clipped_ = 0;
  bool finished_ = false;
};

}  // namespace objdb::io

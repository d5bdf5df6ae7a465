// objdb's dataset layout (one folder per recording session):
//   intrinsics.json   {"width","height","fx","fy","cx","cy","depth_scale_m"}
//   poses.txt         TUM pose format, one line per frame in frame order:
//                     "timestamp tx ty tz qx qy qz qw" (T_world_camera; '#' lines are comments)
//   depth/NNNNNN.png  16-bit depth, metres = value · depth_scale_m (default 0.001), 0 = none
//   color/NNNNNN.png  optional 8-bit RGB
//   instances/NNNNNN.png optional 16-bit ground-truth instance id per pixel, 0 = none
//   objects.json      optional ground truth: {"objects": [{"id","category","mesh","structure",
//                     "T_world_object": {"t": [x,y,z], "q": [qx,qy,qz,qw]}}], ...}
//                     (instances/ and objects.json are read by ground_truth.h, shared with TUM)
// See docs/dataset-format.md.
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "core/io/dataset.h"
#include "core/io/ground_truth.h"

namespace objdb::io {

StatusOr<Intrinsics> readIntrinsicsJson(const std::filesystem::path& path,
                                        double* metres_per_unit);
Status writeIntrinsicsJson(const std::filesystem::path& path, const Intrinsics& intrinsics,
                           double metres_per_unit);

class ObjdbDataset : public Dataset {
 public:
  static StatusOr<std::unique_ptr<ObjdbDataset>> open(const std::filesystem::path& root,
                                                      const DatasetOptions& options = {});
  std::string layout() const override { return "objdb"; }
  const std::filesystem::path& root() const override { return root_; }
  const Intrinsics& intrinsics() const override { return intrinsics_; }
  double metresPerDepthUnit() const override { return metres_per_unit_; }
  size_t size() const override { return poses_.size(); }
  bool hasColor() const override { return has_color_; }
  bool hasInstances() const override { return has_instances_; }
  StatusOr<Frame> loadFrame(size_t i) const override;
  // Ground truth objects (empty when objects.json is absent).
  const std::vector<GroundTruthObject>& objects() const { return objects_; }

 private:
  std::filesystem::path root_;
  Intrinsics intrinsics_;
  double metres_per_unit_ = 0.001;
  std::vector<TumPose> poses_;
  bool has_color_ = false;
  bool has_instances_ = false;
  std::vector<GroundTruthObject> objects_;
};

// Writes a dataset frame by frame; finish() writes poses.txt and objects.json. Frames must be
// added in order 0, 1, 2, ... A writer that is destroyed unfinished leaves no poses.txt, so a
// half-written dataset is never mistaken for a whole one.
class ObjdbDatasetWriter {
 public:
  // Creates `root` (and depth/, color/, instances/ as needed); fails if root holds a poses.txt
  // already, unless `overwrite`.
  static StatusOr<std::unique_ptr<ObjdbDatasetWriter>> create(const std::filesystem::path& root,
                                                              const Intrinsics& intrinsics,
                                                              double metres_per_unit = 0.001,
                                                              bool overwrite = false);
  Status addFrame(const Frame& frame);
  Status finish(const std::vector<GroundTruthObject>& objects = {});
  size_t framesWritten() const { return poses_.size(); }
  // Depth values that did not fit 16 bits at the chosen scale (written as 0).
  size_t clippedDepthPixels() const { return clipped_; }

 private:
  std::filesystem::path root_;
  Intrinsics intrinsics_;
  double metres_per_unit_ = 0.001;
  std::vector<TumPose> poses_;
  size_t clipped_ = 0;
  bool has_color_ = false;      // decided by frame 0
  bool has_instances_ = false;  // decided by frame 0
  bool finished_ = false;
};

}  // namespace objdb::io

// A posed RGB-D sequence on disk, read frame by frame. Three layouts are supported:
//  - objdb's own (objdb_dataset.h): intrinsics.json, poses.txt, depth/, color/, instances/,
//    objects.json;
//  - TUM RGB-D (tum_dataset.h): rgb.txt, depth.txt, groundtruth.txt, depth factor 5000, and
//    optionally instances/ and objects.json as in the objdb layout;
//  - 7-Scenes / 3DMatch / tsdf-fusion (seven_scenes_dataset.h): camera-intrinsics.txt,
//    frame-NNNNNN.{depth.png,pose.txt,color.png|jpg}.
// openDataset() tells them apart. Frames load lazily, so a sequence never sits in memory whole.
#pragma once

#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "core/common/frame.h"

namespace objdb::io {

class Dataset {
 public:
  virtual ~Dataset() = default;
  virtual std::string layout() const = 0;  // "objdb", "tum" or "7scenes"
  virtual const std::filesystem::path& root() const = 0;
  virtual const Intrinsics& intrinsics() const = 0;
  virtual double metresPerDepthUnit() const = 0;
  virtual size_t size() const = 0;
  virtual bool hasColor() const = 0;
  virtual bool hasInstances() const = 0;
  // Loads frame i (0-based): depth in metres, pose, colour / instances when present.
  virtual StatusOr<Frame> loadFrame(size_t i) const = 0;
};

struct DatasetOptions {
  // Overrides intrinsics.json / camera-intrinsics.txt (required for a TUM or 7-Scenes folder
  // without one).
  std::optional<Intrinsics> intrinsics;
  // TUM association: a depth frame takes the pose / colour image closest in time, if within this.
  double max_time_difference_s = 0.02;
};

// Detects the layout of `root` (objdb: poses.txt; else TUM: depth.txt; else 7-Scenes:
// camera-intrinsics.txt or frame-NNNNNN.pose.txt files) and opens it.
StatusOr<std::unique_ptr<Dataset>> openDataset(const std::filesystem::path& root,
                                               const DatasetOptions& options = {});

}  // namespace objdb::io

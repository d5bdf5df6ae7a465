// The 7-Scenes / 3DMatch / tsdf-fusion layout (Microsoft 7-Scenes sequences, 3DMatch RGB-D
// scenes, andyzeng/tsdf-fusion's sample): camera-intrinsics.txt (3x3 K, no image size) and per
// frame frame-NNNNNN.depth.png (16-bit millimetres, 0 and 65535 = no measurement),
// frame-NNNNNN.pose.txt (4x4 T_world_camera, row-major, metres) and an optional
// frame-NNNNNN.color.png|.jpg. One flat folder per sequence; the image size is the first depth
// image's. See docs/dataset-format.md ("7-Scenes / 3DMatch layout").
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "core/io/dataset.h"

namespace objdb::io {

inline constexpr double kSevenScenesMetresPerUnit = 0.001;  // depth PNGs are in millimetres
// 7-Scenes writes 65535 where the Kinect had no reading; read as "no measurement", like 0.
inline constexpr uint16_t kSevenScenesInvalidDepth = 65535;
// The layout has no timestamps: Frame::timestamp = frame number / this (Kinect v1 rate).
inline constexpr double kSevenScenesFrameRateHz = 30.0;
// Pose matrices are printed with 6-8 significant digits, so their rotations are orthonormal only
// to about that precision: max |RᵀR − I| up to this is accepted and projected onto the nearest
// rotation (as a near-unit quaternion is normalised); anything further is an error.
inline constexpr double kPoseMatrixOrthoTolerance = 1e-3;

// camera-intrinsics.txt: the 3x3 matrix "fx 0 cx / 0 fy cy / 0 0 1" (whitespace separated, one
// row per line). The file has no image size: `width` × `height` come from the caller. Skew, a
// last row other than (0 0 1) or a wrong count are errors naming the file and line.
StatusOr<Intrinsics> readCameraIntrinsicsTxt(const std::filesystem::path& path, int width,
                                             int height);

// frame-NNNNNN.pose.txt: a 4x4 row-major camera-to-world matrix. Must be finite, rigid (rotation
// orthonormal within kPoseMatrixOrthoTolerance, det +1) with last row (0 0 0 1); errors name the
// file and what is wrong.
StatusOr<Transform> readPoseMatrixFile(const std::filesystem::path& path);

// True when `root` holds a camera-intrinsics.txt or a frame-N.pose.txt (what openDataset uses).
bool looksLikeSevenScenes(const std::filesystem::path& root);

class SevenScenesDataset : public Dataset {
 public:
  // Intrinsics: DatasetOptions::intrinsics, else camera-intrinsics.txt in `root`, else in its
  // parent folder (3DMatch keeps it beside the seq-NN folders). Reads every pose file and checks
  // that depth, pose and colour files pair up.
  static StatusOr<std::unique_ptr<SevenScenesDataset>> open(const std::filesystem::path& root,
                                                            const DatasetOptions& options = {});
  std::string layout() const override { return "7scenes"; }
  const std::filesystem::path& root() const override { return root_; }
  const Intrinsics& intrinsics() const override { return intrinsics_; }
  double metresPerDepthUnit() const override { return kSevenScenesMetresPerUnit; }
  size_t size() const override { return frames_.size(); }
  bool hasColor() const override { return has_color_; }
  bool hasInstances() const override { return false; }
  StatusOr<Frame> loadFrame(size_t i) const override;
  // The NNNNNN of frame i's file names (frames are sorted by it; gaps are allowed).
  uint64_t frameNumber(size_t i) const { return frames_.at(i).number; }
  // The camera-intrinsics.txt that was read; empty when DatasetOptions::intrinsics was used.
  const std::filesystem::path& intrinsicsFile() const { return intrinsics_file_; }

 private:
  struct FrameFiles {
    uint64_t number = 0;
    std::filesystem::path depth;
    std::filesystem::path color;  // empty without colour
    Transform T_world_camera = Transform::Identity();
  };
  std::filesystem::path root_;
  std::filesystem::path intrinsics_file_;
  Intrinsics intrinsics_;
  std::vector<FrameFiles> frames_;
  bool has_color_ = false;
};

}  // namespace objdb::io

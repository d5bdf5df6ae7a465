// Camera pose drift of the synthetic world: the poses a dataset reports (poses.txt) differ from
// the poses it was rendered from by a smooth, slowly growing error, as the poses of a real
// visual-inertial tracker do (the paper's Tango recordings, §IV). Deterministic for a seed.
#pragma once

#include <cstddef>
#include <cstdint>

#include "core/common/status.h"
#include "core/common/transform.h"

namespace objdb::sim {

// The error grows from 0 at frame 0 to about its amplitude at the last frame, along sinusoids of
// the frame index with seeded phases (no random walk: the same seed gives the same drift).
// Both amplitudes 0 (the default) = off: the written pose is the rendered pose.
struct PoseDrift {
  float translation_m = 0.0f;  // camera-centre error at the last frame (0.7–1× this), metres
  float rotation_deg = 0.0f;   // rotation error at the last frame (0.7–1× this), mostly yaw
  uint64_t seed = 1;           // phases and directions of the drift
  bool enabled() const { return translation_m > 0.0f || rotation_deg > 0.0f; }
  Status validate() const;
};

// The drift of frame `index` of `frames`: the written pose is T_world_camera with its centre
// moved by `translation` and its orientation rotated by `rotation` (world frame, about the
// camera centre). Identity when !drift.enabled() or index == 0.
struct DriftAt {
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
};
DriftAt driftAt(const PoseDrift& drift, size_t index, size_t frames);

// The pose a drifting tracker would report for a camera truly at `T_world_camera`.
Transform driftedPose(const PoseDrift& drift, const Transform& T_world_camera, size_t index,
                      size_t frames);

}  // namespace objdb::sim

// Rigid transforms and their conventions.
//
// `T_a_b` maps coordinates in frame b into frame a: p_a = T_a_b * p_b, and T_a_c = T_a_b * T_b_c.
// `T_world_camera` is the camera pose (camera-to-world). The camera frame is OpenCV's: x right,
// y down, z forward along the optical axis. The world frame of the synthetic world is z-up.
// Quaternions on every text format (TUM poses, JSON) are written in the order qx qy qz qw
// (Hamilton convention, unit norm); Eigen's constructor takes (w, x, y, z) — use the helpers.
#pragma once

#include <array>

#include <Eigen/Geometry>

#include "core/common/status.h"

namespace objdb {

using Transform = Eigen::Isometry3d;   // API and file precision
using Transformf = Eigen::Isometry3f;  // inside voxel code

// Tolerances follow ROS tf2 (quaternion) and are documented on the API.
inline constexpr double kQuaternionNormTolerance = 1e-2;  // |‖q‖² − 1| allowed
inline constexpr double kRotationOrthoTolerance = 1e-4;   // max |RᵀR − I| entry

// A pose as the TUM format writes it: translation then quaternion (qx qy qz qw).
struct TumPose {
  double timestamp = 0.0;
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  std::array<double, 4> q_xyzw = {0.0, 0.0, 0.0, 1.0};
};

// Builds a transform from translation and quaternion (qx qy qz qw). Rejects non-finite values and
// quaternions whose squared norm differs from 1 by more than kQuaternionNormTolerance; a
// quaternion within tolerance is normalised.
StatusOr<Transform> transformFromTranslationQuaternion(const Eigen::Vector3d& t,
                                                       const std::array<double, 4>& q_xyzw);
StatusOr<Transform> transformFromTumPose(const TumPose& pose);
TumPose tumPoseFromTransform(const Transform& T, double timestamp);

// Checks that a transform is finite, its rotation orthonormal with det +1 (within
// kRotationOrthoTolerance) and its last row (0 0 0 1). `what` names the pose in the message.
Status validateTransform(const Transform& T, absl::string_view what);

// A camera pose at `position` looking at `target`, with the image "up" as close to `up` as
// possible (camera y axis = −up projected). Fails when position == target or the view direction
// is parallel to `up`.
StatusOr<Transform> lookAt(const Eigen::Vector3d& position, const Eigen::Vector3d& target,
                           const Eigen::Vector3d& up = Eigen::Vector3d::UnitZ());

// Rotation about the world z axis by `yaw_rad` followed by a translation.
Transform poseFromXyzYaw(const Eigen::Vector3d& t, double yaw_rad);

}  // namespace objdb

#include "core/common/transform.h"

#include <cmath>

namespace objdb {

StatusOr<Transform> transformFromTranslationQuaternion(const Eigen::Vector3d& t,
                                                       const std::array<double, 4>& q_xyzw) {
  if (!t.allFinite()) {
    return absl::InvalidArgumentError(
        absl::StrFormat("translation has a non-finite value (%g %g %g)", t.x(), t.y(), t.z()));
  }
  for (double v : q_xyzw) {
    if (!std::isfinite(v)) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "quaternion has a non-finite value (qx qy qz qw = %g %g %g %g)", q_xyzw[0], q_xyzw[1],
          q_xyzw[2], q_xyzw[3]));
    }
  }
  const Eigen::Quaterniond q(q_xyzw[3], q_xyzw[0], q_xyzw[1], q_xyzw[2]);
  const double norm2 = q.squaredNorm();
  if (!(std::abs(norm2 - 1.0) <= kQuaternionNormTolerance)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "quaternion (qx qy qz qw = %g %g %g %g) has squared norm %g; expected 1 within %g",
        q_xyzw[0], q_xyzw[1], q_xyzw[2], q_xyzw[3], norm2, kQuaternionNormTolerance));
  }
  Transform T = Transform::Identity();
  T.linear() = q.normalized().toRotationMatrix();
  T.translation() = t;
  return T;
}

StatusOr<Transform> transformFromTumPose(const TumPose& pose) {
  return transformFromTranslationQuaternion(pose.t, pose.q_xyzw);
}

TumPose tumPoseFromTransform(const Transform& T, double timestamp) {
  Eigen::Quaterniond q(T.rotation());
  q.normalize();
  if (q.w() < 0) q.coeffs() *= -1.0;  // canonical sign: qw >= 0
  TumPose pose;
  pose.timestamp = timestamp;
  pose.t = T.translation();
  pose.q_xyzw = {q.x(), q.y(), q.z(), q.w()};
  return pose;
}

Status validateTransform(const Transform& T, absl::string_view what) {
  if (!T.matrix().allFinite()) {
    return absl::InvalidArgumentError(absl::StrCat(what, " has a non-finite entry"));
  }
  const Eigen::Matrix3d R = T.linear();
  const double ortho_error = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (!(ortho_error <= kRotationOrthoTolerance)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%s has a rotation that is not orthonormal (max |RᵀR − I| = %g > %g)",
                        what, ortho_error, kRotationOrthoTolerance));
  }
  const double det = R.determinant();
  if (!(det > 0.0)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%s has a reflection, not a rotation (det = %g)", what, det));
  }
  const Eigen::RowVector4d last = T.matrix().row(3);
  if (!(last - Eigen::RowVector4d(0, 0, 0, 1)).isZero(1e-12)) {
    return absl::InvalidArgumentError(absl::StrCat(what, " has a last row other than (0 0 0 1)"));
  }
  return absl::OkStatus();
}

StatusOr<Transform> lookAt(const Eigen::Vector3d& position, const Eigen::Vector3d& target,
                           const Eigen::Vector3d& up) {
  const Eigen::Vector3d forward = target - position;
  if (!(forward.norm() > 1e-9)) {
    return absl::InvalidArgumentError("lookAt: camera position equals its target");
  }
  const Eigen::Vector3d z = forward.normalized();
  Eigen::Vector3d x = z.cross(up);  // camera x (right) = forward × up, since camera y points down
  if (!(x.norm() > 1e-9)) {
    return absl::InvalidArgumentError("lookAt: view direction is parallel to the up vector");
  }
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);
  Transform T = Transform::Identity();
  T.linear().col(0) = x;
  T.linear().col(1) = y;
  T.linear().col(2) = z;
  T.translation() = position;
  return T;
}

Transform poseFromXyzYaw(const Eigen::Vector3d& t, double yaw_rad) {
  Transform T = Transform::Identity();
  T.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = t;
  return T;
}

}  // namespace objdb

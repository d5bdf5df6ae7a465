#include "core/common/transform.h"

#include <cmath>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace objdb {
namespace {

using ::testing::HasSubstr;

TEST(TumPose, RoundTripKeepsTransformAndUsesXyzwOrder) {
  Transform T = Transform::Identity();
  T.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, -2, 0.5).normalized()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(1.5, -2.25, 3.0);
  const TumPose pose = tumPoseFromTransform(T, 12.5);
  EXPECT_EQ(pose.timestamp, 12.5);
  EXPECT_EQ(pose.t, T.translation());
  const Eigen::Quaterniond q(T.rotation());
  // Stored as qx qy qz qw with qw >= 0.
  const double sign = q.w() < 0 ? -1.0 : 1.0;
  EXPECT_NEAR(pose.q_xyzw[0], sign * q.x(), 1e-12);
  EXPECT_NEAR(pose.q_xyzw[1], sign * q.y(), 1e-12);
  EXPECT_NEAR(pose.q_xyzw[2], sign * q.z(), 1e-12);
  EXPECT_NEAR(pose.q_xyzw[3], sign * q.w(), 1e-12);
  EXPECT_GE(pose.q_xyzw[3], 0.0);

  const auto back = transformFromTumPose(pose);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_TRUE(back->isApprox(T, 1e-12));
}

TEST(TumPose, QuaternionIsReadAsXyzw) {
  // 90 degrees about z: qx qy qz qw = 0 0 sin(45°) cos(45°); maps x to y.
  TumPose pose;
  pose.q_xyzw = {0.0, 0.0, std::sqrt(0.5), std::sqrt(0.5)};
  const auto T = transformFromTumPose(pose);
  ASSERT_TRUE(T.ok()) << T.status();
  EXPECT_TRUE((T->linear() * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitY(), 1e-12));
}

TEST(TumPose, NanTranslationIsRejectedWithValues) {
  TumPose pose;
  pose.t = Eigen::Vector3d(1.0, std::numeric_limits<double>::quiet_NaN(), 2.0);
  const auto T = transformFromTumPose(pose);
  ASSERT_FALSE(T.ok());
  EXPECT_EQ(T.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(T.status().message()), HasSubstr("translation"));
  EXPECT_THAT(std::string(T.status().message()), HasSubstr("nan"));
}

TEST(TumPose, NanQuaternionIsRejected) {
  TumPose pose;
  pose.q_xyzw = {0.0, std::numeric_limits<double>::quiet_NaN(), 0.0, 1.0};
  const auto T = transformFromTumPose(pose);
  ASSERT_FALSE(T.ok());
  EXPECT_THAT(std::string(T.status().message()), HasSubstr("quaternion"));
}

TEST(TumPose, QuaternionNormOutsideTf2ToleranceIsRejected) {
  TumPose pose;
  pose.q_xyzw = {0.0, 0.0, 0.0, 1.1};  // squared norm 1.21
  const auto T = transformFromTumPose(pose);
  ASSERT_FALSE(T.ok());
  EXPECT_EQ(T.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(T.status().message()), HasSubstr("squared norm 1.21"));

  pose.q_xyzw = {0.0, 0.0, 0.0, 0.0};
  EXPECT_FALSE(transformFromTumPose(pose).ok());
}

TEST(TumPose, QuaternionWithinToleranceIsNormalised) {
  TumPose pose;
  pose.q_xyzw = {0.0, 0.0, 0.0, 1.004};  // squared norm 1.008 < 1 + 1e-2
  const auto T = transformFromTumPose(pose);
  ASSERT_TRUE(T.ok()) << T.status();
  EXPECT_TRUE(T->linear().isApprox(Eigen::Matrix3d::Identity(), 1e-12));
}

TEST(LookAt, CameraZPointsAtTargetAndYDown) {
  const Eigen::Vector3d position(2.0, -1.0, 1.5);
  const Eigen::Vector3d target(0.0, 0.5, 0.3);
  const auto T = lookAt(position, target);
  ASSERT_TRUE(T.ok()) << T.status();
  EXPECT_TRUE(validateTransform(*T, "lookAt").ok());
  const Eigen::Vector3d z = T->linear().col(2);
  EXPECT_TRUE(z.isApprox((target - position).normalized(), 1e-12));
  EXPECT_LT(T->linear().col(1).dot(Eigen::Vector3d::UnitZ()), 0.0);           // image y points down
  EXPECT_NEAR(T->linear().col(0).dot(Eigen::Vector3d::UnitZ()), 0.0, 1e-12);  // no roll
  EXPECT_TRUE(T->translation().isApprox(position));
  // The target lies on the optical axis in front of the camera.
  const Eigen::Vector3d p_camera = T->inverse() * target;
  EXPECT_NEAR(p_camera.x(), 0.0, 1e-12);
  EXPECT_NEAR(p_camera.y(), 0.0, 1e-12);
  EXPECT_NEAR(p_camera.z(), (target - position).norm(), 1e-12);
}

TEST(LookAt, DegenerateInputsAreErrors) {
  EXPECT_FALSE(lookAt(Eigen::Vector3d(1, 1, 1), Eigen::Vector3d(1, 1, 1)).ok());
  const auto vertical = lookAt(Eigen::Vector3d(0, 0, 2), Eigen::Vector3d(0, 0, 0));
  ASSERT_FALSE(vertical.ok());
  EXPECT_THAT(std::string(vertical.status().message()), HasSubstr("parallel"));
}

TEST(ValidateTransform, AcceptsRigidTransform) {
  const Transform T = poseFromXyzYaw(Eigen::Vector3d(1, 2, 3), 0.3);
  EXPECT_TRUE(validateTransform(T, "T").ok());
}

TEST(ValidateTransform, RejectsNonOrthonormalRotation) {
  Transform T = Transform::Identity();
  T.linear()(0, 0) = 1.01;
  const Status s = validateTransform(T, "T_world_camera of frame 3");
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), HasSubstr("T_world_camera of frame 3"));
  EXPECT_THAT(std::string(s.message()), HasSubstr("not orthonormal"));
}

TEST(ValidateTransform, RejectsReflection) {
  Transform T = Transform::Identity();
  T.linear() = Eigen::Vector3d(1, 1, -1).asDiagonal();
  const Status s = validateTransform(T, "pose");
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("reflection"));
}

TEST(ValidateTransform, RejectsNonFiniteEntry) {
  Transform T = Transform::Identity();
  T.translation().x() = std::numeric_limits<double>::infinity();
  const Status s = validateTransform(T, "pose");
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("non-finite"));
}

}  // namespace
}  // namespace objdb

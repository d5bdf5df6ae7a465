#include "core/common/intrinsics.h"

#include <cmath>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace objdb {
namespace {

using ::testing::HasSubstr;

TEST(Intrinsics, PresetsAreValidAndHaveDocumentedSizes) {
  const Intrinsics vga = Intrinsics::vga();
  EXPECT_TRUE(vga.validate().ok());
  EXPECT_EQ(vga.width, 640);
  EXPECT_EQ(vga.height, 480);
  EXPECT_EQ(vga.fx, 525.0);
  const Intrinsics tango = Intrinsics::tango();
  EXPECT_TRUE(tango.validate().ok());
  EXPECT_EQ(tango.width, 224);
  EXPECT_EQ(tango.height, 172);

  const auto by_name = intrinsicsPreset("vga");
  ASSERT_TRUE(by_name.ok());
  EXPECT_EQ(*by_name, vga);
  EXPECT_EQ(*intrinsicsPreset("tango"), tango);
}

TEST(Intrinsics, UnknownPresetNamesTheKnownOnes) {
  const auto preset = intrinsicsPreset("kinect");
  ASSERT_FALSE(preset.ok());
  EXPECT_THAT(std::string(preset.status().message()), HasSubstr("kinect"));
  EXPECT_THAT(std::string(preset.status().message()), HasSubstr("vga, tango"));
}

TEST(Intrinsics, ValidateNamesTheBadValue) {
  Intrinsics k = Intrinsics::vga();
  k.width = 0;
  EXPECT_THAT(std::string(k.validate().message()), HasSubstr("0x480"));

  k = Intrinsics::vga();
  k.height = kMaxImageSide + 1;
  EXPECT_FALSE(k.validate().ok());

  k = Intrinsics::vga();
  k.fx = std::numeric_limits<double>::quiet_NaN();
  const Status nan_focal = k.validate();
  ASSERT_FALSE(nan_focal.ok());
  EXPECT_THAT(std::string(nan_focal.message()), HasSubstr("focal"));

  k = Intrinsics::vga();
  k.fy = -1.0;
  EXPECT_FALSE(k.validate().ok());

  k = Intrinsics::vga();
  k.cx = 700.0;
  const Status outside = k.validate();
  ASSERT_FALSE(outside.ok());
  EXPECT_THAT(std::string(outside.message()), HasSubstr("principal point (700"));

  k = Intrinsics::vga();
  k.cy = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(k.validate().ok());
}

TEST(Intrinsics, CheckImageSizeNamesBothSizes) {
  const Status s = Intrinsics::tango().checkImageSize(640, 480, "depth image");
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message(), "depth image is 640x480 but intrinsics are for 224x172");
  EXPECT_TRUE(Intrinsics::tango().checkImageSize(224, 172, "depth image").ok());
}

TEST(Intrinsics, ProjectInvertsBackProject) {
  const Intrinsics k = Intrinsics::vga();
  for (const auto& [u, v, z] :
       {std::tuple{0.0, 0.0, 0.5}, std::tuple{319.5, 239.5, 2.0}, std::tuple{600.25, 17.75, 3.3}}) {
    const Eigen::Vector3d p = k.backProject(u, v, z);
    EXPECT_DOUBLE_EQ(p.z(), z);
    const Eigen::Vector2d uv = k.project(p);
    EXPECT_NEAR(uv.x(), u, 1e-9);
    EXPECT_NEAR(uv.y(), v, 1e-9);
  }
  // The principal point back-projects onto the optical axis.
  EXPECT_TRUE(k.backProject(k.cx, k.cy, 1.0).isApprox(Eigen::Vector3d(0, 0, 1)));
}

}  // namespace
}  // namespace objdb

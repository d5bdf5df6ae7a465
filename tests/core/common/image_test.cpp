#include "core/common/image.h"

#include <cmath>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace objdb {
namespace {

using ::testing::HasSubstr;

TEST(DepthFromRaw, ScalesUnitsToMetresAndKeepsZero) {
  RawDepthImage raw(3, 1);
  raw.data = {0, 1000, 65535};
  const auto depth = depthFromRaw(raw, 0.001);
  ASSERT_TRUE(depth.ok()) << depth.status();
  EXPECT_EQ(depth->width, 3);
  EXPECT_EQ(depth->height, 1);
  EXPECT_EQ(depth->data[0], 0.0f);
  EXPECT_FLOAT_EQ(depth->data[1], 1.0f);
  EXPECT_FLOAT_EQ(depth->data[2], 65.535f);
  EXPECT_FALSE(isValidDepth(depth->data[0]));

  const auto tum = depthFromRaw(raw, 1.0 / 5000.0);
  ASSERT_TRUE(tum.ok());
  EXPECT_FLOAT_EQ(tum->data[1], 0.2f);
}

TEST(DepthFromRaw, RejectsBadScale) {
  const RawDepthImage raw(2, 2, 7);
  for (double scale : {0.0, -0.001, std::numeric_limits<double>::quiet_NaN(),
                       std::numeric_limits<double>::infinity()}) {
    const auto depth = depthFromRaw(raw, scale);
    ASSERT_FALSE(depth.ok()) << scale;
    EXPECT_THAT(std::string(depth.status().message()), HasSubstr("depth scale"));
  }
}

TEST(DepthToRaw, InvalidDepthsBecomeZeroAndTooFarIsCountedAsClipped) {
  DepthImage depth(6, 1);
  depth.data = {1.0f,  std::numeric_limits<float>::quiet_NaN(),
                -2.0f, std::numeric_limits<float>::infinity(),
                70.0f, 0.0f};
  size_t clipped = 99;
  const auto raw = depthToRaw(depth, 0.001, &clipped);
  ASSERT_TRUE(raw.ok()) << raw.status();
  EXPECT_EQ(raw->data, (std::vector<uint16_t>{1000, 0, 0, 0, 0, 0}));
  EXPECT_EQ(clipped, 1u);  // 70 m = 70000 units; NaN, inf, negative, 0 are not "clipped"
}

TEST(DepthToRaw, RoundsToNearestUnitAndRoundTrips) {
  DepthImage depth(3, 1);
  depth.data = {0.0014f, 0.0016f, 65.535f};
  const auto raw = depthToRaw(depth, 0.001);
  ASSERT_TRUE(raw.ok());
  EXPECT_EQ(raw->data, (std::vector<uint16_t>{1, 2, 65535}));
  const auto back = depthFromRaw(*raw, 0.001);
  ASSERT_TRUE(back.ok());
  const auto again = depthToRaw(*back, 0.001);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->data, raw->data);
}

TEST(DepthToRaw, RejectsBadScale) {
  EXPECT_FALSE(depthToRaw(DepthImage(1, 1, 1.0f), 0.0).ok());
  EXPECT_FALSE(depthToRaw(DepthImage(1, 1, 1.0f), std::nan("")).ok());
}

TEST(Image, AtIsRowMajor) {
  Image<int> image(3, 2);
  image.at(2, 1) = 5;
  EXPECT_EQ(image.data[5], 5);
  EXPECT_EQ(image.size(), 6u);
}

}  // namespace
}  // namespace objdb

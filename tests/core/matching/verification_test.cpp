#include "core/matching/verification.h"

#include <cmath>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/support/sdf_grid.h"

namespace objdb::matching {
namespace {

using objdb::testing::boxSdf;
using objdb::testing::Sdf;
using objdb::testing::sdfGrid;
using objdb::testing::sphereSdf;
using ::testing::HasSubstr;

constexpr float kVoxel = 0.01f;
const Eigen::Vector3f kLo = Eigen::Vector3f::Constant(-0.3f), kHi = Eigen::Vector3f::Constant(0.3f);

Transform translation(double x, double y, double z) {
  Transform T = Transform::Identity();
  T.translation() = Eigen::Vector3d(x, y, z);
  return T;
}

TEST(CompareGrids, IdenticalGridsAgreeExactly) {
  auto a = sdfGrid(sphereSdf({0, 0, 0}, 0.15f), kLo, kHi, kVoxel, 3 * kVoxel);
  auto b = sdfGrid(sphereSdf({0, 0, 0}, 0.15f), kLo, kHi, kVoxel, 3 * kVoxel);
  const GridAgreement g = compareGrids(a.layer, b.layer, Transform::Identity());
  EXPECT_EQ(g.compared, a.layer.numObservedVoxels());
  // At voxel centres the interpolation needs only that voxel: every voxel pairs up.
  EXPECT_EQ(g.overlap, g.compared);
  EXPECT_LT(g.rmse, 1e-6);
}

TEST(CompareGrids, MeasuresAKnownOffsetAndTheTransformRemovesIt) {
  // The moving sphere sits 6 mm further along x; distances differ by 6 mm · cos(angle).
  auto fixed = sdfGrid(sphereSdf({0, 0, 0}, 0.15f), kLo, kHi, kVoxel, 3 * kVoxel);
  auto moving = sdfGrid(sphereSdf({0.006f, 0, 0}, 0.15f), kLo, kHi, kVoxel, 3 * kVoxel);
  const GridAgreement off = compareGrids(fixed.layer, moving.layer, Transform::Identity());
  // RMS of 6 mm · cos over a sphere: 6 / √3 mm.
  EXPECT_NEAR(off.rmse, 0.006 / std::sqrt(3.0), 0.0005);
  // T_fixed_moving: the moving frame's sphere lies at −6 mm in fixed's frame.
  const GridAgreement aligned =
      compareGrids(fixed.layer, moving.layer, translation(-0.006, 0, 0));
  EXPECT_LT(aligned.rmse, 0.0005);  // trilinear interpolation of a curved field
  EXPECT_GT(aligned.overlap, fixed.layer.numObservedVoxels() * 7 / 10);
}

TEST(CompareGrids, AnUpsideDownSurfaceFailsWhereTheSurfacesCoincide) {
  // The top face of a plate, observed from above (free space +, inside −). Turned upside down
  // about an axis in that face, the surface lands on itself but inside and outside swap.
  const float top = 0.05f;
  auto plate = sdfGrid(boxSdf({0, 0, 0}, {0.2f, 0.2f, top}), Eigen::Vector3f(-0.15f, -0.15f, 0.0f),
                       Eigen::Vector3f(0.15f, 0.15f, 0.1f), kVoxel, 3 * kVoxel);
  Transform flip = translation(0, 0, top) *
                   Transform(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX())) *
                   translation(0, 0, -top);
  const GridAgreement right = compareGrids(plate.layer, plate.layer, Transform::Identity());
  const GridAgreement upside_down = compareGrids(plate.layer, plate.layer, flip);
  ASSERT_GT(upside_down.overlap, 1000u);  // the flipped band overlaps the original
  EXPECT_LT(right.rmse, 1e-6);
  EXPECT_GT(upside_down.rmse, 0.02);  // opposite signs: about twice the distance
  MergingParams params;
  params.tsdf_min_overlap_voxels = 100.0f;
  EXPECT_TRUE(judge(right, params, kVoxel).accepted);
  const Verdict verdict = judge(upside_down, params, kVoxel);
  EXPECT_FALSE(verdict.accepted);
  EXPECT_THAT(verdict.reason, HasSubstr("e_TSDF"));
}

// Paints every observed voxel of the layer with one colour, or with `below` under height z0.
void paint(tsdf::TsdfLayer* layer, Rgb8 colour, Rgb8 below = {}, float z0 = -1e9f) {
  const int vps = layer->voxelsPerSide();
  std::vector<tsdf::BlockIndex> indices;
  for (const auto& [index, block] : layer->blocks()) indices.push_back(index);
  for (const tsdf::BlockIndex& index : indices) {
    for (int i = 0; i < vps * vps * vps; ++i) {
      const tsdf::VoxelIndex v =
          index * vps + Eigen::Vector3i(i % vps, (i / vps) % vps, i / (vps * vps));
      tsdf::TsdfVoxel* voxel = layer->voxel(v);
      if (voxel->weight > 0.0f) voxel->color = layer->voxelCenter(v).z() < z0 ? below : colour;
    }
  }
}

TEST(Chromaticity, IgnoresBrightnessAndSeparatesHues) {
  // The same hue under half the light: 0.
  EXPECT_NEAR(chromaticityDistance({200, 100, 50}, {100, 50, 25}), 0.0, 1e-9);
  // Pure red against pure green: disjoint channels, 1.
  EXPECT_NEAR(chromaticityDistance({255, 0, 0}, {0, 255, 0}), 1.0, 1e-9);
  // A lounge round chair (200, 70, 45) against its square table (170, 140, 100).
  EXPECT_GT(chromaticityDistance({200, 70, 45}, {170, 140, 100}), 0.2);
  // Grey against white: the same chromaticity.
  EXPECT_NEAR(chromaticityDistance({90, 90, 90}, {250, 250, 250}), 0.0, 1e-9);
}

TEST(CompareColours, SameColoursAgreeOtherColoursDisagreeAndDarkOrUncolouredVoxelsDoNotPair) {
  auto a = sdfGrid(sphereSdf({0, 0, 0}, 0.15f), kLo, kHi, kVoxel, 3 * kVoxel);
  auto b = sdfGrid(sphereSdf({0, 0, 0}, 0.15f), kLo, kHi, kVoxel, 3 * kVoxel);
  // Never coloured (a session streamed without colour): nothing to compare.
  EXPECT_EQ(compareColours(a.layer, b.layer, Transform::Identity()).pairs, 0u);

  const Rgb8 green{120, 170, 60}, brown{110, 85, 60};
  paint(&a.layer, green);
  paint(&b.layer, Rgb8{60, 85, 30});  // the same green in half the light
  const ColourAgreement same = compareColours(a.layer, b.layer, Transform::Identity());
  EXPECT_GT(same.pairs, 1000u);
  EXPECT_LT(same.median_distance, 0.01);
  // Green has a hue on both sides: every pair can confirm the match.
  EXPECT_EQ(same.chromatic_pairs, same.pairs);
  EXPECT_LT(same.chromatic_median_distance, 0.01);
  // Only surface voxels pair: fewer than the band's observed voxels.
  EXPECT_LT(same.pairs, a.layer.numObservedVoxels() / 2);

  paint(&b.layer, brown);
  const ColourAgreement other = compareColours(a.layer, b.layer, Transform::Identity());
  EXPECT_EQ(other.pairs, same.pairs);
  EXPECT_NEAR(other.median_distance, chromaticityDistance(green, brown), 1e-6);

  // 60 % of b's surface green (z ≥ −3 cm on a 15 cm sphere), the rest brown: the median
  // follows the larger part, the mean does not.
  paint(&b.layer, green, brown, -0.03f);
  const ColourAgreement mostly = compareColours(a.layer, b.layer, Transform::Identity());
  EXPECT_LT(mostly.median_distance, 0.01);
  EXPECT_GT(mostly.mean_distance, 0.01);

  // Grey against white: they agree, but neither has a hue to confirm anything with.
  paint(&a.layer, Rgb8{90, 90, 95});
  paint(&b.layer, Rgb8{240, 240, 235});
  const ColourAgreement grey = compareColours(a.layer, b.layer, Transform::Identity());
  EXPECT_EQ(grey.pairs, same.pairs);
  EXPECT_LT(grey.median_distance, 0.02);
  EXPECT_EQ(grey.chromatic_pairs, 0u);
  paint(&a.layer, green);

  // Too dark to have a hue: not paired.
  paint(&b.layer, Rgb8{10, 20, 5});
  EXPECT_EQ(compareColours(a.layer, b.layer, Transform::Identity()).pairs, 0u);
}

TEST(CompareColours, LooksUpTheMovingGridThroughTheTransform) {
  // The moving sphere is red on top (z > 0 in its frame) and blue below. Turned upside down
  // onto a fixed sphere that is red on top, the colours disagree; the right way up they agree.
  auto fixed = sdfGrid(sphereSdf({0, 0, 0}, 0.15f), kLo, kHi, kVoxel, 3 * kVoxel);
  auto moving = sdfGrid(sphereSdf({0, 0, 0}, 0.15f), kLo, kHi, kVoxel, 3 * kVoxel);
  const Rgb8 red{200, 30, 30}, blue{30, 30, 200};
  paint(&fixed.layer, red, blue, 0.0f);
  paint(&moving.layer, red, blue, 0.0f);
  EXPECT_LT(compareColours(fixed.layer, moving.layer, Transform::Identity()).median_distance, 0.01);
  const Transform flip(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()));
  EXPECT_GT(compareColours(fixed.layer, moving.layer, flip).median_distance, 0.5);
}

TEST(Judge, AppliesBothThresholdsWithTheOverlapScaledToTheVoxelSize) {
  MergingParams params;  // e* = 2 cm, o* = 10^4 voxels at 1 cm
  GridAgreement g;
  g.overlap = 9999;
  g.rmse = 0.001;
  Verdict v = judge(g, params, 0.01);
  EXPECT_FALSE(v.accepted);
  EXPECT_THAT(v.reason, HasSubstr("overlap 9999 voxels < o*_TSDF 10000"));
  g.overlap = 2500;  // at 2 cm voxels the band holds a quarter as many voxels
  EXPECT_TRUE(judge(g, params, 0.02).accepted);
  g.rmse = 0.021;
  v = judge(g, params, 0.02);
  EXPECT_FALSE(v.accepted);
  EXPECT_THAT(v.reason, HasSubstr("e_TSDF 0.0210 m > e*_TSDF 0.0200 m"));
}

// A linear field d = z − offset on a slab of voxels, every voxel with `weight`.
tsdf::TsdfLayer linearField(float offset, float weight, float x_min, float x_max) {
  const Sdf plane = [offset](const Eigen::Vector3f& p) { return p.z() - offset; };
  return sdfGrid(plane, Eigen::Vector3f(x_min, -0.1f, -0.1f), Eigen::Vector3f(x_max, 0.1f, 0.1f),
                 kVoxel, 0.05f, weight)
      .layer;
}

TEST(MergeGrids, WeightedAverageWhereBothAndSourceValuesWhereOnlyItObserved) {
  tsdf::TsdfLayer target = linearField(0.0f, 2.0f, -0.1f, 0.1f);
  const tsdf::TsdfLayer source = linearField(0.01f, 1.0f, -0.1f, 0.3f);
  const size_t written = mergeGrids(&target, source, Transform::Identity(), 100.0f);
  EXPECT_GT(written, 0u);
  // Inside both: (2 · z + 1 · (z − 0.01)) / 3, weight 3.
  const tsdf::VoxelIndex both = target.voxelIndexOf(Eigen::Vector3f(0.0f, 0.0f, 0.013f));
  const tsdf::TsdfVoxel* v = target.voxel(both);
  ASSERT_NE(v, nullptr);
  const float z = target.voxelCenter(both).z();
  EXPECT_NEAR(v->distance, z - 0.01f / 3.0f, 1e-6f);
  EXPECT_FLOAT_EQ(v->weight, 3.0f);
  // Only the source saw x = 0.2: its values and weight.
  const tsdf::VoxelIndex only = target.voxelIndexOf(Eigen::Vector3f(0.2f, 0.0f, 0.013f));
  v = target.voxel(only);
  ASSERT_NE(v, nullptr);
  EXPECT_NEAR(v->distance, target.voxelCenter(only).z() - 0.01f, 1e-6f);
  EXPECT_FLOAT_EQ(v->weight, 1.0f);
  // Weights saturate at max_weight.
  tsdf::TsdfLayer capped = linearField(0.0f, 2.0f, -0.1f, 0.1f);
  mergeGrids(&capped, source, Transform::Identity(), 2.5f);
  EXPECT_FLOAT_EQ(capped.voxel(both)->weight, 2.5f);
}

TEST(MergeGrids, CarriesColoursFusedByTheSameWeights) {
  tsdf::TsdfLayer target = linearField(0.0f, 2.0f, -0.1f, 0.1f);
  tsdf::TsdfLayer source = linearField(0.01f, 1.0f, -0.1f, 0.3f);
  paint(&target, Rgb8{240, 60, 30});
  paint(&source, Rgb8{30, 60, 240});
  mergeGrids(&target, source, Transform::Identity(), 100.0f);
  // Where both observed: (2 · target + 1 · source) / 3.
  const tsdf::TsdfVoxel* both = target.voxel(target.voxelIndexOf(Eigen::Vector3f(0, 0, 0.013f)));
  ASSERT_NE(both, nullptr);
  EXPECT_EQ(both->color, (Rgb8{170, 60, 100}));
  // Where only the source observed: its colour.
  const tsdf::TsdfVoxel* only = target.voxel(target.voxelIndexOf(Eigen::Vector3f(0.2f, 0, 0.013f)));
  ASSERT_NE(only, nullptr);
  EXPECT_EQ(only->color, (Rgb8{30, 60, 240}));
  // A source without colour leaves the target's as it was.
  tsdf::TsdfLayer plain = linearField(0.0f, 2.0f, -0.1f, 0.1f);
  paint(&plain, Rgb8{240, 60, 30});
  mergeGrids(&plain, linearField(0.01f, 1.0f, -0.1f, 0.3f), Transform::Identity(), 100.0f);
  EXPECT_EQ(plain.voxel(plain.voxelIndexOf(Eigen::Vector3f(0, 0, 0.013f)))->color,
            (Rgb8{240, 60, 30}));
}

TEST(MergeGrids, FillUnobservedLeavesObservedVoxelsAlone) {
  tsdf::TsdfLayer target = linearField(0.0f, 2.0f, -0.1f, 0.1f);
  const tsdf::TsdfLayer source = linearField(0.01f, 1.0f, -0.1f, 0.3f);
  size_t near_surface = 0;
  MergeOptions fill;
  fill.mode = MergeMode::kFillUnobserved;
  const size_t written =
      mergeGrids(&target, source, Transform::Identity(), 100.0f, fill, &near_surface);
  EXPECT_GT(written, 0u);
  EXPECT_GT(near_surface, 0u);
  EXPECT_LT(near_surface, written);  // the band is wider than one voxel
  // Observed by the target: unchanged.
  const tsdf::VoxelIndex both = target.voxelIndexOf(Eigen::Vector3f(0.0f, 0.0f, 0.013f));
  EXPECT_NEAR(target.voxel(both)->distance, target.voxelCenter(both).z(), 1e-6f);
  EXPECT_FLOAT_EQ(target.voxel(both)->weight, 2.0f);
  // Only the source saw it: filled.
  const tsdf::VoxelIndex only = target.voxelIndexOf(Eigen::Vector3f(0.2f, 0.0f, 0.013f));
  ASSERT_NE(target.voxel(only), nullptr);
  EXPECT_NEAR(target.voxel(only)->distance, target.voxelCenter(only).z() - 0.01f, 1e-6f);
}

TEST(MergeGrids, FillUnobservedFusesTargetVoxelsTooLightToBeMeshed) {
  // The target saw the slab twice (weight 2); a scene meshed at weight 3 never showed it.
  tsdf::TsdfLayer target = linearField(0.0f, 2.0f, -0.1f, 0.1f);
  const tsdf::TsdfLayer source = linearField(0.01f, 1.0f, -0.1f, 0.3f);
  MergeOptions fill;
  fill.mode = MergeMode::kFillUnobserved;
  fill.observed_min_weight = 3.0f;
  mergeGrids(&target, source, Transform::Identity(), 100.0f, fill);
  // Fused by weight, as kFuse would: (2 · z + 1 · (z − 0.01)) / 3, weight 3.
  const tsdf::VoxelIndex light = target.voxelIndexOf(Eigen::Vector3f(0.0f, 0.0f, 0.013f));
  EXPECT_NEAR(target.voxel(light)->distance, target.voxelCenter(light).z() - 0.01f / 3.0f, 1e-6f);
  EXPECT_FLOAT_EQ(target.voxel(light)->weight, 3.0f);
  // At the threshold a voxel counts as observed and is kept.
  tsdf::TsdfLayer heavy = linearField(0.0f, 3.0f, -0.1f, 0.1f);
  mergeGrids(&heavy, source, Transform::Identity(), 100.0f, fill);
  EXPECT_NEAR(heavy.voxel(light)->distance, heavy.voxelCenter(light).z(), 1e-6f);
  EXPECT_FLOAT_EQ(heavy.voxel(light)->weight, 3.0f);
}

TEST(MergeGrids, ASourceRegionLimitsTheFillToItsNeighbourhood) {
  tsdf::TsdfLayer target = linearField(0.0f, 2.0f, -0.1f, 0.1f);
  const tsdf::TsdfLayer source = linearField(0.01f, 1.0f, -0.1f, 0.3f);
  // The region: the source's voxels with 0.15 ≤ x ≤ 0.2 (a slab across the plane).
  std::vector<tsdf::VoxelIndex> region;
  for (float x = 0.15f; x <= 0.2f + 1e-4f; x += kVoxel) {
    for (float y = -0.05f; y <= 0.05f + 1e-4f; y += kVoxel) {
      for (float z = -0.03f; z <= 0.03f + 1e-4f; z += kVoxel) {
        region.push_back(source.voxelIndexOf(Eigen::Vector3f(x, y, z)));
      }
    }
  }
  region.push_back(tsdf::VoxelIndex(1000, 1000, 1000));  // unobserved: ignored
  MergeOptions fill;
  fill.mode = MergeMode::kFillUnobserved;
  fill.source_region = &region;
  const size_t written = mergeGrids(&target, source, Transform::Identity(), 100.0f, fill);
  EXPECT_GT(written, 0u);
  EXPECT_LE(written, region.size() * 8);
  // Inside the region: filled with the source's values.
  const tsdf::VoxelIndex inside = target.voxelIndexOf(Eigen::Vector3f(0.175f, 0.0f, 0.013f));
  ASSERT_NE(target.voxel(inside), nullptr);
  EXPECT_GT(target.voxel(inside)->weight, 0.0f);
  EXPECT_NEAR(target.voxel(inside)->distance, target.voxelCenter(inside).z() - 0.01f, 1e-6f);
  // Observed by the source, but far from the region: left unobserved.
  const tsdf::VoxelIndex outside = target.voxelIndexOf(Eigen::Vector3f(0.27f, 0.0f, 0.013f));
  const tsdf::TsdfVoxel* v = target.voxel(outside);
  EXPECT_TRUE(v == nullptr || !(v->weight > 0.0f));
}

TEST(MergeGrids, ATransformedSourceLandsWhereTheTransformSays) {
  // The same box in two frames: source frame = target frame moved by T.
  const Sdf box = boxSdf({0, 0, 0}, {0.1f, 0.08f, 0.06f});
  const Transform T_target_source =
      translation(0.05, -0.02, 0.03) * Transform(Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ()));
  const Sdf in_source = objdb::testing::transformedSdf(box, T_target_source.inverse().cast<float>());
  auto source = sdfGrid(in_source, kLo, kHi, kVoxel, 3 * kVoxel);
  auto truth = sdfGrid(box, kLo, kHi, kVoxel, 3 * kVoxel);
  tsdf::TsdfLayer target = tsdf::TsdfLayer::create(kVoxel, 8).value();
  mergeGrids(&target, source.layer, T_target_source, 100.0f);
  const GridAgreement g = compareGrids(truth.layer, target, Transform::Identity());
  EXPECT_GT(g.overlap, truth.layer.numObservedVoxels() / 2);
  EXPECT_LT(g.rmse, 0.002);
}

}  // namespace
}  // namespace objdb::matching

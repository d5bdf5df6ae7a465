#include "core/common/params_io.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/support/temp_dir.h"

namespace objdb {
namespace {

using ::testing::HasSubstr;

TEST(Params, DefaultsAreThePapers) {
  const Params p;
  EXPECT_FLOAT_EQ(p.keypoints.harris_radius_m, 0.03f);
  EXPECT_EQ(p.keypoints.harris_min_neighbors, 10);
  EXPECT_FLOAT_EQ(p.keypoints.harris_curvature_threshold, 0.07f);
  EXPECT_FLOAT_EQ(p.keypoints.harris_response_threshold, 1e-6f);
  EXPECT_FLOAT_EQ(p.keypoints.iss_border_radius_m, 0.02f);
  EXPECT_FLOAT_EQ(p.keypoints.iss_salient_radius_m, 0.06f);
  EXPECT_FLOAT_EQ(p.keypoints.iss_non_max_radius_m, 0.08f);
  EXPECT_EQ(p.keypoints.iss_min_neighbors, 5);
  EXPECT_FLOAT_EQ(p.descriptors.fpfh_radius_m, 0.10f);
  EXPECT_FLOAT_EQ(p.matching.similarity_threshold, 0.4f);
  EXPECT_EQ(p.matching.k_nn, 5);
  EXPECT_FLOAT_EQ(p.matching.icp_max_rmse_m, 0.02f);
  EXPECT_FLOAT_EQ(p.merging.tsdf_max_rmse_m, 0.02f);
  EXPECT_FLOAT_EQ(p.merging.tsdf_min_overlap_voxels, 1e4f);
  EXPECT_TRUE(p.validate().ok());
}

TEST(Params, OverlapThresholdScalesWithInverseVoxelArea) {
  const MergingParams m;
  EXPECT_DOUBLE_EQ(m.minOverlapVoxels(m.reference_voxel_size_m), m.tsdf_min_overlap_voxels);
  EXPECT_NEAR(m.minOverlapVoxels(2.0 * m.reference_voxel_size_m), 2.5e3, 1e-6);
}

TEST(ParamsJson, OverridesOnlyTheGivenKeys) {
  Params p;
  const Status s =
      applyParamsJson(R"({"tsdf": {"voxel_size_m": 0.01}, "matching": {"k_nn": 8}})", &p);
  ASSERT_TRUE(s.ok()) << s;
  EXPECT_FLOAT_EQ(p.tsdf.voxel_size_m, 0.01f);
  EXPECT_EQ(p.matching.k_nn, 8);
  EXPECT_FLOAT_EQ(p.matching.similarity_threshold, 0.4f);
  EXPECT_EQ(p.tsdf.voxels_per_side, 8);
}

TEST(ParamsJson, UnknownSectionIsNamed) {
  Params p;
  const Status s = applyParamsJson(R"({"tsfd": {"voxel_size_m": 0.01}})", &p);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), HasSubstr("'tsfd'"));
}

// Found by fuzzing (tests/fuzz/regressions/config/json-number-overflow): the JSON parser
// throws out_of_range, not parse_error, for a number beyond double; it aborted the process.
TEST(ParamsJson, ANumberBeyondDoubleIsAnErrorNotACrash) {
  Params p;
  const Status s = applyParamsJson(R"({"tsdf": {"voxel_size_m": 1E99999}})", &p);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(s.message()), HasSubstr("not valid JSON"));
  EXPECT_THAT(std::string(s.message()), HasSubstr("number overflow"));
}

TEST(ParamsJson, TheColourCheckIsSetAndCheckedLikeTheOtherThresholds) {
  Params p;
  EXPECT_FLOAT_EQ(p.merging.colour_max_distance, 0.12f);
  EXPECT_EQ(p.merging.colour_min_pairs, 30);
  ASSERT_TRUE(applyParamsJson(R"({"merging": {"colour_max_distance": 0}})", &p).ok());
  EXPECT_FLOAT_EQ(p.merging.colour_max_distance, 0.0f);
  EXPECT_TRUE(p.validate().ok());  // 0 turns it off
  p.merging.colour_max_distance = 1.5f;  // chromaticity distances lie in [0, 1]
  Status s = p.validate();
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("merging.colour_max_distance"));
  p.merging.colour_max_distance = 0.12f;
  p.merging.colour_min_pairs = 0;
  s = p.validate();
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("merging.colour_min_pairs"));
  p.merging.colour_min_pairs = 30;
  EXPECT_FLOAT_EQ(p.merging.noise_sigmas, 0.0f);
  p.merging.noise_sigmas = -1.0f;
  s = p.validate();
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("merging.noise_sigmas"));
}

TEST(ParamsJson, UnknownKeyIsNamed) {
  Params p;
  const Status s = applyParamsJson(R"({"tsdf": {"voxel_size": 0.01}})", &p);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("tsdf.voxel_size"));
  EXPECT_FLOAT_EQ(p.tsdf.voxel_size_m, 0.02f);  // unchanged on error
}

TEST(ParamsJson, WrongTypeIsNamed) {
  Params p;
  Status s = applyParamsJson(R"({"matching": {"k_nn": 2.5}})", &p);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("matching.k_nn"));
  EXPECT_THAT(std::string(s.message()), HasSubstr("integer"));

  s = applyParamsJson(R"({"tsdf": {"voxel_size_m": "small"}})", &p);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("tsdf.voxel_size_m"));
  EXPECT_THAT(std::string(s.message()), HasSubstr("number"));

  s = applyParamsJson(R"({"tsdf": 3})", &p);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("'tsdf'"));
}

TEST(ParamsJson, InvalidValueIsNamedAndNothingChanges) {
  Params p;
  const Status s =
      applyParamsJson(R"({"matching": {"k_nn": 7}, "tsdf": {"voxel_size_m": -1}})", &p);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("tsdf.voxel_size_m"));
  EXPECT_THAT(std::string(s.message()), HasSubstr("-1"));
  EXPECT_EQ(p.matching.k_nn, 5);
}

TEST(ParamsJson, MalformedJsonIsAnError) {
  Params p;
  EXPECT_FALSE(applyParamsJson("{\"tsdf\": ", &p).ok());
  EXPECT_FALSE(applyParamsJson("[1, 2]", &p).ok());
}

TEST(ParamsJson, ToJsonRoundTrips) {
  Params p;
  p.tsdf.voxel_size_m = 0.015f;
  p.matching.k_nn = 9;
  p.gsm.merge_min_frames = 4;
  p.merging.tsdf_min_overlap_voxels = 5000.0f;
  const std::string text = paramsToJson(p);
  Params back;
  const Status s = applyParamsJson(text, &back);
  ASSERT_TRUE(s.ok()) << s;
  EXPECT_EQ(paramsToJson(back), text);
  EXPECT_FLOAT_EQ(back.tsdf.voxel_size_m, 0.015f);
  EXPECT_EQ(back.matching.k_nn, 9);
  EXPECT_EQ(back.gsm.merge_min_frames, 4);
  EXPECT_FLOAT_EQ(back.merging.tsdf_min_overlap_voxels, 5000.0f);
}

TEST(ParamsFile, LoadsFileAndNamesItOnError) {
  testing::TempDir dir;
  ASSERT_TRUE(
      testing::writeTextFile(dir / "good.json", R"({"descriptors": {"fpfh_radius_m": 0.2}})"));
  const auto good = loadParamsFile(dir / "good.json");
  ASSERT_TRUE(good.ok()) << good.status();
  EXPECT_FLOAT_EQ(good->descriptors.fpfh_radius_m, 0.2f);

  ASSERT_TRUE(testing::writeTextFile(dir / "bad.json", R"({"descriptors": {"radius": 0.2}})"));
  const auto bad = loadParamsFile(dir / "bad.json");
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(std::string(bad.status().message()), HasSubstr("bad.json"));
  EXPECT_THAT(std::string(bad.status().message()), HasSubstr("descriptors.radius"));

  const auto missing = loadParamsFile(dir / "missing.json");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
}

}  // namespace
}  // namespace objdb

// checkModelSettings: one database file keeps one way of describing models.
#include "storage/model_settings.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/common/params_io.h"

namespace objdb::storage {
namespace {

using ::testing::HasSubstr;

SessionInfo session(const std::string& name, const Params& params) {
  SessionInfo s;
  s.name = name;
  s.params_json = paramsToJson(params);
  return s;
}

TEST(CheckModelSettings, AnEmptyDatabaseOrUnrecordedSessionsAcceptAnything) {
  EXPECT_TRUE(checkModelSettings({}, Params{}).ok());
  std::vector<SessionInfo> stored(2);
  stored[0].name = "monday";  // written before sessions recorded their parameters
  stored[0].params_json = "{}";
  stored[1].name = "tuesday";
  stored[1].params_json = "config file lounge.json";
  Params other;
  other.descriptors.surface_spacing_m = 0.0f;
  EXPECT_TRUE(checkModelSettings(stored, other).ok());
}

TEST(CheckModelSettings, TheSameDescriptionPassesAndOtherModulesMayDiffer) {
  Params params;
  const std::vector<SessionInfo> stored = {session("monday", params)};
  EXPECT_TRUE(checkModelSettings(stored, params).ok());
  params.matching.k_nn = 9;            // how models are matched, not how they are described
  params.database.threads = 1;
  params.merging.tsdf_min_overlap_voxels = 5000.0f;
  EXPECT_TRUE(checkModelSettings(stored, params).ok());
}

TEST(CheckModelSettings, ADifferentDescriptionIsRefusedNamingTheKeyAndSession) {
  const std::vector<SessionInfo> stored = {session("monday", Params{})};
  Params params;
  params.descriptors.surface_spacing_m = 0.0f;
  Status s = checkModelSettings(stored, params);
  EXPECT_EQ(s.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(std::string(s.message()), HasSubstr("descriptors.surface_spacing_m"));
  EXPECT_THAT(std::string(s.message()), HasSubstr("session monday"));
  EXPECT_THAT(std::string(s.message()), HasSubstr("= 0.02 (session monday), these parameters say 0;"));
  params = Params{};
  params.keypoints.uniform_spacing_m = 0.0f;
  EXPECT_THAT(std::string(checkModelSettings(stored, params).message()),
              HasSubstr("keypoints.uniform_spacing_m"));
  params = Params{};
  params.tsdf.voxel_size_m = 0.01f;
  EXPECT_THAT(std::string(checkModelSettings(stored, params).message()),
              HasSubstr("tsdf.voxel_size_m"));
  params = Params{};
  params.tsdf.mesh_min_weight = 5.0f;
  EXPECT_THAT(std::string(checkModelSettings(stored, params).message()),
              HasSubstr("tsdf.mesh_min_weight"));
  params = Params{};
  params.tsdf.max_weight = 50.0f;  // fusion, not description
  EXPECT_TRUE(checkModelSettings(stored, params).ok());
}

TEST(CheckModelSettings, TheNewestRecordedSessionDecides) {
  Params before;
  before.descriptors.surface_spacing_m = 0.0f;
  const std::vector<SessionInfo> stored = {session("monday", before),
                                           session("tuesday", Params{})};
  EXPECT_TRUE(checkModelSettings(stored, Params{}).ok());
  EXPECT_THAT(std::string(checkModelSettings(stored, before).message()),
              HasSubstr("session tuesday"));
}

}  // namespace
}  // namespace objdb::storage

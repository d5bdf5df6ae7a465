#include "server/proto_convert.h"

#include <gtest/gtest.h>

#include <set>
#include <string>

namespace objdb::server {
namespace {

database::CandidateResult accepted(int64_t id, double rmse, size_t overlap) {
  database::CandidateResult r;
  r.model_id = id;
  r.accepted = true;
  r.registration.accepted = true;
  r.registration.icp_rmse = rmse / 2;
  r.model_verdict.accepted = true;
  r.model_verdict.agreement.rmse = rmse;
  r.model_verdict.agreement.overlap = overlap;
  r.model_verdict.agreement.compared = overlap + 100;
  r.scene_checks = 3;
  r.colour.pairs = overlap / 3;
  r.colour.chromatic_pairs = overlap / 4;
  r.colour.median_distance = rmse;
  return r;
}

// GetStats fills InsertTimingTotals.<stage>_s from each stage of InsertTimings by name: every
// stage has its field, and every field of seconds has its stage.
TEST(InsertTimingTotals, EveryStageHasItsFieldAndEveryFieldItsStage) {
  const google::protobuf::Descriptor* totals = v1::InsertTimingTotals::descriptor();
  std::set<std::string> stages;
  for (const auto& [stage, member] : database::kInsertStages) {
    const std::string field = std::string(stage) + "_s";
    stages.insert(field);
    const google::protobuf::FieldDescriptor* f = totals->FindFieldByName(field);
    ASSERT_NE(f, nullptr) << field;
    EXPECT_EQ(f->type(), google::protobuf::FieldDescriptor::TYPE_DOUBLE) << field;
  }
  for (int i = 0; i < totals->field_count(); ++i) {
    const google::protobuf::FieldDescriptor* f = totals->field(i);
    if (f->type() != google::protobuf::FieldDescriptor::TYPE_DOUBLE) continue;
    EXPECT_EQ(stages.count(f->name()), 1u) << f->name() << " has no stage";
  }
}

TEST(ObjectEvents, ANewObjectIsCreated) {
  database::InsertReport report;
  report.model_id = 12;
  const auto events = objectEvents(report, 40);
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].kind(), v1::ObjectEvent::CREATED);
  EXPECT_EQ(events[0].object_id(), 12u);
  EXPECT_EQ(events[0].segment_id(), 40u);
  EXPECT_FALSE(events[0].has_evidence());
}

// A re-extracted segment whose earlier version was object 7's only segment: it became object 12,
// and object 7 is gone.
TEST(ObjectEvents, AnObjectEmptiedByAReExtractionIsRemovedAfterTheSegmentsEvent) {
  database::InsertReport report;
  report.model_id = 12;
  report.replaced_earlier = true;
  report.removed_model = 7;
  auto events = objectEvents(report, 40);
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[0].kind(), v1::ObjectEvent::CREATED);
  EXPECT_EQ(events[1].kind(), v1::ObjectEvent::REMOVED);
  EXPECT_EQ(events[1].object_id(), 7u);
  EXPECT_EQ(events[1].into_object_id(), 12u);
  EXPECT_EQ(events[1].segment_id(), 40u);
  // Re-extracted without a surface: only the removal, and no object holds the segment.
  report.unusable = true;
  report.model_id = 0;
  events = objectEvents(report, 40);
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].kind(), v1::ObjectEvent::REMOVED);
  EXPECT_EQ(events[0].into_object_id(), 0u);
}

// The segment merged into object 9 (the lowest e_TSDF); object 26 took it too and joined 9
// afterwards, object 32 took it but failed the check against 9.
TEST(ObjectEvents, ObjectsThatJoinTheSurvivorEachGetAMergedEventAfterTheSegments) {
  database::InsertReport report;
  report.model_id = 9;
  report.merged = true;
  report.results = {accepted(26, 0.0045, 3840), accepted(9, 0.0044, 6550),
                    accepted(32, 0.0171, 5426)};
  report.co_accepted = {accepted(26, 0.0037, 3415), accepted(32, 0.0300, 900)};
  report.co_accepted[1].accepted = false;
  report.co_accepted[1].stage = "model";
  const auto events = objectEvents(report, 77);
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[0].kind(), v1::ObjectEvent::MERGED);
  EXPECT_EQ(events[0].object_id(), 0u);  // the segment's own model
  EXPECT_EQ(events[0].into_object_id(), 9u);
  EXPECT_DOUBLE_EQ(events[0].evidence().tsdf_rmse_m(), 0.0044);
  EXPECT_EQ(events[0].evidence().overlap_voxels(), 6550u);
  EXPECT_EQ(events[0].evidence().non_overlap_voxels(), 100u);
  EXPECT_DOUBLE_EQ(events[0].evidence().colour_distance(), 0.0044);
  EXPECT_EQ(events[0].evidence().colour_pairs(), 6550u / 3);
  EXPECT_EQ(events[0].evidence().colour_chromatic_pairs(), 6550u / 4);
  EXPECT_FALSE(events[0].evidence().loosened());
  EXPECT_EQ(events[1].kind(), v1::ObjectEvent::MERGED);
  EXPECT_EQ(events[1].object_id(), 26u);
  EXPECT_EQ(events[1].into_object_id(), 9u);
  EXPECT_EQ(events[1].segment_id(), 77u);
  EXPECT_DOUBLE_EQ(events[1].evidence().tsdf_rmse_m(), 0.0037);
  EXPECT_EQ(events[1].evidence().scene_checks(), 3u);
}

TEST(ObjectEvents, AMergeBeyondThePapersThresholdsSaysSo) {
  database::InsertReport report;
  report.model_id = 4;
  report.merged = true;
  report.results = {accepted(4, 0.0285, 9461)};
  report.results[0].loosened = true;
  const auto events = objectEvents(report, 8);
  ASSERT_EQ(events.size(), 1u);
  EXPECT_TRUE(events[0].evidence().loosened());
  EXPECT_DOUBLE_EQ(events[0].evidence().tsdf_rmse_m(), 0.0285);
}

}  // namespace
}  // namespace objdb::server

// The Store conformance suite (store_conformance.h), part 1: object models, raw segments, merge
// records, listings, check() and stats(), bad inputs, and concurrent readers and writers. Part 2
// (store_conformance_maps_test.cpp): sessions, scene maps, saved live maps, the scene cache.
#include <algorithm>
#include <atomic>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_format.h"
#include "tests/storage/store_conformance.h"
#include "tests/storage/store_fixtures.h"

namespace objdb::storage {
namespace {

using objdb::testing::diffLayers;
using objdb::testing::diffModels;
using objdb::testing::makeRawSegment;
using objdb::testing::makeStoreModel;
using objdb::testing::StoreConformance;
using objdb::testing::tableRows;
using objdb::testing::wholeModel;
using ::testing::HasSubstr;

database::MergeRecord makeMerge(int64_t target, const std::string& source, double icp_rmse_m) {
  database::MergeRecord record;
  record.target = target;
  record.source = source;
  record.T_target_source = makeStoreModel(uint32_t(target) + 40, 1).observations[0].T_world_object;
  record.icp_rmse_m = icp_rmse_m;
  record.tsdf_rmse_m = icp_rmse_m / 2;
  record.tsdf_overlap = 3415 + size_t(target);
  record.scene_checks = 2;
  return record;
}

// Field by field, bit exact (the transform too); empty when equal.
std::string diffMerges(const database::MergeRecord& a, const database::MergeRecord& b) {
  if (a.target != b.target || a.source != b.source) {
    return absl::StrFormat("merge into %d from '%s' vs into %d from '%s'", a.target, a.source,
                           b.target, b.source);
  }
  if (!(a.T_target_source.matrix() == b.T_target_source.matrix())) return "transform differs";
  if (a.icp_rmse_m != b.icp_rmse_m || a.tsdf_rmse_m != b.tsdf_rmse_m) return "rmse differs";
  if (a.tsdf_overlap != b.tsdf_overlap || a.scene_checks != b.scene_checks) return "counts differ";
  return "";
}

const ModelSummary* findSummary(const std::vector<ModelSummary>& summaries, int64_t id) {
  for (const auto& s : summaries) {
    if (s.id == id) return &s;
  }
  return nullptr;
}

std::vector<int64_t> idsOf(const std::vector<ModelSummary>& summaries) {
  std::vector<int64_t> ids;
  for (const auto& s : summaries) ids.push_back(s.id);
  return ids;
}

std::vector<int64_t> sorted(std::vector<int64_t> ids) {
  std::sort(ids.begin(), ids.end());
  return ids;
}

TEST_P(StoreConformance, ModelsRoundTripBitExactAcrossReopen) {
  const std::string target = freshTarget();
  std::vector<model::ObjectModel> originals;
  {
    auto store = open(target);
    ASSERT_NE(store, nullptr);
    EXPECT_TRUE(store->modelIds().value().empty());
    for (uint32_t seed : {1u, 2u, 5u}) {
      model::ObjectModel m = makeStoreModel(seed, int(seed % 3) + 1);
      m.structure = seed == 2;
      const auto id = store->addModel(model::cloneModel(m));
      ASSERT_TRUE(id.ok()) << id.status();
      m.id = *id;
      originals.push_back(std::move(m));
    }
  }
  auto store = open(target);
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(store->modelIds().value(),
            sorted({originals[0].id, originals[1].id, originals[2].id}));
  for (const auto& m : originals) {
    const auto loaded = store->model(m.id);
    ASSERT_TRUE(loaded.ok()) << loaded.status();
    EXPECT_EQ(diffModels(**loaded, m), "") << "model " << m.id;
  }
  // The prefilter's view of every model, ascending id, with the segments it holds.
  const auto entries = store->matchEntries(true);
  ASSERT_TRUE(entries.ok()) << entries.status();
  EXPECT_TRUE(entries->skipped.empty());
  ASSERT_EQ(entries->entries.size(), 3u);
  for (size_t i = 0; i < entries->entries.size(); ++i) {
    const database::MatchEntry& e = entries->entries[i];
    if (i > 0) EXPECT_LT(entries->entries[i - 1].id, e.id);
    const auto it = std::find_if(originals.begin(), originals.end(),
                                 [&](const model::ObjectModel& m) { return m.id == e.id; });
    ASSERT_NE(it, originals.end()) << e.id;
    EXPECT_EQ(e.planar, it->planar) << e.id;
    EXPECT_EQ(e.structure, it->structure) << e.id;
    EXPECT_EQ(e.num_points, it->cloud.points.size()) << e.id;
    EXPECT_EQ(e.num_keypoints, it->keypoint_indices.size()) << e.id;
    EXPECT_EQ(e.descriptors, it->descriptors) << e.id;
    ASSERT_EQ(e.segments.size(), it->observations.size()) << e.id;
    for (size_t k = 0; k < e.segments.size(); ++k) {
      EXPECT_EQ(e.segments[k], (database::SegmentKey{it->observations[k].session,
                                                      it->observations[k].label}));
    }
  }
}

TEST_P(StoreConformance, ReplaceAndRemoveKeepIdsStableAndNeverReuseThem) {
  const std::string target = freshTarget();
  auto store = open(target);
  ASSERT_NE(store, nullptr);
  const int64_t a = store->addModel(makeStoreModel(1, 1)).value();
  const int64_t b = store->addModel(makeStoreModel(2, 1)).value();
  EXPECT_NE(a, b);
  model::ObjectModel merged = makeStoreModel(3, 2);
  merged.id = a;
  const database::MergeRecord record = makeMerge(a, "segment s1/7", 0.0125);
  ASSERT_TRUE(store->replaceModel(model::cloneModel(merged), record).ok());
  EXPECT_EQ(diffModels(*store->model(a).value(), merged), "");
  auto records = store->mergeRecords().value();
  ASSERT_EQ(records.size(), 1u);
  EXPECT_EQ(diffMerges(records[0], record), "");
  // Without a merge record: the model is replaced, nothing is recorded.
  model::ObjectModel rebuilt = makeStoreModel(7, 3);
  rebuilt.id = a;
  ASSERT_TRUE(store->replaceModel(model::cloneModel(rebuilt), std::nullopt).ok());
  EXPECT_EQ(diffModels(*store->model(a).value(), rebuilt), "");
  EXPECT_EQ(store->mergeRecords().value().size(), 1u);

  ASSERT_TRUE(store->removeModel(b).ok());
  EXPECT_EQ(store->model(b).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(store->removeModel(b).code(), absl::StatusCode::kNotFound);
  model::ObjectModel ghost = makeStoreModel(4, 1);
  ghost.id = b;
  const Status replaced = store->replaceModel(std::move(ghost), std::nullopt);
  EXPECT_EQ(replaced.code(), absl::StatusCode::kNotFound) << replaced;
  EXPECT_EQ(store->model(b).status().code(), absl::StatusCode::kNotFound) << "not revived";
  const int64_t c = store->addModel(makeStoreModel(5, 1)).value();
  EXPECT_NE(c, a);
  EXPECT_NE(c, b) << "a removed model's id is not reused";
  store.reset();
  store = open(target);
  ASSERT_NE(store, nullptr);
  const int64_t d = store->addModel(makeStoreModel(6, 1)).value();
  EXPECT_NE(d, a);
  EXPECT_NE(d, b) << "not reused after a reopen either";
  EXPECT_NE(d, c);
  EXPECT_EQ(store->modelIds().value(), sorted({a, c, d}));
  EXPECT_EQ(diffModels(*store->model(a).value(), rebuilt), "");
  const auto stats = store->stats().value();
  EXPECT_EQ(stats.active_models, 3);
  EXPECT_EQ(stats.removed_models, 1);
  EXPECT_EQ(stats.merged_models, 0);
}

TEST_P(StoreConformance, ARemovedModelNamesTheModelThatHoldsItsSegmentNow) {
  const std::string target = freshTarget();
  auto store = open(target);
  ASSERT_NE(store, nullptr);
  const int64_t a = store->addModel(makeStoreModel(1, 1)).value();
  const int64_t b = store->addModel(makeStoreModel(2, 1)).value();
  EXPECT_EQ(store->modelFate(a).value().state, "active");
  EXPECT_EQ(store->modelFate(a + b + 100).value().state, "") << "never existed";
  ASSERT_TRUE(store->removeModel(a).ok());
  ModelFate fate = store->modelFate(a).value();
  EXPECT_EQ(fate.state, "removed");
  EXPECT_EQ(fate.next, 0) << "not known yet";
  ASSERT_TRUE(store->setSuccessor(a, b).ok());
  // Only a tombstone takes a successor: an active model is not retired by it.
  ASSERT_TRUE(store->setSuccessor(b, a).ok());
  EXPECT_EQ(store->modelFate(b).value().state, "active");
  EXPECT_EQ(store->modelFate(b).value().next, 0);
  store.reset();
  store = open(target);
  ASSERT_NE(store, nullptr);
  fate = store->modelFate(a).value();
  EXPECT_EQ(fate.state, "removed");
  EXPECT_EQ(fate.next, b) << "kept across a reopen";
  EXPECT_EQ(store->model(a).status().code(), absl::StatusCode::kNotFound);
}

TEST_P(StoreConformance, AnAbsorbedModelIsKeptAsMergedIntoItsTargetInOneUnit) {
  const std::string target = freshTarget();
  auto store = open(target);
  ASSERT_NE(store, nullptr);
  const int64_t a = store->addModel(makeStoreModel(1, 1)).value();
  const int64_t b = store->addModel(makeStoreModel(2, 1)).value();
  model::ObjectModel joined = makeStoreModel(3, 2);  // both models' observations
  joined.id = a;
  const database::MergeRecord record = makeMerge(a, absl::StrFormat("model %d", b), 0.004);
  ASSERT_TRUE(store->absorbModel(model::cloneModel(joined), record, b).ok());
  auto check = [&] {
    EXPECT_EQ(diffModels(*store->model(a).value(), joined), "");
    EXPECT_EQ(store->model(b).status().code(), absl::StatusCode::kNotFound);
    EXPECT_EQ(store->modelIds().value(), std::vector<int64_t>{a});
    ModelQuery query;
    query.include_merged = true;
    const auto summaries = store->modelSummaries(query).value();
    ASSERT_EQ(idsOf(summaries), sorted({a, b}));
    const ModelSummary* absorbed = findSummary(summaries, b);
    EXPECT_EQ(absorbed->state, "merged");
    EXPECT_EQ(store->modelFate(b).value().state, "merged");
    EXPECT_EQ(store->modelFate(b).value().next, a);
    EXPECT_EQ(absorbed->merged_into, a);
    EXPECT_TRUE(absorbed->observations.empty());
    const ModelSummary* into = findSummary(summaries, a);
    EXPECT_EQ(into->state, "active");
    EXPECT_EQ(into->observations.size(), 2u);
    EXPECT_EQ(into->merges, 1);
    const auto records = store->mergeRecordsInto(a).value();
    ASSERT_EQ(records.size(), 1u);
    EXPECT_EQ(diffMerges(records[0], record), "");
    EXPECT_EQ(store->stats().value().merged_models, 1);
  };
  check();
  // Again, or into itself: refused, and nothing changes.
  model::ObjectModel again = makeStoreModel(4, 1);
  again.id = a;
  const Status twice = store->absorbModel(model::cloneModel(again), record, b);
  EXPECT_EQ(twice.code(), absl::StatusCode::kNotFound) << twice;
  EXPECT_THAT(twice.message(),
              HasSubstr(absl::StrFormat("merging object model %d into object model %d", b, a)));
  EXPECT_EQ(store->absorbModel(std::move(again), record, a).code(),
            absl::StatusCode::kInvalidArgument);
  check();
  store.reset();
  store = open(target);
  ASSERT_NE(store, nullptr);
  check();
  // Into a model that is gone: refused as a whole, the model that would have been absorbed
  // stays active with everything it had.
  model::ObjectModel survivor = makeStoreModel(5, 2);
  survivor.id = store->addModel(model::cloneModel(survivor)).value();
  const int64_t gone = store->addModel(makeStoreModel(6, 1)).value();
  ASSERT_TRUE(store->removeModel(gone).ok());
  model::ObjectModel into_gone = makeStoreModel(7, 3);
  into_gone.id = gone;
  EXPECT_EQ(store->absorbModel(std::move(into_gone),
                               makeMerge(gone, absl::StrFormat("model %d", survivor.id), 0.01),
                               survivor.id)
                .code(),
            absl::StatusCode::kNotFound);
  EXPECT_EQ(diffModels(*store->model(survivor.id).value(), survivor), "");
  EXPECT_TRUE(store->mergeRecordsInto(gone).value().empty());
  EXPECT_EQ(store->stats().value().merged_models, 1);
}

TEST_P(StoreConformance, RawSegmentKeysComeInTheOrderTheirRowsWereCreated) {
  const std::string target = freshTarget();
  auto store = open(target);
  ASSERT_NE(store, nullptr);
  EXPECT_TRUE(store->rawSegmentKeys().value().empty());
  ASSERT_TRUE(store->putRawSegment(makeRawSegment("tuesday", 9, 1)).ok());
  ASSERT_TRUE(store->putRawSegment(makeRawSegment("monday", 4, 2)).ok());
  ASSERT_TRUE(store->putRawSegment(makeRawSegment("tuesday", 2, 3)).ok());
  // A re-extraction keeps its row, and so its place.
  ASSERT_TRUE(store->putRawSegment(makeRawSegment("tuesday", 9, 4)).ok());
  const std::vector<database::SegmentKey> expected = {{"tuesday", 9}, {"monday", 4}, {"tuesday", 2}};
  EXPECT_EQ(store->rawSegmentKeys().value(), expected);
  store.reset();
  store = open(target);
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(store->rawSegmentKeys().value(), expected);
}

TEST_P(StoreConformance, RawSegmentsRoundTripAndAReExtractionReplacesTheRow) {
  const std::string target = freshTarget();
  auto store = open(target);
  ASSERT_NE(store, nullptr);
  auto first = makeRawSegment("monday", 4, 1);
  first.parts = {4, 9, 12};  // a whole object of three GSM labels
  for (size_t i = 0; i < first.voxels.size(); ++i) first.voxel_parts.push_back(first.parts[i % 3]);
  first.observation_depth_m = 2.75f;
  ASSERT_TRUE(store->putRawSegment(first).ok());
  store.reset();
  store = open(target);
  ASSERT_NE(store, nullptr);
  auto loaded = store->rawSegment({"monday", 4});
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_EQ((*loaded)->key, first.key);
  EXPECT_TRUE((*loaded)->T_world_segment.matrix() == first.T_world_segment.matrix());
  EXPECT_EQ(diffLayers(*(*loaded)->grid, *first.grid), "");
  EXPECT_EQ((*loaded)->voxels, first.voxels);
  EXPECT_EQ((*loaded)->extraction_frame, first.extraction_frame);
  EXPECT_EQ((*loaded)->observation_depth_m, first.observation_depth_m);
  EXPECT_EQ((*loaded)->parts, first.parts);
  EXPECT_EQ((*loaded)->voxel_parts, first.voxel_parts);
  const auto id = store->rawSegmentId({"monday", 4});
  ASSERT_TRUE(id.ok()) << id.status();
  // Voxel parts must match the voxels one to one.
  auto uneven = makeRawSegment("monday", 5, 1);
  uneven.voxel_parts = {5};
  ASSERT_GT(uneven.voxels.size(), 1u);
  const Status refused = store->putRawSegment(uneven);
  EXPECT_EQ(refused.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(refused.message(),
              HasSubstr(absl::StrFormat("1 voxel parts for %d voxels", uneven.voxels.size())));
  EXPECT_EQ(store->rawSegment({"monday", 5}).status().code(), absl::StatusCode::kNotFound);
  // And each voxel's part must be one of the segment's parts.
  auto stray = makeRawSegment("monday", 5, 1);
  stray.parts = {5, 7};
  stray.voxel_parts.assign(stray.voxels.size(), 5);
  stray.voxel_parts.back() = 8;
  const Status stray_refused = store->putRawSegment(stray);
  EXPECT_EQ(stray_refused.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(stray_refused.message(),
              HasSubstr("monday/5: a voxel of part 8, which is not one of its parts (5,7)"));
  EXPECT_EQ(store->rawSegment({"monday", 5}).status().code(), absl::StatusCode::kNotFound);

  // A re-extraction updates the row in place: same id, every field new.
  auto again = makeRawSegment("monday", 4, 2);
  again.parts = {4};
  ASSERT_TRUE(store->putRawSegment(again).ok());
  const auto replaced = store->rawSegment({"monday", 4}).value();
  EXPECT_TRUE(replaced->T_world_segment.matrix() == again.T_world_segment.matrix());
  EXPECT_EQ(diffLayers(*replaced->grid, *again.grid), "");
  EXPECT_EQ(replaced->voxels, again.voxels);
  EXPECT_EQ(replaced->extraction_frame, again.extraction_frame);
  EXPECT_EQ(replaced->observation_depth_m, 0.0f);
  EXPECT_EQ(replaced->parts, again.parts);
  EXPECT_TRUE(replaced->voxel_parts.empty()) << "none recorded";
  EXPECT_EQ(store->rawSegmentId({"monday", 4}).value(), *id);
  EXPECT_EQ(tableRows(store->stats().value(), "raw_segments"), 1);
  EXPECT_EQ(store->rawSegment({"tuesday", 4}).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(store->rawSegmentId({"tuesday", 4}).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(store->rawSegmentId({"monday", 5}).status().code(), absl::StatusCode::kNotFound);
}

TEST_P(StoreConformance, ObservationDepthsComeInTheOrderOfTheKeys) {
  auto store = open(freshTarget());
  ASSERT_NE(store, nullptr);
  const std::pair<database::SegmentKey, float> segments[] = {
      {{"monday", 4}, 2.75f}, {{"tuesday", 9}, 0.0f}, {{"monday", 5}, 1.5f}};
  for (uint32_t i = 0; i < 3; ++i) {
    auto segment = makeRawSegment(segments[i].first.session, segments[i].first.label, i + 1);
    segment.observation_depth_m = segments[i].second;
    ASSERT_TRUE(store->putRawSegment(segment).ok());
  }
  const auto depths = store->observationDepths({{"monday", 5}, {"tuesday", 9}, {"monday", 4}});
  ASSERT_TRUE(depths.ok()) << depths.status();
  EXPECT_EQ(*depths, (std::vector<float>{1.5f, 0.0f, 2.75f}));
  EXPECT_TRUE(store->observationDepths({}).value().empty());
  const auto missing = store->observationDepths({{"monday", 4}, {"friday", 4}});
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(missing.status().message(), HasSubstr("friday/4"));
}

// Six models: observed in up to three sessions, one room structure, one merged into another, one
// removed; the listing's filters and pages, and every field of a summary.
TEST_P(StoreConformance, ModelSummariesFilterBySessionMergedAndStructureAndPage) {
  const std::string target = freshTarget();
  auto store = open(target);
  ASSERT_NE(store, nullptr);
  auto segment = makeRawSegment("s0", 11, 3);  // model 11's first observation, stored before it
  segment.parts = {11, 30};
  ASSERT_TRUE(store->putRawSegment(segment).ok());
  const model::ObjectModel first = makeStoreModel(11, 3);  // s0/11, s1/12, s2/13
  const int64_t m1 = store->addModel(model::cloneModel(first)).value();
  model::ObjectModel wall = makeStoreModel(12, 1);  // s0/12
  wall.structure = true;
  const int64_t m2 = store->addModel(std::move(wall)).value();
  const int64_t m3 = store->addModel(makeStoreModel(13, 2)).value();  // s0/13, s1/14
  const int64_t m4 = store->addModel(makeStoreModel(14, 1)).value();  // s0/14
  const int64_t m5 = store->addModel(makeStoreModel(15, 1)).value();
  const int64_t m6 = store->addModel(makeStoreModel(16, 2)).value();  // s0/16, s1/17
  model::ObjectModel joined = makeStoreModel(13, 2);
  joined.id = m3;
  joined.observations.push_back(makeStoreModel(14, 1).observations[0]);
  ASSERT_TRUE(store->absorbModel(std::move(joined),
                                 makeMerge(m3, absl::StrFormat("model %d", m4), 0.003), m4).ok());
  ASSERT_TRUE(store->removeModel(m5).ok());

  auto list = [&](ModelQuery query) {
    const auto summaries = store->modelSummaries(query);
    EXPECT_TRUE(summaries.ok()) << summaries.status();
    return summaries.ok() ? *summaries : std::vector<ModelSummary>{};
  };
  const std::vector<ModelSummary> all = list({});
  EXPECT_EQ(idsOf(all), sorted({m1, m2, m3, m6})) << "active ones, structure included";
  ModelQuery merged;
  merged.include_merged = true;
  EXPECT_EQ(idsOf(list(merged)), sorted({m1, m2, m3, m4, m6})) << "removed ones never";
  ModelQuery objects;
  objects.include_structure = false;
  EXPECT_EQ(idsOf(list(objects)), sorted({m1, m3, m6}));
  ModelQuery s1;
  s1.session = "s1";
  EXPECT_EQ(idsOf(list(s1)), sorted({m1, m3, m6}));
  ModelQuery s2;
  s2.session = "s2";
  EXPECT_EQ(idsOf(list(s2)), std::vector<int64_t>{m1});
  ModelQuery s0_objects;
  s0_objects.session = "s0";
  s0_objects.include_structure = false;
  EXPECT_EQ(idsOf(list(s0_objects)), sorted({m1, m3, m6}));
  ModelQuery nobody;
  nobody.session = "nobody";
  EXPECT_TRUE(list(nobody).empty());

  // Pages of two: ascending ids above after_id, together the whole listing.
  std::vector<int64_t> paged;
  ModelQuery page = merged;
  page.limit = 2;
  for (int n = 0; n < 10; ++n) {
    const auto ids = idsOf(list(page));
    EXPECT_LE(ids.size(), 2u);
    if (ids.empty()) break;
    EXPECT_GT(ids.front(), page.after_id);
    paged.insert(paged.end(), ids.begin(), ids.end());
    page.after_id = ids.back();
  }
  EXPECT_EQ(paged, idsOf(list(merged)));

  const ModelSummary* s = findSummary(all, m1);
  ASSERT_NE(s, nullptr);
  EXPECT_EQ(s->state, "active");
  EXPECT_EQ(s->merged_into, 0);
  EXPECT_EQ(s->planar, first.planar);
  EXPECT_FALSE(s->structure);
  EXPECT_TRUE(findSummary(all, m2)->structure);
  EXPECT_EQ(s->num_points, int64_t(first.cloud.points.size()));
  EXPECT_EQ(s->num_keypoints, int64_t(first.keypoint_indices.size()));
  EXPECT_EQ(s->voxel_size, double(first.grid.voxelSize()));
  Eigen::Vector3f lo = first.cloud.points.front(), hi = lo;
  for (const auto& p : first.cloud.points) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  EXPECT_TRUE(s->bbox_min == lo.cast<double>()) << s->bbox_min.transpose();
  EXPECT_TRUE(s->bbox_max == hi.cast<double>()) << s->bbox_max.transpose();
  EXPECT_EQ(s->merges, 0);
  EXPECT_EQ(findSummary(all, m3)->merges, 1);
  EXPECT_EQ(findSummary(all, m3)->observations.size(), 3u);
  ASSERT_EQ(s->observations.size(), 3u);
  for (size_t k = 0; k < 3; ++k) {
    const ModelSummary::Pose& pose = s->observations[k];
    EXPECT_EQ(pose.session, first.observations[k].session);
    EXPECT_EQ(pose.label, first.observations[k].label);
    EXPECT_TRUE(pose.T_world_object.matrix() == first.observations[k].T_world_object.matrix());
  }
  // Only the first observation's raw segment is stored: its row and its parts.
  EXPECT_EQ(s->observations[0].raw_segment_id, store->rawSegmentId({"s0", 11}).value());
  EXPECT_EQ(s->observations[0].parts, segment.parts);
  EXPECT_EQ(s->observations[1].raw_segment_id, 0);
  EXPECT_TRUE(s->observations[1].parts.empty());
}

TEST_P(StoreConformance, MergeRecordsListEveryMergeAndMergeRecordsIntoOnlyTheTargets) {
  const std::string target = freshTarget();
  auto store = open(target);
  ASSERT_NE(store, nullptr);
  const int64_t a = store->addModel(makeStoreModel(1, 1)).value();
  const int64_t b = store->addModel(makeStoreModel(2, 1)).value();
  const int64_t c = store->addModel(makeStoreModel(3, 1)).value();
  auto grown = [](int64_t id, uint32_t seed) {
    model::ObjectModel m = makeStoreModel(seed, 2);
    m.id = id;
    return m;
  };
  const database::MergeRecord r1 = makeMerge(a, "segment s0/5", 0.011);
  const database::MergeRecord r2 = makeMerge(a, absl::StrFormat("model %d", c), 0.012);
  const database::MergeRecord r3 = makeMerge(b, "segment s1/3", 0.013);
  const database::MergeRecord r4 = makeMerge(a, "segment s2/8", 0.014);
  EXPECT_TRUE(store->mergeRecords().value().empty());
  ASSERT_TRUE(store->replaceModel(grown(a, 10), r1).ok());
  ASSERT_TRUE(store->absorbModel(grown(a, 11), r2, c).ok());
  ASSERT_TRUE(store->replaceModel(grown(b, 12), r3).ok());
  ASSERT_TRUE(store->replaceModel(grown(a, 13), r4).ok());
  store.reset();
  store = open(target);
  ASSERT_NE(store, nullptr);
  auto records = store->mergeRecords().value();
  ASSERT_EQ(records.size(), 4u);
  std::sort(records.begin(), records.end(),
            [](const auto& x, const auto& y) { return x.icp_rmse_m < y.icp_rmse_m; });
  EXPECT_EQ(diffMerges(records[0], r1), "");
  EXPECT_EQ(diffMerges(records[1], r2), "");
  EXPECT_EQ(diffMerges(records[2], r3), "");
  EXPECT_EQ(diffMerges(records[3], r4), "");
  const auto into_a = store->mergeRecordsInto(a).value();  // oldest first
  ASSERT_EQ(into_a.size(), 3u);
  EXPECT_EQ(diffMerges(into_a[0], r1), "");
  EXPECT_EQ(diffMerges(into_a[1], r2), "");
  EXPECT_EQ(diffMerges(into_a[2], r4), "");
  const auto into_b = store->mergeRecordsInto(b).value();
  ASSERT_EQ(into_b.size(), 1u);
  EXPECT_EQ(diffMerges(into_b[0], r3), "");
  EXPECT_TRUE(store->mergeRecordsInto(c).value().empty()) << "the absorbed one was the source";
  EXPECT_TRUE(store->mergeRecordsInto(c + b + a + 100).value().empty());
  // A re-extracted segment merged into the same model again: its new record replaces the old one,
  // so each merge is listed once and the model's merge count counts merges (issue 47: a lounge
  // model listed one segment four times and "merges 7" for 3 placements).
  const database::MergeRecord again = makeMerge(a, "segment s0/5", 0.015);
  ASSERT_TRUE(store->replaceModel(grown(a, 14), again).ok());
  const auto into_a_again = store->mergeRecordsInto(a).value();
  ASSERT_EQ(into_a_again.size(), 3u);
  EXPECT_EQ(diffMerges(into_a_again[0], r2), "");
  EXPECT_EQ(diffMerges(into_a_again[1], r4), "");
  EXPECT_EQ(diffMerges(into_a_again[2], again), "");
  EXPECT_EQ(store->mergeRecords().value().size(), 4u);
  ModelQuery query;
  EXPECT_EQ(findSummary(store->modelSummaries(query).value(), a)->merges, 3);
}

TEST_P(StoreConformance, AHealthyStoreChecksOkAndCountsItsModels) {
  const std::string target = freshTarget();
  auto store = open(target);
  ASSERT_NE(store, nullptr);
  const auto empty = store->stats();
  ASSERT_TRUE(empty.ok()) << empty.status();
  EXPECT_GT(empty->schema_version, 0);
  EXPECT_EQ(empty->active_models + empty->removed_models + empty->merged_models, 0);
  EXPECT_TRUE(store->check().value().ok());

  SessionInfo info;
  info.name = "s0";
  ASSERT_TRUE(store->beginSession(info).ok());
  ASSERT_TRUE(store->putRawSegment(makeRawSegment("s0", 1, 1)).ok());
  std::vector<int64_t> ids;
  for (uint32_t seed = 1; seed <= 4; ++seed) {
    ids.push_back(store->addModel(makeStoreModel(seed, 2)).value());
  }
  ASSERT_TRUE(store->removeModel(ids[3]).ok());
  model::ObjectModel joined = makeStoreModel(9, 3);
  joined.id = ids[0];
  ASSERT_TRUE(store->absorbModel(std::move(joined), makeMerge(ids[0], absl::StrFormat("model %d", ids[2]), 0.01),
                                 ids[2]).ok());
  const model::ObjectModel scene_source = makeStoreModel(20, 1);
  ASSERT_TRUE(store->putScene("s0", std::make_shared<const tsdf::TsdfLayer>(
                                        scene_source.grid.clone())).ok());
  ASSERT_TRUE(store->putSavedMap("s0", 10, scene_source.grid, {}).ok());
  for (int pass = 0; pass < 2; ++pass) {
    SCOPED_TRACE(pass == 0 ? "open" : "reopened");
    const auto report = store->check();
    ASSERT_TRUE(report.ok()) << report.status();
    EXPECT_TRUE(report->engine_findings.empty())
        << report->engine_findings.size() << " findings, first: " << report->engine_findings[0];
    EXPECT_TRUE(report->damaged.empty());
    EXPECT_TRUE(report->ok());
    EXPECT_GT(report->blobs_checked, 0u);
    const auto stats = store->stats();
    ASSERT_TRUE(stats.ok()) << stats.status();
    EXPECT_EQ(stats->schema_version, empty->schema_version);
    EXPECT_EQ(stats->active_models, 2);
    EXPECT_EQ(stats->removed_models, 1);
    EXPECT_EQ(stats->merged_models, 1);
    store.reset();
    store = open(target);
    ASSERT_NE(store, nullptr);
  }
}

// Each refused with its code, a message naming what was wrong, and nothing stored. (Refusals that
// need earlier state are tested with it: a removed model's replacement, a merge into itself,
// uneven voxel parts, a null scene, a duplicate or unknown session.)
TEST_P(StoreConformance, BadInputsAreRefusedWithTheirCodesAndStoreNothing) {
  const std::string target = freshTarget();
  auto store = open(target);
  ASSERT_NE(store, nullptr);
  auto gridless = makeRawSegment("monday", 4, 1);
  gridless.grid = nullptr;
  const Status no_grid = store->putRawSegment(gridless);
  EXPECT_EQ(no_grid.code(), absl::StatusCode::kInvalidArgument) << no_grid;
  EXPECT_THAT(no_grid.message(), HasSubstr("monday/4"));

  const Status unnamed_segment = store->putRawSegment(makeRawSegment("", 4, 1));
  EXPECT_EQ(unnamed_segment.code(), absl::StatusCode::kInvalidArgument) << unnamed_segment;
  EXPECT_THAT(unnamed_segment.message(), HasSubstr("session name is empty"));
  SessionInfo unnamed;
  const auto begun = store->beginSession(unnamed);
  EXPECT_EQ(begun.status().code(), absl::StatusCode::kInvalidArgument) << begun.status();
  EXPECT_THAT(begun.status().message(), HasSubstr("session name is empty"));
  const model::ObjectModel scene_source = makeStoreModel(3, 1);
  EXPECT_EQ(store->putScene("", std::make_shared<const tsdf::TsdfLayer>(
                                    scene_source.grid.clone())).code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(store->putSavedMap("", 1, scene_source.grid, {}).code(),
            absl::StatusCode::kInvalidArgument);
  // A model observed in an unnamed session: the whole model is refused, its named session too.
  model::ObjectModel half_named = makeStoreModel(2, 2);
  half_named.observations[1].session = "";
  EXPECT_EQ(store->addModel(std::move(half_named)).status().code(),
            absl::StatusCode::kInvalidArgument);

  const auto unknown = store->model(12345);
  EXPECT_EQ(unknown.status().code(), absl::StatusCode::kNotFound) << unknown.status();
  EXPECT_THAT(unknown.status().message(), HasSubstr("12345"));
  EXPECT_EQ(store->model(0).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(store->model(-1).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(store->removeModel(12345).code(), absl::StatusCode::kNotFound);
  model::ObjectModel stranger = makeStoreModel(4, 1);
  stranger.id = 12345;
  EXPECT_EQ(store->replaceModel(std::move(stranger), std::nullopt).code(),
            absl::StatusCode::kNotFound);

  EXPECT_TRUE(store->modelIds().value().empty());
  EXPECT_TRUE(store->sessions().value().empty());
  EXPECT_TRUE(store->mergeRecords().value().empty());
  EXPECT_TRUE(store->modelSummaries({}).value().empty());
  EXPECT_EQ(store->rawSegment({"monday", 4}).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(store->savedMapFrames("").value(), -1);
  EXPECT_TRUE(store->check().value().ok());
}

// Readers list and load models while one writer inserts and grows them: no reader ever sees a
// half-written model (its row and its observations come from one snapshot), whether it reads
// through the writer's store object or through a second store on the same target.
TEST_P(StoreConformance, ReadersNeverSeeHalfWrittenModels) {
  const std::string target = freshTarget();
  StoreOptions options;
  options.sqlite.synchronous = "NORMAL";  // the property under test is isolation, not durability
  auto writer_store = open(target, options);
  ASSERT_NE(writer_store, nullptr);
  ASSERT_TRUE(writer_store->addModel(makeStoreModel(1, 1)).ok());
  StoreOptions second = options;
  second.sqlite.read_only = true;  // SQLite: one writer per file
  auto own_store = open(target, second);
  ASSERT_NE(own_store, nullptr);

  std::atomic<bool> done{false};
  std::atomic<size_t> loads{0}, broken{0}, errors{0};
  auto readLoop = [&](const Store& store) {
    while (!done.load()) {
      const auto ids = store.modelIds();
      if (!ids.ok()) {
        ++errors;
        continue;
      }
      for (int64_t id : *ids) {
        const auto m = store.model(id);
        if (!m.ok()) {
          ++errors;
          continue;
        }
        ++loads;
        if (!wholeModel(**m)) ++broken;
      }
    }
  };
  std::vector<std::thread> readers;
  readers.emplace_back(readLoop, std::cref(*writer_store));
  readers.emplace_back(readLoop, std::cref(*writer_store));
  readers.emplace_back(readLoop, std::cref(*own_store));

  Status failed;
  for (uint32_t i = 0; i < 60 && failed.ok(); ++i) {
    if (i % 2 == 0) {
      failed = writer_store->addModel(makeStoreModel(100 + i, 1 + int(i % 3))).status();
    } else {
      // Merges grow a model: more observations, a larger cloud, more keypoints, in one unit.
      const auto ids = writer_store->modelIds().value();
      const int64_t id = ids[i % ids.size()];
      const size_t before = writer_store->model(id).value()->observations.size();
      model::ObjectModel grown = makeStoreModel(200 + i, int(before % 6) + 1);
      grown.id = id;
      failed = writer_store->replaceModel(std::move(grown), std::nullopt);
    }
  }
  done = true;
  for (auto& t : readers) t.join();
  ASSERT_TRUE(failed.ok()) << failed;
  EXPECT_EQ(broken.load(), 0u);
  EXPECT_EQ(errors.load(), 0u);
  EXPECT_GT(loads.load(), 60u);
  EXPECT_EQ(writer_store->modelIds().value().size(), 31u);
  EXPECT_EQ(own_store->modelIds().value().size(), 31u);
}

// Two writer threads add models at once: every add gets its own id, and every model is stored
// whole, as its writer gave it.
TEST_P(StoreConformance, ConcurrentWritersGetDistinctIdsAndAllTheirModelsAreStored) {
  const std::string target = freshTarget();
  StoreOptions options;
  options.sqlite.synchronous = "NORMAL";
  auto store = open(target, options);
  ASSERT_NE(store, nullptr);
  constexpr uint32_t kPerWriter = 20;
  std::mutex mutex;
  std::vector<std::pair<int64_t, uint32_t>> added;  // (id, seed)
  std::vector<Status> failures;
  auto writeLoop = [&](uint32_t first_seed) {
    for (uint32_t seed = first_seed; seed < first_seed + kPerWriter; ++seed) {
      const auto id = store->addModel(makeStoreModel(seed, 1 + int(seed % 3)));
      std::lock_guard lock(mutex);
      if (id.ok()) {
        added.emplace_back(*id, seed);
      } else {
        failures.push_back(id.status());
      }
    }
  };
  std::thread one(writeLoop, 1000u), two(writeLoop, 2000u);
  one.join();
  two.join();
  ASSERT_TRUE(failures.empty()) << failures.size() << " failed, first: " << failures[0];
  ASSERT_EQ(added.size(), 2 * kPerWriter);
  std::vector<int64_t> ids;
  for (const auto& [id, seed] : added) ids.push_back(id);
  ids = sorted(ids);
  EXPECT_EQ(std::adjacent_find(ids.begin(), ids.end()), ids.end()) << "an id given twice";
  EXPECT_EQ(store->modelIds().value(), ids);
  for (const auto& [id, seed] : added) {
    model::ObjectModel expected = makeStoreModel(seed, 1 + int(seed % 3));
    expected.id = id;
    EXPECT_EQ(diffModels(*store->model(id).value(), expected), "") << "model " << id;
  }
}

}  // namespace
}  // namespace objdb::storage

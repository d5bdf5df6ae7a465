#include "core/database/object_database.h"

#include <cmath>
#include <mutex>

#include "absl/strings/str_cat.h"
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/support/model_compare.h"
#include "tests/support/object_scenes.h"

namespace objdb::database {
namespace {

using objdb::testing::boxSdf;
using objdb::testing::Sdf;
using objdb::testing::sdfGrid;
using ::testing::HasSubstr;

using objdb::testing::boxWithBall;
using objdb::testing::chair;
using objdb::testing::extinguisher;
using objdb::testing::kSceneBand;
using objdb::testing::kSceneVoxel;
using objdb::testing::sceneGrid;
using objdb::testing::View;
using World = objdb::testing::PlacedShape;

constexpr float kVoxel = kSceneVoxel;
constexpr float kBand = kSceneBand;

Transform pose(double x, double y, double yaw) { return objdb::testing::poseXyYaw(x, y, yaw); }

gsm::RawSegment segment(uint32_t label, const World& w, float x_min = -10, float x_max = 10) {
  return objdb::testing::rawSegment(label, w, View{x_min, x_max});
}

Params params(int threads = 2) {
  Params p;
  p.tsdf.voxel_size_m = kVoxel;
  p.database.threads = threads;
  return p;
}

struct Fixture {
  InMemoryModelStore store;
  std::unique_ptr<ObjectDatabase> db;
  explicit Fixture(const Params& p = params()) { db = ObjectDatabase::create(p, &store).value(); }
};

// The same object on Monday and on Tuesday, elsewhere and turned; each scene map holds it.
const World kMonday{boxWithBall(), pose(0.3, -0.2, 0.3)};
const World kTuesday{boxWithBall(), pose(-0.5, 0.4, 2.0)};
void addScenes(InMemoryModelStore* store) {
  EXPECT_TRUE(store->putScene("monday", std::make_shared<tsdf::TsdfLayer>(sceneGrid({kMonday}))).ok());
  EXPECT_TRUE(store->putScene("tuesday", std::make_shared<tsdf::TsdfLayer>(sceneGrid({kTuesday}))).ok());
}

TEST(ObjectDatabase, TwoPartialViewsInTwoSessionsBecomeOneModelWithBothPoses) {
  Fixture f;
  const World& a = kMonday;
  const World& b = kTuesday;
  addScenes(&f.store);
  auto first = f.db->insertSegment("monday", segment(7, a, -0.3f, 0.1f));
  ASSERT_TRUE(first.ok()) << first.status();
  EXPECT_FALSE(first->merged);
  EXPECT_TRUE(first->matchable);
  auto second = f.db->insertSegment("tuesday", segment(3, b, -0.1f, 0.3f));
  ASSERT_TRUE(second.ok()) << second.status();
  ASSERT_EQ(second->candidates, 1u);
  const CandidateResult& r = second->results[0];
  ASSERT_TRUE(second->merged) << r.stage << ": " << r.reason;
  EXPECT_EQ(second->model_id, first->model_id);
  EXPECT_EQ(r.scene_checks, 2u);
  ASSERT_EQ(f.store.modelIds().value().size(), 1u);
  auto model = f.store.model(first->model_id).value();
  ASSERT_EQ(model->observations.size(), 2u);
  // The model frame is monday's world (the first segment's frame); on tuesday it sat at
  // T_world_b · T_a_world.
  const Transform truth = b.T_world_object * a.T_world_object.inverse();
  const Transform error = truth.inverse() * model->observations[1].T_world_object;
  EXPECT_LT(error.translation().norm(), 0.02);
  EXPECT_LT(Eigen::AngleAxisd(error.rotation()).angle() * 180 / M_PI, 3.0);
  // The merged model holds both ends: each view saw 75 % of the box's length, together all of it.
  auto lone = model::buildModel(segment(7, a, -0.3f, 0.1f).grid.clone(),
                                segment(7, a, -0.3f, 0.1f).label_voxels, model::ModelBuildParams{});
  EXPECT_GT(model->surface_voxels.size(), lone->surface_voxels.size() * 5 / 4);
  EXPECT_GT(model->cloud.points.size(), lone->cloud.points.size() * 23 / 20);
  const auto merges = f.store.mergeRecords().value();
  ASSERT_EQ(merges.size(), 1u);
  EXPECT_EQ(merges[0].target, first->model_id);
  EXPECT_LE(merges[0].tsdf_rmse_m, 0.02);
}

// Calls `change` on every observed voxel of the segment's grid.
template <typename Change>
gsm::RawSegment changeObserved(gsm::RawSegment s, Change change) {
  const int vps = s.grid.voxelsPerSide();
  std::vector<tsdf::BlockIndex> indices;
  for (const auto& [index, block] : s.grid.blocks()) indices.push_back(index);
  for (const tsdf::BlockIndex& index : indices) {
    for (int i = 0; i < vps * vps * vps; ++i) {
      tsdf::TsdfVoxel* v =
          s.grid.voxel(index * vps + Eigen::Vector3i(i % vps, (i / vps) % vps, i / (vps * vps)));
      if (v->weight > 0.0f) change(v);
    }
  }
  return s;
}

// Every observed voxel of the segment's grid in one colour (as a coloured stream fuses it).
gsm::RawSegment painted(gsm::RawSegment s, Rgb8 colour) {
  return changeObserved(std::move(s), [&](tsdf::TsdfVoxel* v) { v->color = colour; });
}

TEST(ObjectDatabase, TheSameShapeInAnotherColourIsNotMerged) {
  const Rgb8 green{120, 170, 60}, dim_green{60, 85, 30}, brown{110, 85, 60};
  auto run = [&](Rgb8 tuesday_colour, const Params& p) {
    Fixture f(p);
    addScenes(&f.store);
    const gsm::RawSegment monday = painted(segment(7, kMonday, -0.3f, 0.1f), green);
    EXPECT_TRUE(f.db->insertSegment("monday", monday).ok());
    auto r = f.db->insertSegment("tuesday",
                                 painted(segment(3, kTuesday, -0.1f, 0.3f), tuesday_colour));
    EXPECT_TRUE(r.ok()) << r.status();
    EXPECT_EQ(r->candidates, 1u);
    return *r;
  };
  // The same colour under less light: merged, the colours agreeing.
  const InsertReport same = run(dim_green, params());
  ASSERT_TRUE(same.merged) << same.results[0].stage << ": " << same.results[0].reason;
  EXPECT_GT(same.results[0].colour.pairs, 100u);
  EXPECT_LT(same.results[0].colour.median_distance, 0.01);
  // Brown: the shapes agree, the colours do not.
  const InsertReport other = run(brown, params());
  EXPECT_FALSE(other.merged);
  EXPECT_EQ(other.results[0].stage, "colour");
  EXPECT_THAT(other.results[0].reason, HasSubstr("colours disagree"));
  EXPECT_TRUE(other.results[0].model_verdict.accepted);  // the grids alone would merge
  // With the check off, geometry decides alone.
  Params off = params();
  off.merging.colour_max_distance = 0.0f;
  EXPECT_TRUE(run(brown, off).merged);
}

TEST(ObjectDatabase, NoisyDepthLoosensTheThresholdsOnlyWhereColourConfirms) {
  // An e*_ICP below what these two views reach (2.3 mm; a stand-in for real depth at a
  // distance), so that only the loosening can merge them: seen from 3 m (σ 1.4 cm) in a session
  // measured twice as noisy as the model, e*_ICP and e*_TSDF each gain (2 − 1) · σ(3 m).
  Params p = params();
  p.matching.icp_max_rmse_m = 0.0015f;
  p.merging.noise_sigmas = 1.0f;  // off by default
  const Rgb8 green{120, 170, 60}, grey{150, 150, 150};
  auto run = [&](Rgb8 colour, float noise_scale, const Params& with) {
    Fixture f(with);
    addScenes(&f.store);
    gsm::RawSegment monday = painted(segment(7, kMonday, -0.3f, 0.1f), colour);
    gsm::RawSegment tuesday = painted(segment(3, kTuesday, -0.1f, 0.3f), colour);
    for (gsm::RawSegment* s : {&monday, &tuesday}) {
      s->observation_depth_m = 3.0f;
      s->noise_scale = noise_scale;
    }
    EXPECT_TRUE(f.db->insertSegment("monday", monday).ok());
    auto r = f.db->insertSegment("tuesday", tuesday);
    EXPECT_TRUE(r.ok()) << r.status();
    EXPECT_EQ(r->candidates, 1u);
    return *r;
  };
  // Chromatic and agreeing: merged beyond the paper's thresholds, and said so.
  const InsertReport confirmed = run(green, 2.0f, p);
  const CandidateResult& c = confirmed.results[0];
  ASSERT_TRUE(confirmed.merged) << c.stage << ": " << c.reason;
  EXPECT_TRUE(c.loosened);
  EXPECT_GT(c.registration.icp_rmse, 0.0015);
  EXPECT_GT(c.colour.chromatic_pairs, 100u);
  // Grey: the colours agree but confirm nothing.
  const InsertReport grey_report = run(grey, 2.0f, p);
  EXPECT_FALSE(grey_report.merged);
  EXPECT_EQ(grey_report.results[0].stage, "colour");
  EXPECT_THAT(grey_report.results[0].reason, HasSubstr("no colour confirms it"));
  // Depth as noisy as the model says (no excess), or the loosening off: the paper's thresholds.
  const InsertReport model_noise = run(green, 1.0f, p);
  EXPECT_FALSE(model_noise.merged);
  EXPECT_NE(model_noise.results[0].stage, "colour");
  Params off = p;
  off.merging.noise_sigmas = 0.0f;
  EXPECT_FALSE(run(green, 2.0f, off).merged);
}

TEST(ObjectDatabase, AChairAndAFireExtinguisherAreNeverMerged) {
  Fixture f;
  const World c{chair(), pose(0, 0, 0.2)};
  const World e{extinguisher(), pose(1.0, 0.5, 1.0)};
  EXPECT_TRUE(f.store.putScene("s", std::make_shared<tsdf::TsdfLayer>(sceneGrid({c, e}))).ok());
  ASSERT_TRUE(f.db->insertSegment("s", segment(1, c)).ok());
  auto r = f.db->insertSegment("s", segment(2, e));
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_FALSE(r->merged);
  EXPECT_EQ(f.store.modelIds().value().size(), 2u);
  for (const auto& c : r->results) EXPECT_FALSE(c.accepted) << c.model_id;
}

TEST(ObjectDatabase, TheApproximatePrefilterKeepsTheExactVotesCandidates) {
  Params p = params();
  ASSERT_GT(p.database.prefilter_epsilon, 0.0f);  // the default searches approximately
  Fixture f(p);
  const World c{chair(), pose(0, 0, 0.2)};
  const World e{extinguisher(), pose(1.0, 0.5, 1.0)};
  const World b{boxWithBall(), pose(-1.0, 0.8, 0.7)};
  const World again{chair(), pose(0.2, -1.2, 1.9)};
  EXPECT_TRUE(
      f.store.putScene("s", std::make_shared<tsdf::TsdfLayer>(sceneGrid({c, e, b, again}))).ok());
  auto first = f.db->insertSegment("s", segment(1, c));
  ASSERT_TRUE(first.ok()) << first.status();
  ASSERT_TRUE(f.db->insertSegment("s", segment(2, e)).ok());
  // Off (the default): no exhaustive vote is run, nothing is reported.
  auto plain = f.db->insertSegment("s", segment(3, b));
  ASSERT_TRUE(plain.ok()) << plain.status();
  EXPECT_TRUE(plain->exhaustive_candidates.empty());
  EXPECT_TRUE(plain->prefilter_candidates.empty());
  f.db->measurePrefilterRecall(true);
  auto r = f.db->insertSegment("s", segment(4, again));
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_FALSE(r->exhaustive_candidates.empty());
  EXPECT_EQ(r->prefilter_candidates, r->exhaustive_candidates);
  EXPECT_EQ(r->exhaustive_candidates.front(), first->model_id);
  EXPECT_TRUE(r->merged);
  EXPECT_EQ(r->model_id, first->model_id);
}

TEST(ObjectDatabase, PlanarSegmentsAreStoredButNeverMatched) {
  Fixture f;
  const Sdf floor = boxSdf({0, 0, -0.05f}, {0.5f, 0.5f, 0.05f});
  auto slab = [&](uint32_t label) {
    auto grid = sdfGrid(floor, Eigen::Vector3f(-0.6f, -0.6f, -0.2f), Eigen::Vector3f(0.6f, 0.6f, 0.2f),
                        kVoxel, kBand);
    gsm::RawSegment raw{label, Transform::Identity(), std::move(grid.layer), {}, 0, 0};
    for (const auto& v : grid.surface_voxels) {
      const Eigen::Vector3f p = raw.grid.voxelCenter(v);
      if (p.z() > -0.01f && p.head<2>().cwiseAbs().maxCoeff() < 0.45f) raw.label_voxels.push_back(v);
    }
    return raw;
  };
  auto a = f.db->insertSegment("s", slab(1));
  auto b = f.db->insertSegment("t", slab(1));
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_TRUE(a->planar);
  EXPECT_FALSE(a->matchable);
  EXPECT_EQ(b->candidates, 0u);
  EXPECT_FALSE(b->merged);
  EXPECT_EQ(f.store.modelIds().value().size(), 2u);
}

// A 2.4 x 1.6 m wall seen from 3 m, with a shelf and two boxes on it, its distances perturbed by
// the sensor's axial noise there (σ(3 m) = 1.4 cm): structure, stored, never a candidate.
gsm::RawSegment wallWithShelf(uint32_t label, float seed) {
  const Sdf wall = objdb::testing::unionSdf(
      {boxSdf({0, 0.05f, 0.8f}, {1.2f, 0.05f, 0.8f}), boxSdf({0, -0.15f, 0.8f}, {0.6f, 0.15f, 0.02f}),
       boxSdf({-0.3f, -0.15f, 0.92f}, {0.1f, 0.1f, 0.1f}), boxSdf({0.3f, -0.15f, 0.92f}, {0.1f, 0.1f, 0.1f})});
  const float sigma = 0.0012f + 0.0019f * 2.6f * 2.6f;
  const Sdf noisy = [&wall, sigma, seed](const Eigen::Vector3f& p) {
    // A smooth pseudo-random field of standard deviation about σ (no two walls alike).
    const float n = std::sin(37.0f * p.x() + seed) * std::cos(41.0f * p.z() - seed) +
                    std::sin(53.0f * (p.x() + p.z()) + 2.0f * seed);
    return wall(p) + sigma * 0.8f * n;
  };
  auto grid = sdfGrid(noisy, Eigen::Vector3f(-1.3f, -0.4f, -0.1f), Eigen::Vector3f(1.3f, 0.2f, 1.7f),
                      kVoxel, kBand);
  gsm::RawSegment raw{label, Transform::Identity(), std::move(grid.layer), {}, 0, 0};
  for (const auto& v : grid.surface_voxels) {
    if (raw.grid.voxelCenter(v).y() < 0.02f) raw.label_voxels.push_back(v);  // the seen side
  }
  raw.observation_depth_m = 3.0f;
  return raw;
}

TEST(ObjectDatabase, StructureSegmentsAreStoredAsSuchButNeverMatched) {
  Fixture f;
  auto a = f.db->insertSegment("s", wallWithShelf(1, 0.0f));
  auto b = f.db->insertSegment("t", wallWithShelf(1, 1.0f));
  ASSERT_TRUE(a.ok() && b.ok()) << a.status() << b.status();
  EXPECT_TRUE(a->structure);
  EXPECT_FALSE(a->planar);  // the shelf and the boxes stick out of the wall's plane
  EXPECT_FALSE(a->matchable);
  EXPECT_TRUE(b->structure);
  EXPECT_EQ(b->candidates, 0u);
  EXPECT_FALSE(b->merged);
  ASSERT_EQ(f.store.modelIds().value().size(), 2u);
  EXPECT_TRUE(f.store.model(f.store.modelIds().value()[0]).value()->structure);
  // Without the structure rule the same wall is an object with keypoints: a match candidate.
  Params no_rule = params();
  no_rule.model.structure_max_planes = 0;
  Fixture g(no_rule);
  auto c = g.db->insertSegment("s", wallWithShelf(1, 0.0f));
  ASSERT_TRUE(c.ok());
  EXPECT_FALSE(c->structure);
  EXPECT_TRUE(c->matchable);
}

// A piece of a room corner cut out by segmentation: a strip of floor and a (bigger) strip of the
// wall above it, each under a metre. Grown through the scene, the wall stays a 0.45 m strip (only
// its bottom was observed), the floor grows over the room: structure. Growing only the best
// plane (the wall) would have let it be matched like an object.
TEST(ObjectDatabase, APieceOfAFloorAndAWallStripIsStructureWhenTheFloorGrowsOverTheRoom) {
  Fixture f;
  const Sdf room = objdb::testing::unionSdf({boxSdf({0, 0, -0.05f}, {1.2f, 1.2f, 0.05f}),
                                             boxSdf({0, 1.25f, 0.225f}, {1.2f, 0.05f, 0.225f})});
  auto scene = sdfGrid(room, Eigen::Vector3f(-1.3f, -1.3f, -0.2f), Eigen::Vector3f(1.3f, 1.4f, 0.4f),
                       kVoxel, kBand);
  ASSERT_TRUE(f.store.putScene("s", std::make_shared<tsdf::TsdfLayer>(std::move(scene.layer))).ok());
  auto piece = sdfGrid(room, Eigen::Vector3f(-0.5f, 0.8f, -0.2f), Eigen::Vector3f(0.5f, 1.35f, 0.5f),
                       kVoxel, kBand);
  gsm::RawSegment raw{5, Transform::Identity(), std::move(piece.layer), {}, 0, 0};
  for (const auto& v : piece.surface_voxels) {
    const Eigen::Vector3f p = raw.grid.voxelCenter(v);
    const bool floor = std::abs(p.z()) < 0.015f && p.y() > 0.85f && p.y() < 1.19f;
    const bool wall = p.y() < 1.21f && p.y() > 1.17f && p.z() > 0.0f && p.z() < 0.45f;
    if (std::abs(p.x()) < 0.4f && (floor || wall)) raw.label_voxels.push_back(v);
  }
  ASSERT_GT(raw.label_voxels.size(), 100u);
  auto r = f.db->insertSegment("s", raw);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_TRUE(r->structure) << "grown to " << r->grown_plane_span_m << " m";
  EXPECT_GE(r->grown_plane_span_m, 1.0f);
  EXPECT_FALSE(r->matchable);
  // The same surface as an object the GSM grouped from two labels: the room structure judged
  // it (the grouping never joins a structure label to anything), so it is not grown.
  raw.label = 6;
  raw.parts = {6, 7};
  auto grouped = f.db->insertSegment("s", raw);
  ASSERT_TRUE(grouped.ok()) << grouped.status();
  EXPECT_FALSE(grouped->structure);
  EXPECT_EQ(grouped->grown_plane_span_m, 0.0f);
}

// A segment the GSM's room structure judged is flagged as it says, whatever its own planes or
// one of them grown through the scene would say: one definition of structure.
TEST(ObjectDatabase, TheRoomStructuresVerdictIsTheStructureFlag) {
  Fixture f;
  // The wall with a shelf (structure by its own planes, above) judged an object: an object with
  // keypoints, a match candidate.
  gsm::RawSegment wall = wallWithShelf(1, 0.0f);
  wall.structure = false;
  auto object = f.db->insertSegment("s", wall);
  ASSERT_TRUE(object.ok()) << object.status();
  EXPECT_FALSE(object->structure);
  EXPECT_TRUE(object->matchable);
  EXPECT_EQ(object->grown_plane_span_m, 0.0f);  // not grown: the room structure judged it
  // Judged structure: stored as such, never a candidate.
  wall = wallWithShelf(2, 1.0f);
  wall.structure = true;
  auto structure = f.db->insertSegment("t", wall);
  ASSERT_TRUE(structure.ok()) << structure.status();
  EXPECT_TRUE(structure->structure);
  EXPECT_FALSE(structure->matchable);
  EXPECT_EQ(structure->candidates, 0u);
  // Unjudged (no verdict): the database's own tests, as before.
  auto unjudged = f.db->insertSegment("u", wallWithShelf(3, 2.0f));
  ASSERT_TRUE(unjudged.ok()) << unjudged.status();
  EXPECT_TRUE(unjudged->structure);
}

TEST(ObjectDatabase, AReExtractedSegmentReplacesItsEarlierContribution) {
  Fixture f;
  const World& a = kMonday;
  const World& b = kTuesday;
  addScenes(&f.store);
  ASSERT_TRUE(f.db->insertSegment("monday", segment(7, a, -0.3f, 0.1f)).ok());
  ASSERT_TRUE(f.db->insertSegment("tuesday", segment(3, b, -0.1f, 0.3f)).ok());
  // Tuesday's label 3 grows and is extracted again: it replaces its contribution.
  auto again = f.db->insertSegment("tuesday", segment(3, b, -0.2f, 0.3f));
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_TRUE(again->replaced_earlier);
  EXPECT_EQ(again->removed_model, 0);  // Monday's segment kept the model
  EXPECT_TRUE(again->merged);
  ASSERT_EQ(f.store.modelIds().value().size(), 1u);
  EXPECT_EQ(f.store.model(f.store.modelIds().value()[0]).value()->observations.size(), 2u);
  EXPECT_EQ(f.store.rawSegment({"tuesday", 3}).value()->voxels.size(),
            segment(3, b, -0.2f, 0.3f).label_voxels.size());
  // A lone segment re-extracted: its model is replaced, not duplicated.
  const World e{extinguisher(), pose(1.0, 0.5, 1.0)};
  const auto lone = f.db->insertSegment("monday", segment(9, e));
  ASSERT_TRUE(lone.ok()) << lone.status();
  const auto replaced = f.db->insertSegment("monday", segment(9, e));
  ASSERT_TRUE(replaced.ok()) << replaced.status();
  EXPECT_EQ(replaced->removed_model, lone->model_id);  // emptied: announced as REMOVED
  EXPECT_NE(replaced->model_id, lone->model_id);
  EXPECT_EQ(f.store.modelIds().value().size(), 2u);
}

TEST(ObjectDatabase, OneSurfaceUnderTwoLabelsOfOneSessionIsOnePlacement) {
  Fixture f;
  const World& a = kMonday;
  addScenes(&f.store);
  // Two labels of monday hold overlapping parts of the one box (the GSM split it): the
  // registration puts the second onto the first's placement. It merges (more of the same
  // object), flagged same_place, and the model still has one place.
  auto first = f.db->insertSegment("monday", segment(7, a, -0.3f, 0.1f));
  ASSERT_TRUE(first.ok()) << first.status();
  auto second = f.db->insertSegment("monday", segment(8, a, -0.1f, 0.3f));
  ASSERT_TRUE(second.ok()) << second.status();
  ASSERT_EQ(second->results.size(), 1u);
  ASSERT_TRUE(second->merged) << second->results[0].stage << ": " << second->results[0].reason;
  EXPECT_TRUE(second->results[0].same_place);
  auto model = f.store.model(first->model_id).value();
  ASSERT_EQ(model->observations.size(), 2u);
  const Eigen::Vector3d centre = model::placeCentre(model->cloud);
  auto poses = [&] {
    std::vector<std::pair<std::string, Transform>> out;
    for (const auto& o : f.store.model(first->model_id).value()->observations) {
      out.emplace_back(o.session, o.T_world_object);
    }
    return out;
  };
  EXPECT_EQ(model::countPlaces(poses(), centre), 1u);
  // The same box elsewhere on tuesday is a repeated object: a second place, not same_place.
  auto tuesday = f.db->insertSegment("tuesday", segment(3, kTuesday, -0.1f, 0.3f));
  ASSERT_TRUE(tuesday.ok()) << tuesday.status();
  ASSERT_TRUE(tuesday->merged);
  for (const auto& r : tuesday->results) EXPECT_FALSE(r.same_place);
  EXPECT_EQ(model::countPlaces(poses(), centre), 2u);
}

TEST(ObjectDatabase, AWithdrawnSegmentLeavesItsModel) {
  Fixture f;
  addScenes(&f.store);
  auto first = f.db->insertSegment("monday", segment(7, kMonday, -0.3f, 0.1f));
  ASSERT_TRUE(first.ok()) << first.status();
  auto second = f.db->insertSegment("tuesday", segment(3, kTuesday, -0.1f, 0.3f));
  ASSERT_TRUE(second.ok() && second->merged);
  // Tuesday's label 3 was merged into another label by the GSM: its segment goes.
  auto withdrawn = f.db->withdrawSegment("tuesday", 3);
  ASSERT_TRUE(withdrawn.ok()) << withdrawn.status();
  EXPECT_EQ(withdrawn->model_id, first->model_id);
  EXPECT_FALSE(withdrawn->removed);  // Monday's segment is still in it
  auto model = f.store.model(first->model_id).value();
  ASSERT_EQ(model->observations.size(), 1u);
  EXPECT_EQ(model->observations[0].session, "monday");
  // A segment the database never took: nothing to do. The last segment of a model: it goes.
  EXPECT_EQ(f.db->withdrawSegment("tuesday", 99).value().model_id, 0);
  const auto last = f.db->withdrawSegment("monday", 7);
  ASSERT_TRUE(last.ok()) << last.status();
  EXPECT_EQ(last->model_id, first->model_id);
  EXPECT_TRUE(last->removed);  // the server announces it as REMOVED
  EXPECT_TRUE(f.store.modelIds().value().empty());
  // Inserted again afterwards, it is a new model like any other.
  auto again = f.db->insertSegment("monday", segment(7, kMonday, -0.3f, 0.1f));
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_FALSE(again->replaced_earlier);
  EXPECT_EQ(f.store.modelIds().value().size(), 1u);
}

TEST(ObjectDatabase, TheSceneVetoesAMergeItContradicts) {
  Fixture f;
  const World& a = kMonday;
  const World& b = kTuesday;
  EXPECT_TRUE(f.store.putScene("monday", std::make_shared<tsdf::TsdfLayer>(sceneGrid({a}))).ok());
  // Tuesday's map says: free space all around where the object would be.
  const Sdf empty = [](const Eigen::Vector3f&) { return kBand; };
  EXPECT_TRUE(f.store.putScene("tuesday", std::make_shared<tsdf::TsdfLayer>(
                                  sdfGrid(empty, Eigen::Vector3f(-1.2f, -0.4f, 0.0f),
                                          Eigen::Vector3f(0.2f, 1.2f, 0.5f), kVoxel, kBand)
                                      .layer)).ok());
  ASSERT_TRUE(f.db->insertSegment("monday", segment(7, a, -0.3f, 0.1f)).ok());
  auto r = f.db->insertSegment("tuesday", segment(3, b, -0.1f, 0.3f));
  ASSERT_TRUE(r.ok());
  ASSERT_EQ(r->results.size(), 1u);
  EXPECT_FALSE(r->merged);
  EXPECT_EQ(r->results[0].stage, "scene");
  EXPECT_THAT(r->results[0].reason, HasSubstr("session tuesday"));
  EXPECT_EQ(f.store.modelIds().value().size(), 2u);
}

TEST(ObjectDatabase, OneOrTwoThreadsGiveTheSameDatabase) {
  auto run = [](int threads) {
    Fixture f(params(threads));
    const World a{boxWithBall(), pose(0.3, -0.2, 0.3)};
    const World b{boxWithBall(), pose(-0.5, 0.4, 2.0)};
    const World c{chair(), pose(1.0, 1.0, 0.0)};
    EXPECT_TRUE(f.store.putScene("monday", std::make_shared<tsdf::TsdfLayer>(sceneGrid({a, c}))).ok());
    EXPECT_TRUE(f.store.putScene("tuesday", std::make_shared<tsdf::TsdfLayer>(sceneGrid({b}))).ok());
    f.db->insertSegment("monday", segment(1, a, -0.3f, 0.1f)).value();
    f.db->insertSegment("monday", segment(2, c)).value();
    f.db->insertSegment("tuesday", segment(1, b, -0.1f, 0.3f)).value();
    std::vector<std::pair<int64_t, std::vector<Eigen::Matrix4d>>> out;
    const std::vector<int64_t> ids = f.store.modelIds().value();
    for (int64_t id : ids) {
      std::vector<Eigen::Matrix4d> poses;
      for (const auto& o : f.store.model(id).value()->observations) {
        poses.push_back(o.T_world_object.matrix());
      }
      out.emplace_back(id, poses);
    }
    return out;
  };
  EXPECT_EQ(run(1), run(2));
}

// Four stored copies of one object (each a separate model, as when a database holds many
// identical chairs): evaluation stops after stop_after_accepted acceptances, in prefilter order.
TEST(ObjectDatabase, StopsEvaluatingCandidatesOnceEnoughWereAccepted) {
  auto run = [](int stop_after) {
    Params p = params(/*threads=*/1);
    p.database.stop_after_accepted = stop_after;
    InMemoryModelStore store;
    EXPECT_TRUE(store.putScene("monday", std::make_shared<tsdf::TsdfLayer>(sceneGrid({kMonday}))).ok());
    EXPECT_TRUE(store.putScene("tuesday", std::make_shared<tsdf::TsdfLayer>(sceneGrid({kTuesday}))).ok());
    {
      // The copies are put in through a database of their own: one insert, then cloned models.
      auto seed_db = ObjectDatabase::create(p, &store).value();
      EXPECT_TRUE(seed_db->insertSegment("monday", segment(7, kMonday, -0.3f, 0.1f)).ok());
      const auto first = store.model(1).value();
      for (int c = 0; c < 3; ++c) {
        model::ObjectModel copy = model::cloneModel(*first);
        copy.observations[0].label = uint32_t(100 + c);
        auto raw = *store.rawSegment({"monday", 7}).value();
        raw.key.label = copy.observations[0].label;
        EXPECT_TRUE(store.putRawSegment(raw).ok());
        EXPECT_TRUE(store.addModel(std::move(copy)).ok());
      }
    }
    auto db = ObjectDatabase::create(p, &store).value();
    auto report = db->insertSegment("tuesday", segment(3, kTuesday, -0.1f, 0.3f));
    EXPECT_TRUE(report.ok()) << report.status();
    return *report;
  };
  const InsertReport all = run(0);
  ASSERT_EQ(all.candidates, 4u);
  for (const auto& r : all.results) EXPECT_TRUE(r.accepted) << r.stage << ": " << r.reason;
  const InsertReport two = run(2);
  ASSERT_EQ(two.candidates, 4u);
  EXPECT_TRUE(two.results[0].accepted);
  EXPECT_TRUE(two.results[1].accepted);
  for (size_t c = 2; c < 4; ++c) {
    EXPECT_EQ(two.results[c].stage, "skipped");
    EXPECT_THAT(two.results[c].reason, HasSubstr("2 candidates with more votes were accepted"));
  }
  EXPECT_TRUE(two.merged);
}

// Six stored copies of one object, the fourth seen in a session whose map shows free space where
// it would stand: candidates accept, accept, accept, reject, accept, accept (prefilter order, as
// the copies tie on votes). With stop_after_accepted 4 one thread stops after the fifth; two or
// four threads evaluate the sixth alongside it, which must not count. The outcome is the same
// on 1, 2 and 4 threads: the same stages, the same merges, the same database.
TEST(ObjectDatabase, TheOutcomeIsTheSameOnOneTwoAndFourThreads) {
  auto run = [](int threads) {
    Params p = params(threads);
    p.database.stop_after_accepted = 4;
    InMemoryModelStore store;
    EXPECT_TRUE(store.putScene("monday", std::make_shared<tsdf::TsdfLayer>(sceneGrid({kMonday}))).ok());
    EXPECT_TRUE(store.putScene("tuesday", std::make_shared<tsdf::TsdfLayer>(sceneGrid({kTuesday}))).ok());
    const Sdf empty = [](const Eigen::Vector3f&) { return kBand; };
    EXPECT_TRUE(store.putScene("elsewhere", std::make_shared<tsdf::TsdfLayer>(
                                   sdfGrid(empty, Eigen::Vector3f(-0.4f, -1.0f, 0.0f),
                                           Eigen::Vector3f(1.0f, 0.6f, 0.5f), kVoxel, kBand)
                                       .layer)).ok());
    {
      auto seed_db = ObjectDatabase::create(p, &store).value();
      EXPECT_TRUE(seed_db->insertSegment("monday", segment(7, kMonday, -0.3f, 0.1f)).ok());
      const auto first = store.model(1).value();
      for (int c = 0; c < 5; ++c) {
        model::ObjectModel copy = model::cloneModel(*first);
        auto raw = *store.rawSegment({"monday", 7}).value();
        raw.key.label = uint32_t(100 + c);
        if (c == 2) raw.key.session = "elsewhere";  // model 4
        copy.observations[0].label = raw.key.label;
        copy.observations[0].session = raw.key.session;
        EXPECT_TRUE(store.putRawSegment(raw).ok());
        EXPECT_TRUE(store.addModel(std::move(copy)).ok());
      }
    }
    auto db = ObjectDatabase::create(p, &store).value();
    auto report = db->insertSegment("tuesday", segment(3, kTuesday, -0.1f, 0.3f));
    EXPECT_TRUE(report.ok()) << report.status();
    std::vector<std::string> outcome;
    for (const auto& r : report->results) {
      outcome.push_back(absl::StrCat(r.model_id, ":", r.accepted ? "accepted" : r.stage));
    }
    outcome.push_back(absl::StrCat("into ", report->model_id));
    for (const int64_t id : report->absorbed()) outcome.push_back(absl::StrCat("absorbed ", id));
    const std::vector<int64_t> ids = store.modelIds().value();
    for (const int64_t id : ids) {
      outcome.push_back(absl::StrCat("model ", id, ": ",
                                     store.model(id).value()->observations.size(), " views"));
    }
    return outcome;
  };
  const std::vector<std::string> one = run(1);
  ASSERT_GE(one.size(), 6u);
  EXPECT_EQ(std::vector<std::string>(one.begin(), one.begin() + 6),
            (std::vector<std::string>{"1:accepted", "2:accepted", "3:accepted", "4:scene",
                                      "5:accepted", "6:skipped"}));
  EXPECT_EQ(run(2), one);
  EXPECT_EQ(run(4), one);
}

// Three stored views of one object that took no part in each other (merging off while they were
// put in); a fourth view is accepted by all three and merges into the one it agrees with best:
// the lowest e_TSDF, wherever the prefilter ranked it.
TEST(ObjectDatabase, TheAcceptedCandidateWithTheLowestETsdfTakesTheSegment) {
  Params p = params();
  p.database.merge_co_accepted = false;
  InMemoryModelStore store;
  addScenes(&store);
  {
    Params apart = p;
    apart.database.max_candidates = 1;
    apart.merging.tsdf_max_rmse_m = 1e-6f;  // nothing merges while the three are put in
    auto seed_db = ObjectDatabase::create(apart, &store).value();
    ASSERT_TRUE(seed_db->insertSegment("monday", segment(1, kMonday, -0.3f, 0.05f)).ok());
    ASSERT_TRUE(seed_db->insertSegment("monday", segment(2, kMonday, -0.05f, 0.3f)).ok());
    ASSERT_TRUE(seed_db->insertSegment("monday", segment(3, kMonday, -0.2f, 0.2f)).ok());
  }
  ASSERT_EQ(store.modelIds().value().size(), 3u);
  auto db = ObjectDatabase::create(p, &store).value();
  auto r = db->insertSegment("tuesday", segment(4, kTuesday, -0.25f, 0.17f));
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_EQ(r->results.size(), 3u);
  const CandidateResult* lowest = nullptr;
  for (const auto& c : r->results) {
    ASSERT_TRUE(c.accepted) << c.model_id << ": " << c.stage << ": " << c.reason;
    if (lowest == nullptr || c.model_verdict.agreement.rmse < lowest->model_verdict.agreement.rmse) {
      lowest = &c;
    }
  }
  // The scenario is worth its name only if the prefilter's first is not the best.
  ASSERT_NE(lowest, &r->results.front())
      << "the first candidate has the lowest e_TSDF: the test no longer tells the rules apart";
  EXPECT_TRUE(r->merged);
  EXPECT_EQ(r->model_id, lowest->model_id);
  EXPECT_EQ(store.model(lowest->model_id).value()->observations.size(), 2u);
  for (const auto& c : r->results) {
    if (&c != lowest) EXPECT_EQ(store.model(c.model_id).value()->observations.size(), 1u);
  }
}

// Two halves of one object that share too little to merge (monday's left half, tuesday's right
// half), then a view of all of it on wednesday: both accept it, it merges into the better one,
// and the other is verified onto the result through the transform the segment gives and joins.
TEST(ObjectDatabase, TwoModelsThatBothTakeOneSegmentBecomeOne) {
  const World wednesday{boxWithBall(), pose(0.9, 0.8, -1.0)};
  auto run = [&](bool merge_co_accepted, Fixture* f) {
    addScenes(&f->store);
    EXPECT_TRUE(f->store.putScene("wednesday",
                                  std::make_shared<tsdf::TsdfLayer>(sceneGrid({wednesday}))).ok());
    auto left = f->db->insertSegment("monday", segment(7, kMonday, -0.3f, 0.04f));
    auto right = f->db->insertSegment("tuesday", segment(3, kTuesday, -0.04f, 0.3f));
    EXPECT_TRUE(left.ok() && right.ok());
    EXPECT_FALSE(right->merged) << "the halves alone must stay apart for this test";
    auto whole = f->db->insertSegment("wednesday", segment(5, wednesday, -0.3f, 0.3f));
    EXPECT_TRUE(whole.ok()) << whole.status();
    EXPECT_EQ(whole->results.size(), 2u);
    for (const auto& r : whole->results) EXPECT_TRUE(r.accepted) << r.stage << ": " << r.reason;
    (void)merge_co_accepted;
    return *whole;
  };
  {
    Fixture f;
    const InsertReport whole = run(true, &f);
    ASSERT_TRUE(whole.merged);
    ASSERT_EQ(whole.co_accepted.size(), 1u);
    ASSERT_TRUE(whole.co_accepted[0].accepted)
        << whole.co_accepted[0].stage << ": " << whole.co_accepted[0].reason;
    ASSERT_EQ(whole.absorbed().size(), 1u);
    EXPECT_GT(whole.co_accepted[0].scene_checks, 0u);
    ASSERT_EQ(f.store.modelIds().value(), std::vector<int64_t>{whole.model_id});
    auto model = f.store.model(whole.model_id).value();
    ASSERT_EQ(model->observations.size(), 3u);
    // The merge rebuilt the one-segment model from both segments; the joined model's segment
    // was fused into that: the model all three segments make.
    EXPECT_EQ(whole.merge_fused_segments, 3u);
    EXPECT_EQ(objdb::testing::diffModels(
                  *model, objdb::testing::rebuiltFromSegments(f.store, *model, params()).value(),
                  false),
              "");
    // Every pose where the object was: in the model frame (the first model's), monday's world
    // when the left half defined it, each session's true pose relative to monday's.
    const Transform frame = model->observations[0].session == "monday"
                                ? kMonday.T_world_object.inverse()
                                : model->observations[0].session == "tuesday"
                                      ? kTuesday.T_world_object.inverse()
                                      : wednesday.T_world_object.inverse();
    for (const auto& o : model->observations) {
      const World& w = o.session == "monday" ? kMonday
                       : o.session == "tuesday" ? kTuesday
                                                : wednesday;
      const Transform error = (w.T_world_object * frame).inverse() * o.T_world_object;
      EXPECT_LT(error.translation().norm(), 0.02) << o.session;
      EXPECT_LT(Eigen::AngleAxisd(error.rotation()).angle() * 180 / M_PI, 3.0) << o.session;
    }
    const auto merges = f.store.mergeRecords().value();
    ASSERT_EQ(merges.size(), 2u);
    EXPECT_EQ(merges[1].source, "model " + std::to_string(whole.absorbed()[0]));
    EXPECT_EQ(merges[1].target, whole.model_id);
    // The joined model's segments are the survivor's now: withdrawing one rebuilds it.
    const std::string absorbed_session =
        whole.absorbed()[0] == 1 ? "monday" : "tuesday";
    const uint32_t absorbed_label = absorbed_session == "monday" ? 7 : 3;
    EXPECT_EQ(f.db->withdrawSegment(absorbed_session, absorbed_label).value().model_id,
              whole.model_id);
    EXPECT_EQ(f.store.model(whole.model_id).value()->observations.size(), 2u);
  }
  {
    Params p = params();
    p.database.merge_co_accepted = false;
    Fixture f(p);
    const InsertReport whole = run(false, &f);
    EXPECT_TRUE(whole.merged);
    EXPECT_TRUE(whole.absorbed().empty());
    EXPECT_TRUE(whole.co_accepted.empty());
    EXPECT_EQ(f.store.modelIds().value().size(), 2u);
  }
}

// A store shared by several writers, its writer lock a mutex.
class LockingStore : public InMemoryModelStore {
 public:
  StatusOr<std::unique_ptr<WriterLock>> lockWriter() override {
    struct Held : WriterLock {
      explicit Held(std::mutex& m) : lock(m) {}
      std::unique_lock<std::mutex> lock;
    };
    ++locks;
    return std::unique_ptr<WriterLock>(std::make_unique<Held>(mutex));
  }
  std::mutex mutex;
  int locks = 0;
};

TEST(ObjectDatabase, TheSegmentsOwnModelIsBuiltBeforeTheWriterLock) {
  LockingStore store;
  addScenes(&store);
  auto db = ObjectDatabase::create(params(), &store).value();
  const int opened = store.locks;  // the open reads the models under the lock too
  ASSERT_TRUE(db->insertSegment("monday", segment(7, kMonday, -0.3f, 0.1f)).ok());
  auto second = db->insertSegment("tuesday", segment(3, kTuesday, -0.1f, 0.3f));
  ASSERT_TRUE(second.ok()) << second.status();
  EXPECT_TRUE(second->merged);
  EXPECT_EQ(store.locks, opened + 2);
  // Keypoints and descriptors of the segment are not in the time under the lock (the part of
  // an insert that is serial across servers); the merge's work is.
  const InsertTimings& t = second->timings;
  EXPECT_GT(t.keypoints_ms + t.descriptors_ms, 0.0);
  EXPECT_GT(t.writer_hold_ms, t.match_register_ms);
  EXPECT_LE(t.writer_hold_ms + t.keypoints_ms + t.descriptors_ms, t.total_ms + 1e-6);
}

// The segment with every voxel seen too rarely to hold a surface (weight below the mesh weight).
gsm::RawSegment withoutSurface(gsm::RawSegment s) {
  return changeObserved(std::move(s), [](tsdf::TsdfVoxel* v) { v->weight = 1.0f; });
}

TEST(ObjectDatabase, ASegmentWithoutSurfaceIsStoredAsUnusableNotAnError) {
  Fixture f;
  addScenes(&f.store);
  const auto first = f.db->insertSegment("monday", segment(7, kMonday));
  ASSERT_TRUE(first.ok()) << first.status();
  EXPECT_FALSE(first->unusable);
  ASSERT_EQ(f.store.modelIds().value().size(), 1u);
  // Re-extracted without a surface: its earlier contribution goes, the raw segment is replaced,
  // and no model holds it.
  const auto again = f.db->insertSegment("monday", withoutSurface(segment(7, kMonday)));
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_TRUE(again->unusable);
  EXPECT_THAT(again->unusable_reason, HasSubstr("hold no surface"));
  EXPECT_TRUE(again->replaced_earlier);
  EXPECT_EQ(again->removed_model, first->model_id);  // it was that model's only segment
  EXPECT_EQ(f.store.model(first->model_id).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(again->model_id, 0);
  EXPECT_TRUE(f.store.modelIds().value().empty());
  const auto stored = f.store.rawSegment({"monday", 7});
  ASSERT_TRUE(stored.ok()) << stored.status();
  EXPECT_EQ((*stored)->voxels.size(), segment(7, kMonday).label_voxels.size());
  // The model builder says so explicitly; only buildModel, for callers that need a model,
  // turns it into FAILED_PRECONDITION.
  const gsm::RawSegment bare = withoutSurface(segment(7, kMonday));
  const auto built = model::buildSegmentModel(bare.grid.clone(), bare.label_voxels, {});
  ASSERT_TRUE(built.ok()) << built.status();
  EXPECT_FALSE(built->model.has_value());
  EXPECT_EQ(model::buildModel(bare.grid.clone(), bare.label_voxels, {}).status().code(),
            absl::StatusCode::kFailedPrecondition);
}

TEST(ObjectDatabase, BadInputIsAClearError) {
  Fixture f;
  const World a{boxWithBall(), pose(0, 0, 0)};
  EXPECT_THAT(std::string(f.db->insertSegment("", segment(1, a)).status().message()),
              HasSubstr("session name is empty"));
  gsm::RawSegment nan_pose = segment(1, a);
  nan_pose.T_world_segment.translation().x() = NAN;
  EXPECT_EQ(f.db->insertSegment("s", nan_pose).status().code(), absl::StatusCode::kInvalidArgument);
  gsm::RawSegment empty = segment(1, a);
  empty.label_voxels.clear();
  EXPECT_THAT(std::string(f.db->insertSegment("s", empty).status().message()),
              HasSubstr("has no voxels"));
  EXPECT_TRUE(f.store.modelIds().value().empty());
  Params bad = params();
  bad.database.threads = 0;
  EXPECT_THAT(std::string(ObjectDatabase::create(bad, &f.store).status().message()),
              HasSubstr("database.threads"));
}

}  // namespace
}  // namespace objdb::database

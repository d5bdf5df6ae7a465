// "What is this?" (ObjectDatabase::match, matchModel) and the query segments it takes
// (query_segment.h), on the analytic shapes of tests/support/object_scenes.h with known poses.
#include <cmath>

#include <gtest/gtest.h>

#include "core/database/object_database.h"
#include "core/database/query_segment.h"
#include "tests/support/object_scenes.h"

namespace objdb::database {
namespace {

using objdb::testing::boxWithBall;
using objdb::testing::chair;
using objdb::testing::extinguisher;
using objdb::testing::kSceneVoxel;
using objdb::testing::sceneGrid;
using World = objdb::testing::PlacedShape;

Params params() {
  Params p;
  p.tsdf.voxel_size_m = kSceneVoxel;
  p.database.threads = 2;
  return p;
}

const World kChair{chair(), objdb::testing::poseXyYaw(0, 0, 0.2)};
const World kExtinguisher{extinguisher(), objdb::testing::poseXyYaw(1.0, 0.5, 1.0)};
const World kBox{boxWithBall(), objdb::testing::poseXyYaw(-1.0, 0.8, 0.7)};

// A database of the three shapes, each its own model (model frame = world frame: the test
// segments have T_world_segment = identity).
struct Fixture {
  InMemoryModelStore store;
  std::unique_ptr<ObjectDatabase> db;
  int64_t chair_id = 0, extinguisher_id = 0, box_id = 0;
  Fixture() {
    db = ObjectDatabase::create(params(), &store).value();
    EXPECT_TRUE(store
                    .putScene("s", std::make_shared<tsdf::TsdfLayer>(
                                       sceneGrid({kChair, kExtinguisher, kBox})))
                    .ok());
    chair_id = insert(1, kChair);
    extinguisher_id = insert(2, kExtinguisher);
    box_id = insert(3, kBox);
  }
  int64_t insert(uint32_t label, const World& w) {
    auto r = db->insertSegment("s", objdb::testing::rawSegment(label, w));
    EXPECT_TRUE(r.ok()) << r.status();
    return r.ok() ? r->model_id : 0;
  }
};

// A query frame: the world moved and turned, so that the pose the match finds is not identity.
const Transform kTQueryWorld = [] {
  Transform T = Transform::Identity();
  T.linear() = Eigen::AngleAxisd(0.9, Eigen::Vector3d(0.2, -0.3, 1.0).normalized()).matrix();
  T.translation() = Eigen::Vector3d(0.4, -1.1, 0.6);
  return T;
}();

double angleBetween(const Transform& a, const Transform& b) {
  return Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle();
}

// The stored model's surface cloud with normals, in the query frame.
QueryCloud cloudOf(const model::ObjectModel& m, const Transform& T_query_model) {
  QueryCloud q;
  for (size_t i = 0; i < m.cloud.points.size(); ++i) {
    q.points.push_back((T_query_model * m.cloud.points[i].cast<double>()).cast<float>());
    q.normals.push_back((T_query_model.linear() * m.cloud.normals[i].cast<double>()).cast<float>());
  }
  return q;
}

TEST(Match, AStoredModelsOwnCloudFindsItFirstWithItsPose) {
  Fixture f;
  ASSERT_NE(f.chair_id, 0);
  const auto stored = f.store.model(f.chair_id);
  ASSERT_TRUE(stored.ok());
  const Transform T_query_model = kTQueryWorld;  // model frame = world frame
  auto segment = segmentFromCloud(cloudOf(**stored, T_query_model), params().tsdf);
  ASSERT_TRUE(segment.ok()) << segment.status();
  auto report = f.db->match(*segment);
  ASSERT_TRUE(report.ok()) << report.status();
  ASSERT_TRUE(report->matchable);
  ASSERT_FALSE(report->results.empty());
  const CandidateResult& best = report->results.front();
  EXPECT_EQ(best.model_id, f.chair_id);
  EXPECT_TRUE(best.accepted) << best.stage << ": " << best.reason;
  EXPECT_GE(best.scene_checks, 1u);  // the chair's pose verified against its scene
  // Its pose: the query frame into the model's, the inverse of the known one.
  const Transform T_model_query =
      best.registration.T_target_source * segment->T_world_segment.inverse();
  const Transform expected = T_query_model.inverse();
  EXPECT_LT((T_model_query.translation() - expected.translation()).norm(), 2.0 * kSceneVoxel);
  EXPECT_LT(angleBetween(T_model_query, expected), 0.05);
  for (size_t i = 1; i < report->results.size(); ++i) {
    EXPECT_FALSE(report->results[i].accepted) << report->results[i].model_id;
  }
}

// The chair's cloud turned and moved (by fractions of a voxel too, so that the query's voxels
// sample it differently): found, accepted, at its pose, every time.
TEST(Match, TheOwnCloudIsFoundAtAnyTurnAndPlace) {
  Fixture f;
  const auto stored = f.store.model(f.chair_id).value();
  for (double yaw = 0.3; yaw < 6.2; yaw += 1.5) {
    for (double tx : {0.013, 0.37}) {
      SCOPED_TRACE(::testing::Message() << "yaw " << yaw << ", x " << tx);
      Transform T_query_model = Transform::Identity();
      T_query_model.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).matrix();
      T_query_model.translation() = Eigen::Vector3d(tx, 0.0, 0.0);
      auto segment = segmentFromCloud(cloudOf(*stored, T_query_model), params().tsdf);
      ASSERT_TRUE(segment.ok()) << segment.status();
      auto report = f.db->match(*segment);
      ASSERT_TRUE(report.ok()) << report.status();
      ASSERT_FALSE(report->results.empty());
      const CandidateResult& best = report->results.front();
      EXPECT_EQ(best.model_id, f.chair_id);
      EXPECT_TRUE(best.accepted) << best.stage << ": " << best.reason;
      const Transform T_model_query =
          best.registration.T_target_source * segment->T_world_segment.inverse();
      EXPECT_LT((T_model_query.translation() - T_query_model.inverse().translation()).norm(),
                2.0 * kSceneVoxel);
    }
  }
}

TEST(Match, WritesNothing) {
  Fixture f;
  const auto ids = f.store.modelIds().value();
  const size_t observations = f.store.model(f.chair_id).value()->observations.size();
  const auto stored = f.store.model(f.chair_id).value();
  auto segment = segmentFromCloud(cloudOf(*stored, kTQueryWorld), params().tsdf);
  ASSERT_TRUE(segment.ok()) << segment.status();
  auto first = f.db->match(*segment);
  auto again = f.db->match(*segment);
  ASSERT_TRUE(first.ok() && again.ok());
  EXPECT_EQ(f.store.modelIds().value(), ids);
  EXPECT_EQ(f.store.model(f.chair_id).value()->observations.size(), observations);
  ASSERT_EQ(first->results.size(), again->results.size());
  for (size_t i = 0; i < first->results.size(); ++i) {
    EXPECT_EQ(first->results[i].model_id, again->results[i].model_id);
    EXPECT_EQ(first->results[i].accepted, again->results[i].accepted);
  }
  // An insert afterwards still merges as before: the chair again joins the chair.
  auto merged = f.db->insertSegment("s", objdb::testing::rawSegment(7, kChair));
  ASSERT_TRUE(merged.ok()) << merged.status();
  EXPECT_TRUE(merged->merged);
  EXPECT_EQ(merged->model_id, f.chair_id);
}

// Sphere tracing of a shape: a depth image (z along the optical axis) as a camera sees it.
DepthImage render(const objdb::testing::Sdf& sdf, const Intrinsics& k,
                  const Transform& T_world_camera) {
  DepthImage depth(k.width, k.height, 0.0f);
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      const Eigen::Vector3d ray_c = k.backProject(u, v, 1.0);
      const Eigen::Vector3d dir = (T_world_camera.linear() * ray_c).normalized();
      const Eigen::Vector3d origin = T_world_camera.translation();
      double t = 0.1;
      for (int step = 0; step < 200 && t < 4.0; ++step) {
        const float d = sdf((origin + t * dir).cast<float>());
        if (d < 1e-4f) {
          depth.at(u, v) = float(t / ray_c.norm());  // along the ray → along the axis
          break;
        }
        t += double(d);
      }
    }
  }
  return depth;
}

// One depth frame of the chair from each of 8 directions at two heights. Its segment must lie on
// the surface the camera saw; and since one view
// of a thin part fits either of its faces, no candidate may pass every check at a wrong pose: a
// single frame is matched at its true pose or not at all.
TEST(Match, ADepthFramesSegmentLiesOnTheChairAndIsNeverAcceptedAtAWrongPose) {
  Fixture f;
  const objdb::testing::Sdf placed = objdb::testing::transformedSdf(
      kChair.shape, kChair.T_world_object.cast<float>());
  const Intrinsics k{640, 480, 525.0, 525.0, 319.5, 239.5};
  for (double angle = 0.0; angle < 6.28; angle += 0.785) {
    for (double height : {0.6, 1.2}) {
      SCOPED_TRACE(::testing::Message() << "camera at angle " << angle << ", height " << height);
      const Transform camera =
          lookAt({1.3 * std::cos(angle), 1.3 * std::sin(angle), height}, {0.0, 0.0, 0.4}).value();
      QueryDepth query;  // the query's frame: the camera's (its pose unknown to the database)
      query.intrinsics = k;
      query.depth = render(placed, k, camera);
      auto segment = segmentFromDepth(query, params().tsdf);
      ASSERT_TRUE(segment.ok()) << segment.status();
      EXPECT_NEAR(segment->observation_depth_m, 1.3f, 0.4f);
      const Transform T_world_segment = camera * segment->T_world_segment;
      for (const auto& v : segment->label_voxels) {
        const Eigen::Vector3f x =
            (T_world_segment * segment->grid.voxelCenter(v).cast<double>()).cast<float>();
        ASSERT_LE(std::abs(placed(x)), kSceneVoxel) << "a voxel off the chair's surface";
      }
      auto report = f.db->match(*segment);
      ASSERT_TRUE(report.ok()) << report.status();
      EXPECT_TRUE(report->matchable);
      for (const CandidateResult& r : report->results) {
        if (!r.accepted) continue;
        const Transform T_model_camera =
            r.registration.T_target_source * segment->T_world_segment.inverse();
        EXPECT_EQ(r.model_id, f.chair_id);
        EXPECT_LT((T_model_camera.translation() - camera.translation()).norm(), 2 * kSceneVoxel);
      }
    }
  }
}

TEST(Match, AStoredModelFindsNoOtherShapeAndAnUnknownIdIsNotFound) {
  Fixture f;
  auto report = f.db->matchModel(f.extinguisher_id);
  ASSERT_TRUE(report.ok()) << report.status();
  EXPECT_TRUE(report->matchable);
  for (const auto& r : report->results) {
    EXPECT_NE(r.model_id, f.extinguisher_id);  // not itself
    EXPECT_FALSE(r.accepted) << r.model_id;
  }
  auto missing = f.db->matchModel(999);
  ASSERT_FALSE(missing.ok());
  EXPECT_TRUE(absl::IsNotFound(missing.status())) << missing.status();
  EXPECT_NE(missing.status().message().find("999"), std::string::npos);
}

TEST(Match, AFlatSheetIsNotMatched) {
  Fixture f;
  QueryCloud q;
  for (int i = -20; i < 20; ++i) {
    for (int j = -20; j < 20; ++j) {
      q.points.emplace_back(0.01f * float(i), 0.01f * float(j), 1.0f);
    }
  }
  auto segment = segmentFromCloud(q, params().tsdf);  // seen from the origin
  ASSERT_TRUE(segment.ok()) << segment.status();
  auto report = f.db->match(*segment);
  ASSERT_TRUE(report.ok()) << report.status();
  EXPECT_FALSE(report->matchable);
  EXPECT_TRUE(report->planar || report->unusable);
  EXPECT_TRUE(report->results.empty());
}

// --- the query segments' bad input -------------------------------------------------------------

void expectInvalid(const StatusOr<gsm::RawSegment>& s, const std::string& field) {
  ASSERT_FALSE(s.ok());
  EXPECT_TRUE(absl::IsInvalidArgument(s.status())) << s.status();
  EXPECT_NE(s.status().message().find(field), std::string::npos) << s.status();
}

TEST(QuerySegment, RefusesBadCloudsNamingTheField) {
  const TsdfParams tsdf = params().tsdf;
  expectInvalid(segmentFromCloud(QueryCloud{}, tsdf), "cloud: no points");
  QueryCloud q;
  q.points = {{0, 0, 1}, {0.01f, 0, 1}};
  QueryCloud bad = q;
  bad.normals = {{0, 0, -1}};
  expectInvalid(segmentFromCloud(bad, tsdf), "cloud.normals");
  bad = q;
  bad.colors = {Rgb8{}};
  expectInvalid(segmentFromCloud(bad, tsdf), "cloud.colors");
  bad = q;
  bad.points[1].y() = std::nanf("");
  expectInvalid(segmentFromCloud(bad, tsdf), "cloud.points: point 1");
  bad = q;
  bad.viewpoint = Eigen::Vector3d(0, 0, 5.0 + tsdf.max_ray_length_m);  // everything out of range
  expectInvalid(segmentFromCloud(bad, tsdf), "ray range");
  bad = q;
  bad.points.assign(kMaxQueryPoints + 1, Eigen::Vector3f(0, 0, 1));
  expectInvalid(segmentFromCloud(bad, tsdf), "more than");
  bad = q;
  bad.normals = {{0, 0, -1}, {0, 0, 0}};
  expectInvalid(segmentFromCloud(bad, tsdf), "cloud.normals: normal 1");
}

TEST(QuerySegment, RefusesBadDepthNamingTheField) {
  const TsdfParams tsdf = params().tsdf;
  QueryDepth q;
  q.intrinsics = {8, 6, 10.0, 10.0, 3.5, 2.5};
  q.depth = DepthImage(8, 6, 1.0f);
  ASSERT_TRUE(segmentFromDepth(q, tsdf).ok());
  QueryDepth bad = q;
  bad.mask.assign(47, 1);
  expectInvalid(segmentFromDepth(bad, tsdf), "mask: 47 values");
  bad = q;
  bad.mask.assign(48, 0);  // selects nothing
  expectInvalid(segmentFromDepth(bad, tsdf), "mask: no masked pixel");
  bad = q;
  bad.depth = DepthImage(8, 5, 1.0f);
  expectInvalid(segmentFromDepth(bad, tsdf), "depth is 8x5");
  bad = q;
  bad.T_world_camera.linear() *= 2.0;
  expectInvalid(segmentFromDepth(bad, tsdf), "T_world_camera");
  bad = q;
  bad.depth = DepthImage(8, 6, 0.0f);  // no measurement
  expectInvalid(segmentFromDepth(bad, tsdf), "depth: no pixel has a depth");
}

TEST(QuerySegment, OneFrameReachesTheMeshWeightAndItsVoxelsAreWherePointsFell) {
  const TsdfParams tsdf = params().tsdf;
  QueryDepth q;
  q.intrinsics = {40, 30, 40.0, 40.0, 19.5, 14.5};
  q.depth = DepthImage(40, 30, 1.0f);  // a wall 1 m ahead, 1 m x 0.75 m
  q.mask.assign(40 * 30, 0);
  for (int v = 10; v < 20; ++v) {
    for (int u = 10; u < 30; ++u) q.mask[size_t(v) * 40 + size_t(u)] = 1;  // its middle
  }
  auto segment = segmentFromDepth(q, tsdf);
  ASSERT_TRUE(segment.ok()) << segment.status();
  EXPECT_NEAR(segment->observation_depth_m, 1.0f, 1e-5f);
  ASSERT_FALSE(segment->label_voxels.empty());
  for (const auto& v : segment->label_voxels) {
    const Eigen::Vector3d p = segment->T_world_segment * segment->grid.voxelCenter(v).cast<double>();
    EXPECT_NEAR(p.z(), 1.0, tsdf.voxel_size_m);          // on the wall
    EXPECT_LE(std::abs(p.x()), 0.25 + tsdf.voxel_size_m);  // within the mask's 0.5 m x 0.25 m
    EXPECT_LE(std::abs(p.y()), 0.125 + tsdf.voxel_size_m);
    const tsdf::TsdfVoxel* voxel = segment->grid.voxel(v);
    ASSERT_NE(voxel, nullptr);
    EXPECT_GE(voxel->weight, tsdf.mesh_min_weight * 0.99f);  // weight 1 × mesh_min_weight
  }
}

}  // namespace
}  // namespace objdb::database

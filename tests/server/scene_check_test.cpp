// Model-to-scene verification on the server path (paper §III-C.4): a merge within one
// live session is verified at both poses against the session's map as it is in memory, before
// the session has a stored scene. Two identical boxes in one session merge, with both poses
// checked; when the first box is taken away before the second is extracted, the live map at the
// first pose says free space, and only the scene check rejects the (model-to-model perfect)
// merge.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "absl/strings/str_format.h"
#include "core/common/params.h"
#include "core/io/io_util.h"
#include "core/sim/generator.h"
#include "core/sim/renderer.h"
#include "core/sim/scene.h"
#include "objdb/v1/objdb.grpc.pb.h"
#include "server/server.h"
#include "tests/server/ingest_fixtures.h"
#include "tests/server/loopback_server.h"

namespace objdb {
namespace {

using testing::endSession;
using testing::frame;
using testing::header;
using testing::ingest;
using testing::IngestResult;
using testing::kMetresPerUnit;
using testing::Recording;
using testing::setDeadline;

// Two identical boxes 1.6 m apart on a floor (`with_a` false: box B alone); the camera looks at
// box A, then at box B, then back at A's place until the end.
std::string sceneJson(bool with_a) {
  const std::string a = R"({"position": [-0.8, -1.3, 1.3], "look_at": [-0.8, 0, 0.2]})";
  const std::string b = R"({"position": [0.8, -1.3, 1.3], "look_at": [0.8, 0, 0.2]})";
  std::string keyframes = a + "," + a + "," + b + "," + b;
  for (int i = 0; i < 6; ++i) keyframes += "," + a;
  return absl::StrFormat(
      R"({"name": "boxes", "camera": "tango", "depth_scale_m": 0.001,
          "noise": {"enabled": true, "seed": 3},
          "objects": [%s
            {"id": 2, "category": "large_box", "pose": {"t": [0.8, 0, 0], "yaw_deg": -30}},
            {"id": 20, "category": "floor", "size": [5, 4], "structure": true,
             "pose": {"t": [0, 0, 0]}}],
          "trajectory": {"frames": 100, "fps": 30, "closed": false, "keyframes": [%s]}})",
      with_a ? R"({"id": 1, "category": "large_box", "pose": {"t": [-0.8, 0, 0], "yaw_deg": 20}},)"
             : "",
      keyframes);
}

// With `a_leaves_at` >= 0 the frames from that index on are rendered without box A (it was
// carried away while the camera looked at B).
Recording render(int a_leaves_at) {
  Recording r;
  const sim::Scene with_a = sim::parseSceneJson(sceneJson(true), ".").value();
  const sim::Scene without_a = sim::parseSceneJson(sceneJson(false), ".").value();
  const auto built_with = sim::buildScene(with_a);
  const auto built_without = sim::buildScene(without_a);
  const auto poses = sim::sampleTrajectory(with_a.trajectory);
  EXPECT_TRUE(built_with.ok() && built_without.ok() && poses.ok());
  const sim::Renderer renderer(with_a.intrinsics);
  r.intrinsics = with_a.intrinsics;
  for (size_t i = 0; i < poses->size(); ++i) {
    const bool gone = a_leaves_at >= 0 && int(i) >= a_leaves_at;
    const Frame f = sim::renderFrame(gone ? without_a : with_a, gone ? *built_without : *built_with,
                                     renderer, (*poses)[i], i, true);
    r.depth.push_back(depthToRaw(f.depth, kMetresPerUnit).value());
    r.color.push_back(*f.color);
    r.poses.push_back(f.T_world_camera);
  }
  return r;
}

struct Outcome {
  std::vector<v1::ObjectEvent> merges;
  v1::GetStatsResponse stats;
};

Outcome stream(const Recording& r) {
  ServerOptions options = testing::loopbackOptions();
  // Free space in front of every measured surface is fused too (up to 30 cm): a box taken away
  // leaves free space in the map where it stood, which the scene check can read.
  options.params.tsdf.carve_distance_m = 0.3f;
  auto server = testing::startOrDie(options);
  EXPECT_NE(server, nullptr);
  Outcome out;
  if (server == nullptr) return out;
  auto stub = v1::ObjectDatabase::NewStub(
      grpc::CreateChannel(server->address(), grpc::InsecureChannelCredentials()));
  std::vector<v1::IngestRequest> requests = {header("boxes", r.intrinsics)};
  for (size_t k = 0; k < r.depth.size(); ++k) requests.push_back(frame(r, k));
  const IngestResult result = ingest(*stub, requests);
  EXPECT_TRUE(result.status.ok()) << result.status.error_message();
  for (const auto& response : result.responses) {
    if (response.has_object() && response.object().kind() == v1::ObjectEvent::MERGED) {
      out.merges.push_back(response.object());
    }
  }
  v1::EndSessionResponse ended;
  EXPECT_TRUE(endSession(*stub, "boxes", &ended).ok());
  grpc::ClientContext context;
  setDeadline(&context);
  EXPECT_TRUE(stub->GetStats(&context, v1::GetStatsRequest(), &out.stats).ok());
  return out;
}

TEST(SceneCheck, TwoIdenticalBoxesInOneSessionMergeWithBothPosesCheckedAgainstTheLiveMap) {
  const Outcome out = stream(render(-1));
  ASSERT_FALSE(out.merges.empty());
  // Both poses were verified while the session was still streaming (it had no stored scene).
  for (const auto& merge : out.merges) {
    EXPECT_EQ(merge.evidence().scene_checks(), 2u);
    EXPECT_GT(merge.evidence().scene_overlap_min_voxels(), 0u);
    EXPECT_LT(merge.evidence().scene_rmse_max_m(), 0.01);
  }
  EXPECT_GE(out.stats.scene_checks(), 2u);
  EXPECT_EQ(out.stats.poses_without_scene(), 0u);
  EXPECT_EQ(out.stats.candidates_rejected_by_scene(), 0u);
}

TEST(SceneCheck, AMergeTheLiveMapContradictsIsRejectedByTheSceneCheckAlone) {
  // Box A leaves once the camera has turned to box B (frame 33): when B is extracted, the camera
  // has looked at A's empty place for a while.
  const Outcome out = stream(render(33));
  EXPECT_TRUE(out.merges.empty()) << "box B was merged into box A's model";
  // The candidate passed registration and the model-to-model check (the boxes are identical)
  // and was rejected at the scene.
  EXPECT_GE(out.stats.candidates_rejected_by_scene(), 1u);
  EXPECT_EQ(out.stats.poses_without_scene(), 0u);
}

}  // namespace
}  // namespace objdb

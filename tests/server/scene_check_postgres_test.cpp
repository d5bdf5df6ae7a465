// Model-to-scene verification across servers (server/session/published_scenes.h): two servers
// on one PostgreSQL database. Session "left", on server 1, sees box A, looks away (A is extracted
// and inserted while the session streams) and stays open; server 2 holds no session then, so
// server 1 publishes nothing. Session "right" then starts on server 2: server 1's lease keeper
// sees another server at work and publishes left's map at once. Right sees an identical box B
// and ends; server 2's insert of B finds A's model, seen in "left", which is live on server 1: it
// verifies A's pose against the map server 1 published, and merges. Without that map the
// candidate would be rejected at the scene check ("no scene map").
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_format.h"
#include "core/io/io_util.h"
#include "core/sim/generator.h"
#include "core/sim/renderer.h"
#include "core/sim/scene.h"
#include "objdb/v1/objdb.grpc.pb.h"
#include "server/server.h"
#include "tests/server/ingest_fixtures.h"
#include "tests/server/loopback_server.h"
#include "tests/support/postgres_test_cluster.h"

namespace objdb {
namespace {

using testing::frame;
using testing::header;
using testing::kMetresPerUnit;
using testing::Recording;
using testing::setDeadline;

constexpr const char* kAtA = R"({"position": [-0.8, -1.3, 1.3], "look_at": [-0.8, 0, 0.2]})";
constexpr const char* kAtB = R"({"position": [0.8, -1.3, 1.3], "look_at": [0.8, 0, 0.2]})";

// One box (A at x = -0.8 m, or B at x = 0.8 m, the same box turned otherwise) on a floor; the
// camera follows `keyframes` over `frames` frames.
Recording render(bool box_a, const std::string& keyframes, int frames) {
  const std::string json = absl::StrFormat(
      R"({"name": "box", "camera": "tango", "depth_scale_m": 0.001,
          "noise": {"enabled": true, "seed": %d},
          "objects": [
            {"id": 1, "category": "large_box", "pose": {"t": [%s, 0, 0], "yaw_deg": %d}},
            {"id": 20, "category": "floor", "size": [5, 4], "structure": true,
             "pose": {"t": [0, 0, 0]}}],
          "trajectory": {"frames": %d, "fps": 30, "closed": false, "keyframes": [%s]}})",
      box_a ? 3 : 4, box_a ? "-0.8" : "0.8", box_a ? 20 : -30, frames, keyframes);
  Recording r;
  const auto scene = sim::parseSceneJson(json, ".");
  EXPECT_TRUE(scene.ok()) << scene.status();
  if (!scene.ok()) return r;
  const auto built = sim::buildScene(*scene);
  const auto poses = sim::sampleTrajectory(scene->trajectory);
  EXPECT_TRUE(built.ok() && poses.ok());
  if (!built.ok() || !poses.ok()) return r;
  const sim::Renderer renderer(scene->intrinsics);
  r.intrinsics = scene->intrinsics;
  for (size_t i = 0; i < poses->size(); ++i) {
    const Frame f = sim::renderFrame(*scene, *built, renderer, (*poses)[i], i, true);
    r.depth.push_back(depthToRaw(f.depth, kMetresPerUnit).value());
    r.color.push_back(*f.color);
    r.poses.push_back(f.T_world_camera);
  }
  return r;
}

std::vector<v1::IngestRequest> requestsOf(const std::string& name, const Recording& r) {
  std::vector<v1::IngestRequest> requests = {header(name, r.intrinsics)};
  for (size_t k = 0; k < r.depth.size(); ++k) requests.push_back(frame(r, k));
  return requests;
}

v1::GetStatsResponse statsOf(v1::ObjectDatabase::Stub& stub) {
  grpc::ClientContext context;
  setDeadline(&context);
  v1::GetStatsResponse stats;
  EXPECT_TRUE(stub.GetStats(&context, v1::GetStatsRequest(), &stats).ok());
  return stats;
}

TEST(SceneCheckPostgres, AServerVerifiesAPoseInASessionLiveOnAnotherAgainstItsPublishedMap) {
  const auto uri = testing::freshPostgresDatabase("scene_check");
  ASSERT_TRUE(uri.ok()) << uri.status();
  std::unique_ptr<ObjdbServer> servers[2];
  std::unique_ptr<v1::ObjectDatabase::Stub> stubs[2];
  for (int s = 0; s < 2; ++s) {
    ServerOptions options = testing::loopbackOptions(*uri);
    options.server_id = absl::StrFormat("server-%d", s + 1);
    options.save_map_every = std::chrono::milliseconds(0);  // only the published maps are saved
    options.lease_ttl = std::chrono::milliseconds(300);     // the keeper looks every 100 ms
    options.params.tsdf.carve_distance_m = 0.3f;
    servers[s] = testing::startOrDie(options);
    ASSERT_NE(servers[s], nullptr);
    stubs[s] = v1::ObjectDatabase::NewStub(
        grpc::CreateChannel(servers[s]->address(), grpc::InsecureChannelCredentials()));
  }

  // "left" on server 1: box A, then 40 frames of floor elsewhere (A goes idle and is inserted);
  // the stream half-closes, the session stays open (no EndSession).
  const Recording left = render(true, absl::StrFormat("%s,%s,%s,%s,%s", kAtA, kAtA, kAtB, kAtB, kAtB), 90);
  const testing::IngestResult streamed = testing::ingest(*stubs[0], requestsOf("left", left));
  ASSERT_TRUE(streamed.everyFrameAccepted(left.depth.size()));
  ASSERT_GE(streamed.count(v1::IngestResponse::kSegment), 1u);
  v1::GetStatsResponse one;
  for (int waited = 0; waited < 600; ++waited) {
    one = statsOf(*stubs[0]);
    if (one.queued_segments() == 0 && one.insert_timings().inserts() > 0) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  ASSERT_GT(one.insert_timings().inserts(), 0u);
  EXPECT_EQ(one.maps_published(), 0u) << "published while no other server was at work";

  // "right" on server 2: box B, ended.
  const Recording right = render(false, absl::StrFormat("%s,%s,%s", kAtB, kAtB, kAtB), 40);
  const testing::IngestResult streamed_right =
      testing::ingest(*stubs[1], requestsOf("right", right));
  ASSERT_TRUE(streamed_right.everyFrameAccepted(right.depth.size()));
  for (int waited = 0; waited < 600 && one.maps_published() == 0; ++waited) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    one = statsOf(*stubs[0]);
  }
  ASSERT_GE(one.maps_published(), 1u) << "server 1 did not publish left's map for server 2";
  v1::EndSessionResponse ended;
  ASSERT_TRUE(testing::endSession(*stubs[1], "right", &ended).ok());
  const v1::GetStatsResponse two = statsOf(*stubs[1]);
  EXPECT_GE(two.published_maps_read(), 1u);
  EXPECT_EQ(two.poses_without_scene(), 0u);
  EXPECT_GE(two.scene_checks(), 2u);
  EXPECT_GE(ended.summary().counters().objects_merged(), 1u)
      << "box B was not merged into box A's model";

  for (auto& server : servers) server->shutdown();
}

}  // namespace
}  // namespace objdb

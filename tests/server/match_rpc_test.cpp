// Match ("what is this?") over loopback: a database of three analytic shapes (a chair, an
// extinguisher, a box) stored by the object database itself; a stored object's own cloud, sent
// back moved to a known pose, finds that object first with the inverse pose; nothing is written;
// bad queries get INVALID_ARGUMENT or NOT_FOUND naming the field.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <string>

#include "core/database/object_database.h"
#include "core/database/query_segment.h"
#include "objdb/v1/objdb.grpc.pb.h"
#include "server/proto_convert.h"
#include "server/server.h"
#include "storage/sqlite/sqlite_store.h"
#include "tests/server/loopback_server.h"
#include "tests/support/object_scenes.h"

namespace objdb {
namespace {

using World = objdb::testing::PlacedShape;

struct Stored {
  std::string db_path;
  int64_t chair = 0, extinguisher = 0, box = 0;
};

// The shapes inserted by the object database, with the session's scene, as a server would.
Stored storeShapes() {
  Stored out;
  out.db_path = objdb::testing::scratchDbPath();
  auto store = storage::SqliteStore::open(out.db_path).value();
  const World chair{objdb::testing::chair(), objdb::testing::poseXyYaw(0, 0, 0.2)};
  const World extinguisher{objdb::testing::extinguisher(),
                           objdb::testing::poseXyYaw(1.0, 0.5, 1.0)};
  const World box{objdb::testing::boxWithBall(), objdb::testing::poseXyYaw(-1.0, 0.8, 0.7)};
  EXPECT_TRUE(store
                  ->putScene("s", std::make_shared<tsdf::TsdfLayer>(
                                      objdb::testing::sceneGrid({chair, extinguisher, box})))
                  .ok());
  auto db = database::ObjectDatabase::create(Params(), store.get()).value();
  auto insert = [&](uint32_t label, const World& w) -> int64_t {
    auto r = db->insertSegment("s", objdb::testing::rawSegment(label, w));
    EXPECT_TRUE(r.ok()) << r.status();
    return r.ok() ? r->model_id : 0;
  };
  out.chair = insert(1, chair);
  out.extinguisher = insert(2, extinguisher);
  out.box = insert(3, box);
  return out;
}

grpc::Status match(v1::ObjectDatabase::Stub& stub, const v1::MatchRequest& request,
                   v1::MatchResponse* response) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
  return stub.Match(&context, request, response);
}

void expectRefused(v1::ObjectDatabase::Stub& stub, const v1::MatchRequest& request,
                   grpc::StatusCode code, const std::string& field) {
  v1::MatchResponse response;
  const grpc::Status s = match(stub, request, &response);
  EXPECT_EQ(s.error_code(), code) << s.error_message();
  EXPECT_NE(s.error_message().find(field), std::string::npos) << s.error_message();
}

TEST(MatchRpc, AStoredObjectsOwnCloudFindsItFirstAndNothingIsWritten) {
  const Stored stored = storeShapes();
  ASSERT_NE(stored.chair, 0);
  ServerOptions options = objdb::testing::loopbackOptions(stored.db_path);
  auto server = objdb::testing::startOrDie(options);
  ASSERT_NE(server, nullptr);
  auto stub = v1::ObjectDatabase::NewStub(
      grpc::CreateChannel(server->address(), grpc::InsecureChannelCredentials()));

  // The chair's surface cloud as GetObject serves it, moved into a query frame.
  v1::ObjectDetail detail;
  {
    grpc::ClientContext context;
    v1::GetObjectRequest request;
    request.set_id(uint64_t(stored.chair));
    request.set_include_cloud(true);
    ASSERT_TRUE(stub->GetObject(&context, request, &detail).ok());
  }
  Transform T_query_object = Transform::Identity();
  T_query_object.linear() = Eigen::AngleAxisd(2.0, Eigen::Vector3d::UnitZ()).matrix();
  T_query_object.translation() = Eigen::Vector3d(0.3, 0.2, -0.1);
  PointCloud cloud = server::cloudFromProto(detail.cloud());
  ASSERT_FALSE(cloud.normals.empty());
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    cloud.points[i] = (T_query_object * cloud.points[i].cast<double>()).cast<float>();
    cloud.normals[i] = (T_query_object.linear() * cloud.normals[i].cast<double>()).cast<float>();
  }
  v1::MatchRequest request;
  server::toProto(cloud, request.mutable_cloud());
  request.set_max_results(2);
  v1::MatchResponse response;
  const grpc::Status s = match(*stub, request, &response);
  ASSERT_TRUE(s.ok()) << s.error_message();
  ASSERT_TRUE(response.matchable()) << response.reason();
  EXPECT_GT(response.points(), 0u);
  EXPECT_GT(response.keypoints(), 0u);
  ASSERT_GE(response.results_size(), 1);
  EXPECT_LE(response.results_size(), 2);
  const v1::MatchResult& best = response.results(0);
  EXPECT_EQ(best.object_id(), uint64_t(stored.chair));
  EXPECT_TRUE(best.accepted()) << best.stage() << ": " << best.reason();
  EXPECT_GE(best.evidence().scene_checks(), 1u);
  auto T = server::fromProto(best.t_object_query(), "T_object_query");
  ASSERT_TRUE(T.ok());
  const Transform expected = T_query_object.inverse();
  EXPECT_LT((T->translation() - expected.translation()).norm(), 0.04);
  EXPECT_LT(Eigen::AngleAxisd(T->linear().transpose() * expected.linear()).angle(), 0.05);

  // "Find similar" by id: the chair has no twin here; nothing accepted, itself not listed.
  v1::MatchRequest by_id;
  by_id.set_object_id(uint64_t(stored.chair));
  v1::MatchResponse similar;
  ASSERT_TRUE(match(*stub, by_id, &similar).ok());
  for (const auto& r : similar.results()) {
    EXPECT_NE(r.object_id(), uint64_t(stored.chair));
    EXPECT_FALSE(r.accepted());
  }

  // Nothing written: the same three objects, the chair seen once.
  v1::ListObjectsResponse objects;
  {
    grpc::ClientContext context;
    ASSERT_TRUE(stub->ListObjects(&context, v1::ListObjectsRequest(), &objects).ok());
  }
  ASSERT_EQ(objects.objects_size(), 3);
  for (const auto& o : objects.objects()) EXPECT_EQ(o.num_poses(), 1u) << o.id();
}

TEST(MatchRpc, BadQueriesAreRefusedNamingTheField) {
  const Stored stored = storeShapes();
  ServerOptions options = objdb::testing::loopbackOptions(stored.db_path);
  options.max_receive_message_bytes = 64 << 20;  // room for the huge cloud below
  auto server = objdb::testing::startOrDie(options);
  ASSERT_NE(server, nullptr);
  grpc::ChannelArguments arguments;
  arguments.SetMaxSendMessageSize(64 << 20);
  auto stub = v1::ObjectDatabase::NewStub(grpc::CreateCustomChannel(
      server->address(), grpc::InsecureChannelCredentials(), arguments));
  using Code = grpc::StatusCode;

  expectRefused(*stub, v1::MatchRequest(), Code::INVALID_ARGUMENT, "query:");
  v1::MatchRequest r;
  r.mutable_cloud();  // present, empty
  expectRefused(*stub, r, Code::INVALID_ARGUMENT, "cloud.points: no points");
  r.mutable_cloud()->add_points(1.0f);
  expectRefused(*stub, r, Code::INVALID_ARGUMENT, "cloud.points: 1 values");
  r.mutable_cloud()->add_points(0.0f);
  r.mutable_cloud()->add_points(1.0f);
  r.mutable_cloud()->add_normals(0.0f);
  expectRefused(*stub, r, Code::INVALID_ARGUMENT, "cloud.normals");
  r.mutable_cloud()->clear_normals();
  r.mutable_cloud()->set_colors("ab");
  expectRefused(*stub, r, Code::INVALID_ARGUMENT, "cloud.colors");

  v1::MatchRequest huge;
  huge.mutable_cloud()->mutable_points()->Resize(int(3 * (database::kMaxQueryPoints + 1)), 1.0f);
  expectRefused(*stub, huge, Code::INVALID_ARGUMENT, "cloud.points: 2000001 points");

  v1::MatchRequest by_id;
  by_id.set_object_id(uint64_t(stored.box + 100));
  expectRefused(*stub, by_id, Code::NOT_FOUND, "object_id");
  by_id.mutable_viewpoint()->set_z(1.0);
  expectRefused(*stub, by_id, Code::INVALID_ARGUMENT, "viewpoint");

  v1::MatchRequest depth;
  v1::DepthSegment& d = *depth.mutable_depth();
  d.mutable_intrinsics()->set_width(4);
  d.mutable_intrinsics()->set_height(3);
  d.mutable_intrinsics()->set_fx(5.0);
  d.mutable_intrinsics()->set_fy(5.0);
  d.mutable_intrinsics()->set_cx(1.5);
  d.mutable_intrinsics()->set_cy(1.0);
  DepthImage image(4, 3, 1.0f);
  *d.mutable_depth() = server::encodeDepth(image);
  d.set_mask(std::string(11, '\1'));
  expectRefused(*stub, depth, Code::INVALID_ARGUMENT, "depth.mask: 11 bytes");
  d.set_mask(std::string(12, '\0'));
  expectRefused(*stub, depth, Code::INVALID_ARGUMENT, "mask: no masked pixel");
  d.clear_mask();
  d.mutable_intrinsics()->set_fx(0.0);
  expectRefused(*stub, depth, Code::INVALID_ARGUMENT, "depth.intrinsics");
}

}  // namespace
}  // namespace objdb

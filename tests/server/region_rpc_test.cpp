// "What is here?" over loopback on a two-session world of known shapes, stored by the object
// database itself: Monday a chair and a box; Tuesday the chair where it was, the box 1.2 m on,
// and an extinguisher. ObjectsInRegion finds each where it stands; SessionChanges says the box
// moved by 1.2 m and the extinguisher was added (and, the other way round, removed); bad
// regions and unknown sessions name the field.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <string>

#include "core/database/object_database.h"
#include "objdb/v1/objdb.grpc.pb.h"
#include "server/proto_convert.h"
#include "server/server.h"
#include "storage/sqlite/sqlite_store.h"
#include "tests/server/loopback_server.h"
#include "tests/support/object_scenes.h"

namespace objdb {
namespace {

using World = objdb::testing::PlacedShape;

struct TwoDays {
  std::string db_path;
  int64_t chair = 0, box = 0, extinguisher = 0;
};

// In the shapes' world (tests/support/object_scenes.h: x and y within ±2 m).
const Transform kChairAt = objdb::testing::poseXyYaw(-1.0, -1.0, 0.2);
const Transform kBoxMonday = objdb::testing::poseXyYaw(1.0, -1.0, 0.7);
const Transform kBoxTuesday = objdb::testing::poseXyYaw(1.0, 0.2, 0.7);  // 1.2 m on
const Transform kExtinguisherAt = objdb::testing::poseXyYaw(-1.0, 1.0, 1.0);

TwoDays storeTwoDays() {
  TwoDays out;
  out.db_path = objdb::testing::scratchDbPath();
  auto store = storage::SqliteStore::open(out.db_path).value();
  const World chair{objdb::testing::chair(), kChairAt};
  const World box_monday{objdb::testing::boxWithBall(), kBoxMonday};
  const World box_tuesday{objdb::testing::boxWithBall(), kBoxTuesday};
  const World extinguisher{objdb::testing::extinguisher(), kExtinguisherAt};
  EXPECT_TRUE(store->putScene("monday", std::make_shared<tsdf::TsdfLayer>(
                                            objdb::testing::sceneGrid({chair, box_monday})))
                  .ok());
  EXPECT_TRUE(store
                  ->putScene("tuesday",
                             std::make_shared<tsdf::TsdfLayer>(objdb::testing::sceneGrid(
                                 {chair, box_tuesday, extinguisher})))
                  .ok());
  auto db = database::ObjectDatabase::create(Params(), store.get()).value();
  auto insert = [&](const std::string& session, uint32_t label, const World& w) -> int64_t {
    auto r = db->insertSegment(session, objdb::testing::rawSegment(label, w));
    EXPECT_TRUE(r.ok()) << r.status();
    return r.ok() ? r->model_id : 0;
  };
  out.chair = insert("monday", 1, chair);
  out.box = insert("monday", 2, box_monday);
  EXPECT_EQ(insert("tuesday", 1, chair), out.chair) << "the chair seen again merges";
  EXPECT_EQ(insert("tuesday", 2, box_tuesday), out.box) << "the moved box merges";
  out.extinguisher = insert("tuesday", 3, extinguisher);
  return out;
}

class RegionRpc : public ::testing::Test {
 protected:
  void SetUp() override {
    days_ = storeTwoDays();
    ASSERT_NE(days_.extinguisher, 0);
    server_ = objdb::testing::startOrDie(objdb::testing::loopbackOptions(days_.db_path));
    ASSERT_NE(server_, nullptr);
    stub_ = v1::ObjectDatabase::NewStub(
        grpc::CreateChannel(server_->address(), grpc::InsecureChannelCredentials()));
  }
  grpc::Status inRegion(const v1::ObjectsInRegionRequest& request,
                        v1::ObjectsInRegionResponse* response) {
    grpc::ClientContext context;
    return stub_->ObjectsInRegion(&context, request, response);
  }
  std::vector<uint64_t> idsIn(const std::string& session, const Eigen::Vector3d& centre,
                              double radius) {
    v1::ObjectsInRegionRequest request;
    request.set_session_name(session);
    server::setVector(centre, request.mutable_ball()->mutable_centre());
    request.mutable_ball()->set_radius_m(radius);
    v1::ObjectsInRegionResponse response;
    const grpc::Status s = inRegion(request, &response);
    EXPECT_TRUE(s.ok()) << s.error_message();
    std::vector<uint64_t> ids;
    for (const auto& p : response.placements()) ids.push_back(p.object().id());
    return ids;
  }
  grpc::Status changes(const std::string& from, const std::string& to,
                       v1::SessionChangesResponse* response) {
    v1::SessionChangesRequest request;
    request.set_from_session(from);
    request.set_to_session(to);
    grpc::ClientContext context;
    return stub_->SessionChanges(&context, request, response);
  }
  TwoDays days_;
  std::unique_ptr<ObjdbServer> server_;
  std::unique_ptr<v1::ObjectDatabase::Stub> stub_;
};

TEST_F(RegionRpc, EachObjectIsFoundWhereItStandsThatDay) {
  const Eigen::Vector3d chair = kChairAt.translation(), box_monday = kBoxMonday.translation(),
                        box_tuesday = kBoxTuesday.translation(),
                        extinguisher = kExtinguisherAt.translation();
  // Balls of 0.7 m around each shape's origin (the shapes stand 1.2 m apart or more).
  EXPECT_EQ(idsIn("monday", chair, 0.7), std::vector<uint64_t>{uint64_t(days_.chair)});
  EXPECT_EQ(idsIn("monday", box_monday, 0.7), std::vector<uint64_t>{uint64_t(days_.box)});
  EXPECT_TRUE(idsIn("monday", box_tuesday, 0.7).empty());
  EXPECT_TRUE(idsIn("monday", extinguisher, 0.7).empty());
  EXPECT_EQ(idsIn("tuesday", chair, 0.7), std::vector<uint64_t>{uint64_t(days_.chair)});
  EXPECT_TRUE(idsIn("tuesday", box_monday, 0.7).empty());
  EXPECT_EQ(idsIn("tuesday", box_tuesday, 0.7), std::vector<uint64_t>{uint64_t(days_.box)});
  EXPECT_EQ(idsIn("tuesday", extinguisher, 0.7),
            std::vector<uint64_t>{uint64_t(days_.extinguisher)});

  // A box around Tuesday's whole room: all three, each with its pose and world box.
  v1::ObjectsInRegionRequest request;
  request.set_session_name("tuesday");
  server::setVector({-2.0, -2.0, -1.0}, request.mutable_box()->mutable_min());
  server::setVector({2.0, 2.0, 2.0}, request.mutable_box()->mutable_max());
  v1::ObjectsInRegionResponse response;
  ASSERT_TRUE(inRegion(request, &response).ok());
  ASSERT_EQ(response.placements_size(), 3);
  for (const auto& p : response.placements()) {
    const v1::BoundingBox& b = p.bounds_world();
    const v1::Vector3& c = p.centre_world();
    EXPECT_TRUE(b.min().x() <= c.x() && c.x() <= b.max().x()) << p.object().id();
    EXPECT_TRUE(b.min().z() <= c.z() && c.z() <= b.max().z()) << p.object().id();
    if (p.object().id() == uint64_t(days_.box)) {
      EXPECT_NEAR(c.y(), box_tuesday.y(), 0.5);
      EXPECT_NEAR(p.t_world_object().y(), 1.2, 0.03)
          << "the box's model frame is Monday's world: on Tuesday it stands 1.2 m on";
    }
  }
}

TEST_F(RegionRpc, ChangesBetweenTheDaysHaveTheKnownAnswer) {
  v1::SessionChangesResponse forward, back;
  ASSERT_TRUE(changes("monday", "tuesday", &forward).ok());
  ASSERT_TRUE(changes("tuesday", "monday", &back).ok());
  ASSERT_EQ(forward.added_size(), 1);
  EXPECT_EQ(forward.added(0).object().id(), uint64_t(days_.extinguisher));
  EXPECT_EQ(forward.added(0).after_size(), 1);
  EXPECT_EQ(forward.removed_size(), 0);
  ASSERT_EQ(forward.moved_size(), 1);
  EXPECT_EQ(forward.moved(0).object().id(), uint64_t(days_.box));
  EXPECT_NEAR(forward.moved(0).moved_m(), 1.2, 0.03);
  EXPECT_EQ(forward.unchanged(), 1u);  // the chair

  ASSERT_EQ(back.removed_size(), 1);
  EXPECT_EQ(back.removed(0).object().id(), uint64_t(days_.extinguisher));
  EXPECT_EQ(back.added_size(), 0);
  EXPECT_EQ(back.moved_size(), 1);
}

TEST_F(RegionRpc, BadRegionsAndUnknownSessionsNameTheField) {
  auto refused = [&](const v1::ObjectsInRegionRequest& request, grpc::StatusCode code,
                     const std::string& field) {
    v1::ObjectsInRegionResponse response;
    const grpc::Status s = inRegion(request, &response);
    EXPECT_EQ(s.error_code(), code) << s.error_message();
    EXPECT_NE(s.error_message().find(field), std::string::npos) << s.error_message();
  };
  v1::ObjectsInRegionRequest r;
  r.set_session_name("monday");
  refused(r, grpc::StatusCode::INVALID_ARGUMENT, "region");
  server::setVector({1.0, 0.0, 0.0}, r.mutable_box()->mutable_min());
  server::setVector({0.0, 1.0, 1.0}, r.mutable_box()->mutable_max());
  refused(r, grpc::StatusCode::INVALID_ARGUMENT, "box.min.x 1 > box.max.x 0");
  r.mutable_ball()->set_radius_m(-1.0);
  refused(r, grpc::StatusCode::INVALID_ARGUMENT, "radius_m");
  r.mutable_ball()->set_radius_m(1.0);
  r.set_session_name("sunday");
  refused(r, grpc::StatusCode::NOT_FOUND, "session_name: no session named \"sunday\"");

  auto refusedChanges = [&](const std::string& from, const std::string& to,
                            grpc::StatusCode code, const std::string& field) {
    v1::SessionChangesResponse response;
    const grpc::Status s = changes(from, to, &response);
    EXPECT_EQ(s.error_code(), code) << s.error_message();
    EXPECT_NE(s.error_message().find(field), std::string::npos) << s.error_message();
  };
  refusedChanges("sunday", "monday", grpc::StatusCode::NOT_FOUND, "from_session");
  refusedChanges("monday", "sunday", grpc::StatusCode::NOT_FOUND, "to_session");
  refusedChanges("monday", "monday", grpc::StatusCode::INVALID_ARGUMENT, "to_session: the same");
}

}  // namespace
}  // namespace objdb

// "What is here?": ObjectsInRegion and SessionChanges (core/database/placements.h) over the
// placements the store lists for a session, on the query pool.
#include <algorithm>
#include <map>
#include <string>
#include <vector>

#include "absl/strings/str_format.h"
#include "core/database/placements.h"
#include "core/model/object_model.h"
#include "server/object_database_service.h"
#include "server/proto_convert.h"
#include "server/service_util.h"

namespace objdb::server {
namespace {

// INVALID_ARGUMENT for an empty name, else NOT_FOUND naming `field` unless the store holds it.
Status checkSession(const storage::Store& store, const std::string& name, const char* field) {
  if (name.empty()) return absl::InvalidArgumentError(absl::StrFormat("%s: empty", field));
  return checkSessionStored(store, name, field);
}

// Every active model placed in `session`, with its placements there (the store finds a session's
// observations by its index), by model id.
struct Placed {
  std::map<int64_t, storage::ModelSummary> models;
  std::vector<database::Placement> placements;
};
StatusOr<Placed> placementsIn(const storage::Store& store, const std::string& session,
                              bool include_structure) {
  Placed out;
  storage::ModelQuery query;
  query.session = session;
  query.include_structure = include_structure;
  query.limit = 1000;
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const std::vector<storage::ModelSummary> page,
                           store.modelSummaries(query));
    for (const storage::ModelSummary& m : page) {
      for (const auto& o : m.observations) {
        if (o.session != session) continue;
        out.placements.push_back(
            {m.id, o.T_world_object, Eigen::AlignedBox3d(m.bbox_min, m.bbox_max)});
      }
      out.models.emplace(m.id, m);
    }
    if (page.size() < query.limit) return out;
    query.after_id = page.back().id;
  }
}

v1::BoundingBox boxProto(const Eigen::AlignedBox3d& box) {
  v1::BoundingBox out;
  setVector(box.min(), out.mutable_min());
  setVector(box.max(), out.mutable_max());
  return out;
}

Eigen::Vector3d vectorOf(const v1::Vector3& v) { return {v.x(), v.y(), v.z()}; }

void describeChange(const storage::ModelSummary& model, const database::PlacementChange& change,
                    v1::ObjectChange* out) {
  toProto(model, out->mutable_object());
  for (const auto& p : change.before) *out->add_before() = toProto(p.T_world_object);
  for (const auto& p : change.after) *out->add_after() = toProto(p.T_world_object);
  out->set_moved_m(change.moved_m);
}

}  // namespace

grpc::ServerUnaryReactor* ObjectDatabaseService::ObjectsInRegion(
    grpc::CallbackServerContext* context, const v1::ObjectsInRegionRequest* request,
    v1::ObjectsInRegionResponse* response) {
  return answerAuthorized(context, [this, request, response]() -> Status {
    database::Region region;
    switch (request->region_case()) {
      case v1::ObjectsInRegionRequest::kBox:
        region.box = Eigen::AlignedBox3d(vectorOf(request->box().min()),
                                         vectorOf(request->box().max()));
        break;
      case v1::ObjectsInRegionRequest::kBall:
        region.centre = vectorOf(request->ball().centre());
        region.radius_m = request->ball().radius_m();
        break;
      default:
        return absl::InvalidArgumentError("region: give a box or a ball");
    }
    if (Status bad = database::validateRegion(region); !bad.ok()) {
      return annotate(bad, request->has_box() ? "box" : "ball");
    }
    OBJDB_RETURN_IF_ERROR(checkSession(*store_, request->session_name(), "session_name"));
    OBJDB_ASSIGN_OR_RETURN(const Placed placed, placementsIn(*store_, request->session_name(),
                                                             request->include_structure()));
    for (const database::Placement& p : placed.placements) {
      if (!database::inRegion(p, region)) continue;
      v1::PlacedObject& out = *response->add_placements();
      toProto(placed.models.at(p.model_id), out.mutable_object());
      *out.mutable_t_world_object() = toProto(p.T_world_object);
      setVector(p.centre(), out.mutable_centre_world());
      *out.mutable_bounds_world() = boxProto(p.worldBox());
    }
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* ObjectDatabaseService::SessionChanges(
    grpc::CallbackServerContext* context, const v1::SessionChangesRequest* request,
    v1::SessionChangesResponse* response) {
  return answerAuthorized(context, [this, request, response]() -> Status {
    OBJDB_RETURN_IF_ERROR(checkSession(*store_, request->from_session(), "from_session"));
    OBJDB_RETURN_IF_ERROR(checkSession(*store_, request->to_session(), "to_session"));
    if (request->from_session() == request->to_session()) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "to_session: the same session as from_session (\"%s\"); name two", request->to_session()));
    }
    OBJDB_ASSIGN_OR_RETURN(const Placed from, placementsIn(*store_, request->from_session(),
                                                           request->include_structure()));
    OBJDB_ASSIGN_OR_RETURN(const Placed to, placementsIn(*store_, request->to_session(),
                                                         request->include_structure()));
    // One place: model::samePlace's distance, the database's own rule for one surface.
    const database::SessionChanges changes =
        database::changesBetween(from.placements, to.placements, model::kSamePlaceM);
    auto modelOf = [&](int64_t id) -> const storage::ModelSummary& {
      const auto it = from.models.find(id);
      return it != from.models.end() ? it->second : to.models.at(id);
    };
    for (const auto& c : changes.added) {
      describeChange(modelOf(c.model_id), c, response->add_added());
    }
    for (const auto& c : changes.removed) {
      describeChange(modelOf(c.model_id), c, response->add_removed());
    }
    for (const auto& c : changes.moved) {
      describeChange(modelOf(c.model_id), c, response->add_moved());
    }
    response->set_unchanged(uint32_t(changes.unchanged));
    return absl::OkStatus();
  });
}

}  // namespace objdb::server

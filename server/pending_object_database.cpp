#include "server/pending_object_database.h"

#include <map>

#include "absl/strings/str_cat.h"

namespace objdb {
namespace {

// What each RPC waits for (DESIGN.md "Data flow").
const std::map<std::string, std::string>& pendingFeatures() {
  static const auto* features = new std::map<std::string, std::string>{
      {"Ingest", "the server's session pipeline: a stream worker that decodes frames and runs "
                 "them through segmentation, the GSM and the object database (offline today: "
                 "`objdb ingest`)"},
      {"EndSession", "the server's session pipeline: flushing the GSM, storing the scene map and "
                     "ending the session (offline today: `objdb ingest`)"},
      {"ListSessions", "the proto conversion of the stored sessions (offline today: `objdb db "
                       "stats`)"},
      {"ListObjects", "the proto conversion and paging of the stored models (offline today: "
                      "`objdb db models`)"},
      {"GetObject", "the proto conversion of a stored model (offline today: `objdb db export`)"},
      {"GetSceneMesh", "streaming a session's (completed) mesh in chunks (offline today: "
                       "`objdb db complete`)"},
      {"GetStats", "the proto conversion of the store's statistics and the session pipeline's "
                   "counters (offline today: `objdb db stats`)"},
  };
  return *features;
}

grpc::Status pendingStatus(const std::string& method) {
  return grpc::Status(grpc::StatusCode::UNIMPLEMENTED, pendingRpcMessage(method));
}

grpc::ServerUnaryReactor* finishUnary(grpc::CallbackServerContext* context,
                                      const std::string& method) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  reactor->Finish(pendingStatus(method));
  return reactor;
}

// Streaming reactors that end the call at once; gRPC calls OnDone() last, which frees them.
class PendingWriteReactor final : public grpc::ServerWriteReactor<v1::MeshChunk> {
 public:
  explicit PendingWriteReactor(const std::string& method) { Finish(pendingStatus(method)); }
  void OnDone() override { delete this; }
};

class PendingBidiReactor final
    : public grpc::ServerBidiReactor<v1::IngestRequest, v1::IngestResponse> {
 public:
  explicit PendingBidiReactor(const std::string& method) { Finish(pendingStatus(method)); }
  void OnDone() override { delete this; }
};

}  // namespace

std::string pendingRpcMessage(const std::string& method) {
  const auto it = pendingFeatures().find(method);
  return absl::StrCat("objdb.v1.ObjectDatabase/", method, " is not implemented yet; it waits for ",
                      it != pendingFeatures().end() ? it->second : "further work",
                      ". Only grpc.health.v1.Health is served for now.");
}

grpc::ServerBidiReactor<v1::IngestRequest, v1::IngestResponse>*
PendingObjectDatabaseService::Ingest(grpc::CallbackServerContext*) {
  return new PendingBidiReactor("Ingest");
}

grpc::ServerUnaryReactor* PendingObjectDatabaseService::EndSession(
    grpc::CallbackServerContext* context, const v1::EndSessionRequest*, v1::EndSessionResponse*) {
  return finishUnary(context, "EndSession");
}

grpc::ServerUnaryReactor* PendingObjectDatabaseService::ListSessions(
    grpc::CallbackServerContext* context, const v1::ListSessionsRequest*,
    v1::ListSessionsResponse*) {
  return finishUnary(context, "ListSessions");
}

grpc::ServerUnaryReactor* PendingObjectDatabaseService::ListObjects(
    grpc::CallbackServerContext* context, const v1::ListObjectsRequest*, v1::ListObjectsResponse*) {
  return finishUnary(context, "ListObjects");
}

grpc::ServerUnaryReactor* PendingObjectDatabaseService::GetObject(
    grpc::CallbackServerContext* context, const v1::GetObjectRequest*, v1::ObjectDetail*) {
  return finishUnary(context, "GetObject");
}

grpc::ServerWriteReactor<v1::MeshChunk>* PendingObjectDatabaseService::GetSceneMesh(
    grpc::CallbackServerContext*, const v1::GetSceneMeshRequest*) {
  return new PendingWriteReactor("GetSceneMesh");
}

grpc::ServerUnaryReactor* PendingObjectDatabaseService::GetStats(
    grpc::CallbackServerContext* context, const v1::GetStatsRequest*, v1::GetStatsResponse*) {
  return finishUnary(context, "GetStats");
}

}  // namespace objdb

// `objdb web`'s JSON and binary endpoints, each a read-only call of the objdb gRPC API: it never
// opens a database itself. Paths (docs/web.md):
//   GET /api/sessions                              ListSessions, each with its objects' count
//   GET /api/objects?session=&page_size=&page_token=&structure=&merged=&parts=   ListObjects
//   GET /api/objects/{id}                          GetObject without geometry: poses, lineage,
//                                                  merge evidence
//   GET /api/objects/{id}/mesh.ply | cloud.ply     the model's geometry, binary PLY
//   GET /api/objects/{id}/thumbnail/{0|1}.png      a view rendered here, cached
//   GET /api/sessions/{name}/scene.ply?completed=  GetSceneMesh, binary PLY
//   GET /api/stats                                 GetStats
//   GET /api/viewer                                what this viewer has: the sessions whose
//                                                  datasets it was given (objdb web --dataset)
//   GET /api/objects/{id}/sheet.png                the model's merge-sheet row (merge_sheet.h):
//                                                  its placements over those datasets' frames
//   GET /api/objects/{id}/similar?max_results=     Match of the stored object ("find similar"):
//                                                  the objects it would merge with, and why not
// Answers: 200 with JSON, PLY or PNG; else a JSON {"error": "...", "grpc_code": "..."} with
// 400 (malformed path or query parameters), 404 (unknown object or session), 503 (the objdb
// server is down or overloaded, with its gRPC message), 504 (its deadline passed) or 502
// (another failure of the call).
#pragma once

#include <grpcpp/grpcpp.h>

#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "objdb/v1/objdb.grpc.pb.h"

namespace objdb::web {

// What an endpoint answers.
struct Reply {
  int status = 200;
  std::string content_type = "application/json";
  std::string body;
};

// A request's query parameters (decoded).
using Query = std::multimap<std::string, std::string>;

class WebApi {
 public:
  // `datasets`: session name → dataset folder, for the merge-sheet rows (may be empty).
  WebApi(std::shared_ptr<grpc::Channel> channel, double call_timeout_s, double scene_timeout_s,
         std::map<std::string, std::string> datasets = {});

  Reply sessions(const Query& query);
  Reply objects(const Query& query);
  Reply object(const std::string& id, const Query& query);
  Reply objectGeometry(const std::string& id, const std::string& what, const Query& query);
  Reply thumbnail(const std::string& id, const std::string& view, const Query& query);
  Reply scene(const std::string& session, const Query& query);
  Reply stats(const Query& query);
  Reply viewer(const Query& query);
  Reply sheet(const std::string& id, const Query& query);
  Reply similar(const std::string& id, const Query& query);

  // A JSON error reply.
  static Reply error(int status, const std::string& message, const std::string& grpc_code = "");

 private:
  // GetObject of `id` (geometry as asked) into `out`; on failure the reply to send.
  bool getObject(uint64_t id, bool mesh, bool cloud, v1::ObjectDetail* out, Reply* failed);
  void deadline(grpc::ClientContext* context, double seconds) const;

  std::unique_ptr<v1::ObjectDatabase::Stub> stub_;
  double call_timeout_s_, scene_timeout_s_;
  // Thumbnails by object id, with what they were drawn from: a model that changes (a merge, a
  // re-extracted segment) is drawn again.
  struct Thumbnails {
    std::string version;
    std::string png[2];
  };
  std::map<std::string, std::string> datasets_;
  std::mutex mutex_;
  std::map<uint64_t, Thumbnails> thumbnails_;
  std::map<uint64_t, std::pair<std::string, std::string>> sheets_;  // id → (version, PNG)
};

}  // namespace objdb::web

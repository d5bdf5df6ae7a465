// objdb.v1.ObjectDatabase as it stands before its features land: every RPC ends at once with
// UNIMPLEMENTED and a message naming the feature it waits for. Never returns data. Registering it
// also gives the gRPC server the callback service it needs to start (gRPC 1.51 refuses to build a
// server without any service). Each RPC moves to the real implementation with its issue.
#pragma once

#include <string>

#include "objdb/v1/objdb.grpc.pb.h"

namespace objdb {

// "objdb.v1.ObjectDatabase/GetStats is not implemented yet: ..." for `method` ("GetStats").
std::string pendingRpcMessage(const std::string& method);

class PendingObjectDatabaseService final : public v1::ObjectDatabase::CallbackService {
 public:
  grpc::ServerBidiReactor<v1::IngestRequest, v1::IngestResponse>* Ingest(
      grpc::CallbackServerContext* context) override;
  grpc::ServerUnaryReactor* EndSession(grpc::CallbackServerContext* context,
                                       const v1::EndSessionRequest* request,
                                       v1::EndSessionResponse* response) override;
  grpc::ServerUnaryReactor* ListSessions(grpc::CallbackServerContext* context,
                                         const v1::ListSessionsRequest* request,
                                         v1::ListSessionsResponse* response) override;
  grpc::ServerUnaryReactor* ListObjects(grpc::CallbackServerContext* context,
                                        const v1::ListObjectsRequest* request,
                                        v1::ListObjectsResponse* response) override;
  grpc::ServerUnaryReactor* GetObject(grpc::CallbackServerContext* context,
                                      const v1::GetObjectRequest* request,
                                      v1::ObjectDetail* response) override;
  grpc::ServerWriteReactor<v1::MeshChunk>* GetSceneMesh(
      grpc::CallbackServerContext* context, const v1::GetSceneMeshRequest* request) override;
  grpc::ServerUnaryReactor* GetStats(grpc::CallbackServerContext* context,
                                     const v1::GetStatsRequest* request,
                                     v1::GetStatsResponse* response) override;
};

}  // namespace objdb

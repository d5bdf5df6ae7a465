// What the commands that talk to an objdb server share: how to reach it (address, TLS, token:
// server/auth.h), the channel (large receive limit for meshes) and one way to report a failed
// call.
#pragma once

#include <grpcpp/grpcpp.h>

#include <chrono>
#include <memory>
#include <string>

#include "core/common/mesh.h"
#include "core/common/status.h"
#include "objdb/v1/objdb.grpc.pb.h"
#include "server/auth.h"

namespace objdb::cli {

inline constexpr const char* kDefaultServer = "127.0.0.1:50051";

// --server, --token-file, --tls-ca, --tls-cert, --tls-key.
struct Connection {
  std::string server = kDefaultServer;
  std::string token_file;     // its token goes with every call ("authorization: Bearer ...")
  auth::TlsClientFiles tls;   // empty ca_file = plaintext
};

// The usage lines of those options, spliced into the commands' help texts (a macro so that it
// joins their string literals at compile time).
#define OBJDB_CONNECTION_USAGE                                                                   \
  "  --server HOST:PORT   server address (default 127.0.0.1:50051)\n"                           \
  "  --token-file FILE    send the token in FILE with every call (a server with --token-file)\n" \
  "  --tls-ca FILE        connect with TLS, trusting server certificates this PEM CA signed\n"   \
  "  --tls-cert FILE      with --tls-key: a PEM client certificate (a server with\n"             \
  "                       --tls-client-ca)\n"                                                    \
  "  --tls-key FILE       that certificate's PEM key\n"

// When `flag` is one of the connection options, stores `value` and returns true.
bool takeConnectionFlag(const std::string& flag, const std::string& value, Connection* connection);

// The channel: TLS when a CA is given, the token attached to every call when a token file is.
// Errors: an empty server address, unreadable or bad token / PEM files (named).
StatusOr<std::shared_ptr<grpc::Channel>> openChannel(const Connection& connection);

// A deadline `seconds` from now.
void setDeadline(grpc::ClientContext* context, double seconds);

// Prints "objdb <command>: <what> failed on <server>: <CODE>: <message>" to stderr (with a hint
// when the server cannot be reached); returns 1.
int reportRpcError(const char* command, const std::string& what, const std::string& server,
                   const grpc::Status& status);

// A session's scene mesh (GetSceneMesh; `completed`: filled by the merged models), its chunks
// appended into `mesh`; `chunks` gets their number when not null. A timeout of 0 sets no deadline.
grpc::Status fetchSceneMesh(v1::ObjectDatabase::Stub& stub, const std::string& session,
                            bool completed, double timeout_s, TriangleMesh* mesh,
                            size_t* chunks = nullptr);

}  // namespace objdb::cli

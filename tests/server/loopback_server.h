// In-process objdb servers for the server tests: a fresh database file per server (in a folder
// removed when the test binary exits), loopback on a free port, a generous drain deadline.
#pragma once

#include <memory>
#include <string>

#include "server/server.h"

namespace objdb::testing {

// A new database path on every call.
std::string scratchDbPath();
// 127.0.0.1:0, the given (or a fresh) database file, 30 s to drain.
ServerOptions loopbackOptions(const std::string& db_path = scratchDbPath());
// The started server, or null after a test failure naming why.
std::unique_ptr<ObjdbServer> startOrDie(const ServerOptions& options);

}  // namespace objdb::testing

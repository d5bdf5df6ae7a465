#include "tests/server/loopback_server.h"

#include <gtest/gtest.h>

#include <chrono>

#include "tests/support/temp_dir.h"

namespace objdb::testing {

std::string scratchDbPath() {
  static TempDir dir;
  static int next = 0;
  return (dir / ("server" + std::to_string(next++) + ".sqlite")).string();
}

ServerOptions loopbackOptions(const std::string& db_path) {
  ServerOptions options;
  options.listen_address = "127.0.0.1:0";
  options.db_path = db_path;
  options.drain_deadline = std::chrono::seconds(30);
  return options;
}

std::unique_ptr<ObjdbServer> startOrDie(const ServerOptions& options) {
  StatusOr<std::unique_ptr<ObjdbServer>> server = ObjdbServer::start(options);
  EXPECT_TRUE(server.ok()) << server.status();
  return server.ok() ? *std::move(server) : nullptr;
}

}  // namespace objdb::testing

// The objdb client binary: command dispatch and `objdb health` against a loopback server.
#include <gtest/gtest.h>

#include <chrono>
#include <memory>
#include <string>

#include "server/server.h"
#include "tests/support/subprocess.h"
#include "tests/support/temp_dir.h"

namespace objdb {
namespace {

using testing::ProcessResult;
using testing::runProcess;

const std::string kObjdb = OBJDB_CLIENT_BINARY;

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

std::unique_ptr<ObjdbServer> startLoopbackServer() {
  static testing::TempDir dir;  // the servers' database files, removed at exit
  static int next = 0;
  ServerOptions options;
  options.listen_address = "127.0.0.1:0";
  options.db_path = (dir / ("server" + std::to_string(next++) + ".sqlite")).string();
  StatusOr<std::unique_ptr<ObjdbServer>> server = ObjdbServer::start(options);
  EXPECT_TRUE(server.ok()) << server.status();
  return server.ok() ? *std::move(server) : nullptr;
}

TEST(ObjdbCli, HelpListsEverySubcommandAndExitsZero) {
  for (const char* help : {"help", "--help", "-h"}) {
    const ProcessResult result = runProcess({kObjdb, help});
    EXPECT_EQ(result.exit_code, 0) << help << "\n" << result.err;
    EXPECT_TRUE(contains(result.out, "usage: objdb <command>")) << result.out;
    for (const char* command :
         {"\n  health ", "\n  sim ", "\n  info ", "\n  segment ", "\n  fuse ", "\n  gsm ",
          "\n  ingest ", "\n  db ", "\n  stream ", "\n  remote ", "\n  help "}) {
      EXPECT_TRUE(contains(result.out, command)) << command << " missing in\n" << result.out;
    }
  }
}

TEST(ObjdbCli, NoOrUnknownCommandPrintsUsageAndExitsTwo) {
  ProcessResult result = runProcess({kObjdb});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(contains(result.err, "no command given")) << result.err;
  EXPECT_TRUE(contains(result.err, "usage: objdb")) << result.err;

  result = runProcess({kObjdb, "frobnicate"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(contains(result.err, "unknown command \"frobnicate\"")) << result.err;
}

TEST(ObjdbCli, HealthHelpAndBadOptions) {
  ProcessResult result = runProcess({kObjdb, "health", "--help"});
  EXPECT_EQ(result.exit_code, 0);
  EXPECT_TRUE(contains(result.out, "--server HOST:PORT")) << result.out;
  EXPECT_TRUE(contains(result.out, "--timeout-ms")) << result.out;

  result = runProcess({kObjdb, "health", "--timeout-ms", "0"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(contains(result.err, "--timeout-ms must be an integer in [1, 3600000], got \"0\""))
      << result.err;

  result = runProcess({kObjdb, "health", "--server"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(contains(result.err, "--server needs a value")) << result.err;

  result = runProcess({kObjdb, "health", "--verbose"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(contains(result.err, "unknown option \"--verbose\"")) << result.err;
}

TEST(ObjdbCli, HealthPrintsServingForARunningServer) {
  auto server = startLoopbackServer();
  ASSERT_NE(server, nullptr);
  const ProcessResult result =
      runProcess({kObjdb, "health", "--server", server->address(), "--timeout-ms", "10000"});
  EXPECT_EQ(result.exit_code, 0) << result.err;
  EXPECT_EQ(result.out, "SERVING\n");
}

TEST(ObjdbCli, HealthOfAnUnknownServiceExitsOne) {
  auto server = startLoopbackServer();
  ASSERT_NE(server, nullptr);
  const ProcessResult result =
      runProcess({kObjdb, "health", "--server", server->address(), "--service", "no.such.Service"});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_TRUE(contains(result.err, "does not know the service \"no.such.Service\"")) << result.err;
}

TEST(ObjdbCli, HealthOfAStoppedServerSaysItCannotReachIt) {
  auto server = startLoopbackServer();
  ASSERT_NE(server, nullptr);
  const std::string address = server->address();
  server->shutdown();
  const ProcessResult result =
      runProcess({kObjdb, "health", "--server", address, "--timeout-ms", "10000"});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_EQ(result.out, "");
  EXPECT_TRUE(contains(result.err, "cannot reach " + address)) << result.err;
}

}  // namespace
}  // namespace objdb

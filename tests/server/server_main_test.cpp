// The objdb-server binary: usage, command-line errors, config checks, serving until SIGTERM/SIGINT.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <fstream>
#include <iterator>
#include <signal.h>
#include <string.h>

#include <cctype>
#include <cstdio>
#include <filesystem>
#include <future>
#include <vector>
#include <chrono>
#include <memory>
#include <string>

#include "grpc/health/v1/health.grpc.pb.h"
#include "storage/sqlite/sqlite_store.h"
#include "tests/server/ingest_fixtures.h"
#include "tests/support/subprocess.h"
#include "tests/support/temp_dir.h"

namespace objdb {
namespace {

using testing::ChildProcess;
using testing::listeningAddress;
using testing::ProcessResult;
using testing::runProcess;
using testing::TempDir;
using testing::writeTextFile;

constexpr auto kStartTimeout = std::chrono::seconds(30);
const std::string kServer = OBJDB_SERVER_BINARY;
constexpr const char* kListening = "listening on 127.0.0.1:";

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

grpc::Status checkHealth(const std::string& address,
                         grpc::health::v1::HealthCheckResponse* response) {
  auto stub = grpc::health::v1::Health::NewStub(
      grpc::CreateChannel(address, grpc::InsecureChannelCredentials()));
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  return stub->Check(&context, grpc::health::v1::HealthCheckRequest(), response);
}

TEST(ObjdbServerBinary, HelpPrintsUsageAndExitsZero) {
  for (const char* flag : {"--help", "-h"}) {
    const ProcessResult result = runProcess({kServer, flag});
    EXPECT_EQ(result.exit_code, 0) << flag << "\n" << result.err;
    EXPECT_TRUE(contains(result.out, "usage: objdb-server")) << result.out;
    for (const char* option : {"--listen", "--allow-remote", "--db", "--config", "--log-level",
                               "--help", "127.0.0.1:50051", "objdb.sqlite"}) {
      EXPECT_TRUE(contains(result.out, option)) << option;
    }
    EXPECT_EQ(result.err, "");
  }
}

TEST(ObjdbServerBinary, UnknownOptionPrintsUsageAndExitsTwo) {
  const ProcessResult result = runProcess({kServer, "--bogus"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(contains(result.err, "unknown option \"--bogus\"")) << result.err;
  EXPECT_TRUE(contains(result.err, "usage: objdb-server")) << result.err;
  EXPECT_EQ(result.out, "");
}

TEST(ObjdbServerBinary, MissingOrMalformedValuesExitTwo) {
  ProcessResult result = runProcess({kServer, "--listen"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(contains(result.err, "--listen needs a value")) << result.err;

  result = runProcess({kServer, "--drain-deadline-ms", "soon"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(contains(result.err, "--drain-deadline-ms must be an integer")) << result.err;

  result = runProcess({kServer, "--max-message-mib=0"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(contains(result.err, "--max-message-mib must be an integer in [1, 1024]"))
      << result.err;

  result = runProcess({kServer, "--save-map-s", "-1"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(contains(result.err, "--save-map-s must be 0 (never) or a number of seconds in "
                                    "[0.001, 86400]"))
      << result.err;
  result = runProcess({kServer, "--save-map-s", "0.0001"});
  EXPECT_EQ(result.exit_code, 2);
  result = runProcess({kServer, "--save-map-s=often"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(contains(result.err, "got \"often\"")) << result.err;

  result = runProcess({kServer, "--slow-reader-s", "0"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(contains(result.err, "--slow-reader-s must be an integer in [1, 86400]"))
      << result.err;

  result = runProcess({kServer, "--keepalive-s", "0"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(contains(result.err, "--keepalive-s must be a number of seconds in [0.1, 86400]"))
      << result.err;
  result = runProcess({kServer, "--max-connection-idle-s", "-3"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(contains(result.err, "--max-connection-idle-s must be 0 (never) or a number"))
      << result.err;
  result = runProcess({kServer, "--keepalive-timeout-s=soon"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(contains(result.err, "got \"soon\"")) << result.err;

  result = runProcess({kServer, "--allow-remote=yes"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(contains(result.err, "--allow-remote takes no value")) << result.err;

  result = runProcess({kServer, "--log-level", "loud"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(contains(result.err, "unknown --log-level \"loud\"")) << result.err;
}

TEST(ObjdbServerBinary, ConfigThatIsNotJsonRefusesToStartNamingTheFile) {
  TempDir dir;
  const std::string config = (dir / "broken.json").string();
  ASSERT_TRUE(writeTextFile(config, "{\"tsdf\": {\"voxel_size_m\": 0.01"));
  const ProcessResult result = runProcess({kServer, "--listen", "127.0.0.1:0", "--config", config});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_TRUE(contains(result.err, config)) << result.err;
  EXPECT_TRUE(contains(result.err, "not valid JSON")) << result.err;
  EXPECT_FALSE(contains(result.err, "listening on")) << result.err;
}

TEST(ObjdbServerBinary, ConfigWithUnknownKeyOrBadValueRefusesToStart) {
  TempDir dir;
  const std::string typo = (dir / "typo.json").string();
  ASSERT_TRUE(writeTextFile(typo, R"({"tsdf": {"voxel_size": 0.01}})"));
  ProcessResult result = runProcess({kServer, "--listen", "127.0.0.1:0", "--config", typo});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_TRUE(contains(result.err, typo)) << result.err;
  EXPECT_TRUE(contains(result.err, "tsdf.voxel_size")) << result.err;

  const std::string bad_value = (dir / "negative.json").string();
  ASSERT_TRUE(writeTextFile(bad_value, R"({"tsdf": {"voxel_size_m": -1}})"));
  result = runProcess({kServer, "--listen", "127.0.0.1:0", "--config", bad_value});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_TRUE(contains(result.err, bad_value)) << result.err;
  EXPECT_TRUE(contains(result.err, "tsdf.voxel_size_m")) << result.err;
}

TEST(ObjdbServerBinary, MissingConfigFileRefusesToStart) {
  TempDir dir;
  const std::string missing = (dir / "missing.json").string();
  const ProcessResult result = runProcess({kServer, "--config", missing});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_TRUE(contains(result.err, missing)) << result.err;
}

TEST(ObjdbServerBinary, PrintConfigShowsTheConfigFileApplied) {
  TempDir dir;
  const std::string config = (dir / "fine.json").string();
  ASSERT_TRUE(writeTextFile(config, R"({"matching": {"k_nn": 8}})"));
  const ProcessResult result = runProcess({kServer, "--config", config, "--print-config"});
  EXPECT_EQ(result.exit_code, 0) << result.err;
  EXPECT_TRUE(contains(result.out, "\"k_nn\": 8")) << result.out;
  EXPECT_TRUE(contains(result.out, "\"voxel_size_m\"")) << result.out;
}

TEST(ObjdbServerBinary, NonLoopbackAddressNeedsAllowRemote) {
  const ProcessResult result = runProcess({kServer, "--listen", "0.0.0.0:0"});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_TRUE(contains(result.err, "0.0.0.0:0")) << result.err;
  EXPECT_TRUE(contains(result.err, "--allow-remote")) << result.err;
  EXPECT_FALSE(contains(result.err, "listening on")) << result.err;
}

TEST(ObjdbServerBinary, ADatabaseFileItCannotServeRefusesTheStartUntouched) {
  TempDir dir;
  const std::string notes = (dir / "notes.txt").string();
  ASSERT_TRUE(writeTextFile(notes, std::string(4096, 'n')));
  ProcessResult result = runProcess({kServer, "--listen", "127.0.0.1:0", "--db", notes});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_TRUE(contains(result.err, notes)) << result.err;
  EXPECT_TRUE(contains(result.err, "not a database")) << result.err;
  EXPECT_FALSE(contains(result.err, "listening on")) << result.err;
  std::ifstream in(notes);
  EXPECT_EQ(std::string(std::istreambuf_iterator<char>(in), {}), std::string(4096, 'n'));
}

// Two servers on one database file would each keep their own copy of its index: the second
// refuses to start, and the first serves on; once it stops, the file can be opened again.
TEST(ObjdbServerBinary, ASecondServerOnTheSameDatabaseRefusesToStart) {
  TempDir dir;
  const std::string db = (dir / "db.sqlite").string();
  ChildProcess first({kServer, "--listen", "127.0.0.1:0", "--db", db});
  ASSERT_TRUE(first.started());
  ASSERT_TRUE(first.waitForStderr(kListening, kStartTimeout)) << first.stderrText();
  ASSERT_TRUE(first.waitForStderr("\n", kStartTimeout));
  const std::string address = listeningAddress(first.stderrText());

  ProcessResult second = runProcess({kServer, "--listen", "127.0.0.1:0", "--db", db});
  EXPECT_EQ(second.exit_code, 1);
  EXPECT_TRUE(contains(second.err, "open for writing by another objdb store")) << second.err;
  EXPECT_FALSE(contains(second.err, "listening on")) << second.err;
  grpc::health::v1::HealthCheckResponse response;
  ASSERT_TRUE(checkHealth(address, &response).ok());
  EXPECT_EQ(response.status(), grpc::health::v1::HealthCheckResponse::SERVING);

  ASSERT_TRUE(first.sendSignal(SIGTERM));
  EXPECT_EQ(first.wait(std::chrono::seconds(60)).exit_code, 0);
  ChildProcess third({kServer, "--listen", "127.0.0.1:0", "--db", db});
  ASSERT_TRUE(third.started());
  EXPECT_TRUE(third.waitForStderr(kListening, kStartTimeout)) << third.stderrText();
  ASSERT_TRUE(third.sendSignal(SIGTERM));
  EXPECT_EQ(third.wait(std::chrono::seconds(60)).exit_code, 0);
}

TEST(ObjdbServerBinary, MalformedListenAddressRefusesToStart) {
  const ProcessResult result = runProcess({kServer, "--listen=localhost"});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_TRUE(contains(result.err, "\"localhost\" has no port")) << result.err;
}

class ObjdbServerBinarySignal : public ::testing::TestWithParam<int> {};

TEST_P(ObjdbServerBinarySignal, ServesHealthThenDrainsAndExitsZero) {
  const int signal_number = GetParam();
  TempDir dir;
  ChildProcess server({kServer, "--listen", "127.0.0.1:0", "--db", (dir / "db.sqlite").string(),
                       "--log-level", "debug"});
  ASSERT_TRUE(server.started());
  ASSERT_TRUE(server.waitForStderr(kListening, kStartTimeout)) << server.stderrText();
  ASSERT_TRUE(server.waitForStderr("\n", kStartTimeout));
  const std::string address = listeningAddress(server.stderrText());
  ASSERT_NE(address, "127.0.0.1:") << server.stderrText();
  ASSERT_NE(address, "127.0.0.1:0") << server.stderrText();

  grpc::health::v1::HealthCheckResponse response;
  const grpc::Status status = checkHealth(address, &response);
  ASSERT_TRUE(status.ok()) << status.error_message() << "\n" << server.stderrText();
  EXPECT_EQ(response.status(), grpc::health::v1::HealthCheckResponse::SERVING);

  ASSERT_TRUE(server.sendSignal(signal_number));
  const ProcessResult result = server.wait(std::chrono::seconds(60));
  EXPECT_FALSE(result.timed_out);
  EXPECT_EQ(result.term_signal, 0) << result.err;
  EXPECT_EQ(result.exit_code, 0) << result.err;
  EXPECT_TRUE(contains(result.err, "received SIG" + std::string(sigabbrev_np(signal_number))))
      << result.err;
  EXPECT_TRUE(contains(result.err, "stopped serving " + address)) << result.err;
  EXPECT_EQ(checkHealth(address, &response).error_code(), grpc::StatusCode::UNAVAILABLE);
}

// Starts objdb-server on an ephemeral port and returns its address ("" on failure).
std::string startServer(ChildProcess* server) {
  if (!server->started() || !server->waitForStderr(kListening, kStartTimeout) ||
      !server->waitForStderr("\n", kStartTimeout)) {
    return "";
  }
  return listeningAddress(server->stderrText());
}

// A health Watch keeps a call in flight, so the drain has something to wait for.
struct OpenWatch {
  explicit OpenWatch(const std::string& address)
      : stub(grpc::health::v1::Health::NewStub(
            grpc::CreateChannel(address, grpc::InsecureChannelCredentials()))) {
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
    reader = stub->Watch(&context, grpc::health::v1::HealthCheckRequest());
  }
  std::unique_ptr<grpc::health::v1::Health::Stub> stub;
  grpc::ClientContext context;
  std::unique_ptr<grpc::ClientReader<grpc::health::v1::HealthCheckResponse>> reader;
};

TEST(ObjdbServerBinary, CallStillOpenAtTheDrainDeadlineIsCancelledAndTheServerExitsZero) {
  TempDir dir;
  ChildProcess server({kServer, "--listen", "127.0.0.1:0", "--db", (dir / "db.sqlite").string(),
                       "--drain-deadline-ms", "300"});
  const std::string address = startServer(&server);
  ASSERT_FALSE(address.empty()) << server.stderrText();
  OpenWatch watch(address);
  grpc::health::v1::HealthCheckResponse response;
  ASSERT_TRUE(watch.reader->Read(&response));
  EXPECT_EQ(response.status(), grpc::health::v1::HealthCheckResponse::SERVING);

  ASSERT_TRUE(server.sendSignal(SIGTERM));
  ASSERT_TRUE(watch.reader->Read(&response));
  EXPECT_EQ(response.status(), grpc::health::v1::HealthCheckResponse::NOT_SERVING);
  while (watch.reader->Read(&response)) {
  }
  const grpc::Status ended = watch.reader->Finish();
  // gRPC ends calls still running at the Shutdown deadline with UNAVAILABLE.
  EXPECT_EQ(ended.error_code(), grpc::StatusCode::UNAVAILABLE) << ended.error_message();
  const ProcessResult result = server.wait(std::chrono::seconds(60));
  EXPECT_EQ(result.exit_code, 0) << result.err;
  EXPECT_TRUE(contains(result.err, "stopped serving")) << result.err;
}

TEST(ObjdbServerBinary, SecondSignalExitsAtOnceDuringADrain) {
  TempDir dir;
  ChildProcess server({kServer, "--listen", "127.0.0.1:0", "--db", (dir / "db.sqlite").string(),
                       "--drain-deadline-ms", "600000"});
  const std::string address = startServer(&server);
  ASSERT_FALSE(address.empty()) << server.stderrText();
  OpenWatch watch(address);
  grpc::health::v1::HealthCheckResponse response;
  ASSERT_TRUE(watch.reader->Read(&response));

  ASSERT_TRUE(server.sendSignal(SIGTERM));
  // Standard signals do not queue: wait until the first one was taken before sending another.
  ASSERT_TRUE(server.waitForStderr("received SIGTERM", kStartTimeout)) << server.stderrText();
  ASSERT_TRUE(server.sendSignal(SIGTERM));
  const ProcessResult result = server.wait(std::chrono::seconds(60));
  EXPECT_FALSE(result.timed_out);
  EXPECT_EQ(result.exit_code, 128 + SIGTERM) << result.err;
  EXPECT_TRUE(contains(result.err, "received SIGTERM again, exiting without draining"))
      << result.err;
  watch.context.TryCancel();
}

INSTANTIATE_TEST_SUITE_P(SigtermAndSigint, ObjdbServerBinarySignal,
                         ::testing::Values(SIGTERM, SIGINT),
                         [](const ::testing::TestParamInfo<int>& info) {
                           return std::string(sigabbrev_np(info.param));
                         });

// Graceful shutdown under load: SIGTERM with four sessions streaming (header and frames sent,
// never half-closed) and one EndSession flushing. Health turns NOT_SERVING, a new call is
// UNAVAILABLE, the flush finishes with its objects committed, the open streams end at the drain
// deadline with UNAVAILABLE, the server exits 0 and stores every session with every frame it
// acknowledged, and leaves one checkpointed file that passes its checks. The times are printed
// (this machine is too noisy to assert them).
TEST(ObjdbServerBinary, ASigtermWithFourOpenStreamsAndAFlushDrainsAndLosesNothing) {
  using Clock = std::chrono::steady_clock;
  const auto ms = [](Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
  };
  TempDir dir;
  const std::string db = (dir / "db.sqlite").string();
  constexpr int kDrainMs = 10000;  // the default: the flush must fit in it even under load
  ChildProcess server({kServer, "--listen", "127.0.0.1:0", "--db", db, "--drain-deadline-ms",
                       std::to_string(kDrainMs)});
  const std::string address = startServer(&server);
  ASSERT_FALSE(address.empty()) << server.stderrText();
  auto stub = v1::ObjectDatabase::NewStub(
      grpc::CreateChannel(address, grpc::InsecureChannelCredentials()));
  constexpr size_t kFlushedFrames = 20, kOpenFrames = 3;
  ASSERT_TRUE(testing::ingest(*stub, testing::session("flushed", kFlushedFrames))
                  .everyFrameAccepted(kFlushedFrames));

  struct OpenStream {
    grpc::ClientContext context;
    std::unique_ptr<grpc::ClientReaderWriter<v1::IngestRequest, v1::IngestResponse>> stream;
  };
  std::vector<std::unique_ptr<OpenStream>> open;
  for (int s = 0; s < 4; ++s) {
    auto o = std::make_unique<OpenStream>();
    o->stream = stub->Ingest(&o->context);
    const std::vector<v1::IngestRequest> requests =
        testing::session("open-" + std::to_string(s), kOpenFrames);
    for (const auto& r : requests) ASSERT_TRUE(o->stream->Write(r));
    size_t acks = 0;
    v1::IngestResponse response;
    while (acks < kOpenFrames && o->stream->Read(&response)) {
      if (response.has_ack()) {
        ASSERT_TRUE(response.ack().accepted()) << response.ack().reason();
        ++acks;
      }
    }
    ASSERT_EQ(acks, kOpenFrames);
    open.push_back(std::move(o));
  }
  OpenWatch watch(address);
  grpc::health::v1::HealthCheckResponse health;
  ASSERT_TRUE(watch.reader->Read(&health));
  ASSERT_EQ(health.status(), grpc::health::v1::HealthCheckResponse::SERVING);

  v1::EndSessionResponse flushed;
  auto end_call = std::async(std::launch::async, [&] {
    return testing::endSession(*stub, "flushed", &flushed);
  });
  ASSERT_TRUE(server.waitForStderr("session flushed: EndSession: flushing", kStartTimeout))
      << server.stderrText();
  const Clock::time_point signalled = Clock::now();
  ASSERT_TRUE(server.sendSignal(SIGTERM));
  ASSERT_TRUE(watch.reader->Read(&health));
  EXPECT_EQ(health.status(), grpc::health::v1::HealthCheckResponse::NOT_SERVING);
  const double not_serving_ms = ms(signalled, Clock::now());
  {
    grpc::ClientContext context;
    testing::setDeadline(&context);
    v1::GetStatsResponse stats;
    const grpc::Status late = stub->GetStats(&context, v1::GetStatsRequest(), &stats);
    EXPECT_EQ(late.error_code(), grpc::StatusCode::UNAVAILABLE)
        << "a call after the drain began: " << late.error_message();
  }
  const grpc::Status end_status = end_call.get();
  const double flushed_ms = ms(signalled, Clock::now());
  ASSERT_TRUE(end_status.ok()) << end_status.error_message() << "\n" << server.stderrText();
  EXPECT_GT(flushed.summary().object_ids_size(), 0);
  for (auto& o : open) {
    v1::IngestResponse response;
    while (o->stream->Read(&response)) {
    }
    const grpc::Status ended = o->stream->Finish();
    EXPECT_EQ(ended.error_code(), grpc::StatusCode::UNAVAILABLE) << ended.error_message();
  }
  const double streams_ms = ms(signalled, Clock::now());
  const ProcessResult result = server.wait(std::chrono::seconds(120));
  const double exit_ms = ms(signalled, Clock::now());
  EXPECT_FALSE(result.timed_out);
  EXPECT_EQ(result.exit_code, 0) << result.err;
  std::printf("drain with 4 open streams and a flush (deadline %d ms): NOT_SERVING after %.0f ms, "
              "EndSession answered after %.0f ms, open streams ended after %.0f ms, exit after "
              "%.0f ms\n",
              kDrainMs, not_serving_ms, flushed_ms, streams_ms, exit_ms);

  std::error_code error;
  EXPECT_FALSE(std::filesystem::exists(db + "-wal", error) &&
               std::filesystem::file_size(db + "-wal", error) > 0)
      << "the WAL was checkpointed into the file";
  storage::SqliteStoreOptions read_only;
  read_only.read_only = true;
  auto store = storage::SqliteStore::open(db, read_only);
  ASSERT_TRUE(store.ok()) << store.status();
  const auto check = (*store)->check();
  ASSERT_TRUE(check.ok()) << check.status();
  EXPECT_TRUE(check->ok());
  const auto sessions = (*store)->sessions();
  ASSERT_TRUE(sessions.ok()) << sessions.status();
  ASSERT_EQ(sessions->size(), 5u);
  for (const auto& s : *sessions) {
    // Every session ended by the stop, with every frame that was acknowledged.
    EXPECT_EQ(s.state, storage::SessionState::kEnded) << s.name;
    EXPECT_EQ(s.frames, int64_t(s.name == "flushed" ? kFlushedFrames : kOpenFrames)) << s.name;
  }
}

}  // namespace
}  // namespace objdb

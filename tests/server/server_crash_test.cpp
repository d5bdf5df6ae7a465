// RELIABILITY.md R1 on the server binary: objdb-server is SIGKILLed at a random instant while a
// session streams in (or while EndSession flushes it), then restarted on the same file, several
// times over. Nothing the server reported as done may be lost: every segment it announced is
// stored, every stored model loads whole, SQLite's and the blobs' checks pass, and each killed
// session is reported ended (EndSession answered before the kill) or interrupted, never open.
#include <gtest/gtest.h>
#include <signal.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <map>
#include <random>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "storage/sqlite_store.h"
#include "tests/server/ingest_fixtures.h"
#include "tests/support/subprocess.h"
#include "tests/support/temp_dir.h"

namespace objdb {
namespace {

using testing::ChildProcess;

const std::string kServer = OBJDB_SERVER_BINARY;
constexpr auto kStartTimeout = std::chrono::seconds(30);

std::unique_ptr<v1::ObjectDatabase::Stub> stubAt(const std::string& address) {
  return v1::ObjectDatabase::NewStub(
      grpc::CreateChannel(address, grpc::InsecureChannelCredentials()));
}

TEST(ObjdbServerCrash, KilledWhileStreamingLosesNothingItReported) {
  testing::TempDir dir;
  const std::string db = (dir / "objects.sqlite").string();
  const std::vector<std::string> command = {kServer, "--listen", "127.0.0.1:0", "--db", db};
  std::mt19937 rng(20261130);
  // A session (40 Tango frames, then EndSession) takes about a second here: some kills land in
  // the stream, some in EndSession, some after it.
  std::uniform_int_distribution<int> kill_after_ms(0, 2000);
  testing::twoBoxes();  // rendered before the clock starts
  constexpr int kTrials = 6;
  std::vector<std::pair<std::string, uint32_t>> announced;  // (session, label) of SegmentExtracted
  std::vector<uint64_t> objects;  // object ids of the EndSession answers
  std::map<std::string, bool> ended;  // session → its EndSession answered OK before the kill
  for (int trial = 0; trial < kTrials; ++trial) {
    ChildProcess server(command);
    ASSERT_TRUE(server.started());
    ASSERT_TRUE(server.waitForStderr("listening on 127.0.0.1:", kStartTimeout))
        << server.stderrText();
    const std::string address = testing::listeningAddress(server.stderrText());
    ASSERT_FALSE(address.empty()) << server.stderrText();
    const std::string name = "trial" + std::to_string(trial);
    auto stub = stubAt(address);
    testing::IngestResult streamed;
    bool end_ok = false;
    std::thread client([&] {
      streamed = testing::ingest(*stub, testing::session(name, 40));
      if (!streamed.status.ok()) return;
      v1::EndSessionResponse response;
      end_ok = testing::endSession(*stub, name, &response).ok();
      if (end_ok) objects.insert(objects.end(), response.summary().object_ids().begin(),
                                 response.summary().object_ids().end());
    });
    std::this_thread::sleep_for(std::chrono::milliseconds(kill_after_ms(rng)));
    server.sendSignal(SIGKILL);
    client.join();
    const testing::ProcessResult killed = server.wait(std::chrono::seconds(10));
    EXPECT_EQ(killed.term_signal, SIGKILL);
    for (const auto& r : streamed.responses) {
      if (r.has_segment()) announced.emplace_back(name, r.segment().gsm_label());
    }
    ended[name] = end_ok;
  }

  // A last start on the file: it serves, and every killed session is ended or interrupted.
  {
    ChildProcess server(command);
    ASSERT_TRUE(server.waitForStderr("listening on 127.0.0.1:", kStartTimeout))
        << server.stderrText();
    auto stub = stubAt(testing::listeningAddress(server.stderrText()));
    grpc::ClientContext context;
    testing::setDeadline(&context);
    v1::ListSessionsResponse sessions;
    const grpc::Status listed = stub->ListSessions(&context, v1::ListSessionsRequest(), &sessions);
    ASSERT_TRUE(listed.ok()) << listed.error_message();
    size_t seen = 0;
    for (const auto& s : sessions.sessions()) {
      if (!ended.count(s.session_name())) continue;
      ++seen;
      const v1::SessionState want =
          ended[s.session_name()] ? v1::SESSION_STATE_ENDED : v1::SESSION_STATE_INTERRUPTED;
      EXPECT_EQ(s.state(), want) << s.session_name();
      if (want == v1::SESSION_STATE_INTERRUPTED) {
        v1::EndSessionResponse response;
        const grpc::Status end = testing::endSession(*stub, s.session_name(), &response);
        EXPECT_EQ(end.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << end.error_message();
      }
    }
    // A session killed before its header was stored may be missing; none may be extra.
    EXPECT_LE(seen, size_t(kTrials));
    EXPECT_EQ(size_t(sessions.sessions_size()), seen);
    server.sendSignal(SIGTERM);
    EXPECT_EQ(server.wait(std::chrono::seconds(30)).exit_code, 0);
  }

  auto store = storage::SqliteStore::open(db).value();
  const storage::CheckReport report = store->check().value();
  EXPECT_TRUE(report.ok()) << report.sqlite_findings.size() << " SQLite findings, "
                           << report.damaged.size() << " damaged blobs";
  for (const auto& [session, label] : announced) {
    EXPECT_TRUE(store->rawSegment({session, label}).ok()) << session << "/" << label;
  }
  const std::vector<int64_t> ids = store->modelIds().value();
  for (int64_t id : ids) EXPECT_TRUE(store->model(id).ok()) << "model " << id;
  for (uint64_t id : objects) {
    EXPECT_TRUE(std::count(ids.begin(), ids.end(), int64_t(id)) == 1) << "object " << id;
  }
  std::printf("%d kills; %zu announced segments and %zu objects of ended sessions, all stored; "
              "%zu sessions ended before the kill\n",
              kTrials, announced.size(), objects.size(),
              size_t(std::count_if(ended.begin(), ended.end(), [](const auto& e) { return e.second; })));
}

}  // namespace
}  // namespace objdb

// Several objdb-server processes on one PostgreSQL database: server B runs throughout;
// in each of 20 trials a server A starts, A and B each take a stream at the same time, and A is
// SIGKILLed while its stream runs (after a random number of acks) or after its EndSession
// answered. B must take A's interrupted session over once A's lease expires (end it from its
// saved map, as a restarted server would), while it goes on serving its own. Nothing reported is
// lost: every raw segment A announced is stored, every object of an answered EndSession is
// stored, no segment is held by two models (no insert ran twice), no session is left open, and
// the database's checks pass.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <signal.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <map>
#include <mutex>
#include <random>
#include <set>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "storage/postgres/postgres_store.h"
#include "tests/server/ingest_fixtures.h"
#include "tests/server/stored_objects.h"
#include "tests/support/postgres_test_cluster.h"
#include "tests/support/subprocess.h"

namespace objdb {
namespace {

using testing::ChildProcess;

const std::string kServer = OBJDB_SERVER_BINARY;
constexpr auto kStartTimeout = std::chrono::seconds(60);
constexpr int kTrials = 20;

std::unique_ptr<v1::ObjectDatabase::Stub> stubAt(const std::string& address) {
  return v1::ObjectDatabase::NewStub(
      grpc::CreateChannel(address, grpc::InsecureChannelCredentials()));
}

std::vector<std::string> serverCommand(const std::string& uri, const std::string& id) {
  return {kServer,     "--listen", "127.0.0.1:0", "--db",        uri, "--server-id",
          id,          "--lease-s", "0.6",         "--save-map-s", "0.05"};
}

// What one client saw of its stream and its EndSession.
struct ClientLog {
  std::mutex mutex;
  std::condition_variable changed;
  int acks = 0;
  bool end_sent = false, end_answered = false, done = false;
  std::set<uint32_t> segments;      // GSM labels of the SegmentExtracted events
  std::vector<uint64_t> objects;    // of the answered EndSession
};

// Streams session `name` to `stub`, then ends it; fills `log` as it goes.
void runClient(v1::ObjectDatabase::Stub* stub, const std::string& name, size_t frames,
               ClientLog* log) {
  grpc::ClientContext context;
  testing::setDeadline(&context);
  auto stream = stub->Ingest(&context);
  std::thread reader([&] {
    v1::IngestResponse response;
    while (stream->Read(&response)) {
      std::lock_guard lock(log->mutex);
      log->acks += response.has_ack() ? 1 : 0;
      if (response.has_segment()) log->segments.insert(response.segment().gsm_label());
      log->changed.notify_all();
    }
  });
  for (const auto& request : testing::session(name, frames)) {
    if (!stream->Write(request)) break;
  }
  stream->WritesDone();
  reader.join();
  if (stream->Finish().ok()) {
    {
      std::lock_guard lock(log->mutex);
      log->end_sent = true;
      log->changed.notify_all();
    }
    v1::EndSessionResponse response;
    if (testing::endSession(*stub, name, &response).ok()) {
      std::lock_guard lock(log->mutex);
      log->end_answered = true;
      log->objects.assign(response.summary().object_ids().begin(),
                          response.summary().object_ids().end());
    }
  }
  std::lock_guard lock(log->mutex);
  log->done = true;
  log->changed.notify_all();
}

// The state of session `name` as `stub` lists it (UNSPECIFIED when it is not listed).
v1::SessionState stateOf(v1::ObjectDatabase::Stub& stub, const std::string& name) {
  grpc::ClientContext context;
  testing::setDeadline(&context);
  v1::ListSessionsResponse sessions;
  if (!stub.ListSessions(&context, v1::ListSessionsRequest(), &sessions).ok()) {
    return v1::SESSION_STATE_UNSPECIFIED;
  }
  for (const auto& s : sessions.sessions()) {
    if (s.session_name() == name) return s.state();
  }
  return v1::SESSION_STATE_UNSPECIFIED;
}

TEST(ObjdbServersOnPostgres, AKilledServersSessionsAreTakenOverAndNothingReportedIsLost) {
  const auto uri = testing::freshPostgresDatabase("multi_server");
  ASSERT_TRUE(uri.ok()) << uri.status();
  ChildProcess b(serverCommand(*uri, "B"));
  ASSERT_TRUE(b.started());
  ASSERT_TRUE(b.waitForStderr("listening on 127.0.0.1:", kStartTimeout)) << b.stderrText();
  auto stub_b = stubAt(testing::listeningAddress(b.stderrText()));

  const testing::Recording& recording = testing::twoBoxes();
  const size_t frames = recording.depth.size();
  std::mt19937 rng(20261204);
  std::uniform_int_distribution<int> ack(1, int(frames) - 1);
  std::map<std::string, std::set<uint32_t>> reported;  // session → segments A announced
  std::vector<uint64_t> objects;                       // of answered EndSessions (A's and B's)
  std::vector<std::string> killed_streaming, killed_after_end;
  int taken_over = 0;  // A's sessions B ended from their saved maps
  for (int trial = 0; trial < kTrials; ++trial) {
    // A new server A each time, with a name of its own (as a new process would have).
    ChildProcess a(serverCommand(*uri, "A" + std::to_string(trial)));
    ASSERT_TRUE(a.started());
    ASSERT_TRUE(a.waitForStderr("listening on 127.0.0.1:", kStartTimeout)) << a.stderrText();
    auto stub_a = stubAt(testing::listeningAddress(a.stderrText()));
    const std::string on_a = "a" + std::to_string(trial), on_b = "b" + std::to_string(trial);
    const bool kill_streaming = trial % 4 != 3;  // three in four while streaming
    const int kill_at_ack = ack(rng);
    ClientLog log_a, log_b;
    std::thread client_a(runClient, stub_a.get(), on_a, frames, &log_a);
    std::thread client_b(runClient, stub_b.get(), on_b, frames, &log_b);
    // Both servers' logs are read while waiting (a child blocks on a full pipe).
    const auto kill_due = [&] {
      return kill_streaming ? log_a.acks >= kill_at_ack || log_a.done : log_a.done;
    };
    bool too_late = false, unanswered = false;
    {
      const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
      std::unique_lock lock(log_a.mutex);
      while (!kill_due() && std::chrono::steady_clock::now() < deadline) {
        lock.unlock();
        a.collect(std::chrono::milliseconds(5));
        b.collect(std::chrono::milliseconds(5));
        lock.lock();
      }
      too_late = kill_streaming && log_a.end_sent;
      unanswered = !kill_streaming && !log_a.end_answered;
    }
    a.sendSignal(SIGKILL);
    client_a.join();
    while (true) {
      {
        std::lock_guard lock(log_b.mutex);
        if (log_b.done) break;
      }
      b.collect(std::chrono::milliseconds(10));
    }
    client_b.join();
    ASSERT_FALSE(too_late) << "the kill came too late for this trial";
    ASSERT_FALSE(unanswered) << "A's EndSession of " << on_a << " failed";
    EXPECT_EQ(a.wait(std::chrono::seconds(10)).term_signal, SIGKILL);
    ASSERT_TRUE(log_b.end_answered) << "B's own session " << on_b << " did not end";
    objects.insert(objects.end(), log_b.objects.begin(), log_b.objects.end());
    objects.insert(objects.end(), log_a.objects.begin(), log_a.objects.end());
    reported[on_a] = log_a.segments;
    (kill_streaming ? killed_streaming : killed_after_end).push_back(on_a);

    // B takes A's session over once its lease expires (0.6 s): it is interrupted, not open.
    if (kill_streaming) {
      v1::SessionState state = v1::SESSION_STATE_UNSPECIFIED;
      const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
      while (std::chrono::steady_clock::now() < deadline) {
        state = stateOf(*stub_b, on_a);
        if (state == v1::SESSION_STATE_INTERRUPTED) break;
        b.collect(std::chrono::milliseconds(50));
      }
      ASSERT_EQ(state, v1::SESSION_STATE_INTERRUPTED)
          << on_a << " was not taken over by B: " << b.stderrText();
      v1::EndSessionResponse response;
      grpc::Status end;
      for (int attempt = 0; attempt < 1000; ++attempt) {  // UNAVAILABLE while being recovered
        end = testing::endSession(*stub_b, on_a, &response);
        if (end.error_code() != grpc::StatusCode::UNAVAILABLE) break;
        b.collect(std::chrono::milliseconds(20));
      }
      EXPECT_EQ(end.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << end.error_message();
      if (end.error_message().find("saved after") != std::string::npos) ++taken_over;
    } else {
      EXPECT_EQ(stateOf(*stub_b, on_a), v1::SESSION_STATE_ENDED) << on_a;
    }
  }
  b.sendSignal(SIGTERM);
  EXPECT_EQ(b.wait(std::chrono::seconds(60)).exit_code, 0) << b.stderrText();

  auto store = storage::PostgresStore::open(*uri).value();
  const storage::CheckReport report = store->check().value();
  EXPECT_TRUE(report.ok()) << report.engine_findings.size() << " engine findings, "
                           << report.damaged.size() << " damaged blobs";
  const std::vector<storage::SessionInfo> stored = store->sessions().value();
  for (const auto& s : stored) {
    EXPECT_NE(s.state, storage::SessionState::kOpen) << s.name << " was left open";
  }
  const std::vector<int64_t> ids = store->modelIds().value();
  for (int64_t id : ids) EXPECT_TRUE(store->model(id).ok()) << "model " << id;
  // Every segment A announced is stored.
  size_t segments = 0;
  for (const auto& [session, labels] : reported) {
    for (uint32_t label : labels) {
      EXPECT_TRUE(store->rawSegmentId({session, label}).ok()) << session << "/" << label;
      ++segments;
    }
  }
  // No segment is held by two models: no insert ran twice.
  storage::ModelQuery all;  // active models (merged ones have no observations left)
  all.limit = 1000000;
  std::map<std::pair<std::string, uint32_t>, int> holders;
  const std::vector<storage::ModelSummary> summaries = store->modelSummaries(all).value();
  for (const auto& m : summaries) {
    for (const auto& o : m.observations) ++holders[{o.session, o.label}];
  }
  for (const auto& [key, count] : holders) {
    EXPECT_EQ(count, 1) << key.first << "/" << key.second << " is held by " << count
                        << " models";
  }
  // An object of an answered EndSession is stored: active, or joined into another object later
  // (state merged), whose chain ends at an active one.
  EXPECT_THAT(testing::objectsNotHeld(*store, objects), ::testing::IsEmpty());
  ASSERT_FALSE(objects.empty());
  EXPECT_GT(taken_over, 0) << "B ended none of A's sessions from a saved map";
  std::printf("%d kills of server A (%zu while streaming, %zu after EndSession); B took over %d "
              "sessions from their saved maps; %zu segments A announced and %zu objects of "
              "answered EndSessions, all stored; %zu segments held, each by one model\n",
              kTrials, killed_streaming.size(), killed_after_end.size(), taken_over, segments,
              objects.size(), holders.size());
}

}  // namespace
}  // namespace objdb

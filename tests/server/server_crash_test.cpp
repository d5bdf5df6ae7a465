// Crash safety of the server binary: objdb-server is SIGKILLed while a session streams in
// (after a random number of acks), while EndSession flushes it, or after EndSession answered,
// then restarted on the same file, eight times over. Nothing the server reported as done may be
// lost: every object of an answered EndSession is stored, every stored model loads whole,
// SQLite's and the blobs' checks pass, and each killed session is reported ended (EndSession
// answered) or interrupted (killed while streaming), never open. The server saves open
// sessions' maps every 50 ms, so kills also land during saves, and a session killed after a
// save is ended from its saved map at the next start. A session killed so and resumed builds the
// database of one uninterrupted stream.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <signal.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <cstdio>
#include <map>
#include <random>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "storage/sqlite/sqlite_store.h"
#include "tests/server/ingest_fixtures.h"
#include "tests/server/stored_objects.h"
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

// When a trial's SIGKILL lands.
enum class Phase {
  kStreaming,    // after the k-th ack was read: EndSession never sent
  kFlushing,     // right after EndSession was sent: its answer may or may not have been committed
  kAfterEnding,  // after EndSession answered
};

TEST(ObjdbServerCrash, KilledWhileStreamingLosesNothingItReported) {
  testing::TempDir dir;
  const std::string db = (dir / "objects.sqlite").string();
  const std::vector<std::string> command = {kServer, "--listen", "127.0.0.1:0", "--db", db,
                                            "--save-map-s", "0.05"};
  const testing::Recording& recording = testing::twoBoxes();
  std::mt19937 rng(20261130);
  std::uniform_int_distribution<int> ack(1, int(recording.depth.size()) - 1);
  std::uniform_int_distribution<int> flush_ms(0, 150);
  const std::vector<Phase> phases = {Phase::kStreaming,   Phase::kFlushing, Phase::kAfterEnding,
                                     Phase::kStreaming,   Phase::kFlushing, Phase::kAfterEnding,
                                     Phase::kStreaming,   Phase::kFlushing};
  std::vector<uint64_t> objects;  // object ids of the EndSession answers
  std::map<std::string, Phase> killed;
  std::map<std::string, bool> answered;  // its EndSession answered OK before the kill
  int recovered = 0;  // interrupted sessions ended from their saved maps at a restart
  for (size_t trial = 0; trial < phases.size(); ++trial) {
    ChildProcess server(command);
    ASSERT_TRUE(server.started());
    ASSERT_TRUE(server.waitForStderr("listening on 127.0.0.1:", kStartTimeout))
        << server.stderrText();
    const std::string address = testing::listeningAddress(server.stderrText());
    ASSERT_FALSE(address.empty()) << server.stderrText();
    const std::string name = "trial" + std::to_string(trial);
    auto stub = stubAt(address);
    const int kill_at_ack = ack(rng);
    std::mutex mutex;
    std::condition_variable changed;
    int acks = 0;
    bool end_sent = false, end_answered = false, done = false;
    std::thread client([&] {
      // Stream, then EndSession; the main thread kills the server at the trial's phase.
      grpc::ClientContext context;
      testing::setDeadline(&context);
      auto stream = stub->Ingest(&context);
      std::thread reader([&] {
        v1::IngestResponse response;
        while (stream->Read(&response)) {
          std::lock_guard lock(mutex);
          acks += response.has_ack() ? 1 : 0;
          changed.notify_all();
        }
      });
      for (const auto& request : testing::session(name, recording.depth.size())) {
        if (!stream->Write(request)) break;
      }
      stream->WritesDone();
      reader.join();
      if (stream->Finish().ok()) {
        {
          std::lock_guard lock(mutex);
          end_sent = true;
          changed.notify_all();
        }
        v1::EndSessionResponse response;
        if (testing::endSession(*stub, name, &response).ok()) {
          std::lock_guard lock(mutex);
          end_answered = true;
          objects.insert(objects.end(), response.summary().object_ids().begin(),
                         response.summary().object_ids().end());
        }
      }
      std::lock_guard lock(mutex);
      done = true;
      changed.notify_all();
    });
    {
      std::unique_lock lock(mutex);
      const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
      switch (phases[trial]) {
        case Phase::kStreaming:
          changed.wait_until(lock, deadline, [&] { return acks >= kill_at_ack || done; });
          ASSERT_FALSE(end_sent) << "the kill came too late for this phase";
          break;
        case Phase::kFlushing:
          changed.wait_until(lock, deadline, [&] { return end_sent || done; });
          ASSERT_TRUE(end_sent);
          lock.unlock();
          std::this_thread::sleep_for(std::chrono::milliseconds(flush_ms(rng)));
          lock.lock();
          break;
        case Phase::kAfterEnding:
          changed.wait_until(lock, deadline, [&] { return done; });
          ASSERT_TRUE(end_answered);
          break;
      }
    }
    server.sendSignal(SIGKILL);
    client.join();
    EXPECT_EQ(server.wait(std::chrono::seconds(10)).term_signal, SIGKILL);
    killed[name] = phases[trial];
    answered[name] = end_answered;
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
    // Every session was stored before its first ack, so all are listed.
    ASSERT_EQ(size_t(sessions.sessions_size()), phases.size());
    for (const auto& s : sessions.sessions()) {
      // (Ended from its saved map at a start: listed before or after its recovery ran.)
      const std::string& name = s.session_name();
      ASSERT_TRUE(killed.count(name)) << name;
      if (answered[name]) {
        EXPECT_EQ(s.state(), v1::SESSION_STATE_ENDED) << name;
      } else if (killed[name] == Phase::kStreaming) {
        EXPECT_EQ(s.state(), v1::SESSION_STATE_INTERRUPTED) << name;
      } else {  // killed while flushing: committed as ended, or not at all
        EXPECT_TRUE(s.state() == v1::SESSION_STATE_ENDED ||
                    s.state() == v1::SESSION_STATE_INTERRUPTED)
            << name << " " << v1::SessionState_Name(s.state());
      }
      if (s.state() == v1::SESSION_STATE_INTERRUPTED) {
        v1::EndSessionResponse response;
        grpc::Status end;
        for (int attempt = 0; attempt < 500; ++attempt) {  // UNAVAILABLE while being recovered
          end = testing::endSession(*stub, name, &response);
          if (end.error_code() != grpc::StatusCode::UNAVAILABLE) break;
          std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
        EXPECT_EQ(end.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << end.error_message();
        if (end.error_message().find("saved after") != std::string::npos) ++recovered;
      }
    }
    server.sendSignal(SIGTERM);
    EXPECT_EQ(server.wait(std::chrono::seconds(30)).exit_code, 0);
  }

  auto store = storage::SqliteStore::open(db).value();
  const storage::CheckReport report = store->check().value();
  EXPECT_TRUE(report.ok()) << report.engine_findings.size() << " SQLite findings, "
                           << report.damaged.size() << " damaged blobs";
  const std::vector<int64_t> ids = store->modelIds().value();
  for (int64_t id : ids) EXPECT_TRUE(store->model(id).ok()) << "model " << id;
  // An object a session reported is stored: active, or joined into another object later
  // (state merged), whose chain ends at an active one.
  EXPECT_THAT(testing::objectsNotHeld(*store, objects), ::testing::IsEmpty());
  ASSERT_FALSE(objects.empty());
  EXPECT_GT(recovered, 0) << "no killed session was ended from a saved map";
  std::printf("%zu kills; %zu objects of answered EndSessions, all stored; %d sessions ended "
              "from their saved maps\n",
              phases.size(), objects.size(), recovered);
}

// The address a started objdb-server child listens on ("" when it did not start).
std::string addressOf(ChildProcess& server) {
  if (!server.started() || !server.waitForStderr("listening on 127.0.0.1:", kStartTimeout)) {
    return "";
  }
  return testing::listeningAddress(server.stderrText());
}

// A session whose server is SIGKILLed mid-stream is resumed at the next start: the map went with
// the server, so the session continues from its first frame (its segments, inserted before the
// kill or from its saved map at the start, withdrawn) and the database is the one an
// uninterrupted stream builds.
TEST(ObjdbServerCrash, AResumeAfterAKillBuildsTheDatabaseOfOneUninterruptedStream) {
  testing::TempDir dir;
  const testing::Recording& recording = testing::twoBoxes();
  const size_t frames = recording.depth.size();
  constexpr size_t kKilledAfter = 17;
  ASSERT_GT(frames, kKilledAfter);
  auto command = [](const std::string& db) {
    return std::vector<std::string>{kServer, "--listen", "127.0.0.1:0", "--db", db,
                                    "--save-map-s", "0.05"};
  };
  auto endAndStop = [](ChildProcess& server, v1::ObjectDatabase::Stub& stub) {
    v1::EndSessionResponse ended;
    const grpc::Status end = testing::endSession(stub, "kitchen", &ended);
    EXPECT_TRUE(end.ok()) << end.error_message();
    EXPECT_EQ(ended.summary().counters().frames_integrated(), testing::twoBoxes().depth.size());
    server.sendSignal(SIGTERM);
    EXPECT_EQ(server.wait(std::chrono::seconds(30)).exit_code, 0) << server.stderrText();
  };

  const std::string whole_db = (dir / "whole.sqlite").string();
  {
    ChildProcess server(command(whole_db));
    const std::string address = addressOf(server);
    ASSERT_FALSE(address.empty()) << server.stderrText();
    auto stub = stubAt(address);
    const testing::IngestResult all = testing::ingest(*stub, testing::session("kitchen", frames));
    ASSERT_TRUE(all.status.ok()) << all.status.error_message();
    endAndStop(server, *stub);
  }

  const std::string db = (dir / "killed.sqlite").string();
  {
    ChildProcess server(command(db));
    const std::string address = addressOf(server);
    ASSERT_FALSE(address.empty()) << server.stderrText();
    auto stub = stubAt(address);
    grpc::ClientContext context;
    testing::setDeadline(&context);
    auto call = stub->Ingest(&context);
    const std::vector<v1::IngestRequest> requests = testing::session("kitchen", kKilledAfter);
    for (const auto& request : requests) ASSERT_TRUE(call->Write(request));
    v1::IngestResponse response;
    for (size_t acked = 0; acked < kKilledAfter;) {
      ASSERT_TRUE(call->Read(&response)) << server.stderrText();
      acked += response.has_ack() ? 1 : 0;
    }
    server.collect(std::chrono::milliseconds(300));  // (a map save may land meanwhile)
    server.sendSignal(SIGKILL);
    EXPECT_EQ(server.wait(std::chrono::seconds(10)).term_signal, SIGKILL);
    EXPECT_FALSE(call->Finish().ok());
  }

  ChildProcess server(command(db));
  const std::string address = addressOf(server);
  ASSERT_FALSE(address.empty()) << server.stderrText();
  auto stub = stubAt(address);
  std::vector<v1::IngestRequest> requests = testing::session("kitchen", frames);
  requests.front().mutable_header()->set_if_exists(v1::SessionHeader::IF_EXISTS_RESUME);
  testing::IngestResult resumed;
  for (int attempt = 0; attempt < 500; ++attempt) {  // UNAVAILABLE while ended from a saved map
    resumed = testing::ingest(*stub, requests);
    if (resumed.status.error_code() != grpc::StatusCode::UNAVAILABLE) break;
    server.collect(std::chrono::milliseconds(20));
  }
  ASSERT_TRUE(resumed.status.ok()) << resumed.status.error_message() << server.stderrText();
  ASSERT_FALSE(resumed.responses.empty());
  ASSERT_TRUE(resumed.responses.front().has_opened());
  const v1::SessionOpened& opened = resumed.responses.front().opened();
  EXPECT_TRUE(opened.resumed());
  EXPECT_TRUE(opened.replaced());
  EXPECT_FALSE(opened.has_frames());
  EXPECT_EQ(resumed.acks().size(), frames);
  const bool from_saved_map = server.stderrText().find("ended from its saved map") !=
                              std::string::npos;
  endAndStop(server, *stub);

  const auto expected = testing::activeModels(*storage::SqliteStore::open(whole_db).value());
  ASSERT_FALSE(expected.empty());
  EXPECT_EQ(testing::activeModels(*storage::SqliteStore::open(db).value()), expected);
  std::printf("killed after %zu of %zu frames (%s); resumed from the first frame, %llu segments "
              "withdrawn; the same %zu active models\n",
              kKilledAfter, frames, from_saved_map ? "ended from its saved map at the start"
                                                   : "no saved map",
              (unsigned long long)opened.segments_withdrawn(), expected.size());
}

}  // namespace
}  // namespace objdb

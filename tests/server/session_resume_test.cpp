// Sessions whose name is in use (SessionHeader.if_exists): a stream that broke is resumed from
// the first frame its map does not hold and builds the database one uninterrupted stream builds;
// an ended session is replaced (its segments withdrawn) but never resumed; a name in use is
// refused naming both options; a session that never received a frame is not kept. A session's
// counters and client survive a restart, and counters a crash lost read as unknown, not zero.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include "objdb/v1/objdb.grpc.pb.h"
#include "server/server.h"
#include "storage/sqlite/sqlite_store.h"
#include "storage/store.h"
#include "tests/server/ingest_fixtures.h"
#include "tests/server/loopback_server.h"
#include "tests/server/stored_objects.h"

namespace objdb {
namespace {

using testing::endSession;
using testing::frame;
using testing::header;
using testing::ingest;
using testing::IngestResult;
using testing::loopbackOptions;
using testing::Recording;
using testing::scratchDbPath;
using testing::session;
using testing::setDeadline;
using testing::startOrDie;
using testing::twoBoxes;

constexpr size_t kFrames = 40;

// Every segment is extracted after the frame that makes it idle, whatever the database's pace:
// the same inserts in the same order on every run.
ServerOptions deterministicOptions() {
  ServerOptions options = loopbackOptions(scratchDbPath());
  options.segment_queue = 100000;
  return options;
}

std::unique_ptr<v1::ObjectDatabase::Stub> stubFor(const ObjdbServer& server) {
  return v1::ObjectDatabase::NewStub(
      grpc::CreateChannel(server.address(), grpc::InsecureChannelCredentials()));
}

v1::IngestRequest headerFor(const std::string& name, v1::SessionHeader::IfExists if_exists) {
  v1::IngestRequest request = header(name, twoBoxes().intrinsics);
  request.mutable_header()->set_if_exists(if_exists);
  return request;
}

// Frames [first, last) of the recording after `head`.
std::vector<v1::IngestRequest> stream(const v1::IngestRequest& head, size_t first, size_t last) {
  std::vector<v1::IngestRequest> requests = {head};
  for (size_t k = first; k < last; ++k) requests.push_back(frame(twoBoxes(), k));
  return requests;
}

const v1::SessionOpened* openedOf(const IngestResult& result) {
  if (result.responses.empty() || !result.responses.front().has_opened()) return nullptr;
  return &result.responses.front().opened();
}

// What a database holds, to compare two of them: each model's state, points, poses (session
// without any ".replaced-" suffix, label) and merges, in id order.
std::vector<std::string> contents(ObjdbServer& server) {
  storage::ModelQuery query;
  query.limit = 100000;
  query.include_merged = true;
  auto models = server.store().modelSummaries(query);
  EXPECT_TRUE(models.ok()) << models.status();
  std::vector<std::string> out;
  if (!models.ok()) return out;
  for (const auto& m : *models) {
    std::string line = std::to_string(m.id) + " " + m.state + " " +
                       std::to_string(m.num_points) + " merges " + std::to_string(m.merges);
    for (const auto& pose : m.observations) {
      line += " " + pose.session + "/" + std::to_string(pose.label);
    }
    out.push_back(line);
  }
  return out;
}

std::vector<v1::SessionInfo> sessions(v1::ObjectDatabase::Stub& stub) {
  grpc::ClientContext context;
  setDeadline(&context);
  v1::ListSessionsResponse response;
  const grpc::Status status = stub.ListSessions(&context, v1::ListSessionsRequest(), &response);
  EXPECT_TRUE(status.ok()) << status.error_message();
  return {response.sessions().begin(), response.sessions().end()};
}

// A server that took every frame of session `name` in one uninterrupted stream and ended it
// (`ended`: EndSession's answer); null after a test failure naming why.
std::unique_ptr<ObjdbServer> uninterrupted(const std::string& name,
                                           v1::EndSessionResponse* ended) {
  auto server = startOrDie(deterministicOptions());
  if (server == nullptr) return nullptr;
  auto stub = stubFor(*server);
  const IngestResult streamed = ingest(*stub, session(name, kFrames));
  const grpc::Status end = streamed.status.ok() ? endSession(*stub, name, ended) : streamed.status;
  if (!end.ok()) {
    ADD_FAILURE() << "session " << name << ": " << end.error_message();
    return nullptr;
  }
  return server;
}

// Streams frames [0, frames) of `name` and cancels the call once all are acknowledged, as a
// killed client does; returns once the server no longer streams it (a resume is accepted).
void streamAndKill(v1::ObjectDatabase::Stub& stub, const std::string& name, size_t frames) {
  grpc::ClientContext context;
  setDeadline(&context);
  auto call = stub.Ingest(&context);
  ASSERT_TRUE(call->Write(headerFor(name, v1::SessionHeader::IF_EXISTS_REFUSE)));
  for (size_t k = 0; k < frames; ++k) ASSERT_TRUE(call->Write(frame(twoBoxes(), k)));
  v1::IngestResponse response;
  for (size_t acked = 0; acked < frames;) {
    ASSERT_TRUE(call->Read(&response));
    acked += response.has_ack() ? 1 : 0;
  }
  context.TryCancel();
  EXPECT_FALSE(call->Finish().ok());
}

// Resumes `name` with frames [first, kFrames), retrying while the server has not yet seen the
// old stream break (FAILED_PRECONDITION "still has an Ingest stream").
IngestResult resume(v1::ObjectDatabase::Stub& stub, const std::string& name, size_t first) {
  IngestResult result;
  for (int attempt = 0; attempt < 300; ++attempt) {
    result = ingest(stub, stream(headerFor(name, v1::SessionHeader::IF_EXISTS_RESUME), first,
                                 kFrames));
    if (result.status.error_message().find("still has an Ingest stream") == std::string::npos) {
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return result;
}

TEST(SessionResume, AResumedSessionBuildsTheDatabaseOfOneUninterruptedStream) {
  // One stream of every frame.
  auto whole = startOrDie(deterministicOptions());
  ASSERT_NE(whole, nullptr);
  auto whole_stub = stubFor(*whole);
  const IngestResult one = ingest(*whole_stub, session("kitchen", kFrames));
  ASSERT_TRUE(one.status.ok()) << one.status.error_message();
  ASSERT_NE(openedOf(one), nullptr);
  EXPECT_FALSE(openedOf(one)->resumed());
  v1::EndSessionResponse whole_end;
  ASSERT_TRUE(endSession(*whole_stub, "kitchen", &whole_end).ok());

  // The client is killed after 17 frames, then resumed: it is told the map holds frames up to
  // 16, and sends the rest.
  auto broken = startOrDie(deterministicOptions());
  ASSERT_NE(broken, nullptr);
  auto stub = stubFor(*broken);
  streamAndKill(*stub, "kitchen", 17);
  const IngestResult rest = resume(*stub, "kitchen", 17);
  ASSERT_TRUE(rest.status.ok()) << rest.status.error_message();
  const v1::SessionOpened* opened = openedOf(rest);
  ASSERT_NE(opened, nullptr);
  EXPECT_TRUE(opened->resumed());
  EXPECT_TRUE(opened->has_frames());
  EXPECT_EQ(opened->last_frame_index(), 16u);
  EXPECT_EQ(opened->counters().frames_integrated(), 17u);
  const std::vector<v1::FrameAck> acks = rest.acks();
  ASSERT_EQ(acks.size(), kFrames - 17);
  for (const auto& ack : acks) EXPECT_TRUE(ack.accepted()) << ack.reason();
  EXPECT_EQ(acks.front().index(), 17u);
  EXPECT_EQ(acks.back().session().frames_integrated(), kFrames);
  v1::EndSessionResponse ended;
  ASSERT_TRUE(endSession(*stub, "kitchen", &ended).ok());
  EXPECT_EQ(ended.summary().counters().frames_integrated(), kFrames);

  // The same database: models, points, poses and merges.
  const std::vector<std::string> expected = contents(*whole);
  ASSERT_FALSE(expected.empty());
  EXPECT_EQ(contents(*broken), expected);
  EXPECT_EQ(ended.summary().object_ids_size(), whole_end.summary().object_ids_size());

  // A frame the map holds already is rejected like any frame out of order; once ended, the
  // session cannot be resumed, and the error names --replace.
  const IngestResult ended_resume = ingest(
      *stub, stream(headerFor("kitchen", v1::SessionHeader::IF_EXISTS_RESUME), 0, 1));
  EXPECT_EQ(ended_resume.status.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(ended_resume.status.error_message().find("has ended"), std::string::npos)
      << ended_resume.status.error_message();
  EXPECT_NE(ended_resume.status.error_message().find("--replace"), std::string::npos)
      << ended_resume.status.error_message();
}

// A graceful stop ends every session with all its acknowledged frames: a resume after it is
// refused naming --replace, and the replacement builds the database of one uninterrupted stream.
// (A resume after a crash streams the session again: server_crash_test.cpp.)
TEST(SessionResume, AfterAServerStopAResumeIsRefusedAndAReplaceBuildsTheSameDatabase) {
  v1::EndSessionResponse whole_end;
  const auto whole = uninterrupted("kitchen", &whole_end);
  ASSERT_NE(whole, nullptr);
  const std::vector<std::string> expected = testing::activeModels(whole->store());
  ASSERT_FALSE(expected.empty());

  // The client is killed after 17 frames, then the server stops (ending the session) and starts
  // again on the same file.
  ServerOptions options = deterministicOptions();
  options.db_path = scratchDbPath();
  {
    auto first = startOrDie(options);
    ASSERT_NE(first, nullptr);
    auto stub = stubFor(*first);
    streamAndKill(*stub, "kitchen", 17);
  }
  auto again = startOrDie(options);
  ASSERT_NE(again, nullptr);
  auto stub = stubFor(*again);
  const std::vector<v1::SessionInfo> listed = sessions(*stub);
  ASSERT_EQ(listed.size(), 1u);
  EXPECT_EQ(listed[0].state(), v1::SESSION_STATE_ENDED);
  EXPECT_EQ(listed[0].counters().frames_integrated(), 17u);
  ASSERT_NE(testing::activeModels(again->store()), std::vector<std::string>())
      << "the stop inserted nothing of the 17 frames";

  const IngestResult refused = resume(*stub, "kitchen", 0);
  EXPECT_EQ(refused.status.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(refused.status.error_message().find("a server stop ended it"), std::string::npos)
      << refused.status.error_message();
  EXPECT_NE(refused.status.error_message().find("--replace"), std::string::npos)
      << refused.status.error_message();

  const IngestResult replaced =
      ingest(*stub, stream(headerFor("kitchen", v1::SessionHeader::IF_EXISTS_REPLACE), 0, kFrames));
  ASSERT_TRUE(replaced.status.ok()) << replaced.status.error_message();
  ASSERT_NE(openedOf(replaced), nullptr);
  EXPECT_TRUE(openedOf(replaced)->replaced());
  EXPECT_GT(openedOf(replaced)->segments_withdrawn(), 0u);
  v1::EndSessionResponse ended;
  ASSERT_TRUE(endSession(*stub, "kitchen", &ended).ok());
  EXPECT_EQ(ended.summary().counters().frames_integrated(), kFrames);
  EXPECT_EQ(testing::activeModels(again->store()), expected);
}

TEST(SessionResume, AResumeSendingAFrameTheMapHoldsGetsItRejectedAndCarriesOn) {
  auto server = startOrDie(deterministicOptions());
  ASSERT_NE(server, nullptr);
  auto stub = stubFor(*server);
  streamAndKill(*stub, "hall", 5);
  const IngestResult again = resume(*stub, "hall", 4);  // frame 4 once more, then 5..
  ASSERT_TRUE(again.status.ok()) << again.status.error_message();
  const std::vector<v1::FrameAck> acks = again.acks();
  ASSERT_EQ(acks.size(), kFrames - 4);
  EXPECT_FALSE(acks[0].accepted());
  EXPECT_NE(acks[0].reason().find("frame.index 4 is not above the previous frame's 4"),
            std::string::npos)
      << acks[0].reason();
  EXPECT_TRUE(acks[1].accepted()) << acks[1].reason();
}

TEST(SessionResume, ANameInUseIsRefusedNamingResumeReplaceAndAnotherName) {
  auto server = startOrDie(deterministicOptions());
  ASSERT_NE(server, nullptr);
  auto stub = stubFor(*server);
  ASSERT_TRUE(ingest(*stub, session("office", 3)).status.ok());
  const IngestResult again = ingest(*stub, session("office", 3));
  EXPECT_EQ(again.status.error_code(), grpc::StatusCode::ALREADY_EXISTS);
  for (const char* option : {"--resume", "--replace", "--session"}) {
    EXPECT_NE(again.status.error_message().find(option), std::string::npos)
        << again.status.error_message();
  }
  // Another camera is not the same session.
  v1::IngestRequest other = headerFor("office", v1::SessionHeader::IF_EXISTS_RESUME);
  other.mutable_header()->mutable_intrinsics()->set_fx(123.0);
  const IngestResult camera = ingest(*stub, {other});
  EXPECT_EQ(camera.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(camera.status.error_message().find("header.intrinsics"), std::string::npos)
      << camera.status.error_message();
  // --resume of a name not in use opens a new session.
  const IngestResult fresh =
      ingest(*stub, stream(headerFor("attic", v1::SessionHeader::IF_EXISTS_RESUME), 0, 2));
  ASSERT_TRUE(fresh.status.ok()) << fresh.status.error_message();
  ASSERT_NE(openedOf(fresh), nullptr);
  EXPECT_FALSE(openedOf(fresh)->resumed());
  EXPECT_TRUE(fresh.everyFrameAccepted(2));
}

TEST(SessionResume, AReplacedSessionsSegmentsAreWithdrawnAndItsRecordKeptUnderANewName) {
  v1::EndSessionResponse ended;
  const auto reference = uninterrupted("lab", &ended);
  ASSERT_NE(reference, nullptr);
  const std::vector<std::string> once = contents(*reference);

  const auto server = uninterrupted("lab", &ended);
  ASSERT_NE(server, nullptr);
  auto stub = stubFor(*server);
  const size_t objects = size_t(ended.summary().object_ids_size());
  ASSERT_GT(objects, 0u);

  const IngestResult replaced =
      ingest(*stub, stream(headerFor("lab", v1::SessionHeader::IF_EXISTS_REPLACE), 0, kFrames));
  ASSERT_TRUE(replaced.status.ok()) << replaced.status.error_message();
  ASSERT_NE(openedOf(replaced), nullptr);
  EXPECT_TRUE(openedOf(replaced)->replaced());
  EXPECT_GT(openedOf(replaced)->segments_withdrawn(), 0u);
  EXPECT_TRUE(replaced.everyFrameAccepted(kFrames));
  ASSERT_TRUE(endSession(*stub, "lab", &ended).ok());
  EXPECT_EQ(size_t(ended.summary().object_ids_size()), objects);

  // Two sessions: the new "lab" and the old one's record, which no active model observes.
  const std::vector<v1::SessionInfo> listed = sessions(*stub);
  ASSERT_EQ(listed.size(), 2u);
  EXPECT_EQ(listed[1].session_name(), "lab");
  EXPECT_EQ(listed[0].session_name().rfind("lab.replaced-", 0), 0u) << listed[0].session_name();
  storage::ModelQuery query;
  query.limit = 100000;
  query.session = listed[0].session_name();
  auto old_models = server->store().modelSummaries(query);
  ASSERT_TRUE(old_models.ok()) << old_models.status();
  EXPECT_TRUE(old_models->empty());
  // The active models are those of one session alone: nothing of the old one merged in.
  query.session = "";
  auto active = server->store().modelSummaries(query);
  auto active_once = reference->store().modelSummaries(query);
  ASSERT_TRUE(active.ok() && active_once.ok());
  ASSERT_EQ(active->size(), active_once->size());
  for (size_t i = 0; i < active->size(); ++i) {
    EXPECT_EQ((*active)[i].num_points, (*active_once)[i].num_points);
    EXPECT_EQ((*active)[i].observations.size(), (*active_once)[i].observations.size());
  }
  EXPECT_FALSE(once.empty());
}

TEST(SessionResume, ASessionThatNeverReceivedAFrameIsNotKept) {
  auto server = startOrDie(deterministicOptions());
  ASSERT_NE(server, nullptr);
  auto stub = stubFor(*server);
  // The header alone, then the client goes away.
  {
    grpc::ClientContext context;
    setDeadline(&context);
    auto call = stub->Ingest(&context);
    ASSERT_TRUE(call->Write(headerFor("empty", v1::SessionHeader::IF_EXISTS_REFUSE)));
    v1::IngestResponse response;
    ASSERT_TRUE(call->Read(&response));  // the session is open
    EXPECT_TRUE(response.has_opened());
    context.TryCancel();
    EXPECT_FALSE(call->Finish().ok());
  }
  bool gone = false;
  for (int attempt = 0; attempt < 300 && !gone; ++attempt) {
    gone = sessions(*stub).empty();
    if (!gone) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_TRUE(gone);
  // Its name is free again; a header half-closed at once and ended is not kept either.
  ASSERT_TRUE(ingest(*stub, {headerFor("empty", v1::SessionHeader::IF_EXISTS_REFUSE)}).status.ok());
  v1::EndSessionResponse ended;
  const grpc::Status end = endSession(*stub, "empty", &ended);
  ASSERT_TRUE(end.ok()) << end.error_message();
  EXPECT_EQ(ended.summary().counters().frames_received(), 0u);
  EXPECT_TRUE(sessions(*stub).empty());
  // A session with frames is kept.
  ASSERT_TRUE(ingest(*stub, session("empty", 2)).status.ok());
  ASSERT_EQ(sessions(*stub).size(), 1u);
}

TEST(SessionCounters, SurviveARestartAndWhatACrashLostIsUnknownNotZero) {
  const std::string db = scratchDbPath();
  ServerOptions options = deterministicOptions();
  options.db_path = db;
  v1::SessionInfo before;
  {
    auto server = startOrDie(options);
    ASSERT_NE(server, nullptr);
    auto stub = stubFor(*server);
    ASSERT_TRUE(ingest(*stub, session("kitchen", kFrames)).status.ok());
    v1::EndSessionResponse ended;
    ASSERT_TRUE(endSession(*stub, "kitchen", &ended).ok());
    const std::vector<v1::SessionInfo> listed = sessions(*stub);
    ASSERT_EQ(listed.size(), 1u);
    before = listed[0];
    ASSERT_GT(before.counters().segments_extracted(), 0u);
  }
  // A session a crash left before anything of its counters was stored (as a server killed
  // before its first saved map leaves it).
  {
    auto store = storage::SqliteStore::open(db);
    ASSERT_TRUE(store.ok()) << store.status();
    storage::SessionInfo crashed;
    crashed.name = "crashed";
    crashed.client_info = "a client";
    ASSERT_TRUE((*store)->beginSession(crashed).ok());
    ASSERT_TRUE((*store)->finishSession("crashed", storage::SessionState::kInterrupted, 0).ok());
  }
  auto server = startOrDie(options);
  ASSERT_NE(server, nullptr);
  auto stub = stubFor(*server);
  const std::vector<v1::SessionInfo> after = sessions(*stub);
  ASSERT_EQ(after.size(), 2u);
  EXPECT_EQ(after[0].session_name(), "kitchen");
  EXPECT_FALSE(after[0].counters_unknown());
  EXPECT_EQ(after[0].client_info(), before.client_info());
  EXPECT_EQ(after[0].counters().SerializeAsString(), before.counters().SerializeAsString())
      << after[0].counters().DebugString() << " against " << before.counters().DebugString();
  EXPECT_EQ(after[1].session_name(), "crashed");
  EXPECT_TRUE(after[1].counters_unknown());
  EXPECT_EQ(after[1].client_info(), "a client");
  // EndSession of the ended session answers its stored counters too.
  v1::EndSessionResponse again;
  ASSERT_TRUE(endSession(*stub, "kitchen", &again).ok());
  EXPECT_EQ(again.summary().counters().objects_created(), before.counters().objects_created());
}

}  // namespace
}  // namespace objdb

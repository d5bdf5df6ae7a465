// `objdb stream` and `objdb remote` against a loopback server: two sessions of the same tiny
// scene streamed over gRPC build the database `objdb ingest` builds offline, and every query
// action answers; bad arguments and an unreachable server are clear errors. And both binaries
// with TLS and a token: the clients get in only with both, and the token is never printed.
#include <gtest/gtest.h>

#include <signal.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <string>

#include "absl/strings/str_cat.h"
#include "server/server.h"
#include "storage/sqlite/sqlite_store.h"
#include "tests/support/subprocess.h"
#include "tests/support/temp_dir.h"
#include "tests/support/test_pki.h"

namespace objdb {
namespace {

using testing::ProcessResult;
using testing::runProcess;
namespace fs = std::filesystem;

const std::string kObjdb = OBJDB_CLIENT_BINARY;
const std::string kServerBinary = OBJDB_SERVER_BINARY;

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

std::unique_ptr<ObjdbServer> startServer(const fs::path& db) {
  ServerOptions options;
  options.listen_address = "127.0.0.1:0";
  options.db_path = db.string();
  StatusOr<std::unique_ptr<ObjdbServer>> server = ObjdbServer::start(options);
  EXPECT_TRUE(server.ok()) << server.status();
  return server.ok() ? *std::move(server) : nullptr;
}

TEST(StreamCommand, StreamedSessionsBuildWhatIngestBuildsAndRemoteDescribesThem) {
  testing::TempDir dir;
  const fs::path sessions = dir / "sessions";
  ProcessResult r = runProcess({kObjdb, "sim", "--preset", "two-boxes", "--frames", "20",
                                "--camera", "tango", "--out", (sessions / "monday").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // Tuesday: the same scene seen again with other sensor noise (another seed), so its segments
  // merge through registration and verification, not as byte copies of Monday's.
  r = runProcess({kObjdb, "sim", "--preset", "two-boxes", "--frames", "20", "--camera", "tango",
                  "--seed", "2", "--out", (sessions / "tuesday").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;

  auto server = startServer(dir / "served.sqlite");
  ASSERT_NE(server, nullptr);
  const std::string address = server->address();
  r = runProcess({kObjdb, "stream", "--server", address, sessions.string()});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_TRUE(contains(r.out, "session monday: 20 frames")) << r.out;
  EXPECT_TRUE(contains(r.out, "20 frames acked (0 rejected)")) << r.out;
  EXPECT_TRUE(contains(r.out, "ended: 20 frames integrated")) << r.out;
  EXPECT_TRUE(contains(r.out, "session tuesday: 20 frames")) << r.out;

  // The offline pipeline on the same folders: the same models and merges.
  r = runProcess({kObjdb, "ingest", "--db", (dir / "offline.sqlite").string(), sessions.string()});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  auto offline = storage::SqliteStore::open((dir / "offline.sqlite").string()).value();
  const auto offline_ids = offline->modelIds().value();
  const auto served_ids = server->store().modelIds().value();
  ASSERT_EQ(served_ids.size(), offline_ids.size());
  EXPECT_EQ(server->store().mergeRecords().value().size(), 2u);
  EXPECT_EQ(offline->mergeRecords().value().size(), 2u);
  for (size_t i = 0; i < served_ids.size(); ++i) {
    const auto a = server->store().model(served_ids[i]).value();
    const auto b = offline->model(offline_ids[i]).value();
    EXPECT_EQ(a->observations.size(), b->observations.size()) << i;
    EXPECT_EQ(a->cloud.points.size(), b->cloud.points.size()) << i;
  }

  r = runProcess({kObjdb, "remote", "stats", "--server", address});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "sessions: 2 (0 streaming now), 40 frames integrated")) << r.out;
  EXPECT_TRUE(contains(r.out, absl::StrCat("objects: ", served_ids.size(), " active"))) << r.out;
  r = runProcess({kObjdb, "remote", "sessions", "--server", address});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "monday")) << r.out;
  EXPECT_TRUE(contains(r.out, "ENDED")) << r.out;
  EXPECT_TRUE(contains(r.out, "objdb stream")) << r.out;
  r = runProcess({kObjdb, "remote", "objects", "--server", address, "--session", "tuesday"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "monday, tuesday")) << r.out;  // the merged boxes
  // With their parts: a line per part of each object at each pose.
  r = runProcess(
      {kObjdb, "remote", "objects", "--server", address, "--session", "tuesday", "--parts"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "part ")) << r.out;
  EXPECT_TRUE(contains(r.out, " voxels, extent ")) << r.out;
  const fs::path cloud = dir / "object.ply";
  r = runProcess({kObjdb, "remote", "object", "--server", address, "--id",
                  std::to_string(served_ids.front()), "--out", cloud.string(), "--what", "cloud"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "seen in monday")) << r.out;
  EXPECT_TRUE(contains(r.out, "part ")) << r.out;  // GetObject lists its parts
  EXPECT_GT(fs::file_size(cloud), 1000u);
  // "What is this?": a box's own cloud finds the box; nothing is written.
  int64_t box = 0;
  for (const int64_t id : served_ids) {
    const auto m = server->store().model(id).value();
    if (box == 0 && !m->structure && !m->planar) box = id;
  }
  ASSERT_NE(box, 0);
  const fs::path box_cloud = dir / "box.ply";
  r = runProcess({kObjdb, "remote", "object", "--server", address, "--id", std::to_string(box),
                  "--out", box_cloud.string(), "--what", "cloud"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = runProcess({kObjdb, "remote", "match", "--server", address, "--cloud", box_cloud.string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, absl::StrCat(" ", box, " match "))) << r.out;
  r = runProcess({kObjdb, "remote", "match", "--server", address, "--id", std::to_string(box)});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "candidates evaluated")) << r.out;
  EXPECT_EQ(server->store().modelIds().value(), served_ids);
  // "What is here?" and what changed between the days.
  r = runProcess({kObjdb, "remote", "here", "--server", address, "--session", "tuesday", "--ball",
                  "0,0,0,100"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, absl::StrCat(" ", box, " object "))) << r.out;
  EXPECT_TRUE(contains(r.out, "placements in the region of session tuesday")) << r.out;
  r = runProcess({kObjdb, "remote", "here", "--server", address, "--session", "tuesday", "--box",
                  "1,0,0,0,1,1"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "box.min.x 1 > box.max.x 0")) << r.err;
  r = runProcess({kObjdb, "remote", "here", "--server", address, "--session", "tuesday"});
  EXPECT_EQ(r.exit_code, 2);
  r = runProcess({kObjdb, "remote", "changes", "--server", address, "--from", "monday", "--to",
                  "tuesday"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "from monday to tuesday: ")) << r.out;
  r = runProcess({kObjdb, "remote", "match", "--server", address});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(contains(r.err, "match needs --id ID or --cloud FILE.ply")) << r.err;
  r = runProcess({kObjdb, "remote", "match", "--server", address, "--id", "99999"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "NOT_FOUND")) << r.err;
  const fs::path scene = dir / "scene.ply";
  r = runProcess({kObjdb, "remote", "scene", "--server", address, "--session", "tuesday", "--out",
                  scene.string(), "--completed"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "session tuesday (completed)")) << r.out;
  EXPECT_GT(fs::file_size(scene), 10000u);

  // A session name the database holds already.
  r = runProcess({kObjdb, "stream", "--server", address, (sessions / "monday").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "ALREADY_EXISTS")) << r.err;
  r = runProcess({kObjdb, "remote", "object", "--server", address, "--id", "99999"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "NOT_FOUND: no object 99999")) << r.err;
}

// Issue 47: a depth file of the wrong size stops the stream; once it is fixed, --resume continues
// the session from the first frame its map does not hold, --replace streams it again, and
// --session names it.
TEST(StreamCommand, AStreamStoppedByABadFileIsResumedOnceTheFileIsFixedOrReplaced) {
  testing::TempDir dir;
  const fs::path monday = dir / "monday", other = dir / "other-camera";
  ProcessResult r = runProcess({kObjdb, "sim", "--preset", "two-boxes", "--frames", "12",
                                "--camera", "tango", "--out", monday.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = runProcess({kObjdb, "sim", "--preset", "two-boxes", "--frames", "6", "--out",
                  other.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const fs::path bad = monday / "depth" / "000005.png", kept = dir / "000005.png";
  fs::copy_file(bad, kept);
  fs::copy_file(other / "depth" / "000005.png", bad, fs::copy_options::overwrite_existing);

  auto server = startServer(dir / "served.sqlite");
  ASSERT_NE(server, nullptr);
  const std::string address = server->address();
  r = runProcess({kObjdb, "stream", "--server", address, monday.string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "000005.png is 640x480 but intrinsics are for 224x172")) << r.err;
  EXPECT_TRUE(contains(r.err, "session monday stops before frame 5, open on the server")) << r.err;
  EXPECT_TRUE(contains(r.err, "--resume")) << r.err;

  // Fixed: the same command says the name is taken and what to do.
  fs::copy_file(kept, bad, fs::copy_options::overwrite_existing);
  r = runProcess({kObjdb, "stream", "--server", address, monday.string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "ALREADY_EXISTS")) << r.err;
  for (const char* option : {"--resume", "--replace", "--session NAME"}) {
    EXPECT_TRUE(contains(r.err, option)) << r.err;
  }
  r = runProcess({kObjdb, "stream", "--server", address, monday.string(), "--resume"});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  // The frames sent before the bad file were fused: it goes on from frame 5.
  EXPECT_TRUE(contains(r.out, "resumed: its map holds 5 frames, up to frame 4; sending from frame 5"))
      << r.out;
  EXPECT_TRUE(contains(r.out, "ended: 12 frames integrated")) << r.out;

  // Ended: not resumed again, but replaced; its record stays under another name.
  r = runProcess({kObjdb, "stream", "--server", address, monday.string(), "--resume"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "FAILED_PRECONDITION: session monday has ended")) << r.err;
  r = runProcess({kObjdb, "stream", "--server", address, monday.string(), "--replace"});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_TRUE(contains(r.out, "replaced the earlier session of this name")) << r.out;
  EXPECT_TRUE(contains(r.out, "ended: 12 frames integrated")) << r.out;
  r = runProcess({kObjdb, "stream", "--server", address, monday.string(), "--session", "tue"});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_TRUE(contains(r.out, "session tue: 12 frames")) << r.out;
  r = runProcess({kObjdb, "remote", "sessions", "--server", address});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "monday.replaced-")) << r.out;
  EXPECT_TRUE(contains(r.out, "tue ")) << r.out;

  r = runProcess({kObjdb, "stream", "--server", address, monday.string(), other.string(),
                  "--session", "x"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(contains(r.err, "--session names one session, but the datasets hold 2")) << r.err;
  r = runProcess({kObjdb, "stream", "--server", address, monday.string(), "--resume",
                  "--replace"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(contains(r.err, "--resume and --replace exclude each other")) << r.err;
}

TEST(StreamCommand, BadArgumentsAndAMissingServerAreClearErrors) {
  testing::TempDir dir;
  ProcessResult r = runProcess({kObjdb, "stream"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(contains(r.err, "at least one DATASET")) << r.err;
  r = runProcess({kObjdb, "stream", "d", "--every", "0"});
  EXPECT_EQ(r.exit_code, 2);
  r = runProcess({kObjdb, "stream", dir.path().string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "holds no dataset")) << r.err;
  r = runProcess({kObjdb, "remote"});
  EXPECT_EQ(r.exit_code, 2);
  r = runProcess({kObjdb, "remote", "launch"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(contains(r.err, "unknown action")) << r.err;
  r = runProcess({kObjdb, "remote", "object"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(contains(r.err, "--id")) << r.err;
  r = runProcess({kObjdb, "remote", "scene", "--session", "s"});
  EXPECT_EQ(r.exit_code, 2);
  // --what without --out would be ignored: refused (issue 47).
  r = runProcess({kObjdb, "remote", "object", "--id", "3", "--what", "cloud"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(contains(r.err, "--what says what --out FILE.ply gets")) << r.err;
  // Nothing listens on the port of a stopped server.
  std::string address;
  {
    auto server = startServer(dir / "gone.sqlite");
    ASSERT_NE(server, nullptr);
    address = server->address();
  }
  r = runProcess({kObjdb, "remote", "stats", "--server", address, "--timeout", "5"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "UNAVAILABLE")) << r.err;
  EXPECT_TRUE(contains(r.err, "is objdb-server running there?")) << r.err;
  // A host name that does not resolve: no advice to start a server there (issue 47).
  r = runProcess({kObjdb, "remote", "stats", "--server", "nosuchhost.invalid:50051", "--timeout",
                  "5"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "UNAVAILABLE")) << r.err;
  EXPECT_TRUE(contains(r.err, "does not resolve: check --server HOST:PORT")) << r.err;
  EXPECT_FALSE(contains(r.err, "start it with")) << r.err;
}


TEST(StreamCommand, WithTlsAndATokenOnlyClientsWithBothGetInAndTheTokenIsNeverPrinted) {
  const testing::TestPki pki;
  ASSERT_TRUE(pki.ok()) << pki.log();
  testing::TempDir dir;
  const std::string token = "f00dfeedcafe-objdb-cli-test-token-4711";
  ASSERT_TRUE(testing::writeTextFile(dir / "token", token + "\n"));
  ASSERT_TRUE(testing::writeTextFile(dir / "wrong", std::string(token.size(), 'x')));
  ProcessResult r = runProcess({kObjdb, "sim", "--preset", "two-boxes", "--frames", "10",
                                "--camera", "tango", "--out", (dir / "monday").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;

  testing::ChildProcess server({kServerBinary, "--listen", "127.0.0.1:0", "--db",
                                (dir / "db.sqlite").string(), "--token-file",
                                (dir / "token").string(), "--tls-cert", pki.path("server.pem"),
                                "--tls-key", pki.path("server.key"), "--log-level", "trace"});
  ASSERT_TRUE(server.started());
  ASSERT_TRUE(server.waitForStderr("bearer token required)", std::chrono::seconds(30)))
      << server.stderrText();
  const std::string log = server.stderrText();
  const size_t at = log.find("listening on ") + std::string("listening on ").size();
  const std::string address = log.substr(at, log.find(' ', at) - at);
  ASSERT_TRUE(contains(address, "127.0.0.1:")) << log;

  const std::vector<std::string> tls = {"--server", address, "--tls-ca", pki.path("ca.pem")};
  auto with = [&](std::vector<std::string> args, const std::vector<std::string>& extra) {
    args.insert(args.begin(), kObjdb);
    args.insert(args.end(), extra.begin(), extra.end());
    return runProcess(args);
  };
  std::string printed;  // everything the clients wrote
  r = with({"remote", "stats"}, tls);
  printed += r.out + r.err;
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "UNAUTHENTICATED")) << r.err;
  EXPECT_TRUE(contains(r.err, "--token-file")) << r.err;
  r = with({"remote", "stats", "--token-file", (dir / "wrong").string()}, tls);
  printed += r.out + r.err;
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "UNAUTHENTICATED")) << r.err;
  r = with({"remote", "stats", "--server", address, "--token-file", (dir / "token").string()}, {});
  printed += r.out + r.err;
  EXPECT_EQ(r.exit_code, 1) << "plaintext against TLS";
  EXPECT_TRUE(contains(r.err, "UNAVAILABLE")) << r.err;

  r = with({"stream", (dir / "monday").string(), "--token-file", (dir / "token").string()}, tls);
  printed += r.out + r.err;
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_TRUE(contains(r.out, "10 frames acked (0 rejected)")) << r.out;
  r = with({"remote", "stats", "--token-file", (dir / "token").string()}, tls);
  printed += r.out + r.err;
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "sessions: 1 (0 streaming now), 10 frames integrated")) << r.out;
  r = with({"health"}, tls);
  printed += r.out + r.err;
  EXPECT_EQ(r.exit_code, 0) << "health needs no token: " << r.err;
  // A token is sent in clear text only to this machine.
  r = with({"remote", "stats", "--server", "192.0.2.7:50051", "--token-file",
            (dir / "token").string()}, {});
  printed += r.out + r.err;
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "would send the token in clear text to 192.0.2.7:50051")) << r.err;
  r = with({"remote", "stats", "--tls-cert", pki.path("client.pem")}, tls);
  EXPECT_EQ(r.exit_code, 1) << "a certificate without its key is an error";
  EXPECT_TRUE(contains(r.err, "--tls-cert with --tls-key")) << r.err;

  ASSERT_TRUE(server.sendSignal(SIGTERM));
  const ProcessResult stopped = server.wait(std::chrono::seconds(60));
  EXPECT_EQ(stopped.exit_code, 0) << stopped.err;
  EXPECT_TRUE(contains(stopped.err, "stopped serving")) << stopped.err;
  EXPECT_FALSE(contains(stopped.err, token)) << "the server's log holds the token";
  EXPECT_FALSE(contains(printed, token)) << "a client printed the token";
}

}  // namespace
}  // namespace objdb

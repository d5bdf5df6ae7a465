// `objdb ingest`: two sessions of the same tiny scene go into one database file; the boxes of
// the second session merge into the first session's models; a session already stored is refused.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <string>

#include "storage/sqlite/sqlite_store.h"
#include "tests/support/subprocess.h"
#include "tests/support/temp_dir.h"

namespace objdb {
namespace {

using testing::ProcessResult;
using testing::runProcess;
namespace fs = std::filesystem;

const std::string kObjdb = OBJDB_CLIENT_BINARY;

TEST(IngestCommand, TwoSessionsOfTheSameSceneMergeTheirObjects) {
  testing::TempDir dir;
  const fs::path sessions = dir / "sessions";
  ProcessResult r = runProcess({kObjdb, "sim", "--preset", "two-boxes", "--frames", "20", "--camera",
                                "tango", "--out", (sessions / "monday").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // Tuesday: the same scene seen again with other sensor noise (another seed), so its segments
  // merge through registration and verification, not as byte copies of Monday's.
  r = runProcess({kObjdb, "sim", "--preset", "two-boxes", "--frames", "20", "--camera", "tango",
                  "--seed", "2", "--out", (sessions / "tuesday").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const fs::path db = dir / "objects.sqlite";
  r = runProcess({kObjdb, "ingest", "--db", db.string(), sessions.string()});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("session monday: 20 frames"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("(2 merged into earlier models"), std::string::npos) << r.out;

  auto store = storage::SqliteStore::open(db.string()).value();
  const auto sessions_stored = store->sessions().value();
  ASSERT_EQ(sessions_stored.size(), 2u);
  EXPECT_EQ(sessions_stored[1].name, "tuesday");
  EXPECT_EQ(sessions_stored[1].state, storage::SessionState::kEnded);
  EXPECT_EQ(sessions_stored[1].frames, 20);
  EXPECT_NE(store->scene("tuesday").value(), nullptr);
  EXPECT_NE(store->sceneLabels("tuesday").value(), nullptr);
  // Each box is one model seen in both sessions; the floor is planar and stays apart.
  size_t both = 0;
  const std::vector<int64_t> ids = store->modelIds().value();
  for (int64_t id : ids) {
    const auto m = store->model(id).value();
    if (m->observations.size() == 2) {
      ++both;
      EXPECT_EQ(m->observations[0].session, "monday");
      EXPECT_EQ(m->observations[1].session, "tuesday");
    }
  }
  EXPECT_EQ(both, 2u);
  EXPECT_EQ(store->mergeRecords().value().size(), 2u);
  store.reset();

  r = runProcess({kObjdb, "ingest", "--db", db.string(), (sessions / "monday").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("session monday is already in"), std::string::npos) << r.err;

  // Sessions record their effective parameters; a session that would describe its models
  // differently is refused before any work, naming the setting.
  {
    auto reopened = storage::SqliteStore::open(db.string()).value();
    const auto recorded = reopened->sessions().value();
    ASSERT_FALSE(recorded.empty());
    EXPECT_NE(recorded[0].params_json.find("\"surface_spacing_m\""), std::string::npos)
        << recorded[0].params_json;
  }
  fs::copy(sessions / "monday", dir / "wednesday", fs::copy_options::recursive);
  const fs::path config = dir / "full-cloud.json";
  std::FILE* f = std::fopen(config.string().c_str(), "w");
  ASSERT_NE(f, nullptr);
  std::fputs(R"({"descriptors": {"surface_spacing_m": 0}})", f);
  std::fclose(f);
  r = runProcess({kObjdb, "ingest", "--db", db.string(), "--config", config.string(),
                  (dir / "wednesday").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("descriptors.surface_spacing_m"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("session tuesday"), std::string::npos) << r.err;
  EXPECT_EQ(storage::SqliteStore::open(db.string()).value()->sessions().value().size(), 2u);
}

TEST(IngestCommand, BadArgumentsAreClearErrors) {
  testing::TempDir dir;
  ProcessResult r = runProcess({kObjdb, "ingest", "--db", (dir / "x.sqlite").string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("at least one DATASET"), std::string::npos) << r.err;
  r = runProcess({kObjdb, "ingest", "--db", (dir / "x.sqlite").string(), dir.path().string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("holds no dataset"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir / "x.sqlite"));
  r = runProcess({kObjdb, "ingest", "--db", "y.sqlite", "d", "--every", "0"});
  EXPECT_EQ(r.exit_code, 2);
  r = runProcess({kObjdb, "ingest", "--db", (dir / "z.sqlite").string(), "--synchronous", "OFF",
                  (dir / "missing").string()});
  EXPECT_EQ(r.exit_code, 1);
}

}  // namespace
}  // namespace objdb

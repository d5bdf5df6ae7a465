// `objdb eval`: datasets run through an in-process server on a new database and scored. Two
// sessions of the two-box scene give the known counts (both boxes merged across the sessions,
// nothing else, recall 4 of 4) and the time per stage; a room with a floor and a wall gives its
// dominant planes, the floor and wall placements on them and no structure merge; bad input is a
// clear error naming the file.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "tests/support/subprocess.h"
#include "tests/support/temp_dir.h"

namespace objdb {
namespace {

using testing::ProcessResult;
using testing::runProcess;
namespace fs = std::filesystem;

const std::string kObjdb = OBJDB_CLIENT_BINARY;

std::string row(const std::string& text, const std::string& what) {
  return testing::valueAfter(text, what);
}

int count(const std::string& text, const std::string& what) {
  const std::string value = row(text, what);
  return value == "(missing)" ? -1 : std::stoi(value);
}

TEST(EvalCommand, TwoSessionsOfTwoBoxesGiveTheKnownCounts) {
  testing::TempDir dir;
  const fs::path sessions = dir / "sessions";
  ProcessResult r = runProcess({kObjdb, "sim", "--preset", "two-boxes", "--frames", "20",
                                "--camera", "tango", "--out", (sessions / "monday").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  fs::copy(sessions / "monday", sessions / "tuesday", fs::copy_options::recursive);
  const fs::path db = dir / "kept.sqlite";
  r = runProcess({kObjdb, "eval", "--db", db.string(), sessions.string()});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_EQ(count(r.out, "models from >= 2 segments"), 2) << r.out;
  EXPECT_EQ(count(r.out, "erroneous merges (kinds differ)"), 0) << r.out;
  EXPECT_EQ(count(r.out, "structure merges (true structure in a model of >= 2)"), 0) << r.out;
  EXPECT_NE(row(r.out, "repeated kinds' mergeable segments with their kind elsewhere")
                .find("100 % (4 of 4)"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("large_box"), std::string::npos) << r.out;
  EXPECT_EQ(count(r.out, "structure merges (on a dominant plane, in a model of >= 2 places)"), 0) << r.out;
  // Every insert timed, the model-to-scene check ran on the server's path.
  EXPECT_NE(r.out.find("database time over 6 inserts"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("session monday streamed and ended in"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("poses without a scene 0"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("model-to-scene checks 0,"), std::string::npos) << r.out;
  EXPECT_TRUE(fs::exists(db));
  // A database is never reused: the counts would mix two runs.
  r = runProcess({kObjdb, "eval", "--db", db.string(), sessions.string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("kept.sqlite exists"), std::string::npos) << r.err;
}

TEST(EvalCommand, FloorAndWallAreDominantPlanesAndNeverMerged) {
  testing::TempDir dir;
  const fs::path scene = dir / "room.json";
  std::ofstream(scene) << R"({
    "name": "room", "camera": "tango", "noise": {"enabled": true, "seed": 3},
    "objects": [
      {"id": 1, "category": "floor", "size": [4, 4], "structure": true, "pose": {"t": [1, 1, 0]}},
      {"id": 2, "category": "wall", "size": [4, 2.5], "structure": true,
       "pose": {"t": [1, 2.4, 0], "yaw_deg": -90}},
      {"id": 3, "category": "large_box", "pose": {"t": [0.6, 1.5, 0], "yaw_deg": 20}},
      {"id": 4, "category": "large_box", "pose": {"t": [1.6, 1.6, 0], "yaw_deg": -15}}
    ],
    "trajectory": {"frames": 24, "fps": 30, "closed": false,
                   "keyframes": [{"position": [0.2, -0.3, 1.8], "look_at": [0.8, 1.6, 0.0]},
                                 {"position": [2.0, -0.3, 1.8], "look_at": [1.4, 1.6, 0.0]}]}
  })";
  const fs::path sessions = dir / "sessions";
  ProcessResult r = runProcess(
      {kObjdb, "sim", "--scene", scene.string(), "--out", (sessions / "monday").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  fs::copy(sessions / "monday", sessions / "tuesday", fs::copy_options::recursive);
  r = runProcess({kObjdb, "eval", sessions.string()});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  // Floor and wall in each session (a box face is far below 1 m²).
  const std::string planes = row(r.out, "dominant planes (sessions with a scene)");
  EXPECT_NE(planes.find("(2)"), std::string::npos) << r.out;
  EXPECT_GE(std::stoi(planes), 4) << r.out;
  EXPECT_LE(std::stoi(planes), 6) << r.out;
  // Floor and wall segments lie on them, and the database flags them structure.
  const std::string on = row(r.out, "  placements on them / of them flagged structure");
  ASSERT_NE(on, "(missing)") << r.out;
  const int on_planes = std::stoi(on), flagged = std::stoi(on.substr(on.find('/') + 1));
  EXPECT_GE(on_planes, 2) << r.out;
  EXPECT_EQ(flagged, on_planes) << r.out;
  EXPECT_EQ(count(r.out, "structure merges (on a dominant plane, in a model of >= 2 places)"), 0) << r.out;
  EXPECT_EQ(count(r.out, "structure merges (true structure in a model of >= 2)"), 0) << r.out;
  EXPECT_EQ(count(r.out, "erroneous merges (kinds differ)"), 0) << r.out;
}

TEST(EvalCommand, BadInputIsAClearError) {
  testing::TempDir dir;
  ProcessResult r = runProcess({kObjdb, "eval"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("at least one DATASET is required"), std::string::npos) << r.err;
  r = runProcess({kObjdb, "eval", "--every", "0", dir.path().string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--every needs a positive integer"), std::string::npos) << r.err;
  r = runProcess({kObjdb, "eval", "--structure-ids", "1,floor", dir.path().string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--structure-ids needs class ids 1-65535 separated by commas, got 1,floor"),
            std::string::npos)
      << r.err;
  // A folder in none of the layouts.
  fs::create_directories(dir / "holiday");
  std::ofstream(dir / "holiday" / "notes.txt") << "not a dataset\n";
  r = runProcess({kObjdb, "eval", (dir / "holiday").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("holiday"), std::string::npos) << r.err;
  // Ground truth present but broken: the error names objects.json, never a silent zero score.
  r = runProcess({kObjdb, "sim", "--preset", "two-boxes", "--frames", "3", "--camera", "tango",
                  "--out", (dir / "broken").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::ofstream(dir / "broken" / "objects.json") << "{ not json";
  r = runProcess({kObjdb, "eval", (dir / "broken").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("objects.json"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace objdb

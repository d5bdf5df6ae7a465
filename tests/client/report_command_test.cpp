// `objdb report merges`: two sessions of the same two-box scene, ingested into one file, give a
// sheet with one row per merged model (both boxes), each placement found in its session's frames;
// bad arguments and missing inputs are clear errors.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <string>

#include <opencv2/imgcodecs.hpp>

#include "tests/support/subprocess.h"
#include "tests/support/temp_dir.h"

namespace objdb {
namespace {

using testing::ProcessResult;
using testing::runProcess;
namespace fs = std::filesystem;

const std::string kObjdb = OBJDB_CLIENT_BINARY;

TEST(ReportCommand, DrawsOneRowPerMergedModelWithEveryPlacementSeen) {
  testing::TempDir dir;
  const fs::path sessions = dir / "sessions";
  ProcessResult r = runProcess({kObjdb, "sim", "--preset", "two-boxes", "--frames", "20",
                                "--camera", "tango", "--out", (sessions / "monday").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  fs::copy(sessions / "monday", sessions / "tuesday", fs::copy_options::recursive);
  const fs::path db = dir / "objects.sqlite";
  // OBJDB_LOG_LEVEL=debug shows the database's reasons (a candidate rejected, a segment's class).
  r = runProcess({"/usr/bin/env", "OBJDB_LOG_LEVEL=debug", kObjdb, "ingest", "--db", db.string(),
                  sessions.string()});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.err.find("[database] [debug] segment "), std::string::npos) << r.err;
  const fs::path sheet = dir / "merges.png";
  r = runProcess({kObjdb, "report", "merges", "--db", db.string(), "--out", sheet.string(),
                  (sessions / "monday").string(), "tuesday=" + (sessions / "tuesday").string()});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("2 models drawn"), std::string::npos) << r.out;
  EXPECT_NE(r.err.find("session monday: 20 frames"), std::string::npos) << r.err;
  const cv::Mat image = cv::imread(sheet.string());
  ASSERT_FALSE(image.empty());
  EXPECT_EQ(image.rows, 40 + 2 * 240);  // a title line and two rows
  EXPECT_EQ(image.cols, 380 + 240 + 5 * 320);
  // Each placement tile holds drawn points (bright pixels over the dimmed image): the first tile
  // of the first row is not just the dimmed frame.
  const cv::Mat tile = image(cv::Rect(380 + 240, 40, 320, 240));
  double brightest = 0;
  cv::minMaxLoc(tile.reshape(1), nullptr, &brightest);
  EXPECT_GT(brightest, 200);
  // --min-segments 1: every model, the unmerged ones (the floor) too.
  r = runProcess({kObjdb, "report", "merges", "--db", db.string(), "--out", sheet.string(),
                  "--min-segments", "1", (sessions / "monday").string()});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_EQ(r.out.find("2 models drawn"), std::string::npos) << r.out;
  EXPECT_GT(cv::imread(sheet.string()).rows, 40 + 2 * 240);

  // Scored against the sessions' ground truth: both boxes merged across the sessions, nothing
  // else, the floor planar.
  r = runProcess({kObjdb, "report", "truth", "--db", db.string(), (sessions / "monday").string(),
                  (sessions / "tuesday").string()});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  auto row = [&](const std::string& what) { return testing::valueAfter(r.out, what); };
  EXPECT_EQ(std::stoi(row("models from >= 2 segments")), 2) << r.out;
  EXPECT_EQ(std::stoi(row("erroneous merges (kinds differ)")), 0) << r.out;
  EXPECT_NE(row("repeated kinds' mergeable segments with their kind elsewhere").find("100 % (4 of 4)"),
            std::string::npos)
      << r.out;
  // Per kind: objects (per session), segments, models the kind ends in, models per object. Both
  // sessions' large boxes end in one model.
  const std::string large_box = row("large_box");
  EXPECT_NE(large_box, "(missing)") << r.out;
  int objects = 0, segments = 0, models = 0;
  double per_object = 0;
  ASSERT_EQ(
      std::sscanf(large_box.c_str(), "%d %d %d %lf", &objects, &segments, &models, &per_object), 4)
      << large_box;
  EXPECT_EQ(objects, 2);
  EXPECT_EQ(models, 1) << r.out;
  EXPECT_DOUBLE_EQ(per_object, 1.0);
}

TEST(ReportCommand, TruthNeedsGroundTruth) {
  testing::TempDir dir;
  const fs::path plain = dir / "plain";
  ProcessResult r = runProcess({kObjdb, "sim", "--preset", "two-boxes", "--frames", "3",
                                "--camera", "tango", "--out", plain.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  fs::remove_all(plain / "instances");
  r = runProcess({kObjdb, "report", "truth", "--db", (dir / "none.sqlite").string(),
                  plain.string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("has no ground truth"), std::string::npos) << r.err;
}

TEST(ReportCommand, BadArgumentsAndMissingInputsAreClearErrors) {
  testing::TempDir dir;
  ProcessResult r = runProcess({kObjdb, "report", "merges", "--out", (dir / "s.png").string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--db and --out are required"), std::string::npos) << r.err;
  r = runProcess({kObjdb, "report", "splits"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("unknown report \"splits\""), std::string::npos) << r.err;
  r = runProcess({kObjdb, "report", "merges", "--db", (dir / "none.sqlite").string(), "--out",
                  (dir / "s.png").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("none.sqlite"), std::string::npos) << r.err;
  r = runProcess({kObjdb, "report", "merges", "--max-rows", "0"});
  EXPECT_EQ(r.exit_code, 2);
  r = runProcess({kObjdb, "report", "merges", "--min-segments", "0"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--min-segments must be a whole number >= 1"), std::string::npos) << r.err;
  r = runProcess({"/usr/bin/env", "OBJDB_LOG_LEVEL=loud", kObjdb, "help"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("unknown OBJDB_LOG_LEVEL \"loud\""), std::string::npos) << r.err;
}

}  // namespace
}  // namespace objdb

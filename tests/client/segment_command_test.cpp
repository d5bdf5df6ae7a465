// `objdb segment`: runs the client binary on a tiny synthetic dataset written by `objdb sim` and
// checks the pictures it writes and its errors (missing dataset, frame out of range, bad config).
#include <gtest/gtest.h>

#include <filesystem>
#include <memory>
#include <string>

#include "core/io/image_io.h"
#include "tests/support/subprocess.h"
#include "tests/support/temp_dir.h"

namespace objdb {
namespace {

using testing::ProcessResult;
using testing::runProcess;
using testing::TempDir;
namespace fs = std::filesystem;

const std::string kObjdb = OBJDB_CLIENT_BINARY;

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// One two-frame two-boxes dataset shared by the suite (written once, removed at the end).
class SegmentCommand : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = std::make_unique<TempDir>();
    const ProcessResult sim = runProcess(
        {kObjdb, "sim", "--preset", "two-boxes", "--frames", "2", "--out", dataset().string()});
    ASSERT_EQ(sim.exit_code, 0) << sim.err;
  }
  static void TearDownTestSuite() { dir_.reset(); }
  static fs::path dataset() { return dir_->path() / "two_boxes"; }
  static fs::path tmp() { return dir_->path(); }

  static std::unique_ptr<TempDir> dir_;
};
std::unique_ptr<TempDir> SegmentCommand::dir_;

TEST_F(SegmentCommand, WritesEveryStepAsAPngForAFrame) {
  const fs::path out = tmp() / "out_frame1";
  const ProcessResult r = runProcess(
      {kObjdb, "segment", "--dataset", dataset().string(), "--frame", "1", "--out", out.string()});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  for (const char* name :
       {"depth.png", "filtered_depth.png", "discontinuities.png", "convexity.png", "normals.png",
        "boundaries.png", "labels.png", "overlay.png"}) {
    EXPECT_TRUE(fs::exists(out / name)) << name;
  }
  // labels.png is a VGA colour image with at least one labelled (non-black) pixel.
  StatusOr<ColorImage> labels = io::readColorImage(out / "labels.png");
  ASSERT_TRUE(labels.ok()) << labels.status();
  EXPECT_EQ(labels->width, 640);
  EXPECT_EQ(labels->height, 480);
  size_t coloured = 0;
  for (const Rgb8& c : labels->data) coloured += (c.r | c.g | c.b) != 0 ? 1 : 0;
  EXPECT_GT(coloured, labels->data.size() / 4);
  EXPECT_TRUE(contains(r.out, "segments: ")) << r.out;
  EXPECT_TRUE(contains(r.out, "timings (ms)")) << r.out;
  EXPECT_TRUE(contains(r.out, "normals")) << r.out;
}

TEST_F(SegmentCommand, AppliesTheSegmentationSectionOfAConfigFile) {
  const fs::path config = tmp() / "big_min.json";
  // No region of a VGA frame has 300000 pixels: every region is dropped.
  ASSERT_TRUE(testing::writeTextFile(config, R"({"segmentation": {"min_segment_px": 300000}})"));
  const ProcessResult r =
      runProcess({kObjdb, "segment", "--dataset", dataset().string(), "--frame", "0", "--out",
                  (tmp() / "out_config").string(), "--config", config.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "segments: 0")) << r.out;
}

TEST_F(SegmentCommand, FrameOutOfRangeNamesTheRange) {
  const ProcessResult r = runProcess({kObjdb, "segment", "--dataset", dataset().string(), "--frame",
                                      "99", "--out", (tmp() / "out99").string()});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_TRUE(contains(r.err, "frame 99 is out of range")) << r.err;
  EXPECT_TRUE(contains(r.err, "2 frames (0..1)")) << r.err;
  EXPECT_FALSE(fs::exists(tmp() / "out99" / "labels.png"));
}

TEST_F(SegmentCommand, MissingDatasetIsAClearError) {
  const ProcessResult r =
      runProcess({kObjdb, "segment", "--dataset", (tmp() / "no_such_dataset").string(), "--frame",
                  "0", "--out", (tmp() / "out_missing").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "no_such_dataset")) << r.err;
  EXPECT_TRUE(contains(r.err, "does not exist")) << r.err;
}

TEST_F(SegmentCommand, BadConfigIsAClearError) {
  const fs::path config = tmp() / "bad.json";
  ASSERT_TRUE(testing::writeTextFile(config, R"({"segmentation": {"normal_window_px": 4}})"));
  ProcessResult r =
      runProcess({kObjdb, "segment", "--dataset", dataset().string(), "--frame", "0", "--out",
                  (tmp() / "out_bad").string(), "--config", config.string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "bad config")) << r.err;
  EXPECT_TRUE(contains(r.err, "normal_window_px")) << r.err;

  r = runProcess({kObjdb, "segment", "--dataset", dataset().string(), "--frame", "0", "--out",
                  (tmp() / "out_bad").string(), "--config", (tmp() / "none.json").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "none.json")) << r.err;
}

TEST_F(SegmentCommand, CommandLineErrorsExitTwo) {
  ProcessResult r = runProcess({kObjdb, "segment", "--frame", "0", "--out", "x"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(contains(r.err, "--dataset DIR is required")) << r.err;

  r = runProcess(
      {kObjdb, "segment", "--dataset", dataset().string(), "--frame", "-1", "--out", "x"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(contains(r.err, "--frame needs a non-negative integer")) << r.err;

  r = runProcess({kObjdb, "segment", "--dataset", dataset().string(), "--frame"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(contains(r.err, "--frame needs a value")) << r.err;

  r = runProcess({kObjdb, "segment", "--colour"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(contains(r.err, "unknown option '--colour'")) << r.err;

  r = runProcess({kObjdb, "segment", "--help"});
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_TRUE(contains(r.out, "labels.png")) << r.out;
}

}  // namespace
}  // namespace objdb

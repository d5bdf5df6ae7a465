#include "core/io/seven_scenes_dataset.h"

#include <cmath>
#include <filesystem>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/io/image_io.h"
#include "tests/support/temp_dir.h"

namespace objdb::io {
namespace {

namespace fs = std::filesystem;
using objdb::testing::TempDir;
using objdb::testing::writeTextFile;
using ::testing::HasSubstr;

const fs::path kSample = fs::path(OBJDB_SOURCE_DIR) / "tests" / "data" / "seven_scenes_sample";
const Intrinsics kSampleCamera{8, 6, 11.0, 12.0, 3.5, 2.5};

// make_sample.py: depth frame n holds 1000 + 250 n + 10 v + u millimetres, except (1, 1) = 0 and
// (2, 1) = 65535, both "no measurement".
float sampleDepthMetres(int u, int v, int n) {
  if (u == 1 && v == 1) return 0.0f;
  if (u == 2 && v == 1) return 0.0f;
  return float(1000 + 250 * n + 10 * v + u) * float(0.001);
}

Transform pose(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  Transform T = Transform::Identity();
  T.linear() = R;
  T.translation() = t;
  return T;
}

Eigen::Matrix3d rotZ(double degrees) {
  return Eigen::AngleAxisd(degrees * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
}

double poseError(const Transform& a, const Transform& b) {
  return (a.matrix() - b.matrix()).cwiseAbs().maxCoeff();
}

std::string message(const Status& status) { return std::string(status.message()); }

// A copy of the sample to break.
void copySample(const TempDir& dir) {
  fs::copy(kSample, dir.path(), fs::copy_options::recursive);
  fs::remove(dir / "make_sample.py");
}

TEST(SevenScenesDataset, SampleHasKnownIntrinsicsPosesAndDepth) {
  const auto opened = openDataset(kSample);
  ASSERT_TRUE(opened.ok()) << opened.status();
  const Dataset& dataset = **opened;
  EXPECT_EQ(dataset.layout(), "7scenes");
  EXPECT_EQ(dataset.root(), kSample);
  // fx fy cx cy from camera-intrinsics.txt, 8x6 from the first depth image's header.
  EXPECT_EQ(dataset.intrinsics(), kSampleCamera);
  EXPECT_DOUBLE_EQ(dataset.metresPerDepthUnit(), 0.001);
  EXPECT_TRUE(dataset.hasColor());
  EXPECT_FALSE(dataset.hasInstances());
  // Frames 0, 1, 3: the gap at 2 is allowed.
  ASSERT_EQ(dataset.size(), 3u);
  const auto& seven = dynamic_cast<const SevenScenesDataset&>(dataset);
  EXPECT_EQ(seven.frameNumber(0), 0u);
  EXPECT_EQ(seven.frameNumber(1), 1u);
  EXPECT_EQ(seven.frameNumber(2), 3u);
  EXPECT_EQ(seven.intrinsicsFile(), kSample / "camera-intrinsics.txt");

  Eigen::Matrix3d flip_y = Eigen::Matrix3d::Zero();
  flip_y.diagonal() << -1.0, 1.0, -1.0;
  struct Expected {
    int number;
    Transform pose;
    double tolerance;  // frame 1 is printed with 7 significant digits
  };
  const Expected expected[3] = {
      {0, pose(rotZ(90), {1.0, 2.0, 3.0}), 1e-9},
      {1, pose(rotZ(30), {-0.5, 0.25, 1.5}), 1e-7},
      {3, pose(flip_y, {0.0, -1.0, 0.75}), 1e-12},
  };
  for (size_t i = 0; i < 3; ++i) {
    SCOPED_TRACE(i);
    const int n = expected[i].number;
    const auto frame = dataset.loadFrame(i);
    ASSERT_TRUE(frame.ok()) << frame.status();
    EXPECT_EQ(frame->index, i);
    EXPECT_DOUBLE_EQ(frame->timestamp, n / kSevenScenesFrameRateHz);
    EXPECT_LT(poseError(frame->T_world_camera, expected[i].pose), expected[i].tolerance);
    // What the pipeline checks: a valid rigid pose (frame 1 was re-orthonormalised).
    EXPECT_TRUE(validateFrame(*frame, dataset.intrinsics()).ok());
    ASSERT_EQ(frame->depth.width, 8);
    ASSERT_EQ(frame->depth.height, 6);
    for (int v = 0; v < 6; ++v) {
      for (int u = 0; u < 8; ++u) {
        EXPECT_FLOAT_EQ(frame->depth.at(u, v), sampleDepthMetres(u, v, n)) << u << "," << v;
      }
    }
    EXPECT_FLOAT_EQ(frame->depth.at(0, 0), 1.0f + 0.25f * float(n));
    EXPECT_FLOAT_EQ(frame->depth.at(7, 5), 1.057f + 0.25f * float(n));
    EXPECT_EQ(frame->depth.at(1, 1), 0.0f);  // 0 in the file
    EXPECT_EQ(frame->depth.at(2, 1), 0.0f);  // 65535 in the file, not 65.535 m
    ASSERT_TRUE(frame->color.has_value());
    EXPECT_EQ(frame->color->at(5, 4), (Rgb8{50, 80, uint8_t(50 * n + 1)}));
    EXPECT_FALSE(frame->instances.has_value());
  }
  const auto beyond = dataset.loadFrame(3);
  EXPECT_EQ(beyond.status().code(), absl::StatusCode::kOutOfRange);
}

TEST(SevenScenesDataset, IntrinsicsOverrideReplacesFile) {
  DatasetOptions options;
  options.intrinsics = Intrinsics{8, 6, 20.0, 21.0, 4.0, 3.0};
  auto dataset = SevenScenesDataset::open(kSample, options);
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_EQ((*dataset)->intrinsics(), *options.intrinsics);
  EXPECT_TRUE((*dataset)->intrinsicsFile().empty());
  EXPECT_TRUE((*dataset)->loadFrame(0).ok());

  // The override's size is what the images must have.
  options.intrinsics = Intrinsics{10, 6, 20.0, 21.0, 4.0, 3.0};
  dataset = SevenScenesDataset::open(kSample, options);
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  const auto frame = (*dataset)->loadFrame(0);
  ASSERT_FALSE(frame.ok());
  EXPECT_THAT(message(frame.status()),
              HasSubstr("frame-000000.depth.png is 8x6 but intrinsics are for 10x6"));
}

TEST(SevenScenesDataset, WithoutColourFilesFramesHaveNoColour) {
  TempDir dir;
  copySample(dir);
  for (const char* name :
       {"frame-000000.color.png", "frame-000001.color.png", "frame-000003.color.png"}) {
    ASSERT_TRUE(fs::remove(dir / name));
  }
  const auto dataset = openDataset(dir.path());
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_FALSE((*dataset)->hasColor());
  const auto frame = (*dataset)->loadFrame(1);
  ASSERT_TRUE(frame.ok()) << frame.status();
  EXPECT_FALSE(frame->color.has_value());
  EXPECT_FLOAT_EQ(frame->depth.at(3, 2), 1.273f);
}

TEST(SevenScenesDataset, ReadsJpegColourAsTsdfFusionShipsIt) {
  TempDir dir;
  copySample(dir);
  for (int n : {0, 1, 3}) {
    ASSERT_TRUE(fs::remove(dir / absl::StrFormat("frame-%06d.color.png", n)));
    // Uniform colour survives JPEG almost exactly. OpenCV takes BGR.
    const cv::Mat bgr(6, 8, CV_8UC3, cv::Scalar(30, 120, 200 + n));
    ASSERT_TRUE(cv::imwrite((dir / absl::StrFormat("frame-%06d.color.jpg", n)).string(), bgr));
  }
  const auto dataset = openDataset(dir.path());
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_TRUE((*dataset)->hasColor());
  const auto frame = (*dataset)->loadFrame(2);
  ASSERT_TRUE(frame.ok()) << frame.status();
  ASSERT_TRUE(frame->color.has_value());
  const Rgb8 rgb = frame->color->at(4, 3);
  EXPECT_NEAR(rgb.r, 203, 3);
  EXPECT_NEAR(rgb.g, 120, 3);
  EXPECT_NEAR(rgb.b, 30, 3);
}

TEST(SevenScenesDataset, FramesSortNumericallyNotByName) {
  TempDir dir;
  ASSERT_TRUE(writeTextFile(dir / "camera-intrinsics.txt", "5 0 1.5\n0 5 1\n0 0 1\n"));
  // "frame-10" sorts before "frame-9" as text.
  for (int n : {9, 10, 100}) {
    ASSERT_TRUE(writeUint16Png(dir / absl::StrFormat("frame-%d.depth.png", n),
                               RawDepthImage(3, 2, uint16_t(n)))
                    .ok());
    ASSERT_TRUE(writeTextFile(dir / absl::StrFormat("frame-%d.pose.txt", n),
                              absl::StrFormat("1 0 0 %d\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", n)));
  }
  ASSERT_TRUE(writeTextFile(dir / "README.txt", "not a frame"));
  ASSERT_TRUE(writeTextFile(dir / "frame-notes.txt", "not a frame either"));
  const auto dataset = SevenScenesDataset::open(dir.path());
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_EQ((*dataset)->intrinsics(), (Intrinsics{3, 2, 5.0, 5.0, 1.5, 1.0}));
  ASSERT_EQ((*dataset)->size(), 3u);
  const int numbers[3] = {9, 10, 100};
  for (size_t i = 0; i < 3; ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ((*dataset)->frameNumber(i), uint64_t(numbers[i]));
    const auto frame = (*dataset)->loadFrame(i);
    ASSERT_TRUE(frame.ok()) << frame.status();
    EXPECT_EQ(frame->T_world_camera.translation().x(), double(numbers[i]));
    EXPECT_FLOAT_EQ(frame->depth.at(2, 1), 0.001f * float(numbers[i]));
  }
}

TEST(SevenScenesDataset, SequenceFolderTakesIntrinsicsFromItsScene) {
  TempDir dir;
  const fs::path sequence = dir / "seq-01";
  fs::create_directories(sequence);
  fs::copy(kSample, sequence, fs::copy_options::recursive);
  fs::rename(sequence / "camera-intrinsics.txt", dir / "camera-intrinsics.txt");
  const auto dataset = openDataset(sequence);
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_EQ((*dataset)->layout(), "7scenes");
  EXPECT_EQ((*dataset)->intrinsics(), kSampleCamera);
  EXPECT_EQ((*dataset)->size(), 3u);

  // The scene folder itself holds no frames: the error says to open a sequence.
  const auto scene = openDataset(dir.path());
  ASSERT_FALSE(scene.ok());
  EXPECT_EQ(scene.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(message(scene.status()), HasSubstr(dir.path().string()));
  EXPECT_THAT(message(scene.status()), HasSubstr("seq-NN"));

  // Raw 7-Scenes has no intrinsics file anywhere: the folder is still recognised by its pose
  // files, and the error asks for the intrinsics.
  fs::remove(dir / "camera-intrinsics.txt");
  const auto raw = openDataset(sequence);
  ASSERT_FALSE(raw.ok());
  EXPECT_EQ(raw.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(message(raw.status()), HasSubstr("camera-intrinsics.txt"));
  EXPECT_THAT(message(raw.status()), HasSubstr("DatasetOptions::intrinsics"));
  DatasetOptions options;
  options.intrinsics = Intrinsics{8, 6, 585.0 / 80.0, 585.0 / 80.0, 4.0, 3.0};
  const auto with_override = openDataset(sequence, options);
  ASSERT_TRUE(with_override.ok()) << with_override.status();
  EXPECT_EQ((*with_override)->intrinsics(), *options.intrinsics);
}

TEST(SevenScenesDataset, DepthWithoutPoseFileIsNamed) {
  TempDir dir;
  copySample(dir);
  fs::remove(dir / "frame-000001.pose.txt");
  const auto dataset = openDataset(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_EQ(dataset.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(message(dataset.status()),
              HasSubstr((dir / "frame-000001.depth.png").string() + " has no pose file " +
                        (dir / "frame-000001.pose.txt").string()));
}

TEST(SevenScenesDataset, PoseWithoutDepthIsNamed) {
  TempDir dir;
  copySample(dir);
  ASSERT_TRUE(writeTextFile(dir / "frame-000002.pose.txt", "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"));
  const auto dataset = openDataset(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_EQ(dataset.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(message(dataset.status()),
              HasSubstr("pose file " + (dir / "frame-000002.pose.txt").string() +
                        " has no depth image " + (dir / "frame-000002.depth.png").string()));
}

TEST(SevenScenesDataset, ColourOnSomeFramesOnlyIsAnError) {
  TempDir dir;
  copySample(dir);
  fs::remove(dir / "frame-000003.color.png");
  const auto dataset = openDataset(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_EQ(dataset.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(message(dataset.status()),
              HasSubstr((dir / "frame-000003.depth.png").string() + " has no colour image"));
  EXPECT_THAT(message(dataset.status()), HasSubstr("2 of the 3 frames"));
}

TEST(SevenScenesDataset, TwoFilesForOneFrameAreAnError) {
  TempDir dir;
  copySample(dir);
  fs::copy(dir / "frame-000001.depth.png", dir / "frame-1.depth.png");
  const auto dataset = openDataset(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_EQ(dataset.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(message(dataset.status()), HasSubstr("frame-1.depth.png"));
  EXPECT_THAT(message(dataset.status()), HasSubstr("frame-000001.depth.png"));
  EXPECT_THAT(message(dataset.status()), HasSubstr("both the depth image of frame 1"));
}

TEST(SevenScenesDataset, NonRigidPosesAreNamedWithWhatIsWrong) {
  TempDir dir;
  copySample(dir);
  const fs::path path = dir / "frame-000001.pose.txt";
  const auto check = [&](const std::string& text, const std::string& expected) {
    SCOPED_TRACE(text);
    ASSERT_TRUE(writeTextFile(path, text));
    const auto dataset = openDataset(dir.path());
    ASSERT_FALSE(dataset.ok());
    EXPECT_EQ(dataset.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(message(dataset.status()), HasSubstr(path.string()));
    EXPECT_THAT(message(dataset.status()), HasSubstr(expected));
  };
  // Scaled by 2 (a similarity, not a rigid motion).
  check("2 0 0 1\n0 2 0 2\n0 0 2 3\n0 0 0 1\n", "not orthonormal");
  // Sheared.
  check("1 0.1 0 1\n0 1 0 2\n0 0 1 3\n0 0 0 1\n", "not orthonormal");
  // A mirror image: orthonormal but det = -1.
  check("-1 0 0 1\n0 1 0 2\n0 0 1 3\n0 0 0 1\n", "reflection");
  check("1 0 0 1\n0 1 0 2\n0 0 1 3\n0 0 1 1\n", "last row");
  check("1 0 0 nan\n0 1 0 2\n0 0 1 3\n0 0 0 1\n", "non-finite");
  check("1 0 0 -inf\n0 1 0 2\n0 0 1 3\n0 0 0 1\n", "non-finite");
  check("1 0 0 1\n0 1 0 2\n0 0 1 3\n", "has 3 rows");
  check("1 0 0 1\n0 1 0 2\n0 0 1 3\n0 0 0 1\n0 0 0 1\n", "line 5");
  check("1 0 0 1\n0 1 0\n0 0 1 3\n0 0 0 1\n", "line 2: expected 4 numbers");
  check("1 0 0 1\n0 1 0 2\n0 0 1 x3\n0 0 0 1\n", "line 3: 'x3' is not a number");
}

TEST(SevenScenesDataset, PoseRotationWithinToleranceIsMadeOrthonormal) {
  TempDir dir;
  const fs::path path = dir / "frame-000000.pose.txt";
  // Entries off by 4e-4 (inside 1e-3): accepted and projected onto the nearest rotation.
  ASSERT_TRUE(writeTextFile(path, "1.0002 0 0 1\n0 0.9998 0 2\n0 0 1 3\n0 0 0 1\n"));
  const auto T = readPoseMatrixFile(path);
  ASSERT_TRUE(T.ok()) << T.status();
  EXPECT_LT(poseError(*T, pose(Eigen::Matrix3d::Identity(), {1.0, 2.0, 3.0})), 1e-12);
  // Off by 2e-3 in RᵀR: rejected.
  ASSERT_TRUE(writeTextFile(path, "1.001 0 0 1\n0 1 0 2\n0 0 1 3\n0 0 0 1\n"));
  const auto bad = readPoseMatrixFile(path);
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(message(bad.status()), HasSubstr("not orthonormal"));
  EXPECT_THAT(message(bad.status()), HasSubstr("0.002"));
}

TEST(SevenScenesDataset, WrongSizeDepthIsNamed) {
  TempDir dir;
  copySample(dir);
  ASSERT_TRUE(writeUint16Png(dir / "frame-000003.depth.png", RawDepthImage(5, 4, 1000)).ok());
  const auto dataset = openDataset(dir.path());
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_TRUE((*dataset)->loadFrame(1).ok());
  const auto frame = (*dataset)->loadFrame(2);
  ASSERT_FALSE(frame.ok());
  EXPECT_EQ(frame.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(message(frame.status()),
              HasSubstr("depth image " + (dir / "frame-000003.depth.png").string() +
                        " is 5x4 but intrinsics are for 8x6"));

  // Colour of the wrong size, likewise.
  ASSERT_TRUE(writeColorPng(dir / "frame-000001.color.png", ColorImage(8, 7)).ok());
  const auto color = (*dataset)->loadFrame(1);
  ASSERT_FALSE(color.ok());
  EXPECT_THAT(message(color.status()),
              HasSubstr("frame-000001.color.png is 8x7 but intrinsics are for 8x6"));
}

TEST(SevenScenesDataset, FirstDepthImageSetsTheSizeAndMustBeSixteenBit) {
  TempDir dir;
  copySample(dir);
  ASSERT_TRUE(writeUint16Png(dir / "frame-000000.depth.png", RawDepthImage(5, 4, 1000)).ok());
  auto dataset = openDataset(dir.path());
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_EQ((*dataset)->intrinsics().width, 5);
  EXPECT_EQ((*dataset)->intrinsics().height, 4);
  const auto frame = (*dataset)->loadFrame(1);
  ASSERT_FALSE(frame.ok());
  EXPECT_THAT(message(frame.status()),
              HasSubstr("frame-000001.depth.png is 8x6 but intrinsics are for 5x4"));

  ASSERT_TRUE(writeColorPng(dir / "frame-000000.depth.png", ColorImage(8, 6)).ok());
  dataset = openDataset(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_THAT(message(dataset.status()), HasSubstr("frame-000000.depth.png is 8-bit"));
}

TEST(SevenScenesDataset, BadIntrinsicsFilesNameFileAndProblem) {
  TempDir dir;
  copySample(dir);
  const fs::path path = dir / "camera-intrinsics.txt";
  const auto check = [&](const std::string& text, const std::string& expected) {
    SCOPED_TRACE(text);
    ASSERT_TRUE(writeTextFile(path, text));
    const auto dataset = openDataset(dir.path());
    ASSERT_FALSE(dataset.ok());
    EXPECT_EQ(dataset.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(message(dataset.status()), HasSubstr(path.string()));
    EXPECT_THAT(message(dataset.status()), HasSubstr(expected));
  };
  check("11 0.5 3.5\n0 12 2.5\n0 0 1\n", "K[0][1] = 0.5");
  check("11 0 3.5\n0 12 2.5\n0 0 2\n", "last row is (0 0 2)");
  check("11 0 3.5 0\n0 12 2.5 0\n0 0 1 0\n", "line 1: expected 3 numbers");
  check("11 0 3.5\n0 12 2.5\n", "has 2 rows");
  check("11 0 30\n0 12 2.5\n0 0 1\n", "principal point (30, 2.5) is outside the 8x6 image");
  check("-11 0 3.5\n0 12 2.5\n0 0 1\n", "focal lengths");
  check("11 0 3.5\n0 nan 2.5\n0 0 1\n", "non-finite");
}

TEST(OpenDataset, UnknownLayoutListsAllThree) {
  TempDir dir;
  ASSERT_TRUE(writeTextFile(dir / "notes.txt", "nothing to see"));
  const auto dataset = openDataset(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_EQ(dataset.status().code(), absl::StatusCode::kInvalidArgument);
  const std::string text = message(dataset.status());
  EXPECT_THAT(text, HasSubstr(dir.path().string()));
  EXPECT_THAT(text, HasSubstr("poses.txt"));
  EXPECT_THAT(text, HasSubstr("depth.txt"));
  EXPECT_THAT(text, HasSubstr("camera-intrinsics.txt"));
  EXPECT_THAT(text, HasSubstr("7-Scenes"));
}

}  // namespace
}  // namespace objdb::io

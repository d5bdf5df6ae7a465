#include "core/io/tum_dataset.h"

#include <cmath>
#include <filesystem>
#include <string>
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

const fs::path kSample = fs::path(OBJDB_SOURCE_DIR) / "tests" / "data" / "tum_sample";

// make_sample.py: depth image k holds 5000 + 250 k + 10 v + u, except (1, 1) = 0.
float sampleDepthMetres(int u, int v, int k) {
  if (u == 1 && v == 1) return 0.0f;
  return float(5000 + 250 * k + 10 * v + u) * float(1.0 / 5000.0);
}

Transform expectedPose(const Eigen::Vector3d& t, const Eigen::Quaterniond& q) {
  Transform T = Transform::Identity();
  T.linear() = q.normalized().toRotationMatrix();
  T.translation() = t;
  return T;
}

double poseError(const Transform& a, const Transform& b) {
  return (a.matrix() - b.matrix()).cwiseAbs().maxCoeff();
}

TEST(TumDataset, SampleAssociatesNearestPoseAndSkipsFrameWithoutOne) {
  const auto opened = openDataset(kSample);
  ASSERT_TRUE(opened.ok()) << opened.status();
  const Dataset& dataset = **opened;
  EXPECT_EQ(dataset.layout(), "tum");
  EXPECT_EQ(dataset.intrinsics(), (Intrinsics{8, 6, 10.0, 10.0, 3.5, 2.5}));
  EXPECT_DOUBLE_EQ(dataset.metresPerDepthUnit(), 1.0 / 5000.0);
  EXPECT_TRUE(dataset.hasColor());
  EXPECT_FALSE(dataset.hasInstances());
  // 4 depth images; the one at 100.2 s has no pose within 0.02 s.
  ASSERT_EQ(dataset.size(), 3u);
  EXPECT_EQ(dynamic_cast<const TumDataset&>(dataset).framesWithoutPose(), 1u);

  struct Expected {
    double timestamp;
    int depth_file;  // k in make_sample.py
    Transform pose;
    int color_file;  // -1: no colour within 0.02 s
  };
  const Expected expected[3] = {
      {100.0, 0, expectedPose({1.0, 2.0, 3.0}, Eigen::Quaterniond(0.70710678, 0, 0, 0.70710678)),
       0},
      {100.033, 1, expectedPose({-0.5, 0.25, 1.5}, Eigen::Quaterniond(0.5, 0.5, 0.5, 0.5)), -1},
      {100.4, 3, expectedPose({0.0, -1.0, 0.75}, Eigen::Quaterniond(0, 0, 1, 0)), 2},
  };
  for (size_t i = 0; i < 3; ++i) {
    SCOPED_TRACE(i);
    const auto frame = dataset.loadFrame(i);
    ASSERT_TRUE(frame.ok()) << frame.status();
    EXPECT_EQ(frame->index, i);
    EXPECT_DOUBLE_EQ(frame->timestamp, expected[i].timestamp);
    EXPECT_LT(poseError(frame->T_world_camera, expected[i].pose), 1e-9);
    ASSERT_EQ(frame->depth.width, 8);
    ASSERT_EQ(frame->depth.height, 6);
    for (int v = 0; v < 6; ++v) {
      for (int u = 0; u < 8; ++u) {
        EXPECT_FLOAT_EQ(frame->depth.at(u, v), sampleDepthMetres(u, v, expected[i].depth_file))
            << u << "," << v;
      }
    }
    EXPECT_EQ(frame->depth.at(1, 1), 0.0f);
    EXPECT_FLOAT_EQ(frame->depth.at(0, 0), 1.0f + 0.05f * float(expected[i].depth_file));
    if (expected[i].color_file < 0) {
      EXPECT_FALSE(frame->color.has_value());
    } else {
      ASSERT_TRUE(frame->color.has_value());
      const Rgb8 expected_rgb{uint8_t(10 * 5), uint8_t(20 * 4),
                              uint8_t(50 * expected[i].color_file + 1)};
      EXPECT_EQ(frame->color->at(5, 4), expected_rgb);
    }
  }
}

TEST(TumDataset, WiderToleranceAssociatesEveryFrame) {
  DatasetOptions options;
  options.max_time_difference_s = 0.2;
  const auto dataset = TumDataset::open(kSample, options);
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_EQ((*dataset)->size(), 4u);
  EXPECT_EQ((*dataset)->framesWithoutPose(), 0u);
}

TEST(TumDataset, IntrinsicsOverrideReplacesFile) {
  DatasetOptions options;
  options.intrinsics = Intrinsics{8, 6, 20.0, 20.0, 4.0, 3.0};
  const auto dataset = TumDataset::open(kSample, options);
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_EQ((*dataset)->intrinsics(), *options.intrinsics);
}

TEST(TumDataset, MissingIntrinsicsNeedsOverride) {
  TempDir dir;
  fs::copy(kSample, dir.path(), fs::copy_options::recursive);
  fs::remove(dir / "intrinsics.json");
  auto dataset = TumDataset::open(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("intrinsics.json"));
  DatasetOptions options;
  options.intrinsics = Intrinsics{8, 6, 10.0, 10.0, 3.5, 2.5};
  dataset = TumDataset::open(dir.path(), options);
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_DOUBLE_EQ((*dataset)->metresPerDepthUnit(), 1.0 / kTumDepthFactor);
}

TEST(TumDataset, DepthFactorComesFromIntrinsicsFile) {
  TempDir dir;
  fs::copy(kSample, dir.path(), fs::copy_options::recursive);
  ASSERT_TRUE(writeTextFile(dir / "intrinsics.json",
                            R"({"width": 8, "height": 6, "fx": 10, "fy": 10, "cx": 3.5,
                                "cy": 2.5, "depth_factor": 1000})"));
  const auto dataset = TumDataset::open(dir.path());
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  const auto frame = (*dataset)->loadFrame(0);
  ASSERT_TRUE(frame.ok());
  EXPECT_FLOAT_EQ(frame->depth.at(0, 0), 5.0f);
}

TEST(TumDataset, BadListsNameFileAndLine) {
  TempDir dir;
  fs::copy(kSample, dir.path(), fs::copy_options::recursive);
  ASSERT_TRUE(writeTextFile(dir / "depth.txt", "# c\n100.0 depth/100.000000.png\n100.1\n"));
  auto dataset = TumDataset::open(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("depth.txt line 3"));

  ASSERT_TRUE(writeTextFile(dir / "depth.txt", "abc depth/100.000000.png\n"));
  dataset = TumDataset::open(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("depth.txt line 1"));
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("timestamp 'abc'"));

  ASSERT_TRUE(writeTextFile(dir / "depth.txt", "100.0 ../../etc/passwd\n"));
  dataset = TumDataset::open(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("must be relative"));

  ASSERT_TRUE(writeTextFile(dir / "depth.txt", "100.0 depth/100.000000.png\n"));
  ASSERT_TRUE(writeTextFile(dir / "groundtruth.txt", "# c\n# c\n100.0 1 2 3 0 0 0\n"));
  dataset = TumDataset::open(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("groundtruth.txt line 3"));

  fs::remove(dir / "groundtruth.txt");
  dataset = TumDataset::open(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_EQ(dataset.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("groundtruth.txt"));
}

TEST(TumDataset, MissingDepthImageIsNamedWhenLoaded) {
  TempDir dir;
  fs::copy(kSample, dir.path(), fs::copy_options::recursive);
  fs::remove(dir / "depth" / "100.033000.png");
  const auto dataset = TumDataset::open(dir.path());
  ASSERT_TRUE(dataset.ok());
  EXPECT_TRUE((*dataset)->loadFrame(0).ok());
  const auto frame = (*dataset)->loadFrame(1);
  ASSERT_FALSE(frame.ok());
  EXPECT_EQ(frame.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(std::string(frame.status().message()), HasSubstr("depth/100.033000.png"));
}

// The TUM sample plus ground truth: instances/<depth stem>.png for each of its four depth
// images, holding 100 k + 10 v + u (k = position in depth.txt), and an objects.json.
const char* const kSampleDepthStems[4] = {"100.000000", "100.033000", "100.200000", "100.400000"};

InstanceImage sampleInstances(int k) {
  InstanceImage ids(8, 6);
  for (int v = 0; v < 6; ++v) {
    for (int u = 0; u < 8; ++u) ids.at(u, v) = uint16_t(100 * k + 10 * v + u);
  }
  ids.at(0, 0) = 0;      // no object
  ids.at(7, 5) = 65535;  // the largest id
  return ids;
}

std::vector<GroundTruthObject> sampleObjects() {
  GroundTruthObject chair;
  chair.id = 12;
  chair.category = "chair";
  chair.mesh = "meshes/chair.ply";
  chair.T_world_object = poseFromXyzYaw(Eigen::Vector3d(1.0, -2.0, 0.0), 0.5);
  GroundTruthObject floor;
  floor.id = 65535;
  floor.category = "floor";
  floor.is_structure = true;
  return {chair, floor};
}

void writeGroundTruthSample(const TempDir& dir) {
  fs::copy(kSample, dir.path(), fs::copy_options::recursive);
  fs::create_directories(dir / "instances");
  for (int k = 0; k < 4; ++k) {
    ASSERT_TRUE(writeUint16Png(dir / "instances" / (std::string(kSampleDepthStems[k]) + ".png"),
                               sampleInstances(k))
                    .ok());
  }
  ASSERT_TRUE(writeObjectsJson(dir / "objects.json", sampleObjects()).ok());
}

TEST(TumDataset, InstancesFolderGivesEachFrameItsGroundTruthImage) {
  TempDir dir;
  ASSERT_NO_FATAL_FAILURE(writeGroundTruthSample(dir));
  const auto opened = openDataset(dir.path());
  ASSERT_TRUE(opened.ok()) << opened.status();
  ASSERT_EQ((*opened)->layout(), "tum");
  const auto& dataset = dynamic_cast<const TumDataset&>(**opened);
  EXPECT_TRUE(dataset.hasInstances());
  EXPECT_EQ(dataset.objects(), sampleObjects());
  ASSERT_EQ(dataset.size(), 3u);
  // Frames 0, 1, 2 are depth images 0, 1, 3 (the one at 100.2 s has no pose).
  const int depth_file[3] = {0, 1, 3};
  for (size_t i = 0; i < 3; ++i) {
    SCOPED_TRACE(i);
    const auto frame = dataset.loadFrame(i);
    ASSERT_TRUE(frame.ok()) << frame.status();
    ASSERT_TRUE(frame->instances.has_value());
    EXPECT_EQ(*frame->instances, sampleInstances(depth_file[i]));
    EXPECT_EQ(frame->instances->at(3, 2), 100 * depth_file[i] + 23);
    EXPECT_EQ(frame->instances->at(7, 5), 65535);
    EXPECT_FLOAT_EQ(frame->depth.at(0, 0), 1.0f + 0.05f * float(depth_file[i]));
  }
}

// label-fusion's layout: labels/<depth stem>.png of 8-bit class ids and no objects.json serve as
// the instances; a colour image there is an error naming it.
TEST(TumDataset, LabelsFolderOf8BitClassIdsServesAsInstances) {
  TempDir dir;
  fs::copy(kSample, dir.path(), fs::copy_options::recursive);
  fs::create_directories(dir / "labels");
  for (int k = 0; k < 4; ++k) {
    cv::Mat labels(6, 8, CV_8UC1);
    for (int v = 0; v < 6; ++v) {
      for (int u = 0; u < 8; ++u) labels.at<uint8_t>(v, u) = uint8_t(40 * k + 8 * v + u);
    }
    ASSERT_TRUE(cv::imwrite((dir / "labels" / (std::string(kSampleDepthStems[k]) + ".png")).string(),
                            labels));
  }
  const auto opened = openDataset(dir.path());
  ASSERT_TRUE(opened.ok()) << opened.status();
  const auto& dataset = dynamic_cast<const TumDataset&>(**opened);
  EXPECT_TRUE(dataset.hasInstances());
  EXPECT_EQ(dataset.instancesFolder(), "labels");
  EXPECT_TRUE(dataset.objects().empty());
  const auto frame = dataset.loadFrame(2);  // depth image 3
  ASSERT_TRUE(frame.ok()) << frame.status();
  ASSERT_TRUE(frame->instances.has_value());
  EXPECT_EQ(frame->instances->at(3, 2), 40 * 3 + 8 * 2 + 3);
  EXPECT_EQ(frame->instances->at(7, 5), 40 * 3 + 8 * 5 + 7);
  // A colour image is no id image.
  cv::Mat colour(6, 8, CV_8UC3, cv::Scalar(1, 2, 3));
  const fs::path bad = dir / "labels" / "100.000000.png";
  ASSERT_TRUE(cv::imwrite(bad.string(), colour));
  const auto broken = dataset.loadFrame(0);
  ASSERT_FALSE(broken.ok());
  EXPECT_THAT(std::string(broken.status().message()), HasSubstr(bad.string()));
  EXPECT_THAT(std::string(broken.status().message()), HasSubstr("3 channels"));
}

TEST(TumDataset, WithoutGroundTruthFramesHaveNoInstances) {
  const auto dataset = TumDataset::open(kSample);
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_FALSE((*dataset)->hasInstances());
  EXPECT_TRUE((*dataset)->objects().empty());
  const auto frame = (*dataset)->loadFrame(0);
  ASSERT_TRUE(frame.ok()) << frame.status();
  EXPECT_FALSE(frame->instances.has_value());
}

TEST(TumDataset, WrongSizeInstancesImageIsNamed) {
  TempDir dir;
  ASSERT_NO_FATAL_FAILURE(writeGroundTruthSample(dir));
  const fs::path bad = dir / "instances" / "100.400000.png";
  ASSERT_TRUE(writeUint16Png(bad, InstanceImage(5, 4, 3)).ok());
  const auto dataset = TumDataset::open(dir.path());
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_TRUE((*dataset)->loadFrame(1).ok());
  const auto frame = (*dataset)->loadFrame(2);
  ASSERT_FALSE(frame.ok());
  EXPECT_EQ(frame.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(frame.status().message()),
              HasSubstr("instances image " + bad.string() + " is 5x4 but intrinsics are for 8x6"));
}

TEST(TumDataset, MissingInstancesImageIsNamed) {
  TempDir dir;
  ASSERT_NO_FATAL_FAILURE(writeGroundTruthSample(dir));
  const fs::path missing = dir / "instances" / "100.033000.png";
  ASSERT_TRUE(fs::remove(missing));
  const auto dataset = TumDataset::open(dir.path());
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_TRUE((*dataset)->loadFrame(0).ok());
  const auto frame = (*dataset)->loadFrame(1);
  ASSERT_FALSE(frame.ok());
  EXPECT_EQ(frame.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(std::string(frame.status().message()), HasSubstr(missing.string()));
}

TEST(TumDataset, BadObjectsJsonIsNamedWhenOpening) {
  TempDir dir;
  ASSERT_NO_FATAL_FAILURE(writeGroundTruthSample(dir));
  ASSERT_TRUE(writeTextFile(dir / "objects.json",
                            R"({"objects": [{"id": 0, "category": "chair",
                                "T_world_object": {"t": [0, 0, 0], "q": [0, 0, 0, 1]}}]})"));
  const auto dataset = openDataset(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_EQ(dataset.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("objects.json"));
  EXPECT_THAT(std::string(dataset.status().message()),
              HasSubstr("objects[0].id must be an integer in 1..65535"));
}

TEST(TumTrajectory, WriteReadRoundTripIsExact) {
  TempDir dir;
  std::vector<TumPose> poses(2);
  poses[0].timestamp = 1305031102.160407;
  poses[0].t = Eigen::Vector3d(0.1, -1.0 / 3.0, 2.5e-7);
  poses[1] = tumPoseFromTransform(poseFromXyzYaw(Eigen::Vector3d(1, 2, 3), 0.123), 17.0);
  ASSERT_TRUE(writeTumTrajectory(dir / "gt.txt", poses, "line one\nline two").ok());
  const auto back = readTumTrajectory(dir / "gt.txt");
  ASSERT_TRUE(back.ok()) << back.status();
  ASSERT_EQ(back->size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_EQ((*back)[i].timestamp, poses[i].timestamp);
    EXPECT_EQ((*back)[i].t, poses[i].t);
    EXPECT_EQ((*back)[i].q_xyzw, poses[i].q_xyzw);
  }
  poses[1].q_xyzw = {0, 0, 0, 0};
  const Status s = writeTumTrajectory(dir / "bad.txt", poses, "");
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("pose 1"));
}

Frame writerFrame(size_t k, const Intrinsics& intrinsics, bool color) {
  RawDepthImage raw(intrinsics.width, intrinsics.height);
  for (size_t i = 0; i < raw.data.size(); ++i) raw.data[i] = uint16_t(1000 + 97 * i + 13 * k);
  raw.data[3] = 0;
  Frame frame;
  frame.index = k;
  frame.timestamp = 50.0 + 0.1 * double(k);
  frame.depth = *depthFromRaw(raw, 1.0 / kTumDepthFactor);
  frame.T_world_camera = poseFromXyzYaw(Eigen::Vector3d(0.5 * double(k), 1.0, -2.0), 0.4 * k);
  if (color) {
    ColorImage image(intrinsics.width, intrinsics.height);
    for (size_t i = 0; i < image.data.size(); ++i) {
      image.data[i] = {uint8_t(i), uint8_t(2 * k), uint8_t(255 - i)};
    }
    frame.color = image;
  }
  return frame;
}

TEST(TumDatasetWriter, WriteThenReadBack) {
  TempDir dir;
  const Intrinsics camera{8, 6, 10.0, 10.0, 3.5, 2.5};
  auto writer = TumDatasetWriter::create(dir.path(), camera);
  ASSERT_TRUE(writer.ok()) << writer.status();
  for (size_t k = 0; k < 3; ++k) {
    ASSERT_TRUE((*writer)->addFrame(writerFrame(k, camera, k != 1)).ok());
  }
  ASSERT_TRUE((*writer)->finish().ok());
  EXPECT_EQ((*writer)->framesWritten(), 3u);

  const auto opened = openDataset(dir.path());
  ASSERT_TRUE(opened.ok()) << opened.status();
  EXPECT_EQ((*opened)->layout(), "tum");
  EXPECT_EQ((*opened)->intrinsics(), camera);
  ASSERT_EQ((*opened)->size(), 3u);
  for (size_t k = 0; k < 3; ++k) {
    SCOPED_TRACE(k);
    const Frame expected = writerFrame(k, camera, k != 1);
    const auto frame = (*opened)->loadFrame(k);
    ASSERT_TRUE(frame.ok()) << frame.status();
    EXPECT_EQ(frame->timestamp, expected.timestamp);
    EXPECT_EQ(frame->depth, expected.depth);
    EXPECT_LT(poseError(frame->T_world_camera, expected.T_world_camera), 1e-9);
    EXPECT_EQ(frame->color.has_value(), expected.color.has_value());
    if (expected.color) {
      EXPECT_EQ(*frame->color, *expected.color);
    }
  }

  const auto again = TumDatasetWriter::create(dir.path(), camera);
  ASSERT_FALSE(again.ok());
  EXPECT_EQ(again.status().code(), absl::StatusCode::kAlreadyExists);
  EXPECT_TRUE(TumDatasetWriter::create(dir.path(), camera, true).ok());
  EXPECT_FALSE(fs::exists(dir / "depth.txt"));
}

TEST(TumDatasetWriter, RejectsNonIncreasingTimestamps) {
  TempDir dir;
  const Intrinsics camera{8, 6, 10.0, 10.0, 3.5, 2.5};
  auto writer = TumDatasetWriter::create(dir.path(), camera);
  ASSERT_TRUE(writer.ok());
  ASSERT_TRUE((*writer)->addFrame(writerFrame(0, camera, false)).ok());
  Frame same_time = writerFrame(1, camera, false);
  same_time.timestamp = 50.0;
  const Status s = (*writer)->addFrame(same_time);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("not after"));
}

// Real TUM-layout sequences (e.g. SUN3D) in OBJDB_SHARED_DATA_DIR (absent in a fresh clone: skip).
TEST(TumDataset, SharedSequencesLoadFirstAndLastFrame) {
  const fs::path shared(OBJDB_SHARED_DATA_DIR);
  std::error_code ec;
  if (!fs::is_directory(shared, ec)) GTEST_SKIP() << "no shared data at " << shared;
  size_t sequences = 0;
  for (const auto& entry : fs::directory_iterator(shared)) {
    if (!entry.is_directory() || !fs::exists(entry.path() / "depth.txt")) continue;
    SCOPED_TRACE(entry.path().string());
    ++sequences;
    const auto dataset = openDataset(entry.path());
    ASSERT_TRUE(dataset.ok()) << dataset.status();
    EXPECT_EQ((*dataset)->layout(), "tum");
    ASSERT_GT((*dataset)->size(), 0u);
    for (size_t i : {size_t{0}, (*dataset)->size() - 1}) {
      const auto frame = (*dataset)->loadFrame(i);
      ASSERT_TRUE(frame.ok()) << frame.status();
      EXPECT_TRUE(validateFrame(*frame, (*dataset)->intrinsics()).ok());
      size_t valid = 0;
      for (float d : frame->depth.data) valid += (isValidDepth(d) && d < 10.0f) ? 1 : 0;
      EXPECT_GT(valid, frame->depth.data.size() / 10) << "frame " << i;
      EXPECT_TRUE(frame->color.has_value());
    }
  }
  if (sequences == 0) GTEST_SKIP() << "no TUM sequences in " << shared;
}

}  // namespace
}  // namespace objdb::io

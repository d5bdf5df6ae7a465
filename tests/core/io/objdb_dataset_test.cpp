#include "core/io/objdb_dataset.h"

#include <cmath>
#include <filesystem>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/io/image_io.h"
#include "tests/support/temp_dir.h"

namespace objdb::io {
namespace {

namespace fs = std::filesystem;
using objdb::testing::TempDir;
using objdb::testing::writeTextFile;
using ::testing::HasSubstr;

Intrinsics smallCamera() { return {8, 6, 10.0, 11.0, 3.5, 2.5}; }

// Frame k: depth from raw millimetres (so it survives the 16-bit round trip exactly), a colour
// gradient, two instances and a pose that differs per frame.
Frame makeFrame(size_t k, const Intrinsics& intrinsics, bool color = true, bool instances = true) {
  RawDepthImage raw(intrinsics.width, intrinsics.height);
  for (int v = 0; v < raw.height; ++v) {
    for (int u = 0; u < raw.width; ++u) raw.at(u, v) = uint16_t(500 + 100 * k + 37 * v + u);
  }
  raw.at(2, 3) = 0;  // no measurement
  Frame frame;
  frame.index = k;
  frame.timestamp = 1.0 + 0.0333 * double(k);
  frame.depth = *depthFromRaw(raw, 0.001);
  Transform T = Transform::Identity();
  T.linear() =
      Eigen::AngleAxisd(0.3 + 0.5 * double(k), Eigen::Vector3d(0.2, 1.0, -0.4).normalized())
          .toRotationMatrix();
  T.translation() = Eigen::Vector3d(0.1 * double(k), -1.25, 1.0 / 3.0);
  frame.T_world_camera = T;
  if (color) {
    ColorImage image(intrinsics.width, intrinsics.height);
    for (int v = 0; v < image.height; ++v) {
      for (int u = 0; u < image.width; ++u) {
        image.at(u, v) = {uint8_t(30 * u), uint8_t(40 * v), uint8_t(k * 60 + 1)};
      }
    }
    frame.color = image;
  }
  if (instances) {
    InstanceImage ids(intrinsics.width, intrinsics.height);
    for (int v = 0; v < ids.height; ++v) {
      for (int u = 0; u < ids.width; ++u) ids.at(u, v) = u < 4 ? 0 : uint16_t(7 + k * 1000);
    }
    ids.at(7, 5) = 65535;
    frame.instances = ids;
  }
  return frame;
}

std::vector<GroundTruthObject> makeObjects() {
  GroundTruthObject chair;
  chair.id = 7;
  chair.category = "round_chair";
  chair.mesh = "meshes/chair.ply";
  chair.T_world_object = poseFromXyzYaw(Eigen::Vector3d(1.0, 2.0, 0.0), 0.75);
  GroundTruthObject floor;
  floor.id = 65535;
  floor.category = "floor";
  floor.mesh = "procedural:plane";
  floor.is_structure = true;
  return {chair, floor};
}

Status writeDataset(const fs::path& root, size_t frames, bool color = true, bool instances = true) {
  auto writer = ObjdbDatasetWriter::create(root, smallCamera(), 0.001);
  if (!writer.ok()) return writer.status();
  for (size_t k = 0; k < frames; ++k) {
    OBJDB_RETURN_IF_ERROR((*writer)->addFrame(makeFrame(k, smallCamera(), color, instances)));
  }
  return (*writer)->finish(makeObjects());
}

TEST(ObjdbDataset, WriteThenReadIsBitExact) {
  TempDir dir;
  const fs::path root = dir / "session";
  ASSERT_TRUE(writeDataset(root, 3).ok());

  const auto opened = openDataset(root);
  ASSERT_TRUE(opened.ok()) << opened.status();
  const Dataset& dataset = **opened;
  EXPECT_EQ(dataset.layout(), "objdb");
  EXPECT_EQ(dataset.size(), 3u);
  EXPECT_TRUE(dataset.hasColor());
  EXPECT_TRUE(dataset.hasInstances());
  EXPECT_EQ(dataset.intrinsics(), smallCamera());
  EXPECT_EQ(dataset.metresPerDepthUnit(), 0.001);
  for (size_t k = 0; k < 3; ++k) {
    const Frame expected = makeFrame(k, smallCamera());
    const auto frame = dataset.loadFrame(k);
    ASSERT_TRUE(frame.ok()) << frame.status();
    EXPECT_EQ(frame->index, k);
    EXPECT_EQ(frame->timestamp, expected.timestamp);
    EXPECT_EQ(frame->depth, expected.depth);
    EXPECT_EQ(frame->depth.at(2, 3), 0.0f);
    ASSERT_TRUE(frame->color.has_value());
    EXPECT_EQ(*frame->color, *expected.color);
    ASSERT_TRUE(frame->instances.has_value());
    EXPECT_EQ(*frame->instances, *expected.instances);
    const double pose_error =
        (frame->T_world_camera.matrix() - expected.T_world_camera.matrix()).cwiseAbs().maxCoeff();
    EXPECT_LT(pose_error, 1e-9) << "frame " << k;
  }

  const auto objdb = ObjdbDataset::open(root);
  ASSERT_TRUE(objdb.ok());
  EXPECT_EQ((*objdb)->objects(), makeObjects());
}

TEST(ObjdbDataset, DepthOnlyDatasetHasNoColourOrInstances) {
  TempDir dir;
  ASSERT_TRUE(writeDataset(dir.path(), 2, false, false).ok());
  const auto dataset = ObjdbDataset::open(dir.path());
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_FALSE((*dataset)->hasColor());
  EXPECT_FALSE((*dataset)->hasInstances());
  const auto frame = (*dataset)->loadFrame(1);
  ASSERT_TRUE(frame.ok()) << frame.status();
  EXPECT_FALSE(frame->color.has_value());
  EXPECT_FALSE(frame->instances.has_value());
  EXPECT_TRUE((*dataset)->objects().size() == 2);
}

TEST(ObjdbDataset, LoadFrameOutOfRangeIsAnError) {
  TempDir dir;
  ASSERT_TRUE(writeDataset(dir.path(), 1).ok());
  const auto dataset = ObjdbDataset::open(dir.path());
  ASSERT_TRUE(dataset.ok());
  const auto frame = (*dataset)->loadFrame(1);
  ASSERT_FALSE(frame.ok());
  EXPECT_EQ(frame.status().code(), absl::StatusCode::kOutOfRange);
}

TEST(ObjdbDatasetWriter, RefusesExistingDatasetUnlessOverwrite) {
  TempDir dir;
  ASSERT_TRUE(writeDataset(dir.path(), 3).ok());
  const auto again = ObjdbDatasetWriter::create(dir.path(), smallCamera());
  ASSERT_FALSE(again.ok());
  EXPECT_EQ(again.status().code(), absl::StatusCode::kAlreadyExists);
  EXPECT_THAT(std::string(again.status().message()), HasSubstr(dir.path().string()));
  EXPECT_THAT(std::string(again.status().message()), HasSubstr("poses.txt"));

  // Overwriting replaces the whole dataset: no stale frames, colour or objects survive.
  auto writer = ObjdbDatasetWriter::create(dir.path(), smallCamera(), 0.0005, true);
  ASSERT_TRUE(writer.ok()) << writer.status();
  ASSERT_TRUE((*writer)->addFrame(makeFrame(0, smallCamera(), false, false)).ok());
  ASSERT_TRUE((*writer)->finish().ok());
  const auto dataset = ObjdbDataset::open(dir.path());
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_EQ((*dataset)->size(), 1u);
  EXPECT_EQ((*dataset)->metresPerDepthUnit(), 0.0005);
  EXPECT_FALSE((*dataset)->hasColor());
  EXPECT_TRUE((*dataset)->objects().empty());
  EXPECT_FALSE(fs::exists(dir / "depth" / "000001.png"));
}

TEST(ObjdbDatasetWriter, UnfinishedWriterLeavesNoPosesFile) {
  TempDir dir;
  {
    auto writer = ObjdbDatasetWriter::create(dir.path(), smallCamera());
    ASSERT_TRUE(writer.ok());
    ASSERT_TRUE((*writer)->addFrame(makeFrame(0, smallCamera())).ok());
    EXPECT_EQ((*writer)->framesWritten(), 1u);
  }
  EXPECT_TRUE(fs::exists(dir / "depth" / "000000.png"));
  EXPECT_FALSE(fs::exists(dir / "poses.txt"));
  const auto dataset = openDataset(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("none of the known layouts"));
}

TEST(ObjdbDatasetWriter, RejectsBadFrames) {
  TempDir dir;
  auto writer = ObjdbDatasetWriter::create(dir.path(), smallCamera());
  ASSERT_TRUE(writer.ok());
  ObjdbDatasetWriter& w = **writer;

  Status s = w.addFrame(makeFrame(1, smallCamera()));
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("expected frame 0, got frame 1"));

  Frame wrong_size = makeFrame(0, smallCamera());
  wrong_size.depth = DepthImage(4, 4, 1.0f);
  s = w.addFrame(wrong_size);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("frame 0 depth image is 4x4"));

  Frame nan_pose = makeFrame(0, smallCamera());
  nan_pose.T_world_camera.translation().y() = std::numeric_limits<double>::quiet_NaN();
  s = w.addFrame(nan_pose);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("non-finite"));

  ASSERT_TRUE(w.addFrame(makeFrame(0, smallCamera())).ok());
  s = w.addFrame(makeFrame(1, smallCamera(), /*color=*/false));
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("colour=no"));
  EXPECT_EQ(w.framesWritten(), 1u);

  ASSERT_TRUE(w.finish().ok());
  EXPECT_EQ(w.addFrame(makeFrame(1, smallCamera())).code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(w.finish().code(), absl::StatusCode::kFailedPrecondition);
}

TEST(ObjdbDatasetWriter, CountsDepthBeyondSixteenBits) {
  TempDir dir;
  auto writer = ObjdbDatasetWriter::create(dir.path(), smallCamera(), 0.001);
  ASSERT_TRUE(writer.ok());
  Frame frame = makeFrame(0, smallCamera(), false, false);
  frame.depth.at(0, 0) = 70.0f;  // 70000 mm does not fit
  frame.depth.at(1, 0) = std::numeric_limits<float>::quiet_NaN();
  ASSERT_TRUE((*writer)->addFrame(frame).ok());
  EXPECT_EQ((*writer)->clippedDepthPixels(), 1u);
  ASSERT_TRUE((*writer)->finish().ok());
  const auto dataset = ObjdbDataset::open(dir.path());
  ASSERT_TRUE(dataset.ok());
  const auto back = (*dataset)->loadFrame(0);
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(back->depth.at(0, 0), 0.0f);
  EXPECT_EQ(back->depth.at(1, 0), 0.0f);
}

TEST(ObjdbDataset, MalformedPosesLineNamesFileAndLine) {
  TempDir dir;
  ASSERT_TRUE(writeDataset(dir.path(), 3).ok());
  ASSERT_TRUE(writeTextFile(dir / "poses.txt",
                            "# comment\n"
                            "0.0 0 0 0 0 0 0 1\n"
                            "\n"
                            "0.1 0 0 0 0 0 0 1\n"
                            "0.2 0 0 zero 0 0 0 1\n"));
  auto dataset = ObjdbDataset::open(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_EQ(dataset.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("poses.txt line 5"));
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("tz 'zero'"));

  ASSERT_TRUE(writeTextFile(dir / "poses.txt", "0.0 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 1\n"));
  dataset = ObjdbDataset::open(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("poses.txt line 2"));
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("got 7"));

  ASSERT_TRUE(writeTextFile(dir / "poses.txt", "0.0 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 0 2\n"));
  dataset = ObjdbDataset::open(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("poses.txt line 2"));
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("squared norm"));

  ASSERT_TRUE(writeTextFile(dir / "poses.txt", "0.0 nan 0 0 0 0 0 1\n"));
  dataset = ObjdbDataset::open(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("poses.txt line 1"));
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("tx 'nan'"));
}

TEST(ObjdbDataset, CommentsAndBlankLinesDoNotCountAsFrames) {
  TempDir dir;
  ASSERT_TRUE(writeDataset(dir.path(), 3).ok());
  ASSERT_TRUE(writeTextFile(dir / "poses.txt",
                            "# header\n\n5.0 0 0 0 0 0 0 1\n  # note\r\n6.0 1 0 0 0 0 0 1\r\n"));
  const auto dataset = ObjdbDataset::open(dir.path());
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  ASSERT_EQ((*dataset)->size(), 2u);
  const auto frame = (*dataset)->loadFrame(1);
  ASSERT_TRUE(frame.ok());
  EXPECT_EQ(frame->timestamp, 6.0);
  EXPECT_EQ(frame->T_world_camera.translation(), Eigen::Vector3d(1, 0, 0));
  // Frame 1 is depth/000001.png, whatever its timestamp.
  EXPECT_EQ(frame->depth, makeFrame(1, smallCamera()).depth);
}

TEST(ObjdbDataset, MissingDepthPngIsNamed) {
  TempDir dir;
  ASSERT_TRUE(writeDataset(dir.path(), 3).ok());
  fs::remove(dir / "depth" / "000001.png");
  const auto dataset = ObjdbDataset::open(dir.path());
  ASSERT_TRUE(dataset.ok());
  EXPECT_TRUE((*dataset)->loadFrame(0).ok());
  const auto frame = (*dataset)->loadFrame(1);
  ASSERT_FALSE(frame.ok());
  EXPECT_EQ(frame.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(std::string(frame.status().message()), HasSubstr("depth/000001.png"));
}

TEST(ObjdbDataset, WrongImageSizeIsNamed) {
  TempDir dir;
  ASSERT_TRUE(writeDataset(dir.path(), 3).ok());
  ASSERT_TRUE(writeUint16Png(dir / "depth" / "000002.png", RawDepthImage(5, 4, 1000)).ok());
  ASSERT_TRUE(writeColorPng(dir / "color" / "000001.png", ColorImage(8, 7)).ok());
  const auto dataset = ObjdbDataset::open(dir.path());
  ASSERT_TRUE(dataset.ok());
  auto frame = (*dataset)->loadFrame(2);
  ASSERT_FALSE(frame.ok());
  EXPECT_THAT(std::string(frame.status().message()),
              HasSubstr("depth/000002.png is 5x4 but intrinsics are for 8x6"));
  frame = (*dataset)->loadFrame(1);
  ASSERT_FALSE(frame.ok());
  EXPECT_THAT(std::string(frame.status().message()),
              HasSubstr("color/000001.png is 8x7 but intrinsics are for 8x6"));
}

TEST(ObjdbDataset, MissingIntrinsicsOrPosesAreErrors) {
  TempDir dir;
  ASSERT_TRUE(writeDataset(dir.path(), 1).ok());
  fs::remove(dir / "intrinsics.json");
  auto dataset = ObjdbDataset::open(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("intrinsics.json"));

  DatasetOptions options;
  options.intrinsics = smallCamera();
  dataset = ObjdbDataset::open(dir.path(), options);
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  EXPECT_EQ((*dataset)->metresPerDepthUnit(), 0.001);

  const auto missing = ObjdbDataset::open(dir / "nowhere");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(std::string(missing.status().message()), HasSubstr("nowhere"));
}

TEST(OpenDataset, FolderWithNeitherLayoutIsNamed) {
  TempDir dir;
  const auto dataset = openDataset(dir.path());
  ASSERT_FALSE(dataset.ok());
  EXPECT_EQ(dataset.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr(dir.path().string()));
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("poses.txt"));
  EXPECT_THAT(std::string(dataset.status().message()), HasSubstr("depth.txt"));
  EXPECT_EQ(openDataset(dir / "missing").status().code(), absl::StatusCode::kNotFound);
}

TEST(IntrinsicsJson, RoundTripAndNotes) {
  TempDir dir;
  const Intrinsics k{
      640, 480, 615.1951904296875, 615.1952514648438, 298.44268798828125, 247.51919555664062};
  ASSERT_TRUE(writeIntrinsicsJson(dir / "intrinsics.json", k, 0.00025).ok());
  double scale = 0.0;
  auto back = readIntrinsicsJson(dir / "intrinsics.json", &scale);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(*back, k);
  EXPECT_EQ(scale, 0.00025);

  ASSERT_TRUE(writeTextFile(dir / "notes.json",
                            R"({"width": 8, "height": 6, "fx": 10, "fy": 10, "cx": 3.5,
                                "cy": 2.5, "source": "hand-written"})"));
  back = readIntrinsicsJson(dir / "notes.json", &scale);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(scale, 0.001);  // default
}

TEST(IntrinsicsJson, BadFilesNameFileAndKey) {
  TempDir dir;
  const auto check = [&](const std::string& text, const std::string& expected) {
    ASSERT_TRUE(writeTextFile(dir / "k.json", text));
    double scale = 0.0;
    const auto k = readIntrinsicsJson(dir / "k.json", &scale);
    ASSERT_FALSE(k.ok()) << text;
    EXPECT_THAT(std::string(k.status().message()), HasSubstr("k.json")) << text;
    EXPECT_THAT(std::string(k.status().message()), HasSubstr(expected)) << text;
  };
  check(R"({"width": 8, "height": 6, "fy": 10, "cx": 3.5, "cy": 2.5})", "missing key 'fx'");
  check(R"({"width": 8, "height": 6, "fx": 10, "fy": 10, "cx": 3.5, "cy": 2.5,
            "depth_scale": 0.001})",
        "unknown key 'depth_scale'");
  check(R"({"width": 8.5, "height": 6, "fx": 10, "fy": 10, "cx": 3.5, "cy": 2.5})",
        "'width' must be an integer");
  check(R"({"width": 8, "height": 6, "fx": "ten", "fy": 10, "cx": 3.5, "cy": 2.5})",
        "'fx' must be a number");
  check(R"({"width": 8, "height": 6, "fx": 10, "fy": 10, "cx": 30, "cy": 2.5})", "principal point");
  check(R"({"width": 8, "height": 6, "fx": 10, "fy": 10, "cx": 3.5, "cy": 2.5,
            "depth_scale_m": -1})",
        "depth_scale_m");
  check(R"({"width": 8, "height": 6,)", "not valid JSON");
  check(R"([8, 6])", "JSON object");
  const auto missing = readIntrinsicsJson(dir / "none.json", nullptr);
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
}

TEST(ObjectsJson, RoundTrip) {
  TempDir dir;
  ASSERT_TRUE(writeObjectsJson(dir / "objects.json", makeObjects()).ok());
  const auto back = readObjectsJson(dir / "objects.json");
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(*back, makeObjects());
}

TEST(ObjectsJson, BadEntriesNameIndexAndField) {
  TempDir dir;
  const auto check = [&](const std::string& text, const std::string& expected) {
    ASSERT_TRUE(writeTextFile(dir / "objects.json", text));
    const auto objects = readObjectsJson(dir / "objects.json");
    ASSERT_FALSE(objects.ok()) << text;
    EXPECT_THAT(std::string(objects.status().message()), HasSubstr("objects.json")) << text;
    EXPECT_THAT(std::string(objects.status().message()), HasSubstr(expected)) << text;
  };
  const std::string good =
      R"({"id": 1, "category": "chair", "mesh": "m", "structure": false,
          "T_world_object": {"t": [0, 0, 0], "q": [0, 0, 0, 1]}})";
  check(R"({"objects": [)" + good + R"(, {"id": 0, "category": "x",
        "T_world_object": {"t": [0, 0, 0], "q": [0, 0, 0, 1]}}]})",
        "objects[1].id must be an integer in 1..65535");
  check(R"({"objects": [)" + good + R"(, {"id": 2, "category": "x",
        "T_world_object": {"t": [0, 0, 0], "q": [0, 0, 0, 3]}}]})",
        "objects[1].T_world_object");
  check(R"({"objects": [)" + good + R"(, {"id": 2, "category": "x",
        "T_world_object": {"t": [0, 0], "q": [0, 0, 0, 1]}}]})",
        "objects[1].T_world_object.t must be an array of 3 numbers");
  check(R"({"objects": [)" + good + "," + good + "]}", "objects[1].id repeats id 1");
  check(R"({"objects": [{"id": 3, "T_world_object": {"t": [0, 0, 0], "q": [0, 0, 0, 1]}}]})",
        "objects[0].category is missing");
  check(R"({"objects": [{"id": 3, "category": "x", "structure": "yes",
        "T_world_object": {"t": [0, 0, 0], "q": [0, 0, 0, 1]}}]})",
        "objects[0].structure must be true or false");
  check(R"({"things": []})", "'objects'");
}

TEST(ObjectsJson, WriterRejectsBadIdsAndPoses) {
  TempDir dir;
  auto objects = makeObjects();
  objects[1].id = objects[0].id;
  EXPECT_THAT(std::string(writeObjectsJson(dir / "o.json", objects).message()),
              HasSubstr("repeats id 7"));
  objects = makeObjects();
  objects[0].T_world_object.linear()(0, 1) = 0.5;
  EXPECT_THAT(std::string(writeObjectsJson(dir / "o.json", objects).message()),
              HasSubstr("not orthonormal"));
  EXPECT_FALSE(fs::exists(dir / "o.json"));
}

}  // namespace
}  // namespace objdb::io

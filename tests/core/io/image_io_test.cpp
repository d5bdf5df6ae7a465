#include "core/io/image_io.h"

#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "tests/support/temp_dir.h"

namespace objdb::io {
namespace {

using objdb::testing::TempDir;
using ::testing::HasSubstr;

std::string readBytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

void writeBytes(const std::filesystem::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out << bytes;
}

ColorImage gradient(int w, int h) {
  ColorImage image(w, h);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      image.at(u, v) = {uint8_t(10 * u), uint8_t(20 * v), uint8_t(200 - u - v)};
    }
  }
  return image;
}

TEST(Uint16Png, RoundTripIsBitExact) {
  TempDir dir;
  RawDepthImage image(7, 5);
  for (size_t i = 0; i < image.data.size(); ++i) image.data[i] = uint16_t(i * 1871 + 3);
  image.at(0, 0) = 0;
  image.at(6, 4) = 65535;
  ASSERT_TRUE(writeUint16Png(dir / "d.png", image).ok());
  const auto back = readUint16Png(dir / "d.png");
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(*back, image);
  // Written as a real 16-bit single-channel PNG (what other tools expect).
  const cv::Mat mat = cv::imread((dir / "d.png").string(), cv::IMREAD_UNCHANGED);
  EXPECT_EQ(mat.type(), CV_16UC1);
  EXPECT_EQ(mat.at<uint16_t>(2, 3), image.at(3, 2));
}

TEST(Uint16Png, EightBitPngIsRejectedNamingFileAndExpectation) {
  TempDir dir;
  cv::Mat mat(4, 4, CV_8UC1, cv::Scalar(7));
  ASSERT_TRUE(cv::imwrite((dir / "000003.png").string(), mat));
  const auto image = readUint16Png(dir / "000003.png");
  ASSERT_FALSE(image.ok());
  EXPECT_EQ(image.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(image.status().message()), HasSubstr("000003.png is 8-bit"));
  EXPECT_THAT(std::string(image.status().message()), HasSubstr("expected 16-bit single channel"));
}

TEST(Uint16Png, ThreeChannelPngIsRejected) {
  TempDir dir;
  cv::Mat mat(4, 4, CV_16UC3, cv::Scalar(1, 2, 3));
  ASSERT_TRUE(cv::imwrite((dir / "rgb16.png").string(), mat));
  const auto image = readUint16Png(dir / "rgb16.png");
  ASSERT_FALSE(image.ok());
  EXPECT_THAT(std::string(image.status().message()), HasSubstr("rgb16.png has 3 channels"));
}

TEST(Uint16Png, MissingFileIsNotFoundAndNamed) {
  TempDir dir;
  const auto image = readUint16Png(dir / "depth" / "000042.png");
  ASSERT_FALSE(image.ok());
  EXPECT_EQ(image.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(std::string(image.status().message()), HasSubstr("depth/000042.png"));
}

TEST(Uint16Png, NonPngAndCorruptFilesAreRejected) {
  TempDir dir;
  writeBytes(dir / "text.png", "this is not an image");
  auto image = readUint16Png(dir / "text.png");
  ASSERT_FALSE(image.ok());
  EXPECT_THAT(std::string(image.status().message()), HasSubstr("text.png is not a PNG"));

  // A valid header whose image data is cut off.
  RawDepthImage big(64, 64);
  for (size_t i = 0; i < big.data.size(); ++i) big.data[i] = uint16_t(i * 7919);
  ASSERT_TRUE(writeUint16Png(dir / "full.png", big).ok());
  const std::string bytes = readBytes(dir / "full.png");
  writeBytes(dir / "cut.png", bytes.substr(0, bytes.size() / 2));
  image = readUint16Png(dir / "cut.png");
  ASSERT_FALSE(image.ok());
  EXPECT_THAT(std::string(image.status().message()), HasSubstr("cut.png"));

  writeBytes(dir / "header_only.png", bytes.substr(0, 20));
  image = readUint16Png(dir / "header_only.png");
  ASSERT_FALSE(image.ok());
  EXPECT_THAT(std::string(image.status().message()), HasSubstr("truncated PNG"));
}

TEST(Uint16Png, HeaderWithHugeSizeIsRejectedBeforeDecoding) {
  TempDir dir;
  RawDepthImage small(2, 2, 5);
  ASSERT_TRUE(writeUint16Png(dir / "small.png", small).ok());
  std::string bytes = readBytes(dir / "small.png");
  // IHDR width at offset 16 (big endian): claim 100000 x 100000 pixels.
  const unsigned char huge[4] = {0x00, 0x01, 0x86, 0xA0};
  bytes.replace(16, 4, reinterpret_cast<const char*>(huge), 4);
  bytes.replace(20, 4, reinterpret_cast<const char*>(huge), 4);
  writeBytes(dir / "huge.png", bytes);
  const auto image = readUint16Png(dir / "huge.png");
  ASSERT_FALSE(image.ok());
  EXPECT_THAT(std::string(image.status().message()), HasSubstr("huge.png is 100000x100000"));
}

TEST(Uint16Png, WriteRejectsInconsistentImageAndMissingFolder) {
  TempDir dir;
  RawDepthImage bad(4, 4);
  bad.data.resize(3);
  Status s = writeUint16Png(dir / "bad.png", bad);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("bad.png"));

  s = writeUint16Png(dir / "no_such_folder" / "x.png", RawDepthImage(2, 2));
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("no_such_folder"));

  s = writeUint16Png(dir / "x.jpg", RawDepthImage(2, 2));
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr(".png"));

  EXPECT_FALSE(writeUint16Png(dir / "empty.png", RawDepthImage()).ok());
}

TEST(ColorImage, PngRoundTripKeepsRgbOrder) {
  TempDir dir;
  const ColorImage image = gradient(9, 4);
  ASSERT_TRUE(writeColorPng(dir / "c.png", image).ok());
  const auto back = readColorImage(dir / "c.png");
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(*back, image);
  // On disk the PNG is ordinary RGB: OpenCV hands it back as BGR.
  const cv::Mat mat = cv::imread((dir / "c.png").string(), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(mat.type(), CV_8UC3);
  const cv::Vec3b bgr = mat.at<cv::Vec3b>(3, 5);
  EXPECT_EQ(bgr[2], image.at(5, 3).r);
  EXPECT_EQ(bgr[1], image.at(5, 3).g);
  EXPECT_EQ(bgr[0], image.at(5, 3).b);
}

TEST(ColorImage, ReadsJpegInRgbOrder) {
  TempDir dir;
  cv::Mat bgr(16, 16, CV_8UC3, cv::Scalar(200, 100, 30));  // b=200 g=100 r=30
  ASSERT_TRUE(cv::imwrite((dir / "c.jpg").string(), bgr, {cv::IMWRITE_JPEG_QUALITY, 100}));
  const auto image = readColorImage(dir / "c.jpg");
  ASSERT_TRUE(image.ok()) << image.status();
  EXPECT_EQ(image->width, 16);
  EXPECT_EQ(image->height, 16);
  EXPECT_NEAR(image->at(8, 8).r, 30, 3);
  EXPECT_NEAR(image->at(8, 8).g, 100, 3);
  EXPECT_NEAR(image->at(8, 8).b, 200, 3);
}

TEST(ColorImage, GreyImageIsExpanded) {
  TempDir dir;
  cv::Mat grey(3, 5, CV_8UC1, cv::Scalar(77));
  ASSERT_TRUE(cv::imwrite((dir / "g.png").string(), grey));
  const auto image = readColorImage(dir / "g.png");
  ASSERT_TRUE(image.ok()) << image.status();
  EXPECT_EQ(image->at(4, 2), (Rgb8{77, 77, 77}));
}

TEST(ColorImage, SixteenBitAndAlphaAndMissingAreRejected) {
  TempDir dir;
  ASSERT_TRUE(writeUint16Png(dir / "depth.png", RawDepthImage(4, 4, 1000)).ok());
  auto image = readColorImage(dir / "depth.png");
  ASSERT_FALSE(image.ok());
  EXPECT_THAT(std::string(image.status().message()),
              HasSubstr("depth.png is 16-bit; expected an 8-bit colour image"));

  cv::Mat rgba(4, 4, CV_8UC4, cv::Scalar(1, 2, 3, 4));
  ASSERT_TRUE(cv::imwrite((dir / "rgba.png").string(), rgba));
  image = readColorImage(dir / "rgba.png");
  ASSERT_FALSE(image.ok());
  EXPECT_THAT(std::string(image.status().message()), HasSubstr("rgba.png has 4 channels"));

  image = readColorImage(dir / "none.jpg");
  ASSERT_FALSE(image.ok());
  EXPECT_EQ(image.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(std::string(image.status().message()), HasSubstr("none.jpg"));

  writeBytes(dir / "fake.jpg", "GIF89a....");
  image = readColorImage(dir / "fake.jpg");
  ASSERT_FALSE(image.ok());
  EXPECT_THAT(std::string(image.status().message()), HasSubstr("neither PNG nor JPEG"));
}

TEST(ColorImage, JpegHeaderWithHugeSizeIsRejected) {
  TempDir dir;
  cv::Mat bgr(8, 8, CV_8UC3, cv::Scalar(1, 2, 3));
  ASSERT_TRUE(cv::imwrite((dir / "c.jpg").string(), bgr));
  std::string bytes = readBytes(dir / "c.jpg");
  // Patch the start-of-frame (FFC0) to claim 60000 x 60000.
  const size_t sof = bytes.find("\xFF\xC0");
  ASSERT_NE(sof, std::string::npos);
  bytes[sof + 5] = char(0xEA);
  bytes[sof + 6] = char(0x60);
  bytes[sof + 7] = char(0xEA);
  bytes[sof + 8] = char(0x60);
  writeBytes(dir / "huge.jpg", bytes);
  const auto image = readColorImage(dir / "huge.jpg");
  ASSERT_FALSE(image.ok());
  EXPECT_THAT(std::string(image.status().message()), HasSubstr("huge.jpg is 60000x60000"));
}

}  // namespace
}  // namespace objdb::io

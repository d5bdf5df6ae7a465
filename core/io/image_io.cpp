#include "core/io/image_io.h"

#include <array>
#include <cstring>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/common/intrinsics.h"
#include "core/io/io_util.h"

namespace objdb::io {
namespace {
namespace fs = std::filesystem;

enum class FileFormat { kPng, kJpeg, kOther };

// What the file header says, read before OpenCV decodes (and allocates) anything.
struct HeaderInfo {
  FileFormat format = FileFormat::kOther;
  int64_t width = -1;  // -1 when the header did not say
  int64_t height = -1;
  int bit_depth = -1;  // PNG only
  int channels = -1;   // PNG only: from the colour type (palette counts as 3)
};

uint32_t bigEndian32(const unsigned char* p) {
  return (uint32_t(p[0]) << 24) | (uint32_t(p[1]) << 16) | (uint32_t(p[2]) << 8) | uint32_t(p[3]);
}

// Walks the JPEG marker segments up to the first start-of-frame, which holds the image size.
// Leaves width/height at -1 when it cannot tell (OpenCV then decides).
void scanJpegHeader(std::string_view bytes, HeaderInfo* info) {
  size_t pos = 2;
  auto at = [&](size_t i) { return i < bytes.size() ? int(static_cast<unsigned char>(bytes[i])) : -1; };
  for (int segment = 0; segment < 4096; ++segment) {
    int c = at(pos++);
    if (c != 0xFF) return;
    while (c == 0xFF) c = at(pos++);  // fill bytes
    if (c < 0) return;
    const int marker = c;
    if (marker == 0xD8 || marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) continue;
    if (marker == 0xD9 || marker == 0xDA) return;  // end of image / start of scan
    if (pos + 2 > bytes.size()) return;
    const int length = (at(pos) << 8) | at(pos + 1);
    pos += 2;
    if (length < 2) return;
    const bool is_sof =
        marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
    if (is_sof) {
      if (length < 7 || pos + 5 > bytes.size()) return;
      info->height = (at(pos + 1) << 8) | at(pos + 2);
      info->width = (at(pos + 3) << 8) | at(pos + 4);
      return;
    }
    pos += size_t(length - 2);
    if (pos > bytes.size()) return;
  }
}

// The file's bytes; errors name the file (missing, not a regular file, unreadable).
StatusOr<std::string> readImageFile(const fs::path& path) {
  std::error_code ec;
  const auto status = fs::status(path, ec);
  if (!fs::exists(status)) {
    return absl::NotFoundError(absl::StrCat("image ", path.string(), " does not exist"));
  }
  if (!fs::is_regular_file(status)) {
    return absl::InvalidArgumentError(
        absl::StrCat("image ", path.string(), " is not a regular file"));
  }
  auto bytes = internal::readFile(path);
  if (!bytes.ok()) {
    return absl::UnavailableError(
        absl::StrCat("cannot read image ", path.string(), ": ", bytes.status().message()));
  }
  return bytes;
}

// What the encoded image's header says; `name` names it in errors.
StatusOr<HeaderInfo> readHeader(std::string_view bytes, const std::string& name) {
  const auto* head = reinterpret_cast<const unsigned char*>(bytes.data());
  const size_t got = bytes.size();
  HeaderInfo info;
  static constexpr unsigned char kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  if (got >= 8 && std::memcmp(head, kPngSignature, 8) == 0) {
    info.format = FileFormat::kPng;
    if (got < 33 || std::memcmp(head + 12, "IHDR", 4) != 0) {
      return absl::InvalidArgumentError(
          absl::StrCat(name, " is a truncated PNG (no IHDR header)"));
    }
    info.width = bigEndian32(head + 16);
    info.height = bigEndian32(head + 20);
    info.bit_depth = head[24];
    switch (head[25]) {
      case 0:
        info.channels = 1;
        break;
      case 2:
        info.channels = 3;
        break;
      case 3:
        info.channels = 3;
        break;
      case 4:
        info.channels = 2;
        break;
      case 6:
        info.channels = 4;
        break;
      default:
        return absl::InvalidArgumentError(
            absl::StrFormat("%s has an invalid PNG colour type %d", name, int(head[25])));
    }
  } else if (got >= 3 && head[0] == 0xFF && head[1] == 0xD8 && head[2] == 0xFF) {
    info.format = FileFormat::kJpeg;
    scanJpegHeader(bytes, &info);
  }
  return info;
}

Status checkHeaderSize(const std::string& name, const HeaderInfo& info) {
  if (info.width < 0) return absl::OkStatus();
  if (info.width >= 1 && info.width <= kMaxImageSide && info.height >= 1 &&
      info.height <= kMaxImageSide) {
    return absl::OkStatus();
  }
  return absl::InvalidArgumentError(absl::StrFormat("%s is %dx%d pixels; expected 1..%d per side",
                                                    name, info.width, info.height,
                                                    kMaxImageSide));
}

// With an expected size (> 0), the header must announce exactly it: nothing else is decoded.
Status checkExpectedSize(const std::string& name, const HeaderInfo& info, int width, int height) {
  if (width <= 0) return absl::OkStatus();
  if (info.width < 0) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%s: its header does not tell its size (expected %dx%d)", name, width,
                        height));
  }
  if (info.width != width || info.height != height) {
    return absl::InvalidArgumentError(absl::StrFormat("%s is %dx%d pixels; expected %dx%d", name,
                                                      info.width, info.height, width, height));
  }
  return absl::OkStatus();
}

StatusOr<cv::Mat> decode(std::string_view bytes, const std::string& name) {
  cv::Mat mat;
  try {
    const cv::Mat buffer(1, int(bytes.size()), CV_8UC1, const_cast<char*>(bytes.data()));
    mat = cv::imdecode(buffer, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    return absl::InvalidArgumentError(absl::StrCat("cannot decode image ", name, ": ", e.what()));
  }
  if (mat.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat("cannot decode image ", name, " (corrupt or truncated data)"));
  }
  if (!(mat.dims == 2 && mat.cols >= 1 && mat.cols <= kMaxImageSide && mat.rows >= 1 &&
        mat.rows <= kMaxImageSide)) {
    return absl::InvalidArgumentError(absl::StrFormat("%s is %dx%d pixels; expected 1..%d per side",
                                                      name, mat.cols, mat.rows, kMaxImageSide));
  }
  return mat;
}

const char* depthName(int cv_depth) {
  switch (cv_depth) {
    case CV_8U:
      return "8-bit";
    case CV_8S:
      return "8-bit signed";
    case CV_16U:
      return "16-bit";
    case CV_16S:
      return "16-bit signed";
    case CV_32S:
      return "32-bit integer";
    case CV_32F:
      return "32-bit float";
    case CV_64F:
      return "64-bit float";
    default:
      return "of unknown depth";
  }
}

bool hasPngExtension(const fs::path& path) {
  return internal::toLower(path.extension().string()) == ".png";
}

Status checkImageForWrite(const fs::path& path, int width, int height, size_t pixels) {
  if (!hasPngExtension(path)) {
    return absl::InvalidArgumentError(
        absl::StrCat("cannot write ", path.string(), ": the name must end in .png"));
  }
  if (!(width >= 1 && width <= kMaxImageSide && height >= 1 && height <= kMaxImageSide)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("cannot write %s: image is %dx%d; expected 1..%d per side", path.string(),
                        width, height, kMaxImageSide));
  }
  if (pixels != size_t(width) * size_t(height)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("cannot write %s: image is %dx%d but holds %d pixels", path.string(), width,
                        height, pixels));
  }
  return absl::OkStatus();
}

Status encodeAndWrite(const fs::path& path, const cv::Mat& mat) {
  std::vector<uchar> buffer;
  try {
    if (!cv::imencode(".png", mat, buffer)) {
      return absl::InternalError(absl::StrCat("cannot encode ", path.string(), " as PNG"));
    }
  } catch (const cv::Exception& e) {
    return absl::InternalError(
        absl::StrCat("cannot encode ", path.string(), " as PNG: ", e.what()));
  }
  return internal::writeFileAtomic(
      path, absl::string_view(reinterpret_cast<const char*>(buffer.data()), buffer.size()));
}

}  // namespace

StatusOr<RawDepthImage> decodeUint16Png(std::string_view bytes, const std::string& name,
                                        int expect_width, int expect_height) {
  OBJDB_ASSIGN_OR_RETURN(const HeaderInfo header, readHeader(bytes, name));
  if (header.format != FileFormat::kPng) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, " is not a PNG file; expected a 16-bit single-channel PNG"));
  }
  OBJDB_RETURN_IF_ERROR(checkHeaderSize(name, header));
  OBJDB_RETURN_IF_ERROR(checkExpectedSize(name, header, expect_width, expect_height));
  if (header.bit_depth != 16) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s is %d-bit; expected 16-bit single channel", name, header.bit_depth));
  }
  if (header.channels != 1) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s has %d channels; expected 16-bit single channel", name, header.channels));
  }
  OBJDB_ASSIGN_OR_RETURN(const cv::Mat mat, decode(bytes, name));
  if (mat.depth() != CV_16U || mat.channels() != 1) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%s decodes as %s with %d channels; expected 16-bit single channel",
                        name, depthName(mat.depth()), mat.channels()));
  }
  RawDepthImage image(mat.cols, mat.rows);
  for (int v = 0; v < mat.rows; ++v) {
    std::memcpy(&image.at(0, v), mat.ptr<uint16_t>(v), size_t(mat.cols) * sizeof(uint16_t));
  }
  return image;
}

StatusOr<RawDepthImage> readUint16Png(const fs::path& path) {
  OBJDB_ASSIGN_OR_RETURN(const std::string bytes, readImageFile(path));
  return decodeUint16Png(bytes, path.string());
}

StatusOr<Image<uint16_t>> readIdPng(const fs::path& path) {
  OBJDB_ASSIGN_OR_RETURN(const std::string bytes, readImageFile(path));
  const std::string name = path.string();
  OBJDB_ASSIGN_OR_RETURN(const HeaderInfo header, readHeader(bytes, name));
  if (header.format != FileFormat::kPng || header.bit_depth != 8) {
    return decodeUint16Png(bytes, name);  // 16-bit, or the error saying what it is instead
  }
  OBJDB_RETURN_IF_ERROR(checkHeaderSize(name, header));
  if (header.channels != 1) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s has %d channels; expected a single-channel 8- or 16-bit id image", name,
        header.channels));
  }
  OBJDB_ASSIGN_OR_RETURN(const cv::Mat mat, decode(bytes, name));
  if (mat.depth() != CV_8U || mat.channels() != 1) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s decodes as %s with %d channels; expected a single-channel id image", name,
        depthName(mat.depth()), mat.channels()));
  }
  Image<uint16_t> image(mat.cols, mat.rows);
  for (int v = 0; v < mat.rows; ++v) {
    const uint8_t* row = mat.ptr<uint8_t>(v);
    for (int u = 0; u < mat.cols; ++u) image.at(u, v) = row[u];
  }
  return image;
}

Status writeUint16Png(const fs::path& path, const Image<uint16_t>& image) {
  OBJDB_RETURN_IF_ERROR(checkImageForWrite(path, image.width, image.height, image.data.size()));
  const cv::Mat mat(image.height, image.width, CV_16UC1, const_cast<uint16_t*>(image.data.data()));
  return encodeAndWrite(path, mat);
}

StatusOr<ColorImage> decodeColorImage(std::string_view bytes, const std::string& name,
                                      int expect_width, int expect_height) {
  OBJDB_ASSIGN_OR_RETURN(const HeaderInfo header, readHeader(bytes, name));
  if (header.format == FileFormat::kOther) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, " is neither PNG nor JPEG; expected an 8-bit colour image"));
  }
  OBJDB_RETURN_IF_ERROR(checkHeaderSize(name, header));
  OBJDB_RETURN_IF_ERROR(checkExpectedSize(name, header, expect_width, expect_height));
  if (header.format == FileFormat::kPng && header.bit_depth > 8) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s is %d-bit; expected an 8-bit colour image", name, header.bit_depth));
  }
  OBJDB_ASSIGN_OR_RETURN(const cv::Mat mat, decode(bytes, name));
  if (mat.depth() != CV_8U) {
    return absl::InvalidArgumentError(absl::StrFormat("%s is %s; expected an 8-bit colour image",
                                                      name, depthName(mat.depth())));
  }
  const int channels = mat.channels();
  if (channels != 3 && channels != 1) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s has %d channels; expected 3 (colour) or 1 (grey)", name, channels));
  }
  ColorImage image(mat.cols, mat.rows);
  for (int v = 0; v < mat.rows; ++v) {
    const uint8_t* row = mat.ptr<uint8_t>(v);
    Rgb8* out = &image.at(0, v);
    if (channels == 3) {
      for (int u = 0; u < mat.cols; ++u) out[u] = {row[3 * u + 2], row[3 * u + 1], row[3 * u]};
    } else {
      for (int u = 0; u < mat.cols; ++u) out[u] = {row[u], row[u], row[u]};
    }
  }
  return image;
}

StatusOr<ColorImage> readColorImage(const fs::path& path) {
  OBJDB_ASSIGN_OR_RETURN(const std::string bytes, readImageFile(path));
  return decodeColorImage(bytes, path.string());
}

Status writeColorPng(const fs::path& path, const ColorImage& image) {
  OBJDB_RETURN_IF_ERROR(checkImageForWrite(path, image.width, image.height, image.data.size()));
  cv::Mat mat(image.height, image.width, CV_8UC3);
  for (int v = 0; v < image.height; ++v) {
    uint8_t* row = mat.ptr<uint8_t>(v);
    const Rgb8* in = &image.at(0, v);
    for (int u = 0; u < image.width; ++u) {
      row[3 * u] = in[u].b;
      row[3 * u + 1] = in[u].g;
      row[3 * u + 2] = in[u].r;
    }
  }
  return encodeAndWrite(path, mat);
}

}  // namespace objdb::io

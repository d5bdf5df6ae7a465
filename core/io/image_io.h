// PNG/JPEG image files for datasets (OpenCV imgcodecs underneath). Errors name the file and say
// what was expected ("depth/000003.png is 8-bit; expected 16-bit single channel").
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include "core/common/image.h"

namespace objdb::io {

// 16-bit single-channel PNG (depth in sensor units, or instance ids).
StatusOr<RawDepthImage> readUint16Png(const std::filesystem::path& path);
// The same from an encoded PNG in memory (a frame on the wire); `name` names it in errors. The
// header's size is checked before anything is decoded: at most kMaxImageSide per side, and with
// expect_width > 0 exactly expect_width × expect_height.
StatusOr<RawDepthImage> decodeUint16Png(std::string_view bytes, const std::string& name,
                                        int expect_width = 0, int expect_height = 0);
Status writeUint16Png(const std::filesystem::path& path, const Image<uint16_t>& image);
// An id image (ground-truth instances or class labels): a single-channel PNG of 16 or 8 bits
// (label-fusion's labels/ are 8-bit), as 16-bit ids.
StatusOr<Image<uint16_t>> readIdPng(const std::filesystem::path& path);

// 8-bit colour image (PNG or JPEG, 3 channels; grey images are expanded), RGB order.
StatusOr<ColorImage> readColorImage(const std::filesystem::path& path);
StatusOr<ColorImage> decodeColorImage(std::string_view bytes, const std::string& name,
                                      int expect_width = 0, int expect_height = 0);
Status writeColorPng(const std::filesystem::path& path, const ColorImage& image);

}  // namespace objdb::io

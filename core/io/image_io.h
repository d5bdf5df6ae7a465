// PNG/JPEG image files for datasets (OpenCV imgcodecs underneath). Errors name the file and say
// what was expected ("depth/000003.png is 8-bit; expected 16-bit single channel").
#pragma once

#include <filesystem>

#include "core/common/image.h"

namespace objdb::io {

// 16-bit single-channel PNG (depth in sensor units, or instance ids).
StatusOr<RawDepthImage> readUint16Png(const std::filesystem::path& path);
Status writeUint16Png(const std::filesystem::path& path, const Image<uint16_t>& image);

// 8-bit colour image (PNG or JPEG, 3 channels; grey images are expanded), RGB order.
StatusOr<ColorImage> readColorImage(const std::filesystem::path& path);
Status writeColorPng(const std::filesystem::path& path, const ColorImage& image);

}  // namespace objdb::io

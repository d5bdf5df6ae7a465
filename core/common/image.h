// Images as plain row-major arrays. Depth is either raw 16-bit units with a scale (what files and
// the wire carry) or float metres (what algorithms use); 0 or NaN metres means "no measurement".
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include "core/common/status.h"

namespace objdb {

template <typename T>
struct Image {
  int width = 0;
  int height = 0;
  std::vector<T> data;  // row-major, width * height

  Image() = default;
  Image(int w, int h, T fill = T{}) : width(w), height(h), data(size_t(w) * size_t(h), fill) {}

  T& at(int u, int v) { return data[size_t(v) * size_t(width) + size_t(u)]; }
  const T& at(int u, int v) const { return data[size_t(v) * size_t(width) + size_t(u)]; }
  bool empty() const { return data.empty(); }
  size_t size() const { return data.size(); }
  bool operator==(const Image&) const = default;
};

struct Rgb8 {
  uint8_t r = 0, g = 0, b = 0;
  bool operator==(const Rgb8&) const = default;
};

using DepthImage = Image<float>;           // metres; 0 or non-finite = invalid
using RawDepthImage = Image<uint16_t>;     // sensor units; 0 = invalid
using ColorImage = Image<Rgb8>;
using InstanceImage = Image<uint16_t>;     // ground-truth instance id per pixel, 0 = none

inline bool isValidDepth(float d) { return std::isfinite(d) && d > 0.0f; }

// metres = raw * metres_per_unit. Fails on a non-positive or non-finite scale.
StatusOr<DepthImage> depthFromRaw(const RawDepthImage& raw, double metres_per_unit);

// raw = round(metres / metres_per_unit); invalid, negative or unrepresentable (> 65535 units)
// depths become 0. `clipped` (optional) counts valid depths that did not fit.
StatusOr<RawDepthImage> depthToRaw(const DepthImage& depth, double metres_per_unit,
                                   size_t* clipped = nullptr);

}  // namespace objdb

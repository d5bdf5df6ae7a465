#include "core/common/image.h"

#include <cmath>

namespace objdb {
namespace {
Status checkScale(double metres_per_unit) {
  if (std::isfinite(metres_per_unit) && metres_per_unit > 0.0) return absl::OkStatus();
  return absl::InvalidArgumentError(
      absl::StrFormat("depth scale must be finite and > 0 metres per unit (got %g)",
                      metres_per_unit));
}
}  // namespace

StatusOr<DepthImage> depthFromRaw(const RawDepthImage& raw, double metres_per_unit) {
  OBJDB_RETURN_IF_ERROR(checkScale(metres_per_unit));
  DepthImage depth(raw.width, raw.height);
  const float scale = static_cast<float>(metres_per_unit);
  for (size_t i = 0; i < raw.data.size(); ++i) depth.data[i] = float(raw.data[i]) * scale;
  return depth;
}

StatusOr<RawDepthImage> depthToRaw(const DepthImage& depth, double metres_per_unit,
                                   size_t* clipped) {
  OBJDB_RETURN_IF_ERROR(checkScale(metres_per_unit));
  RawDepthImage raw(depth.width, depth.height);
  size_t n_clipped = 0;
  const double inv = 1.0 / metres_per_unit;
  for (size_t i = 0; i < depth.data.size(); ++i) {
    const float d = depth.data[i];
    if (!isValidDepth(d)) continue;
    const double units = std::round(double(d) * inv);
    if (units <= 65535.0) {
      raw.data[i] = static_cast<uint16_t>(units);
    } else {
      ++n_clipped;
    }
  }
  if (clipped) *clipped = n_clipped;
  return raw;
}

}  // namespace objdb

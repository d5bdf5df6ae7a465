// One posed RGB-D frame as the pipeline consumes it.
#pragma once

#include <optional>

#include "core/common/image.h"
#include "core/common/intrinsics.h"
#include "core/common/transform.h"

namespace objdb {

struct Frame {
  size_t index = 0;          // position in its sequence, from 0
  double timestamp = 0.0;    // seconds
  Transform T_world_camera = Transform::Identity();
  DepthImage depth;          // metres
  std::optional<ColorImage> color;          // registered to depth when present
  std::optional<InstanceImage> instances;   // ground truth (synthetic data only)
};

// Checks sizes against the intrinsics and the pose's validity; names the frame in the message.
Status validateFrame(const Frame& frame, const Intrinsics& intrinsics);

}  // namespace objdb

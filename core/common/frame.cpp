#include "core/common/frame.h"

namespace objdb {

Status validateFrame(const Frame& frame, const Intrinsics& intrinsics) {
  const std::string name = absl::StrCat("frame ", frame.index);
  OBJDB_RETURN_IF_ERROR(
      intrinsics.checkImageSize(frame.depth.width, frame.depth.height, name + " depth image"));
  if (frame.depth.data.size() != size_t(frame.depth.width) * size_t(frame.depth.height)) {
    return absl::InvalidArgumentError(name + " depth image has the wrong number of pixels");
  }
  if (frame.color) {
    OBJDB_RETURN_IF_ERROR(
        intrinsics.checkImageSize(frame.color->width, frame.color->height, name + " colour image"));
  }
  if (frame.instances) {
    OBJDB_RETURN_IF_ERROR(intrinsics.checkImageSize(frame.instances->width,
                                                    frame.instances->height,
                                                    name + " instance image"));
  }
  return validateTransform(frame.T_world_camera, name + " pose T_world_camera");
}

}  // namespace objdb

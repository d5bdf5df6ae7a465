// Ground truth shared by the objdb and TUM layouts: objects.json (the annotated object instances)
// and instances/*.png (16-bit instance id per pixel, 0 = none). One reader for both layouts, so
// the format is defined once. See docs/dataset-format.md ("objects.json").
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "core/common/image.h"
#include "core/common/intrinsics.h"
#include "core/common/transform.h"

namespace objdb::io {

// One ground-truth object instance of a synthetic (or annotated) session.
struct GroundTruthObject {
  int id = 0;            // instance id as in instances/*.png (1..65535)
  std::string category;  // object kind ("round_chair", "floor", "wall", ...)
  std::string mesh;      // mesh name or file the instance was built from
  Transform T_world_object = Transform::Identity();
  bool is_structure = false;  // floor/walls: background for object-level evaluation
  bool operator==(const GroundTruthObject& o) const {
    return id == o.id && category == o.category && mesh == o.mesh &&
           T_world_object.isApprox(o.T_world_object, 1e-9) && is_structure == o.is_structure;
  }
};

// {"objects": [{"id", "category", "mesh", "structure", "T_world_object": {"t", "q"}}, ...]};
// errors name the file, the entry and the field.
StatusOr<std::vector<GroundTruthObject>> readObjectsJson(const std::filesystem::path& path);
Status writeObjectsJson(const std::filesystem::path& path,
                        const std::vector<GroundTruthObject>& objects);

// One frame's instances image (16- or 8-bit single-channel PNG); NotFound when missing, and an
// error naming the file unless it is exactly intrinsics.width × intrinsics.height.
StatusOr<InstanceImage> readInstanceImage(const std::filesystem::path& path,
                                          const Intrinsics& intrinsics);

}  // namespace objdb::io

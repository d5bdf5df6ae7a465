// Small analytic object scenes for the database and completion tests: shapes standing on z = 0,
// their scene maps and raw segments as the GSM would hand them over, with partial views.
#pragma once

#include <cstdint>
#include <vector>

#include "core/common/transform.h"
#include "core/gsm/gsm.h"
#include "tests/support/sdf_grid.h"

namespace objdb::testing {

constexpr float kSceneVoxel = 0.02f;
constexpr float kSceneBand = 3 * kSceneVoxel;

Sdf boxWithBall();    // a box with a ball on its top edge and a block on one side (no symmetry)
Sdf chair();          // seat, back, four legs
Sdf extinguisher();   // cylinder, dome, nozzle

Transform poseXyYaw(double x, double y, double yaw);

struct PlacedShape {
  Sdf shape;
  Transform T_world_object;
};

// Which part of a shape a camera saw: object-frame x in [x_min, x_max].
struct View {
  float x_min = -10.0f, x_max = 10.0f;
  bool contains(const Eigen::Vector3f& p_object) const {
    return p_object.x() >= x_min && p_object.x() <= x_max;
  }
};

// The scene map: every shape's band, observed only where its view saw it (voxels of one shape's
// unseen side stay unobserved).
tsdf::TsdfLayer sceneGrid(const std::vector<PlacedShape>& shapes,
                          const std::vector<View>& views = {});

// A raw segment of one shape: the label's voxels (seen surface above the floor) in a grid of the
// shape's band restricted to the view, in the world frame (T_world_segment = identity).
gsm::RawSegment rawSegment(uint32_t label, const PlacedShape& shape, const View& view = {});

}  // namespace objdb::testing

// CPU z-buffer rasteriser for the synthetic world: renders exact depth (along the optical axis),
// ground-truth instance ids, a shaded colour image and the cosine between the viewing ray and
// the surface normal (used by the noise model for grazing-angle dropouts).
#pragma once

#include <cstdint>
#include <vector>

#include "core/common/image.h"
#include "core/common/intrinsics.h"
#include "core/common/mesh.h"
#include "core/common/transform.h"

namespace objdb::sim {

struct RenderInstance {
  const TriangleMesh* mesh = nullptr;  // object-frame mesh, not owned
  Transform T_world_object = Transform::Identity();
  uint16_t instance_id = 0;            // written to the instance image (0 = none)
  Rgb8 albedo{180, 180, 180};
  float bounding_radius = 0.0f;        // about the object origin; 0 → computed on first use
};

struct RenderParams {
  float near_m = 0.05f;       // triangles are clipped at this depth
  float far_m = 50.0f;        // nothing beyond
  float ambient = 0.3f;       // shading: albedo · (ambient + (1 − ambient) · |cos|), headlight
  bool render_color = true;
};

struct RenderOutput {
  DepthImage depth;           // metres; 0 = nothing hit
  InstanceImage instances;    // 0 = nothing / no instance
  ColorImage color;           // empty unless RenderParams::render_color
  Image<float> cos_incidence; // |cos| between viewing ray and face normal; 0 where no hit
};

class Renderer {
 public:
  Renderer(const Intrinsics& intrinsics, const RenderParams& params = {});
  // Renders `instances` seen from T_world_camera into `out` (images resized as needed).
  void render(const std::vector<RenderInstance>& instances, const Transform& T_world_camera,
              RenderOutput* out) const;
  const Intrinsics& intrinsics() const { return intrinsics_; }

 private:
  void rasterizeTriangle(const Eigen::Vector3f& a, const Eigen::Vector3f& b,
                         const Eigen::Vector3f& c, uint16_t id,
                         const Eigen::Vector3f& normal, const Rgb8& albedo,
                         RenderOutput* out) const;
  Intrinsics intrinsics_;
  RenderParams params_;
};

// Radius of the smallest origin-centred sphere holding every vertex.
float boundingRadius(const TriangleMesh& mesh);

}  // namespace objdb::sim

// Furniture built from parts for the GSM tests: each part its own instance (its own segment in
// every frame, as a convex segmenter would cut it), on a floor (instance 1), fused by a GSM from
// a ring of cameras. `T_world_scene` places the whole scene (and its cameras) in the world, so a
// test can put it in a world whose z is not up.
#pragma once

#include <cmath>
#include <cstdint>
#include <map>
#include <set>
#include <vector>

#include <gtest/gtest.h>

#include "core/common/mesh.h"
#include "core/common/transform.h"
#include "core/gsm/gsm.h"
#include "core/sim/renderer.h"
#include "core/sim/shapes.h"

namespace objdb::testing {

struct FurniturePart {
  TriangleMesh mesh;
  Transform T = Transform::Identity();
  uint16_t id = 0;
};

class FurnitureScene {
 public:
  FurnitureScene() { add(sim::makePlane(8.0f, 8.0f, 0.5f), Eigen::Vector3d::Zero(), 1); }
  void add(TriangleMesh mesh, const Eigen::Vector3d& at, uint16_t id) {
    FurniturePart p{std::move(mesh), Transform::Identity(), id};
    p.T.translation() = at;
    parts_.push_back(std::move(p));
  }
  // Places the scene and its cameras in the world (default: identity, z up).
  void setWorld(const Transform& T_world_scene) { T_world_scene_ = T_world_scene; }
  void addBox(const Eigen::Vector3f& size, const Eigen::Vector3d& centre, uint16_t id) {
    add(sim::makeBox(size), centre, id);
  }
  // A chair: seat (first id), back on the seat's rear edge (+1), four legs (+2 … +5). Its
  // front faces +y; `at` is the middle of its footprint on the floor.
  void addChair(const Eigen::Vector3d& at, uint16_t first_id) {
    addBox({0.45f, 0.45f, 0.04f}, at + Eigen::Vector3d(0, 0, 0.45), first_id);
    addBox({0.45f, 0.04f, 0.45f}, at + Eigen::Vector3d(0, -0.205, 0.695), uint16_t(first_id + 1));
    uint16_t leg = uint16_t(first_id + 2);
    for (const double x : {-0.19, 0.19}) {
      for (const double y : {-0.19, 0.19}) {
        addBox({0.04f, 0.04f, 0.43f}, at + Eigen::Vector3d(x, y, 0.215), leg++);
      }
    }
  }
  // A pedestal chair as the lounge has them: a seat disc (first id) on a thin column (+1) on a
  // base disc 3 cm high, which the segmenter cannot tell from the floor: it is segmented with
  // the floor (instance 1). Seen from 1.6 m, the column's top is in the seat's shadow.
  void addPedestalChair(const Eigen::Vector3d& at, uint16_t first_id) {
    add(sim::makeCylinder(0.25f, 0.03f), at, 1);
    add(sim::makeCylinder(0.035f, 0.42f, 16), at + Eigen::Vector3d(0, 0, 0.03),
        uint16_t(first_id + 1));
    add(sim::makeCylinder(0.23f, 0.05f), at + Eigen::Vector3d(0, 0, 0.43), first_id);
  }
  // A table 1.0 × 0.7 m, 0.74 m high: top (first id), four legs (+1 … +4).
  void addTable(const Eigen::Vector3d& at, uint16_t first_id) {
    addBox({1.0f, 0.7f, 0.04f}, at + Eigen::Vector3d(0, 0, 0.72), first_id);
    uint16_t leg = uint16_t(first_id + 1);
    for (const double x : {-0.45, 0.45}) {
      for (const double y : {-0.3, 0.3}) {
        addBox({0.05f, 0.05f, 0.70f}, at + Eigen::Vector3d(x, y, 0.35), leg++);
      }
    }
  }

  // Fuses the scene seen from `frames` cameras on a circle around `centre` (`radius`,
  // `height` high) and returns the global label of each instance. With `only`, the other
  // instances are fused as surface but get no segment.
  std::map<uint16_t, gsm::Label> fuse(gsm::Gsm* gsm, const Eigen::Vector3d& centre, int frames = 16,
                                 double phase = 0.0, const std::set<uint16_t>& only = {},
                                 double height = 1.6, double radius = 2.2) const {
    const Intrinsics k = Intrinsics::vga();
    const sim::Renderer renderer(k);
    sim::RenderOutput out;
    std::vector<sim::RenderInstance> instances;
    for (const FurniturePart& p : parts_) {
      instances.push_back({&p.mesh, T_world_scene_ * p.T, p.id});
    }
    std::map<uint16_t, gsm::Label> label_of;
    for (int f = 0; f < frames; ++f) {
      const double a = phase + 2.0 * M_PI * f / frames;
      const Transform T = T_world_scene_ *
          lookAt(centre + Eigen::Vector3d(radius * std::cos(a), radius * std::sin(a),
                                         height - centre.z()),
                 centre)
              .value();
      renderer.render(instances, T, &out);
      segmentation::LabelImage labels(out.instances.width, out.instances.height, 0);
      for (size_t i = 0; i < labels.data.size(); ++i) {
        const uint16_t id = out.instances.data[i];
        labels.data[i] = only.empty() || only.count(id) ? id : 0;
      }
      const auto r = gsm->integrate(out.depth, labels, T);
      EXPECT_TRUE(r.ok()) << r.status();
      for (size_t s = 0; s < r->segment_labels.size(); ++s) {
        if (r->segment_labels[s] != 0) label_of[uint16_t(s + 1)] = r->segment_labels[s];
      }
    }
    for (auto& [id, l] : label_of) l = gsm->resolve(l);
    return label_of;
  }

 private:
  std::vector<FurniturePart> parts_;
  Transform T_world_scene_ = Transform::Identity();
};

// A GSM at 2 cm voxels for VGA frames.
inline gsm::Gsm makeGsm(GsmParams params = {}) {
  TsdfParams tsdf;
  tsdf.voxel_size_m = 0.02f;
  return gsm::Gsm::create(tsdf, params, Intrinsics::vga()).value();
}

// The object holding instance `id` (0: none).
inline gsm::Label objectOf(const gsm::ObjectGroups& g,
                           const std::map<uint16_t, gsm::Label>& label_of, uint16_t id) {
  const auto l = label_of.find(id);
  if (l == label_of.end()) return 0;
  const auto o = g.object_of.find(l->second);
  return o == g.object_of.end() ? 0 : o->second;
}

}  // namespace objdb::testing

// Scores of a scene completion (evaluation only: `objdb eval` and bench/database_eval): what it
// added, whether the session's own frames contradict it, and, with ground truth, how much of the
// true surface of repeated objects it recovered.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/common/frame.h"
#include "core/common/intrinsics.h"
#include "core/common/mesh.h"
#include "core/common/mesh_distance.h"
#include "core/common/status.h"
#include "core/common/transform.h"

namespace objdb::completion {

// Vertices of `after` (the completed scene's mesh) farther than before.maxDistance() from the
// measured mesh: the surface completion added.
std::vector<Eigen::Vector3f> addedVertices(const TriangleMesh& after, const MeshDistance& before);

// What a session's frames say about added surface points (world frame). A frame sees through a
// point when, projected into it, the point lies in front of the measured depth by more than
// max(3 cm, 2 % of the depth): the camera saw free space there. It sees the point on a surface
// within that tolerance of the measured depth. Otherwise (behind the measurement, outside the
// image, no depth) it says nothing. A point is seen through when more frames see through it than
// on a surface (one noisy frame does not condemn a point many frames saw on a surface), and on a
// surface when at least as many see it there.
struct FrameEvidence {
  size_t points = 0;
  size_t seen_through = 0;
  size_t seen_on_surface = 0;
};
class FrameChecker {
 public:
  explicit FrameChecker(std::vector<Eigen::Vector3f> points);
  void add(const Frame& frame, const Intrinsics& k);  // one frame's votes
  FrameEvidence evidence() const;

 private:
  std::vector<Eigen::Vector3f> points_;
  std::vector<uint32_t> through_, on_surface_;  // votes per point
};

// One ground-truth object instance: its shape (object frame; instances of one shape share the
// mesh or have equal vertex lists) at its pose in its session.
struct TrueInstance {
  std::string session, kind;
  int id = 0;
  const TriangleMesh* mesh = nullptr;
  Transform T_world_object = Transform::Identity();
};

// For every instance of a kind with two or more instances (over all sessions) whose session is in
// `before`: the share of its true surface (sampled every 1 cm) within `tolerance` of its
// session's reconstruction before and after completion, and the ceiling a perfect completion
// could reach (a point counts when some instance of the same shape, in any session, has it
// reconstructed before completion).
struct InstanceGain {
  size_t instance = 0;  // index into the input
  double before = 0.0, after = 0.0, ceiling = 0.0;
};
struct SurfaceGain {
  std::vector<InstanceGain> instances;  // in input order
  double before = 0.0, after = 0.0, ceiling = 0.0;  // means over them
};
// Errors: an instance without a mesh; `after` lacks a session of `before`.
StatusOr<SurfaceGain> surfaceGain(const std::vector<TrueInstance>& instances,
                                  const std::map<std::string, const MeshDistance*>& before,
                                  const std::map<std::string, const MeshDistance*>& after,
                                  float tolerance_m);

}  // namespace objdb::completion
